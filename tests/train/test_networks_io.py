"""The policy network (saturated mean) and the single-file policy format."""

from __future__ import annotations

import zipfile

import numpy as np
import pytest
import torch
from gymnasium import spaces

from activetrack.envs import CentralizedTrackingEnv, parallel_env
from activetrack.train.networks import NetConfig, build_policy, mean_action, saturate
from activetrack.train.policy_io import load_policy, save_policy

OBS = spaces.Box(-np.inf, np.inf, (23,), np.float32)
ACT = spaces.Box(-1.0, 1.0, (2,), np.float32)


def test_saturate_is_unit_outside_the_small_ball():
    m = torch.tensor([[3.0, 4.0, 0.001, 0.0], [0.0, -0.5, 0.0, 0.0]])
    s = saturate(m, gain=100.0)
    expect = torch.tensor([[0.6, 0.8, 0.1, 0.0], [0.0, -1.0, 0.0, 0.0]])
    torch.testing.assert_close(s, expect)


@pytest.mark.parametrize("gain", [100.0, None])
def test_deterministic_action_is_the_mean(gain):
    torch.manual_seed(0)
    policy = build_policy(OBS, ACT, NetConfig(hidden=(16, 16), action_gain=gain))
    obs = np.random.default_rng(0).normal(size=(5, 23)).astype(np.float32)
    with torch.no_grad():
        mean = mean_action(policy, torch.as_tensor(obs)).numpy()
        dist_mean = policy.get_distribution(torch.as_tensor(obs)).distribution.mean.numpy()
    np.testing.assert_allclose(mean, dist_mean, rtol=1e-6)
    act, _ = policy.predict(obs, deterministic=True)
    np.testing.assert_allclose(act, np.clip(mean, -1, 1), rtol=1e-6)
    if gain is not None:
        with torch.no_grad():  # the raw linear head, before saturation
            raw = policy.action_net(policy.mlp_extractor.forward_actor(torch.as_tensor(obs)))
        raw_norm = np.linalg.norm(raw.numpy(), axis=1)
        np.testing.assert_allclose(
            np.linalg.norm(act, axis=1), np.minimum(gain * raw_norm, 1), rtol=1e-5
        )


def test_save_load_round_trip(tmp_path):
    torch.manual_seed(1)
    net = NetConfig(hidden=(32, 16), activation="relu", action_gain=None, log_std_init=-0.7)
    policy = build_policy(OBS, ACT, net)
    path = save_policy(
        tmp_path / "sub" / "policy.zip",
        policy,
        net,
        kind="bc",
        scenario={"name": "paper"},
        seed=7,
        train_config={"episodes": 3},
    )
    assert zipfile.ZipFile(path).namelist() == ["meta.json", "policy.pth"]
    loaded = load_policy(path)
    assert loaded.meta["seed"] == 7 and loaded.meta["kind"] == "bc"
    assert loaded.meta["train_config"] == {"episodes": 3}
    assert NetConfig.from_dict(loaded.meta["net"]) == net
    for (k, a), (k2, b) in zip(
        policy.state_dict().items(), loaded.policy.state_dict().items(), strict=True
    ):
        assert k == k2 and torch.equal(a, b)
    obs = np.random.default_rng(0).normal(size=(4, 23)).astype(np.float32)
    np.testing.assert_array_equal(loaded.predict(obs), policy.predict(obs, deterministic=True)[0])
    bad = tmp_path / "bad.zip"
    with zipfile.ZipFile(bad, "w") as zf:
        zf.writestr("meta.json", '{"format": "other"}')
    with pytest.raises(ValueError, match="not an activetrack policy"):
        load_policy(bad)


def test_act_uses_the_env_observations(tmp_path):
    env = parallel_env("paper")
    obs, _ = env.reset(seed=4)
    for _ in range(3):
        np.testing.assert_array_equal(
            np.stack(list(env.observe().values())), np.stack(list(obs.values()))
        )
        obs, *_ = env.step({a: np.array([0.2, 0.9]) for a in env.agents})
    torch.manual_seed(0)
    net = NetConfig(hidden=(8,))
    policy = build_policy(OBS, ACT, net)
    learned = load_policy(
        save_policy(tmp_path / "p.zip", policy, net, kind="bc", scenario={}, seed=0)
    )
    actions = learned.act(obs)
    assert list(actions) == env.agents
    np.testing.assert_array_equal(
        np.stack(list(actions.values())), learned.predict(np.stack(list(obs.values())))
    )


def test_centralized_view_act_concatenates(tmp_path):
    cenv = CentralizedTrackingEnv("paper")
    penv = parallel_env("paper")
    torch.manual_seed(0)
    net = NetConfig(hidden=(8,))
    policy = build_policy(cenv.observation_space, cenv.action_space, net)
    learned = load_policy(
        save_policy(
            tmp_path / "c.zip", policy, net, kind="ppo", scenario={}, seed=0, view="centralized"
        )
    )
    cobs, _ = cenv.reset(seed=9)
    pobs, _ = penv.reset(seed=9)
    joint = policy.predict(cobs, deterministic=True)[0]
    per_agent = learned.act(pobs)
    np.testing.assert_allclose(np.concatenate(list(per_agent.values())), joint, rtol=1e-6)
