"""Smoke tests of ``activetrack train bc|dagger|ppo`` and ``evaluate`` (tiny budgets)."""

from __future__ import annotations

import argparse
import json
from dataclasses import fields

import pytest

from activetrack.cli import main
from activetrack.train.cli import configs
from activetrack.train.imitation import DAGGER_DEFAULTS, ImitationConfig
from activetrack.train.networks import NetConfig
from activetrack.train.policy_io import load_policy
from activetrack.train.ppo import PPOConfig


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    root = tmp_path_factory.mktemp("cli")
    common = ["--scenario", "paper", "--seed", "3", "--hidden", "16", "16", "--no-progress"]
    assert (
        main(
            ["train", "bc", *common, "--out", str(root / "bc"), "--episodes", "1", "--epochs", "2"]
        )
        == 0
    )
    assert (
        main(
            [
                "train",
                "dagger",
                *common,
                "--out",
                str(root / "dagger"),
                "--episodes",
                "2",
                "--iterations",
                "2",
                "--epochs",
                "1",
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "train",
                "ppo",
                *common,
                "--out",
                str(root / "ppo"),
                "--total-timesteps",
                "300",
                "--n-copies",
                "1",
                "--n-steps",
                "100",
                "--batch-size",
                "100",
                "--n-epochs",
                "1",
                "--init",
                str(root / "bc" / "policy.zip"),
                "--critic-warmup",
                "150",
            ]
        )
        == 0
    )
    return root


def test_train_outputs(trained):
    for method, kind in (("bc", "bc"), ("dagger", "dagger"), ("ppo", "ppo_warm")):
        policy = load_policy(trained / method / "policy.zip")
        assert policy.meta["kind"] == kind and policy.meta["seed"] == 3
        assert policy.meta["net"]["hidden"] == [16, 16]
        config = json.loads((trained / method / "config.json").read_text())
        assert config["seed"] == 3
    bc = json.loads((trained / "bc" / "config.json").read_text())
    assert bc["labels"] == 1 * 50 * 3 and bc["iterations"] == 1 and bc["epochs"] == 2
    dagger = json.loads((trained / "dagger" / "config.json").read_text())
    assert dagger["labels"] == 2 * 50 * 3 and dagger["iterations"] == 2
    ppo = json.loads((trained / "ppo" / "config.json").read_text())
    assert ppo["total_timesteps"] == 300 and ppo["init"].endswith("bc/policy.zip")
    assert (trained / "ppo" / "model.zip").is_file()
    assert list((trained / "bc" / "tb").glob("events.out.tfevents*"))


