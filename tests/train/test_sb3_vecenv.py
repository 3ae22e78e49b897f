"""The SB3 VecEnv adapter: slots, seeding, truncation, terminal observations, auto-reset.

The reference is SB3's own ``DummyVecEnv`` over the centralized Gymnasium view, whose
observation is the agents' observations concatenated: copy i of the adapter must match
env i of ``DummyVecEnv`` step for step, flags and infos included.
"""

from __future__ import annotations

import numpy as np
import pytest
from gymnasium import spaces
from pettingzoo import ParallelEnv
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

from activetrack.envs import CentralizedTrackingEnv, parallel_env
from activetrack.train.sb3_vecenv import (
    BatchedCopies,
    ParallelCopies,
    SharedPolicyVecEnv,
    make_shared_vec_env,
)

M = 3  # sensors of the paper preset


def _actions(rng: np.random.Generator, n_slots: int) -> np.ndarray:
    # Beyond the box on purpose: both paths must scale long vectors onto the unit disk.
    return rng.uniform(-1.2, 1.2, (n_slots, 2)).astype(np.float32)


def _backend(kind: str, n_copies: int):
    if kind == "batched":
        return BatchedCopies(n_copies, "paper")
    return ParallelCopies([parallel_env("paper") for _ in range(n_copies)], kind == "fast")


@pytest.mark.parametrize("kind", ["batched", "fast", "dicts"])
def test_matches_dummy_vec_env_over_centralized_view(kind):
    n_copies, seed = 2, 11
    vec = SharedPolicyVecEnv(_backend(kind, n_copies))
    ref = DummyVecEnv([lambda: CentralizedTrackingEnv("paper") for _ in range(n_copies)])
    assert isinstance(vec, VecEnv)
    assert vec.num_envs == n_copies * M
    assert vec.seed(seed)[::M] == [seed + i for i in range(n_copies)]
    ref.seed(seed)  # DummyVecEnv: env i gets seed + i, the adapter's convention per copy
    obs, ref_obs = vec.reset(), ref.reset()
    assert obs.shape == (n_copies * M, vec.observation_space.shape[0])
    np.testing.assert_array_equal(obs.reshape(n_copies, -1), ref_obs)
    rng = np.random.default_rng(0)
    n_done = 0
    for _ in range(2 * 50 + 7):  # two full episodes and a bit: covers auto-reset twice
        act = _actions(rng, vec.num_envs)
        obs, rew, done, infos = vec.step(act)
        r_obs, r_rew, r_done, r_infos = ref.step(act.reshape(n_copies, -1))
        np.testing.assert_array_equal(obs.reshape(n_copies, -1), r_obs)
        np.testing.assert_allclose(
            rew.reshape(n_copies, M), np.repeat(r_rew[:, None], M, 1), rtol=1e-6
        )
        np.testing.assert_array_equal(done.reshape(n_copies, M), np.repeat(r_done[:, None], M, 1))
        for s, info in enumerate(infos):
            i = s // M
            assert ("terminal_observation" in info) == bool(r_done[i])
            if r_done[i]:
                n_done += 1
                assert info["TimeLimit.truncated"] is True
                assert r_infos[i]["TimeLimit.truncated"] is True
                term = r_infos[i]["terminal_observation"].reshape(M, -1)[s % M]
                np.testing.assert_array_equal(info["terminal_observation"], term)
            assert info["trace"] == pytest.approx(r_infos[i]["trace"])
    assert n_done == 2 * n_copies * M


