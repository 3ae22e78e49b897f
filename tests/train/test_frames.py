"""The line-of-sight frame (activetrack.train.frames): a rotation-equivariant policy.

The checks are independent of the frame's own code: a rotated world is built by rotating
the loop's state (sensors, prediction, covariance) and observing it with the loop's own
observation, and the invariants of the frame change (trace and determinant of the
covariance, lengths and the angles between vectors) are computed from the raw state.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from activetrack.train.frames import SightFrame, sight_rotation, to_frame
from activetrack.train.networks import NetConfig, build_policy, mean_action


def _rot(theta: float) -> torch.Tensor:
    c, s = np.cos(theta), np.sin(theta)
    return torch.tensor([[c, -s], [s, c]], dtype=torch.float64)


@pytest.fixture(scope="module")
def loop():
    from activetrack.train.pathwise import LoopSimulator

    return LoopSimulator(__import__("activetrack").world.scenarios.make_scenario("paper"))


def _state(loop, seed: int = 0, n: int = 5):
    """Return ``(sensors, x_pred, P_pred)`` of ``n`` episodes with correlated covariances
    and nonzero velocities (the start has neither)."""
    rng = np.random.default_rng(seed)
    s = loop.start(rng, n)
    a = torch.as_tensor(rng.normal(size=(n, 4, 4)))
    P = s["P_pred"] + a @ a.transpose(1, 2)  # SPD, correlated
    x = s["x_pred"] + torch.as_tensor(rng.normal(scale=5.0, size=(n, 4)))
    return s["sensors"], x, P


def _rotated(loop, state, theta: float) -> torch.Tensor:
    """Return the observations (rows, D) of ``state`` turned by ``theta`` about the origin."""
    sensors, x, P = state
    R = _rot(theta)
    R4 = torch.block_diag(R, R)
    return loop.observe(sensors @ R.T, x @ R4.T, R4 @ P @ R4.T).reshape(-1, 5 + 6 * loop.m)


def _policy(frame: str, seed: int = 0):
    from activetrack.envs import parallel_env

    env = parallel_env("paper")
    agent = env.possible_agents[0]
    torch.manual_seed(seed)
    net = NetConfig(hidden=(32, 32), frame=frame)
    return build_policy(env.observation_space(agent), env.action_space(agent), net)


@pytest.mark.parametrize("theta", [0.4, 2.0, -2.9])
def test_the_sight_policy_turns_with_the_world_and_the_world_policy_does_not(loop, theta):
    state = _state(loop)
    obs, turned = _rotated(loop, state, 0.0), _rotated(loop, state, theta)
    R = _rot(theta).float()
    errors = {}
    for frame in ("sight", "world"):
        policy = _policy(frame)
        with torch.no_grad():
            a, b = mean_action(policy, obs.float()), mean_action(policy, turned.float())
        errors[frame] = float((b - a @ R.T).abs().max())
        # SB3's predict (the path of evaluate and of PPO's rollouts) agrees with it
        pa, _ = policy.predict(turned.float().numpy(), deterministic=True)
        np.testing.assert_allclose(pa, b.detach().numpy(), atol=1e-6)
    assert errors["sight"] < 1e-5  # float32 network
    assert errors["world"] > 1e-2  # the check can fail: a plain network is not equivariant


def test_ppo_s_log_probabilities_turn_with_the_world_while_the_noise_is_isotropic(loop):
    """evaluate_actions (PPO's loss) goes through the frame too: with equal standard
    deviations (the start), a turned world and turned actions have the same log-density."""
    state = _state(loop, seed=1)
    obs, turned = _rotated(loop, state, 0.0), _rotated(loop, state, 1.1)
    R = _rot(1.1).float()
    policy = _policy("sight", seed=2)
    actions = torch.as_tensor(np.random.default_rng(5).uniform(-0.7, 0.7, (obs.shape[0], 2)))
    actions = actions.float()
    with torch.no_grad():
        _, logp, _ = policy.evaluate_actions(obs.float(), actions)
        _, logp_turned, _ = policy.evaluate_actions(turned.float(), actions @ R.T)
        # and the log-density is the Gaussian's about the turned-back mean
        mean = mean_action(policy, obs.float())
        std = policy.log_std.exp()
        by_hand = torch.distributions.Normal(mean, std).log_prob(actions).sum(-1)
    torch.testing.assert_close(logp_turned, logp, rtol=0, atol=1e-4)
    torch.testing.assert_close(logp, by_hand, rtol=0, atol=1e-5)


def test_the_frame_keeps_lengths_angles_and_the_covariance_s_invariants(loop):
    sensors, x, P = _state(loop, seed=3)
    obs = loop.observe(sensors, x, P).reshape(-1, 5 + 6 * loop.m)
    framed = to_frame(obs, sight_rotation(obs))
    L = loop.L
    m = loop.m
    # the agent's own line of sight is the first axis: (|c_i|, 0)
    own = torch.linalg.vector_norm(obs[:, 5:7], dim=-1)
    torch.testing.assert_close(framed[:, 5], own)
    torch.testing.assert_close(framed[:, 6], torch.zeros_like(own), atol=1e-12, rtol=0)
    # the covariance: same trace and determinant as the raw P's position block
    sx, sy, corr = framed[:, 0].exp(), framed[:, 1].exp(), framed[:, 2]
    trace = (sx**2 + sy**2) * L**2
    det = (sx * sy) ** 2 * (1 - corr**2) * L**4
    raw = P[:, :2, :2].repeat_interleave(m, 0)
    torch.testing.assert_close(trace, raw.diagonal(dim1=1, dim2=2).sum(-1))
    torch.testing.assert_close(det, torch.linalg.det(raw))
    # every vector keeps its length and its angle to the line of sight
    vel = x[:, 2:].repeat_interleave(m, 0) * loop.dt / L
    torch.testing.assert_close(torch.linalg.vector_norm(framed[:, 3:5], dim=-1), vel.norm(dim=-1))
    for j in range(m):
        c = obs[:, 5 + 6 * j : 7 + 6 * j]
        cos = (c * obs[:, 5:7]).sum(-1) / (c.norm(dim=-1) * own)
        torch.testing.assert_close(framed[:, 5 + 6 * j] / c.norm(dim=-1), cos)
        constants = slice(7 + 6 * j, 11 + 6 * j)
        torch.testing.assert_close(framed[:, constants], obs[:, constants])


def test_degenerate_observations_stay_finite():
    """A correlation of +-1 (a clipped input) with the line of sight along the covariance's
    null direction, and an agent on the prediction: finite frames and actions."""
    obs = torch.zeros(3, 23, dtype=torch.float64)
    obs[:, 0:2] = 0.3  # equal sigmas: P's null direction is (1, -1) for corr = 1
    obs[0, 2], obs[0, 5:7] = 1.0, torch.tensor([1.0, -1.0])
    obs[1, 2], obs[1, 5:7] = -1.0, torch.tensor([2.0, 2.0])
    obs[2, 2] = 0.5  # c_i = 0: the world's frame
    framed = to_frame(obs, sight_rotation(obs))
    assert torch.isfinite(framed).all()
    torch.testing.assert_close(sight_rotation(obs)[2], torch.eye(2, dtype=torch.float64))
    actions, _ = _policy("sight").predict(obs.float().numpy(), deterministic=True)
    assert np.isfinite(actions).all()


def test_a_sight_policy_file_keeps_its_frame(tmp_path):
    from activetrack.train.policy_io import load_policy, save_policy

    policy = _policy("sight", seed=4)
    net = NetConfig(hidden=(32, 32), frame="sight")
    path = save_policy(tmp_path / "p.zip", policy, net, kind="bc", scenario={}, seed=4)
    loaded = load_policy(path)
    assert loaded.meta["net"]["frame"] == "sight"
    obs = np.random.default_rng(0).normal(size=(6, 23)).astype(np.float32)  # paper: M = 3
    obs[:, 2] = np.tanh(obs[:, 2])  # a correlation
    want, _ = policy.predict(obs, deterministic=True)
    np.testing.assert_array_equal(loaded.predict(obs), want)


def test_a_file_without_a_frame_is_in_the_world_frame():
    d = NetConfig(hidden=(8,)).to_dict()
    del d["frame"]  # the files written before the frame existed
    assert NetConfig.from_dict(d).frame == "world"


def test_the_frame_is_refused_where_it_does_not_apply(tmp_path):
    import gymnasium as gym

    from activetrack.train.frames import check_frame
    from activetrack.train.imitation import ImitationConfig, train_imitation

    with pytest.raises(ValueError, match="frame must be one of"):
        NetConfig(frame="body")
    check_frame("sight", "paper")  # the paper's layout
    check_frame("world", "two_targets")
    # five targets: the extended layout's 7K + 12M = 83 entries look like 5 + 6 * 13
    five = {"n_targets": 5, "x0": tuple((10.0 * k, 0.0, 1.0, 0.0) for k in range(5))}
    five["x0_hat"] = five["x0"]
    with pytest.raises(ValueError, match="extended layout"):
        check_frame("sight", "two_targets", **five)
    with pytest.raises(ValueError, match="appended entries"):
        check_frame("sight", "unicycle")  # the heading features after the paper's layout
    # refused by a trainer before any label is collected
    cfg = ImitationConfig(episodes=1, epochs=1, net=NetConfig(hidden=(8,), frame="sight"))
    with pytest.raises(ValueError, match="paper's observation layout"):
        train_imitation("two_targets", config=cfg, **five)
    box = gym.spaces.Box(-1, 1, (19,))
    with pytest.raises(ValueError, match="paper's observation layout"):
        SightFrame(box)
    from activetrack.envs import parallel_env

    env = parallel_env("two_targets")  # the extended layout
    agent = env.possible_agents[0]
    with pytest.raises(ValueError, match="paper's observation layout"):
        build_policy(
            env.observation_space(agent), env.action_space(agent), NetConfig(frame="sight")
        )