def test_evaluate_loads_trained_policies(trained, tmp_path, capsys):
    bc = str(trained / "bc" / "policy.zip")
    ppo = str(trained / "ppo" / "policy.zip")
    assert (
        main(
            [
                "evaluate",
                "--scenario",
                "paper",
                "--policy",
                bc,
                "--policy",
                ppo,
                "--policy",
                "rm",
                "--episodes",
                "2",
                "--seed",
                "1000",
                "--out",
                str(tmp_path),
                "--no-progress",
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "gsr was not requested" in out
    rows = json.loads((tmp_path / "results.json").read_text())
    assert [r["policy"] for r in rows] == [bc, ppo, "rm", "gsr"]
    assert (tmp_path / "mean_trace.png").is_file()


def test_evaluate_rejects_a_policy_of_another_team_size(trained, capsys):
    bc = str(trained / "bc" / "policy.zip")
    code = main(
        [
            "evaluate",
            "--scenario",
            "homogeneous",
            "--policy",
            bc,
            "--episodes",
            "1",
            "--no-progress",
        ]
    )
    assert code == 2
    assert "trained on observations of size 23, this scenario has 29" in capsys.readouterr().err


def _parse(*argv: str) -> argparse.Namespace:
    from activetrack.cli import build_parser

    return build_parser(["train"]).parse_args(["train", *argv])


@pytest.mark.parametrize(
    "method,expected",
    [
        ("bc", ImitationConfig()),
        ("dagger", ImitationConfig(**DAGGER_DEFAULTS)),
        ("ppo", PPOConfig()),
    ],
)
def test_cli_defaults_are_the_config_defaults(method, expected):
    """Options not given are None on the command line: the configs keep their own defaults."""
    args = _parse(method, "--out", "x")
    for f in fields(type(expected)):
        dest = {"learning_rate": "lr"}.get(f.name, f.name)
        if hasattr(args, dest) and f.name not in ("normalize_reward", "keep_best"):
            assert getattr(args, dest) is None, f.name  # no second literal in argparse
    cfg, net = configs(args)
    assert cfg == expected and net == NetConfig()
    assert DAGGER_DEFAULTS["iterations"] > 1


def test_given_options_reach_the_configs():
    cfg, net = configs(
        _parse(
            "ppo",
            "--out",
            "x",
            "--lr",
            "1e-4",
            "--gamma",
            "0.9",
            "--target-kl",
            "0.02",
            "--hidden",
            "8",
            "4",
            "--action-gain",
            "none",
            "--log-std-init",
            "-2",
            "--no-normalize-reward",
            "--keep-best",
            "--eval-every",
            "5000",
        )
    )
    assert cfg.learning_rate == 1e-4 and cfg.gamma == 0.9 and cfg.target_kl == 0.02
    assert cfg.normalize_reward is False and cfg.keep_best is True and cfg.eval_every == 5000
    assert net == NetConfig(hidden=(8, 4), action_gain=None, log_std_init=-2.0)
    assert cfg.net == net and cfg.log_std_init == -2.0
    cfg, _ = configs(_parse("bc", "--out", "x", "--epochs", "3"))
    assert cfg.epochs == 3 and cfg.iterations == 1


@pytest.mark.parametrize(
    "argv,message",
    [
        (["ppo", "--gamma", "5"], "gamma must be a number in (0, 1]"),
        (["ppo", "--gamma", "nan"], "gamma"),
        (["ppo", "--clip-range", "-1"], "clip_range must be a number finite and > 0"),
        (["ppo", "--target-kl", "-1"], "target_kl"),
        (["ppo", "--lr", "inf"], "learning_rate"),
        (["ppo", "--n-steps", "1"], "n_steps must be an integer in [2,"),
        (["ppo", "--total-timesteps", "0"], "total_timesteps"),
        (["ppo", "--action-gain", "-5"], "action_gain"),
        (["bc", "--action-gain", "0"], "action_gain"),
        (["bc", "--hidden", "20000"], "hidden must be an integer in [1, 4096]"),
        (["bc", "--hidden", "0"], "hidden"),
        (["bc", "--episodes", "0"], "episodes"),
        (["bc", "--lr", "nan"], "lr"),
        (
            ["dagger", "--episodes", "2", "--iterations", "3"],
            "iterations must be an integer in [1, 2]",
        ),
        (["dagger", "--beta", "2"], "beta"),
        (["bc", "--threads", "0"], "threads"),
        (["bc", "--batched", "--workers", "2"], "batched runs in this process"),
        (["bc", "--seed", "2147483648"], "must be an integer in [0, 2147483647]"),
        (["ppo", "--keep-best"], "keep_best needs eval_every > 0"),
        (["ppo", "--critic-warmup", "100"], "--critic-warmup trains the critic of a warm start"),
    ],
)
def test_bad_options_are_argparse_errors_before_training(argv, message, tmp_path, capsys):
    out = tmp_path / "out"
    try:  # argparse's own type errors exit; the checks after parsing return the code
        code = main(["train", *argv, "--out", str(out)])
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith(f"usage: activetrack train {argv[0]}")
    assert f"activetrack train {argv[0]}: error: " in err and message in err
    assert not out.exists()  # nothing created: checked before the output folder


def test_bad_init_file_fails_before_training(tmp_path, capsys):
    bad = tmp_path / "policy.zip"
    bad.write_bytes(b"random bytes")
    out = tmp_path / "out"
    assert main(["train", "ppo", "--init", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"activetrack train ppo: error: {bad}: not a policy.zip" in err
    assert "Traceback" not in err and not out.exists()


def test_evaluate_reports_a_bad_policy_file_before_any_episode(tmp_path, capsys):
    bad = tmp_path / "bad.zip"
    bad.write_bytes(b"PK\x03\x04" + bytes(100))
    code = main(
        [
            "evaluate",
            "--policy",
            "gsr",
            "--policy",
            str(bad),
            "--episodes",
            "100000",
            "--no-progress",
        ]
    )
    assert code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert f"activetrack evaluate: error: {bad}: not a policy.zip" in captured.err


def test_train_refuses_results_unless_overwrite(trained, tmp_path, capsys):
    before = (trained / "bc" / "policy.zip").read_bytes()
    argv = ["train", "bc", "--episodes", "1", "--epochs", "1", "--hidden", "8", "--no-progress"]
    assert main([*argv, "--out", str(trained / "bc")]) == 2
    assert "already holds results (policy.zip, config.json, tb/)" in capsys.readouterr().err
    assert (trained / "bc" / "policy.zip").read_bytes() == before
    # --overwrite replaces what train owns, even a PPO run's leftovers, and nothing else.
    out = tmp_path / "run"
    out.mkdir()
    for name in ("model.zip", "policy.zip", "notes.txt"):
        (out / name).write_text("old")
    (out / "checkpoints").mkdir()
    (out / "checkpoints" / "ppo_100_steps.zip").write_text("old")
    assert main([*argv, "--out", str(out), "--overwrite"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["config.json", "notes.txt", "policy.zip", "tb"]
    assert load_policy(out / "policy.zip").meta["net"]["hidden"] == [8]


@pytest.mark.parametrize("method", ["bc", "rllib-ppo"])
def test_a_malformed_address_fails_before_training(method, tmp_path, capsys, monkeypatch):
    import socket

    import activetrack.train.cli as tcli

    def never(*args, **kwargs):
        raise AssertionError("probed or trained with a malformed address")

    if method == "rllib-ppo":
        rllib = pytest.importorskip("activetrack.train.rllib")
        monkeypatch.setattr(rllib, "train_rllib_ppo", never)
    monkeypatch.setattr(tcli, "train_imitation", never)
    monkeypatch.setattr(socket, "create_connection", never)
    out = tmp_path / "out"
    for address in ("127.0.0.1:-5", "127.0.0.1:+1", "127.0.0.1:1.5", "127.0.0.1:99999"):
        assert main(["train", method, "--address", address, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert f"activetrack train {method}: error: address must be 'auto', 'local'" in err
        assert not out.exists()


def test_rllib_says_when_no_episode_finished(tmp_path, capsys, monkeypatch):
    """RLlib reports a mean return only once an episode has finished: the summary line says
    so instead of printing nan, and names the iteration of an older mean."""
    rllib = pytest.importorskip("activetrack.train.rllib")

    def fake(history):
        def train(*args, **kwargs):
            return rllib.RLlibResult(tmp_path / "policy.zip", history, 1.0, 64, 192, None)

        return train

    argv = ["train", "rllib-ppo", "--iterations", "2", "--out", str(tmp_path / "out")]
    for history, expected in [
        ([{}, {}], "no episode finished in training (no mean return)"),
        ([{"episode_return_mean": -1.25}, {}], "(all sensors, scaled) -1.250 at iteration 1"),
        ([{}, {"episode_return_mean": 2.5}], "(all sensors, scaled) 2.500 ->"),
    ]:
        monkeypatch.setattr(rllib, "train_rllib_ppo", fake(history))
        assert main(argv) == 0
        out = capsys.readouterr().out
        assert expected in out and "nan" not in out


@pytest.mark.parametrize("method", ["bc", "ppo", "rllib-ppo"])
def test_a_dangling_link_or_long_name_as_out_fails_before_training(
    method, tmp_path, capsys, monkeypatch
):
    import activetrack.train.cli as tcli

    def never(*args, **kwargs):
        raise AssertionError("trained before checking --out")

    if method == "rllib-ppo":
        rllib = pytest.importorskip("activetrack.train.rllib")
        monkeypatch.setattr(rllib, "train_rllib_ppo", never)
    monkeypatch.setattr(tcli, "train_imitation", never)
    monkeypatch.setattr(tcli, "train_ppo", never)
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    for out, message in [
        (tmp_path / "dangling", "is a symbolic link to"),
        (tmp_path / ("x" * 300), "cannot write to this folder (File name too long)"),
    ]:
        assert main(["train", method, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert f"activetrack train {method}: error: {out}: " in err and message in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling"]


def test_a_failed_run_leaves_no_folder(tmp_path, capsys):
    """train bc with a Ray address nothing answers at: exit 1, and no OUT (nor OUT/tb)."""
    pytest.importorskip("ray")
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # released: nothing listens there
    out = tmp_path / "out"
    argv = ["train", "bc", "--episodes", "1", "--epochs", "1", "--no-progress"]
    assert main([*argv, "--address", f"127.0.0.1:{port}", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "cannot reach a Ray cluster" in err and f"no results were written to {out}" in err
    assert not out.exists()


def _tree(folder):
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
def test_an_interrupted_ppo_overwrite_keeps_every_old_output(signum, tmp_path, monkeypatch, capsys):
    """Interrupted at the end of training (its TensorBoard logs and checkpoints written in
    the staging folder the command printed), an --overwrite run leaves the previous run's
    files *and folders* as they were: the folder never mixes two runs."""
    import os
    import signal

    import activetrack.train.ppo as ppo_module

    out = tmp_path / "ppo"
    (out / "checkpoints").mkdir(parents=True)
    (out / "tb" / "ppo_1").mkdir(parents=True)
    for name in ("policy.zip", "model.zip", "config.json"):
        (out / name).write_text(f"old {name}")
    (out / "checkpoints" / "ppo_100_steps.zip").write_text("old checkpoint")
    (out / "tb" / "ppo_1" / "events.out.tfevents.old").write_text("old events")
    before = _tree(out)
    seen = {}

    def interrupted(*args, **kwargs):
        staging = next(out.glob(".tmp-run-*"))
        seen["staged"] = sorted(str(p.relative_to(staging)) for p in staging.rglob("*"))
        os.kill(os.getpid(), getattr(signal, signum))

    monkeypatch.setattr(ppo_module, "save_policy", interrupted)
    argv = ["train", "ppo", "--hidden", "8", "--no-progress", "--total-timesteps", "200"]
    argv += ["--n-copies", "1", "--n-steps", "100", "--batch-size", "100", "--n-epochs", "1"]
    argv += ["--checkpoint-every", "100", "--out", str(out), "--overwrite"]
    assert main(argv) == 128 + getattr(signal, signum)
    captured = capsys.readouterr()
    staging_tb = captured.out.split("TensorBoard logs while training: ")[1].split(" ")[0]
    assert staging_tb.startswith(str(out / ".tmp-run-")) and staging_tb.endswith("tb")
    # The new run's logs and checkpoints were being written in the staging folder...
    assert any(p.startswith("tb/ppo_1/events.out.tfevents") for p in seen["staged"])
    assert any(p.startswith("checkpoints/ppo_") for p in seen["staged"])
    # ...and the old outputs, folders included, are all still there, unchanged.
    assert _tree(out) == before
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["checkpoints", "config.json", "model.zip", "policy.zip", "tb"]
    )
    assert f"interrupted ({signum}); {out} still holds its previous results" in captured.err
