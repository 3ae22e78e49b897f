"""The permutation-invariant policy (issue 37): its output does not depend on the order of
the neighbour blocks nor on masked (absent) ones, so one network runs on teams of any
size; a saved policy loads back through ``load_policy`` with the same outputs and a
malformed file is refused before allocating; a tiny DAgger run learns (its team's trace
against the untrained network's, on the same episodes)."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import torch

from activetrack.train.policy_io import load_policy
from activetrack.train.set_policy import (
    SetDaggerConfig,
    SetLayout,
    SetPolicy,
    SetPolicyNet,
    parameter_count,
    save_set_policy,
    train_set_dagger,
)
from activetrack.world import World

LAYOUT = SetLayout(own=9, block=6, tail=2)


def _obs(rng: np.random.Generator, n_blocks: int, rows: int = 5) -> np.ndarray:
    """Return random observations with ``n_blocks`` neighbour blocks, some masked off."""
    own = rng.normal(size=(rows, LAYOUT.own))
    blocks = rng.normal(size=(rows, n_blocks, LAYOUT.block))
    mask = rng.random((rows, n_blocks)) < 0.7
    blocks[..., 0] = mask
    blocks[~mask] = 0.0
    tail = rng.normal(size=(rows, LAYOUT.tail))
    return np.concatenate([own, blocks.reshape(rows, -1), tail], -1).astype(np.float32)


def _split(x: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    own, tail = x[:, : LAYOUT.own], x[:, x.shape[1] - LAYOUT.tail :]
    return own, x[:, LAYOUT.own : LAYOUT.own + n * LAYOUT.block].reshape(len(x), n, -1), tail


def test_output_ignores_the_order_and_the_number_of_absent_neighbours():
    torch.manual_seed(0)
    policy = SetPolicy(SetPolicyNet(LAYOUT, hidden=32, action_gain=3.0), {})
    rng = np.random.default_rng(1)
    x = _obs(rng, 5)
    base = policy.predict(x)
    own, blocks, tail = _split(x, 5)
    perm = blocks[:, rng.permutation(5)]
    padded = np.concatenate([blocks, np.zeros((len(x), 7, LAYOUT.block), np.float32)], 1)
    for b in (perm, padded):
        y = np.concatenate([own, b.reshape(len(x), -1), tail], -1)
        np.testing.assert_allclose(policy.predict(y), base, atol=1e-6)
    # A received block does change it (the set is read).
    own2 = blocks.copy()
    own2[:, :, 1:] += 1.0 * own2[:, :, :1]
    y = np.concatenate([own, own2.reshape(len(x), -1), tail], -1)
    assert np.abs(policy.predict(y) - base).max() > 1e-4
    with pytest.raises(ValueError, match="neighbour blocks"):
        policy.predict(x[:, :-1])


def test_saved_policy_loads_back_and_malformed_files_are_refused(tmp_path):
    torch.manual_seed(0)
    net = SetPolicyNet(LAYOUT, hidden=16)
    assert parameter_count(LAYOUT, 16) == sum(p.numel() for p in net.parameters())
    meta = {"network": "set", "layout": {"own": 9, "block": 6, "tail": 2}, "hidden": 16,
            "action_gain": 100.0}  # fmt: skip
    path = save_set_policy(tmp_path / "policy.zip", SetPolicy(net, meta))
    loaded = load_policy(path)
    x = _obs(np.random.default_rng(2), 3)
    np.testing.assert_array_equal(loaded.predict(x), SetPolicy(net, meta).predict(x))
    huge = tmp_path / "huge.zip"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(huge, "w") as dst:
        m = json.loads(src.read("meta.json"))
        m["layout"]["own"] = 1_000_000
        m["hidden"] = 1024
        dst.writestr("meta.json", json.dumps(m))
        dst.writestr("policy.pth", src.read("policy.pth"))
    with pytest.raises(ValueError, match="huge.zip: .*parameters"):
        load_policy(huge)


def test_a_tiny_dagger_run_learns():
    overrides = {"n_sensors": 3, "sigma_d2": 2.0, "sigma_theta2": 0.01, "n_steps": 20}
    cfg = SetDaggerConfig(episodes=6, iterations=2, epochs=15, hidden=32)
    torch.manual_seed(1)
    policy, traces = train_set_dagger("radio", overrides, "distributed-gsr", seed=3, config=cfg)
    untrained = SetPolicy(SetPolicyNet(policy.net.layout, 32), {})

    def team_trace(p: SetPolicy) -> float:
        w = World("radio", 4, team_observation=True, **overrides)
        w.reset(seeds=[1000, 1001, 1002, 1003])
        total = 0.0
        for _ in range(20):
            obs = w.observe()
            w.step_actions(p.predict(obs.reshape(-1, obs.shape[-1])).reshape(4, 3, 2))
            total += float(np.mean(w.robot_scores()))
        return total / 20

    assert len(traces) == 2 and np.isfinite(traces).all()
    assert team_trace(policy) < 0.8 * team_trace(untrained)


def test_the_command_trains_writes_and_refuses_a_central_team(tmp_path, capsys):
    from activetrack.cli import main

    out = tmp_path / "run"
    args = ["train", "set-dagger", "--scenario", "radio", "--robots", "3", "--episodes", "2",
            "--iterations", "1", "--epochs", "1", "--hidden", "8", "--out", str(out)]  # fmt: skip
    assert main(args) == 0
    assert (out / "policy.zip").is_file() and (out / "set_dagger.json").is_file()
    assert load_policy(out / "policy.zip").net.hidden == 8
    capsys.readouterr()
    assert main(args) == 2  # the folder holds results: refused without --overwrite
    assert "already holds results" in capsys.readouterr().err
    assert main(["train", "set-dagger", "--scenario", "paper", "--out", str(tmp_path / "p")]) == 2
    assert "no communication model" in capsys.readouterr().err
