"""PPO through the adapter: determinism, warm start, outputs."""

from __future__ import annotations

import json
import tempfile
from dataclasses import replace

import numpy as np
import pytest
import torch

from activetrack.train.imitation import Dataset, fit
from activetrack.train.networks import NetConfig, build_policy
from activetrack.train.policy_io import load_policy, save_policy
from activetrack.train.ppo import (
    VALIDATION_SEED,
    PPOConfig,
    build_ppo,
    make_training_env,
    train_ppo,
    warm_start,
)
from activetrack.train.utils import params_vector

NET = NetConfig(hidden=(32, 32))
TINY = PPOConfig(
    total_timesteps=3000,
    n_copies=2,
    n_steps=128,
    batch_size=256,
    n_epochs=2,
    checkpoint_every=0,
    net=NET,
)


def test_same_seed_same_parameters_different_seed_different():
    a = train_ppo("paper", seed=5, config=TINY)
    b = train_ppo("paper", seed=5, config=TINY)
    c = train_ppo("paper", seed=6, config=TINY)
    pa, pb, pc = (params_vector(r.model.policy) for r in (a, b, c))
    assert a.model.num_timesteps >= TINY.total_timesteps
    np.testing.assert_array_equal(pa, pb)
    assert not np.array_equal(pa, pc)
    # Training moved the parameters away from the (seeded) initialization.
    fresh = build_ppo(make_training_env("paper", 2, "shared", True, 0.99), TINY, seed=5)
    assert not np.array_equal(params_vector(fresh.policy), pa)


def test_training_without_an_output_folder_writes_no_file(tmp_path, monkeypatch):
    # SB3 names its default log folder after tempfile.gettempdir(); point it at tmp_path.
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    train_ppo("paper", seed=0, config=replace(TINY, total_timesteps=256))
    # (torch may keep its own compile cache there; SB3's log folders must not appear.)
    assert list(tmp_path.glob("SB3-*")) == []


def test_centralized_view_trains_with_plain_sb3(tmp_path):
    cfg = PPOConfig(
        **{
            **TINY.__dict__,
            "view": "centralized",
            "n_steps": 64,
            "total_timesteps": 256,
            "checkpoint_every": 128,
            "batch_size": 128,
        }
    )
    res = train_ppo("paper", seed=0, config=cfg, out_dir=tmp_path)
    assert res.model.action_space.shape == (6,)
    learned = load_policy(tmp_path / "policy.zip")
    assert learned.view == "centralized" and learned.meta["seed"] == 0
    assert list((tmp_path / "checkpoints").glob("*.zip"))
    assert json.loads((tmp_path / "config.json").read_text())["seed"] == 0
    assert list((tmp_path / "tb").rglob("events.out.tfevents*"))


def test_warm_start_loads_the_actor_and_warms_the_critic(tmp_path):
    from activetrack.envs import parallel_env

    env = parallel_env("paper")
    obs_space, act_space = env.observation_space("sensor_0"), env.action_space("sensor_0")
    torch.manual_seed(0)
    bc = build_policy(obs_space, act_space, NET)
    rng = np.random.default_rng(0)
    data = Dataset(
        rng.normal(size=(256, 23)).astype(np.float32),
        rng.uniform(-0.7, 0.7, (256, 2)).astype(np.float32),
    )
    fit(bc, data, epochs=2)
    path = save_policy(tmp_path / "bc.zip", bc, NET, kind="bc", scenario={}, seed=0)

    cfg = PPOConfig(
        **{**TINY.__dict__, "total_timesteps": 1536, "critic_warmup": 768, "log_std_init": -2.0}
    )
    # Warm start alone: actor equal to BC's, critic not copied, log_std overridden.
    model = build_ppo(make_training_env("paper", 2, "shared", True, 0.99), cfg, seed=1)
    warm_start(model, path, -2.0)
    own, src = model.policy.state_dict(), bc.state_dict()
    for k in src:
        if "value" in k:
            continue
        if k == "log_std":
            assert torch.all(own[k] == -2.0)
        else:
            assert torch.equal(own[k], src[k]), k
    assert not torch.equal(own["value_net.weight"], src["value_net.weight"])

    # Training: the critic-only phase leaves the actor untouched, then PPO moves it.
    res = train_ppo("paper", seed=0, config=cfg, init=path)
    assert res.model.num_timesteps >= cfg.total_timesteps
    moved = res.model.policy.state_dict()
    assert not torch.equal(moved["action_net.weight"], src["action_net.weight"])
    only_warmup = PPOConfig(**{**cfg.__dict__, "total_timesteps": 768, "critic_warmup": 1536})
    res = train_ppo("paper", seed=0, config=only_warmup, init=path)
    assert res.model.num_timesteps == 768  # the warm-up stops at the budget
    st = res.model.policy.state_dict()
    assert torch.equal(st["action_net.weight"], src["action_net.weight"])
    assert torch.all(st["log_std"] == -2.0)
    # The same seed builds the same initial critic: the warm-up trained it.
    initial = build_ppo(make_training_env("paper", 2, "shared", True, 0.99), cfg, seed=0)
    assert not torch.equal(st["value_net.weight"], initial.policy.state_dict()["value_net.weight"])


