"""``activetrack train pathwise``: the command line of :mod:`activetrack.train.pathwise`
(a policy fine-tuned by gradients through the filter)."""

from __future__ import annotations

import argparse
from typing import Any

from activetrack.cli import add_output_arguments, field_default, seed_int
from activetrack.train import pathwise as pw
from activetrack.train.frames import FRAMES
from activetrack.train.networks import NetConfig
from activetrack.train.utils import DEFAULT_THREADS, MAX_THREADS

#: The command's options beyond the scenario, seed and output: (flag, config field, type).
OPTIONS = (
    ("--iterations", "iterations", int),
    ("--batch", "batch", int),
    ("--lr", "lr", float),
    ("--grad-clip", "grad_clip", float),
    ("--eval-every", "eval_every", int),
    ("--eval-episodes", "eval_episodes", int),
    ("--horizon", "horizon", int),
)


def add_pathwise_parser(methods: argparse._SubParsersAction) -> None:
    """Add ``pathwise`` to the ``train`` methods ``methods``."""
    text = (
        "fine-tune a policy file by gradients of the episode's mean trace through the "
        "filter's recursion (the paper's loop; start from BC of the look-ahead planner)"
    )
    q = methods.add_parser("pathwise", help=text, description=text)
    q.add_argument("--scenario", choices=pw.paper_loop_presets(), default="paper",
                   help="preset (default %(default)s)")  # fmt: skip
    q.add_argument(
        "--init",
        default=None,
        help="the policy.zip to start from (default: a fresh network, taught by the reward alone)",
    )
    q.add_argument("--hidden", type=int, nargs="+", default=None,
                   help="a fresh network's MLP sizes (default 256 256)")  # fmt: skip
    q.add_argument("--frame", choices=FRAMES, default=None,
                   help="a fresh network's frame: world (default) or sight (each agent's "
                   "line-of-sight frame, rotation-equivariant)")  # fmt: skip
    q.add_argument("--seed", type=seed_int, default=0, help="training seed (default %(default)s)")
    add_output_arguments(q, None, required=True)
    for option, name, type_ in OPTIONS:
        default = field_default(pw.PathwiseConfig, name)  # None: the whole episode (horizon)
        shown = "the whole episode" if default is None else default
        q.add_argument(option, dest=name, type=type_, default=None, help=f"(default {shown})")
    q.add_argument("--threads", type=int, default=DEFAULT_THREADS,
                   help=f"torch threads, 1 to {MAX_THREADS} (default %(default)s)")  # fmt: skip
    q.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    q.set_defaults(func=run_pathwise, parser=q)


def run_pathwise(args: argparse.Namespace) -> int:
    """Run ``activetrack train pathwise``; return the exit code."""
    given: dict[str, Any] = {
        name: getattr(args, name) for _, name, _ in OPTIONS if getattr(args, name) is not None
    }
    cfg = pw.PathwiseConfig(**given, seed=args.seed, threads=args.threads)
    fresh = {"hidden": args.hidden, "frame": args.frame}
    for name, value in fresh.items():
        if value is not None and args.init is not None:
            raise ValueError(
                f"--{name} sets a fresh network's {name}: it cannot be combined with --init"
            )
    given_net = {k: tuple(v) if k == "hidden" else v for k, v in fresh.items() if v is not None}
    net = NetConfig(**given_net) if given_net else None
    result = pw.train_pathwise(
        args.scenario, args.init, args.out, cfg, progress=not args.no_progress,
        overwrite=args.overwrite, net=net,
    )  # fmt: skip
    start, best = result.validation[0][1], min(v for _, v in result.validation)
    print(
        f"pathwise: {cfg.iterations} iterations of {cfg.batch} episodes, {result.seconds:.1f} s;"
        f" validation mean trace {start:.4f} -> {best:.4f} (iteration {result.best_iteration})"
        f" -> {result.policy_path}"
    )
    return 0
