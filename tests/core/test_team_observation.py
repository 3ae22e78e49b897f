"""Decentralized observations (activetrack.world.team_observation): each agent's own
estimate and the messages it received, decoded back and compared with the world's
per-robot filters, links and fixes; never what it did not receive."""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.world import World, observation
from activetrack.world.team_observation import sizes

EXT_T, EXT_S = observation.EXT_TARGET_DIM, observation.EXT_SENSOR_DIM


def _world(name, copies=2, steps=6, **overrides):
    w = World(name, copies, team_observation=True, **overrides)
    w.reset(seeds=list(range(40, 40 + copies)))
    rng = np.random.default_rng(0)
    for _ in range(steps):
        w.step_actions(rng.uniform(-1, 1, (copies, w.n_sensors, 2)))
    return w


@pytest.mark.parametrize("name", ["radio", "urban_radio", "swarm"])
def test_each_agent_observes_its_own_estimate_and_the_messages_it_received(name):
    w = _world(name)
    obs = w.observe()
    m, kk, L = w.n_sensors, w.n_targets, w.length_scale
    own, block, tail, total = sizes(w)
    assert obs.shape == (2, m, total)
    low, high = w.observation_bounds()
    assert np.all((obs >= low) & (obs <= high))
    flags = w.layout.flags
    for c in range(2):
        links = w.links(c)
        fixes = w.get("fixes", c)
        for i in range(m):
            o = obs[c, i].astype(np.float64)
            pos = np.array([w.team_get("x_pred", c, k)[i, :2] for k in range(kk)])
            origin = pos.mean(0)
            for k in range(kk):  # its own prediction, decoded
                blk = o[EXT_T * k : EXT_T * (k + 1)]
                np.testing.assert_allclose(blk[:2] * L, pos[k] - origin, rtol=1e-5, atol=1e-4)
                P, v = observation.decode_target(blk[2:7], w.scenario.dt, L)
                np.testing.assert_allclose(
                    P, w.team_get("P_pred", c, k)[i, :2, :2], rtol=1e-4, atol=1e-6
                )
            mine = o[EXT_T * kk : own]
            np.testing.assert_allclose(mine[:2] * L, fixes[i] - origin, rtol=1e-5, atol=1e-4)
            for slot in range(1, m):
                j = (i + slot) % m
                b = o[own + (slot - 1) * block : own + slot * block]
                assert b[0] == float(links[i, j])
                if not links[i, j]:
                    assert not b.any()  # nothing of a robot it did not hear
                    continue
                np.testing.assert_allclose(b[1:3] * L, fixes[j] - origin, rtol=1e-5, atol=1e-4)
                if flags:
                    np.testing.assert_array_equal(
                        b[1 + EXT_S : 1 + EXT_S + flags], w.get("detected", c)[:, j]
                    )
                theirs = np.array([w.team_get("x_pred", c, k)[j, :2] for k in range(kk)])
                np.testing.assert_allclose(
                    b[1 + EXT_S + flags :].reshape(kk, 2) * L, theirs - origin, rtol=1e-5,
                    atol=1e-4,
                )  # fmt: skip
    # some links missing and some there: both branches ran
    assert 0 < w.links().sum() - 2 * m < 2 * m * (m - 1) or name == "radio"


def test_an_agent_does_not_see_the_estimate_of_a_robot_it_did_not_hear():
    w = _world("swarm", copies=1)
    links = w.links(0)
    i, j = np.argwhere(~links)[0]
    before = w.observe(0)[i].copy()
    for k in range(w.n_targets):  # change robot j's own estimate only
        w._robot_filters[k]["x_pred"][0, j, :2] += 5.0
    np.testing.assert_array_equal(w.observe(0)[i], before)
    heard = np.flatnonzero(links[:, j] & (np.arange(w.n_sensors) != j))
    assert heard.size and not np.array_equal(w.observe(0)[heard[0]], before)


def test_the_global_state_is_unchanged_by_team_observation():
    a = _world("urban_radio")
    b = World("urban_radio", 2)
    b.reset(seeds=[40, 41])
    rng = np.random.default_rng(0)
    for _ in range(6):
        b.step_actions(rng.uniform(-1, 1, (2, b.n_sensors, 2)))
    np.testing.assert_array_equal(a.state(), b.state())
