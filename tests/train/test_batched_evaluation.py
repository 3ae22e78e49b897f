"""Learned policies evaluated batched (``evaluate(..., batched=True)``): the same episodes
as the serial evaluation, to float32 rounding."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from activetrack.baselines.evaluation import evaluate
from activetrack.envs import parallel_env
from activetrack.train.networks import NetConfig, build_policy
from activetrack.train.policy_io import load_policy, save_policy
from activetrack.world.scenarios import make_scenario


def _policy_file(tmp_path, scenario: str, view: str = "shared"):
    env = parallel_env(scenario)
    agent = env.possible_agents[0]
    obs_space, act_space = env.observation_space(agent), env.action_space(agent)
    if view == "centralized":
        from gymnasium import spaces

        m = len(env.possible_agents)
        obs_space = spaces.Box(
            np.tile(obs_space.low, m), np.tile(obs_space.high, m), dtype=np.float32
        )
        act_space = spaces.Box(
            np.tile(act_space.low, m), np.tile(act_space.high, m), dtype=np.float32
        )
    torch.manual_seed(1)
    net = NetConfig(hidden=(32, 32))
    policy = build_policy(obs_space, act_space, net)
    sc = make_scenario(scenario).to_dict()
    return save_policy(
        tmp_path / f"{scenario}_{view}.zip", policy, net, kind="bc", scenario=sc, seed=0,
        view=view,
    )  # fmt: skip


@pytest.mark.parametrize(("scenario", "view"), [("paper", "shared"), ("two_targets", "shared")])
def test_batched_rows_are_the_serial_ones(tmp_path, scenario, view):
    path = str(_policy_file(tmp_path, scenario, view))
    kw = {"scenario": scenario, "episodes": 4, "seed": 40, "progress": False}
    serial = evaluate([path], **kw)
    batched = evaluate([path], batched=True, **kw)
    for a, b in zip(serial, batched, strict=True):
        assert a.policy == b.policy
        np.testing.assert_allclose(b.mean_trace, a.mean_trace, rtol=1e-5)
        np.testing.assert_allclose(b.rmse, a.rmse, rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("view", ["shared", "centralized"])
def test_act_batch_is_act_per_team(tmp_path, view):
    learned = load_policy(_policy_file(tmp_path, "paper", view))
    obs = np.random.default_rng(0).normal(size=(5, 3, 23)).astype(np.float32)
    got = learned.act_batch(obs)
    agents = ["sensor_0", "sensor_1", "sensor_2"]
    for i in range(5):
        want = learned.act(dict(zip(agents, obs[i], strict=True)))
        np.testing.assert_allclose(got[i], np.stack([want[a] for a in agents]), atol=1e-6)
    with pytest.raises(ValueError, match="observations"):
        learned.act_batch(obs[0])
