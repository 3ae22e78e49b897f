"""The decentralized tasks' environments (issue 37): each agent's reward from its own
robot's filter, the team's metrics in the infos, PettingZoo's checkers with decentralized
observations."""

from __future__ import annotations

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

from activetrack.envs import parallel_env
from activetrack.models.communication import FullCommunication
from activetrack.world import World


def _actions(env, rng):
    return {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.agents}


@pytest.mark.parametrize("name", ["radio", "urban_radio"])
def test_each_agent_is_rewarded_on_its_own_robot_filter(name):
    env = parallel_env(name)
    env.reset(seed=3)
    # the same episode in a bare world: the robots' scores, computed there
    w = World(name, 1)
    w.reset(seeds=[3])
    rng = np.random.default_rng(1)
    seen_different = False
    while env.agents:
        act = _actions(env, rng)
        _, rewards, _, _, infos = env.step(act)
        w.step_actions(np.stack([act[a] for a in env.possible_agents]).astype(np.float64))
        scores = np.array([P[..., 0, 0] + P[..., 1, 1] for P in [w.team_get("P", 0, 0)]])[0]
        for i, a in enumerate(env.possible_agents):
            assert rewards[a] == -scores[i]
            assert infos[a]["robot_score"] == scores[i]
        assert infos["sensor_0"]["robot_score_worst"] == scores.max()
        assert infos["sensor_0"]["robot_score_mean"] == pytest.approx(scores.mean(), rel=1e-12)
        seen_different |= len(set(rewards.values())) > 1
    assert seen_different  # limited links: the robots' estimates differ


def test_with_full_communication_every_agent_gets_the_team_reward():
    env = parallel_env("paper", communication=FullCommunication())
    plain = parallel_env("paper")
    env.reset(seed=5)
    plain.reset(seed=5)
    rng = np.random.default_rng(2)
    while env.agents:
        act = _actions(env, rng)
        _, rewards, _, _, infos = env.step(act)
        _, team, _, _, _ = plain.step(act)
        assert rewards == team
        assert infos["sensor_1"]["disagreement"] == 0.0


@pytest.mark.parametrize("name", ["radio", "urban_radio", "swarm"])
def test_decentralized_observations_pass_the_pettingzoo_checkers(name):
    parallel_api_test(parallel_env(name, team_observation=True, n_steps=20), num_cycles=25)
    parallel_seed_test(lambda: parallel_env(name, team_observation=True, n_steps=20), num_cycles=25)