def test_a_batch_larger_than_the_rollout_is_refused():
    # TINY's rollout: n_steps per slot times 2 copies of 3 agents.
    big = PPOConfig(**{**TINY.__dict__, "batch_size": TINY.n_steps * 6 + 1})
    with pytest.raises(
        ValueError, match=rf"batch_size must be at most the rollout.*= {TINY.n_steps * 6}"
    ):
        train_ppo("paper", seed=0, config=big)


def test_warm_start_rejects_another_architecture(tmp_path):
    from activetrack.envs import parallel_env

    env = parallel_env("paper")
    net = NetConfig(hidden=(8,))
    bc = build_policy(env.observation_space("sensor_0"), env.action_space("sensor_0"), net)
    path = save_policy(tmp_path / "bc.zip", bc, net, kind="bc", scenario={}, seed=0)
    with pytest.raises(ValueError, match="does not match"):
        train_ppo("paper", seed=0, config=TINY, init=path)


def test_linear_learning_rate_schedule():
    cfg = PPOConfig(**{**TINY.__dict__, "lr_schedule": "linear", "learning_rate": 1e-3})
    model = build_ppo(make_training_env("paper", 2, "shared", False, 0.99), cfg, seed=0)
    assert model.lr_schedule(1.0) == pytest.approx(1e-3)
    assert model.lr_schedule(0.25) == pytest.approx(2.5e-4)
    with pytest.raises(ValueError, match="lr_schedule"):
        build_ppo(model.env, PPOConfig(lr_schedule="cosine"), seed=0)


def test_keep_best_saves_the_policy_with_the_best_validation_trace(tmp_path):
    """With ``eval_every`` the policy is evaluated on the validation seeds after every
    rollout; ``keep_best`` saves the best of them, not the last. Seed 1 of this tiny run
    scores best at its first evaluation and worse at every later one (a high learning rate),
    so keeping the last policy would be a different, worse policy."""
    cfg = PPOConfig(
        **{
            **TINY.__dict__,
            "total_timesteps": 960,
            "n_copies": 1,
            "n_steps": 32,  # 96 timesteps per rollout (3 slots)
            "batch_size": 96,
            "learning_rate": 3e-3,
            "eval_every": 96,
            "eval_episodes": 4,
            "keep_best": True,
            "net": NetConfig(hidden=(16, 16)),
        }
    )
    episode = {"n_steps": 10}  # the scenario's episode length, in training and validation
    best = train_ppo("paper", seed=1, config=cfg, out_dir=tmp_path / "best", **episode)
    last = train_ppo(
        "paper", seed=1, config=replace(cfg, keep_best=False), out_dir=tmp_path / "last", **episode
    )
    assert best.validation == last.validation  # the same run; only what is saved differs
    steps, traces = zip(*best.validation, strict=True)
    assert list(steps) == list(range(96, 961, 96))  # one evaluation every eval_every steps
    logged = json.loads((tmp_path / "best" / "config.json").read_text())["validation"]
    assert logged == [list(entry) for entry in best.validation]
    k = int(np.argmin(traces))
    assert k < len(traces) - 1 and traces[-1] > traces[k], traces  # a worse later policy

    # The saved files, loaded and run on the validation seeds by the loop below: keep_best
    # saved the policy that scored traces[k] (bit for bit), without it the final policy
    # (updated once more after the last evaluation, which runs as the last rollout ends)
    # is saved, and it scores worse.
    assert _validation_trace(tmp_path / "best" / "policy.zip", 4, **episode) == traces[k]
    final = load_policy(tmp_path / "last" / "policy.zip").policy
    np.testing.assert_array_equal(params_vector(final), params_vector(last.model.policy))
    assert _validation_trace(tmp_path / "last" / "policy.zip", 4, **episode) > traces[k]


def _validation_trace(path, episodes: int, **overrides) -> float:
    """Return the mean trace of the saved policy ``path`` over the validation seeds."""
    from activetrack.envs import parallel_env

    learned = load_policy(path)
    env = parallel_env("paper", **overrides)
    traces = []
    for seed in range(VALIDATION_SEED, VALIDATION_SEED + episodes):
        obs, _ = env.reset(seed=seed)
        while env.agents:
            obs, _, _, _, infos = env.step(learned.act(obs))
            traces.append(infos["sensor_0"]["trace"])
    return float(np.mean(traces))
