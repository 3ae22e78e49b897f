"""``activetrack train set-dagger``: the command line of :mod:`activetrack.train.set_policy`
(a permutation-invariant policy for decentralized teams, DAgger on distributed GSR)."""

from __future__ import annotations

import argparse
import time
from typing import Any

from activetrack.cli import add_output_arguments, field_default, seed_int
from activetrack.files import prepare_output_dir
from activetrack.train import set_policy as spol
from activetrack.train.utils import DEFAULT_THREADS, MAX_THREADS, configure_torch

#: What ``set-dagger`` writes.
OUTPUTS = ("policy.zip", "set_dagger.json")


def add_set_policy_parser(methods: argparse._SubParsersAction) -> None:
    """Add ``set-dagger`` to the ``train`` methods ``methods``."""
    from activetrack.world.presets import PRESETS

    text = (
        "DAgger of a permutation-invariant policy (a set network over the neighbours' "
        "blocks) on distributed GSR in a decentralized scenario; the policy runs on teams "
        "of any size"
    )
    q = methods.add_parser("set-dagger", help=text, description=text)
    q.add_argument("--scenario", choices=sorted(PRESETS), default="radio",
                   help="preset with a communication model (default %(default)s)")  # fmt: skip
    q.add_argument("--robots", type=int, default=None, help="team size (default: the preset's)")
    q.add_argument("--sigma-d2", type=float, default=None,
                   help="every robot's range variance (default: the preset's)")  # fmt: skip
    q.add_argument("--sigma-theta2", type=float, default=None,
                   help="every robot's bearing variance (default: the preset's)")  # fmt: skip
    q.add_argument(
        "--expert", default="distributed-gsr", help="expert policy (default %(default)s)"
    )
    q.add_argument("--seed", type=seed_int, default=1, help="training seed (default %(default)s)")
    for option, name, type_ in (
        ("--episodes", "episodes", int),
        ("--iterations", "iterations", int),
        ("--epochs", "epochs", int),
        ("--hidden", "hidden", int),
        ("--lr", "lr", float),
    ):
        q.add_argument(option, dest=name, type=type_, default=None,
                       help=f"(default {field_default(spol.SetDaggerConfig, name)})")  # fmt: skip
    q.add_argument("--threads", type=int, default=DEFAULT_THREADS,
                   help=f"torch threads, 1 to {MAX_THREADS} (default %(default)s)")  # fmt: skip
    add_output_arguments(q, None, required=True)
    q.set_defaults(func=run_set_dagger, parser=q)


def run_set_dagger(args: argparse.Namespace) -> int:
    """Run ``activetrack train set-dagger``; return the exit code."""
    from activetrack.world.scenarios import make_scenario

    given = {k: getattr(args, k) for k in ("episodes", "iterations", "epochs", "hidden", "lr")}
    cfg = spol.SetDaggerConfig(**{k: v for k, v in given.items() if v is not None})
    overrides: dict[str, Any] = {}
    for key, value in (("n_sensors", args.robots), ("sigma_d2", args.sigma_d2),
                       ("sigma_theta2", args.sigma_theta2)):  # fmt: skip
        if value is not None:
            overrides[key] = value
    sc = make_scenario(args.scenario, **overrides)  # every field checked before training
    if sc.communication is None:
        raise ValueError(f"scenario {args.scenario!r} has no communication model (a central team)")
    configure_torch(args.threads)
    with prepare_output_dir(args.out, OUTPUTS, args.overwrite) as outputs:
        start = time.perf_counter()
        done = lambda i, t: print(f"iteration {i}: mean trace {t:.4f}", flush=True)  # noqa: E731
        policy, traces = spol.train_set_dagger(
            args.scenario, overrides, args.expert, args.seed, cfg, on_iteration=done
        )
        seconds = time.perf_counter() - start
        with outputs:
            spol.save_set_policy(outputs.staged("policy.zip"), policy)
            outputs.write_json("set_dagger.json", {
                "scenario": args.scenario, "overrides": overrides, "expert": args.expert,
                "seed": args.seed, "config": policy.meta["config"], "traces": traces,
                "seconds": seconds,
            })  # fmt: skip
            path = outputs.commit()["policy.zip"]
    print(f"set-dagger: {seconds:.1f} s -> {path}")
    return 0