def test_terminal_observation_and_reset_observation_independently():
    """At the time limit: the last observation goes to the info, the next episode's first
    observation (the copy's generator continued) is returned."""
    seed = 5
    vec = make_shared_vec_env("paper", n_copies=2)
    vec.seed(seed)
    vec.reset()
    ref = [parallel_env("paper") for _ in range(2)]
    for i, env in enumerate(ref):
        env.reset(seed=seed + i)
    act = np.tile(np.array([[0.6, -0.8]], np.float32), (vec.num_envs, 1))
    for k in range(50):
        obs, _, done, infos = vec.step(act)
        expect = [e.step({a: act[0] for a in e.agents}) for e in ref]
        assert done.all() == (k == 49)
        assert not done.any() or k == 49
    for i, (e_obs, _, _, e_trunc, _) in enumerate(expect):
        assert all(e_trunc.values())
        for j, agent in enumerate(ref[i].possible_agents):
            info = infos[i * M + j]
            assert info["TimeLimit.truncated"] is True
            np.testing.assert_array_equal(info["terminal_observation"], e_obs[agent])
        new_obs, _ = ref[i].reset()  # no seed: the copy's generator continues
        np.testing.assert_array_equal(obs[i * M : (i + 1) * M], np.stack(list(new_obs.values())))


def test_termination_is_not_truncation():
    vec = make_shared_vec_env("paper", n_copies=1, max_trace=1e-6)  # ends at the first step
    vec.seed(0)
    vec.reset()
    _, _, done, infos = vec.step(np.zeros((M, 2), np.float32))
    assert done.all()
    assert all(info["TimeLimit.truncated"] is False for info in infos)
    assert all("terminal_observation" in info for info in infos)


def test_seeding_reproducible_and_distinct_per_copy():
    def run(seed):
        vec = make_shared_vec_env("paper", n_copies=3)
        vec.seed(seed)
        out = [vec.reset()]
        rng = np.random.default_rng(1)
        for _ in range(60):
            out.append(vec.step(_actions(rng, vec.num_envs))[0])
        return np.stack(out)

    a, b, c = run(3), run(3), run(4)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # Copy 1 of seed 3 starts like copy 0 of seed 4 (seed + i per copy).
    np.testing.assert_array_equal(a[0, M : 2 * M], c[0, 0:M])
    # Copies differ from each other.
    assert not np.array_equal(a[0, 0:M], a[0, M : 2 * M])
    # A seed is used once: a second reset without seed() continues the generators.
    vec = make_shared_vec_env("paper", n_copies=1)
    vec.seed(3)
    first, second = vec.reset(), vec.reset()
    np.testing.assert_array_equal(first, a[0, :M])
    assert not np.array_equal(first, second)


class _CountdownEnv(ParallelEnv):
    """Two agents; the episode lasts ``length`` steps; obs = [steps left, copy id]."""

    metadata = {"name": "countdown"}

    def __init__(self, length: int, ident: float) -> None:
        self.length, self.ident = length, ident
        self.render_mode = None
        self.possible_agents = ["a", "b"]
        self.agents: list[str] = []
        self._obs = spaces.Box(-np.inf, np.inf, (2,), np.float32)
        self._act = spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.resets: list[int | None] = []

    def observation_space(self, agent):
        return self._obs

    def action_space(self, agent):
        return self._act

    def _o(self):
        return {a: np.array([self.left, self.ident], np.float32) for a in self.agents}

    def reset(self, seed=None, options=None):
        self.resets.append(seed)
        self.agents = self.possible_agents[:]
        self.left = self.length
        return self._o(), {a: {} for a in self.agents}

    def step(self, actions):
        self.left -= 1
        obs = self._o()
        trunc = self.left == 0
        out = (
            obs,
            dict.fromkeys(self.agents, 1.0),
            dict.fromkeys(self.agents, False),
            dict.fromkeys(self.agents, trunc),
            {a: {} for a in self.agents},
        )
        if trunc:
            self.agents = []
        return out


