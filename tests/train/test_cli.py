"""Smoke tests of ``activetrack train bc|dagger|ppo`` and ``evaluate`` (tiny budgets)."""

from __future__ import annotations

import argparse
import json
from dataclasses import fields

import pytest

from activetrack.cli import main
from activetrack.train.imitation import ImitationConfig
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


def _subparser(parser: argparse.ArgumentParser, *names: str) -> argparse.ArgumentParser:
    for name in names:
        action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        parser = action.choices[name]
    return parser


@pytest.mark.parametrize(
    "method,cls", [("bc", ImitationConfig), ("dagger", ImitationConfig), ("ppo", PPOConfig)]
)
def test_cli_defaults_are_the_config_defaults(method, cls):
    """The defaults shown by --help are those the library uses."""
    from activetrack.cli import build_parser

    sub = _subparser(build_parser(), "train", method)
    defaults = {f.name: f.default for f in fields(cls) if f.name != "net"}
    checked = 0
    for action in sub._actions:
        name = (
            {"lr": "learning_rate"}.get(action.dest, action.dest)
            if cls is PPOConfig
            else action.dest
        )
        if name in defaults and action.default is not None:
            if method == "dagger" and name in ("iterations", "epochs"):
                continue  # DAgger's own defaults, asserted below
            assert action.default == defaults[name], name
            checked += 1
    assert checked >= 3
    if method == "dagger":
        args = sub.parse_args(["--out", "x"])
        assert args.iterations > 1
