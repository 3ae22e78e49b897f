"""``activetrack train bc|dagger|ppo``: the command-line runners (argparse lives in ``cli.py``).

Each writes ``OUT/policy.zip`` (loadable by ``activetrack evaluate --policy``), plus
``OUT/config.json`` and TensorBoard logs in ``OUT/tb``; PPO also writes ``model.zip`` and
``checkpoints/``. The parser's defaults equal those of
:class:`~activetrack.train.imitation.ImitationConfig` and :class:`~activetrack.train.ppo.PPOConfig`
(DAgger has its own rounds and epochs; ``tests/train/test_cli.py`` checks the rest).
"""

from __future__ import annotations

import argparse
import json
from dataclasses import fields
from pathlib import Path
from typing import Any

from activetrack.train.imitation import ImitationConfig, train_imitation
from activetrack.train.networks import NetConfig
from activetrack.train.policy_io import save_policy
from activetrack.train.ppo import PPOConfig, train_ppo
from activetrack.train.utils import configure_torch

#: CLI option (argparse dest) -> config field, where the names differ.
_RENAMES = {"lr": "learning_rate"}


def _net_config(args: argparse.Namespace) -> NetConfig:
    kw: dict[str, Any] = {}
    if getattr(args, "hidden", None):
        kw["hidden"] = tuple(args.hidden)
    if getattr(args, "activation", None):
        kw["activation"] = args.activation
    if getattr(args, "action_gain", None) is not None:
        gain = args.action_gain
        kw["action_gain"] = None if str(gain).lower() == "none" else float(gain)
    if getattr(args, "log_std_init", None) is not None:
        kw["log_std_init"] = args.log_std_init
    return NetConfig(**kw)


def _given(args: argparse.Namespace, cls: type, renames: dict[str, str]) -> dict[str, Any]:
    """Return the config fields of ``cls`` that were given on the command line."""
    names = {f.name for f in fields(cls)}
    out = {}
    for key, value in vars(args).items():
        field_name = renames.get(key, key)
        if field_name in names and value is not None and field_name != "net":
            out[field_name] = value
    return out


def run_train(args: argparse.Namespace) -> int:
    """Run ``activetrack train <method>`` from parsed arguments; return the exit code."""
    configure_torch(args.threads)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    net = _net_config(args)
    progress = not args.no_progress
    if args.method in ("bc", "dagger"):
        given = _given(args, ImitationConfig, {})
        if args.method == "bc":
            given["iterations"] = 1
        cfg = ImitationConfig(**given, net=net)
        result = train_imitation(
            args.scenario,
            seed=args.seed,
            config=cfg,
            tensorboard_dir=str(out / "tb"),
            progress=progress,
            threads=args.threads,
        )
        from activetrack.scenarios import make_scenario

        train_config = {
            "algo": args.method,
            **cfg.to_dict(),
            "labels": len(result.data),
            "final_mse": result.losses,
            "rollout_mean_trace": result.rollout_traces,
            "seconds": result.seconds,
        }
        path = save_policy(
            out / "policy.zip",
            result.policy,
            net,
            kind=args.method,
            scenario=make_scenario(args.scenario).to_dict(),
            seed=args.seed,
            train_config=train_config,
        )
        (out / "config.json").write_text(
            json.dumps({"seed": args.seed, "scenario": args.scenario, **train_config}, indent=2)
        )
        print(
            f"{args.method}: {len(result.data)} expert labels, final MSE {result.losses[-1]:.4f}, "
            f"{result.seconds:.1f} s -> {path}"
        )
        return 0
    if args.method == "ppo":
        given = _given(args, PPOConfig, _RENAMES)
        given.pop("log_std_init", None)  # part of the network config here
        if args.no_normalize_reward:
            given["normalize_reward"] = False
        if args.keep_best:
            given["keep_best"] = True
        cfg = PPOConfig(**given, net=net, log_std_init=args.log_std_init)
        result = train_ppo(
            args.scenario,
            seed=args.seed,
            config=cfg,
            out_dir=out,
            init=args.init,
            progress=progress,
            threads=args.threads,
        )
        best = ""
        if result.validation:
            best = f", validation mean trace {min(t for _, t in result.validation):.4f} (best)"
        print(
            f"ppo: {cfg.total_timesteps} timesteps, {result.seconds:.1f} s{best} -> "
            f"{result.policy_path}"
        )
        return 0
    raise ValueError(f"unknown method {args.method!r}")