def test_copies_reset_independently():
    envs = [_CountdownEnv(2, 0.0), _CountdownEnv(3, 1.0)]
    vec = SharedPolicyVecEnv(envs)
    assert vec.num_envs == 4 and not vec.copies.fast
    vec.seed(100)
    vec.reset()
    assert [e.resets for e in envs] == [[100], [101]]
    act = np.zeros((4, 2), np.float32)
    dones = []
    for _ in range(6):
        obs, rew, done, infos = vec.step(act)
        dones.append(done.reshape(2, 2)[:, 0].tolist())
        for s in np.flatnonzero(done):
            assert infos[s]["terminal_observation"][0] == 0.0  # no steps left
            assert infos[s]["TimeLimit.truncated"] is True
            assert obs[s][0] == envs[s // 2].length  # already reset
    assert dones == [
        [False, False],
        [True, False],
        [False, True],
        [True, False],
        [False, False],
        [True, True],
    ]
    assert [e.resets for e in envs] == [[100, None, None, None], [101, None, None]]


@pytest.mark.parametrize("overrides", [{}, {"max_trace": 3.5}], ids=["paper", "terminations"])
def test_batched_and_parallel_backends_agree_exactly(overrides):
    # With max_trace, copies end early with noise of their blocks unused (batched backend).
    a = make_shared_vec_env("paper", 3, backend="batched", **overrides)
    b = make_shared_vec_env("paper", 3, backend="parallel", **overrides)
    a.seed(7)
    b.seed(7)
    np.testing.assert_array_equal(a.reset(), b.reset())
    rng = np.random.default_rng(0)
    for _ in range(110):
        act = _actions(rng, a.num_envs)
        (oa, ra, da, ia), (ob, rb, db, ib) = a.step(act), b.step(act)
        np.testing.assert_array_equal(oa, ob)
        np.testing.assert_array_equal(ra, rb)
        np.testing.assert_array_equal(da, db)
        for x, y in zip(ia, ib, strict=True):
            assert x.keys() == y.keys()
            if "terminal_observation" in x:
                np.testing.assert_array_equal(x["terminal_observation"], y["terminal_observation"])
                assert x["TimeLimit.truncated"] == y["TimeLimit.truncated"]


def test_attribute_access_maps_slots_to_copies():
    vec = make_shared_vec_env("paper", n_copies=2, backend="parallel")
    assert vec.get_attr("n_sensors") == [M] * 6
    assert vec.get_attr("render_mode", indices=[0, 5]) == [None, None]
    assert vec.env_is_wrapped(object) == [False] * 6
    vec.set_attr("marker", 7, indices=[4])
    assert vec.get_attr("marker", indices=[3, 5]) == [7, 7]  # slots 3..5 are copy 1
    with pytest.raises(AttributeError):
        vec.get_attr("marker", indices=[0])


def test_bad_input_names_the_field():
    with pytest.raises(ValueError, match="n_copies must be an integer >= 1"):
        make_shared_vec_env("paper", 0, backend="parallel")
    vec = make_shared_vec_env("paper", 2)
    with pytest.raises(ValueError, match="seed must be None or an integer >= 0"):
        vec.seed(-1)
    vec.reset()
    with pytest.raises(ValueError, match=r"actions must have shape \(6, 2\), got \(7, 2\)"):
        vec.step(np.zeros((7, 2), np.float32))


def test_images_of_both_backends_are_the_copies_frames():
    # One frame per copy (not per slot), equal across backends: each copy is drawn as the
    # single env draws its episode.
    vecs = [
        make_shared_vec_env("paper", 2, backend=b, render_mode="rgb_array", n_steps=4)
        for b in ("batched", "parallel")
    ]
    rng = np.random.default_rng(0)
    for vec in vecs:
        vec.seed(3)
        vec.reset()
    for _ in range(2):
        a = _actions(rng, vecs[0].num_envs)
        frames = [vec.get_images() for vec in vecs]
        assert len(frames[0]) == len(frames[1]) == 2
        for got, want in zip(*frames, strict=True):
            assert got.dtype == np.uint8 and got.ndim == 3
            np.testing.assert_array_equal(got, want)
        for vec in vecs:
            vec.step(a)
    assert make_shared_vec_env("paper", 2).get_images() == [None, None]
