"""The ``activetrack`` command line (console script ``activetrack.cli:main``).

Subcommands are registered by the functions in :data:`COMMANDS`; each adds its own
subparser and sets ``func``, the function that runs it. Every layer (baselines, envs,
train) is imported only inside the command that needs it, so ``activetrack --help`` is
fast and the core never depends on the layers above it.

- ``simulate``: the closed-loop comparison of planners of Section V (Monte Carlo over
  seeds), a results table, ``results.json`` and a Fig. 4 style trajectory plot.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

#: Planner names accepted by ``simulate --planner``.
PLANNERS = ("gsr", "gsr-restarts", "gbes", "rm")


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return value


def _nonneg_int(text: str) -> int:
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text}")
    return value


def _positive_float(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


# simulate ---------------------------------------------------------------------------------
def _add_simulate(sub: argparse._SubParsersAction) -> None:
    from activetrack.scenarios import PRESETS

    p = sub.add_parser(
        "simulate",
        help="compare planners in the closed tracking loop (Monte Carlo over seeds)",
        description=(
            "Run every --planner on --runs seeds (seed, seed+1, ...) of a scenario, print mean "
            "trace and RMSE with 95%% intervals of the mean, and write OUT/results.json and "
            "OUT/trajectories.png (the first seed, Fig. 4 style)."
        ),
    )
    p.add_argument("--scenario", default="paper", choices=sorted(PRESETS), help="preset")
    p.add_argument(
        "--planner",
        action="append",
        choices=PLANNERS,
        help="planner to run (repeatable; default: gsr, gbes, rm)",
    )
    p.add_argument("--runs", type=_positive_int, default=20, help="number of seeds")
    p.add_argument("--seed", type=_nonneg_int, default=0, help="first seed")
    p.add_argument("--out", type=Path, default=Path("results/simulate"), help="output folder")
    p.add_argument(
        "--steps", type=_positive_int, default=None, help="override the scenario's n_steps"
    )
    p.add_argument(
        "--gbes-spacing",
        type=_positive_float,
        default=math.pi / 200,
        help="GBES grid spacing on the curves ADB in metres (default pi/200, the paper's)",
    )
    p.add_argument("--gsr-tol", type=float, default=1e-9, help="GSR relative tolerance")
    p.add_argument("--gsr-max-sweeps", type=_positive_int, default=100, help="GSR sweep cap")
    p.add_argument("--no-plot", action="store_true", help="do not write trajectories.png")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=_cmd_simulate)


def _make_planner(name: str, args: argparse.Namespace) -> tuple[Any, dict[str, Any]]:
    """Return the planner called ``name`` and its configuration (JSON-friendly)."""
    from activetrack.baselines import GBES, GSR, RandomMotion

    if name in ("gsr", "gsr-restarts"):
        cfg = {
            "tol": args.gsr_tol,
            "max_sweeps": args.gsr_max_sweeps,
            "restarts": name == "gsr-restarts",
        }
        return GSR(**cfg), {"type": "GSR", **cfg}
    if name == "gbes":
        cfg = {"spacing": args.gbes_spacing}
        return GBES(**cfg), {"type": "GBES", **cfg}
    return RandomMotion(), {"type": "RandomMotion"}


def _format_table(summaries: dict[str, dict[str, Any]]) -> str:
    """Return the results as an aligned text table (means with 95% intervals)."""
    head = ("planner", "mean trace (m^2) [95% CI]", "RMSE (m) [95% CI]", "NEES", "plan ms (median)")
    rows = [head]
    for name, s in summaries.items():
        lo, hi = s["mean_trace_ci95"]
        rlo, rhi = s["rmse_ci95"]
        rows.append(
            (
                name,
                f"{s['mean_trace']:.4f} [{lo:.4f}, {hi:.4f}]",
                f"{s['rmse']:.4f} [{rlo:.4f}, {rhi:.4f}]",
                f"{s['nees']:.2f}",
                f"{s['plan_time_ms_median']:.2f}",
            )
        )
    widths = [max(len(r[k]) for r in rows) for k in range(len(head))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def _cmd_simulate(args: argparse.Namespace) -> int:
    from activetrack.baselines import run_monte_carlo
    from activetrack.scenarios import make_scenario

    overrides = {} if args.steps is None else {"n_steps": args.steps}
    scenario = make_scenario(args.scenario, **overrides)
    names = list(dict.fromkeys(args.planner or ["gsr", "gbes", "rm"]))
    planners, configs = {}, {}
    for name in names:
        planners[name], configs[name] = _make_planner(name, args)
    results = run_monte_carlo(
        scenario, planners, args.runs, args.seed, progress=not args.no_progress
    )
    summaries = {}
    for name, res in results.items():
        s = res.summary()
        s["seed"] = args.seed
        s["config"] = {"planner": configs[name], "scenario": scenario.to_dict()}
        summaries[name] = s
    last = args.seed + args.runs - 1
    print(
        f"scenario {scenario.name!r}, {args.runs} runs (seeds {args.seed}..{last}), "
        f"{scenario.n_steps} steps"
    )
    print(_format_table(summaries))
    args.out.mkdir(parents=True, exist_ok=True)
    out_json = args.out / "results.json"
    out_json.write_text(json.dumps(summaries, indent=2, default=_json_default) + "\n")
    print(f"wrote {out_json}")
    if not args.no_plot:
        from activetrack.baselines.plotting import plot_trajectories

        first = {name: res.records[0] for name, res in results.items()}
        png = plot_trajectories(
            first,
            args.out / "trajectories.png",
            title=f"scenario {scenario.name!r}, seed {args.seed}",
        )
        print(f"wrote {png}")
    return 0


def _json_default(obj: Any) -> Any:
    """Return a JSON-friendly version of numpy scalars and arrays."""
    import numpy as np

    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


# evaluate ---------------------------------------------------------------------------------
def _add_evaluate(sub: argparse._SubParsersAction) -> None:
    from activetrack.scenarios import PRESETS

    p = sub.add_parser(
        "evaluate",
        help="evaluate policies (planners or trained policy.zip files) on held-out seeds",
        description=(
            "Run every --policy (gsr, gsr-restarts, gbes, rm, or the path of a policy.zip "
            "written by 'activetrack train') in the environment on the same --episodes seeds "
            "(seed, seed+1, ...). Prints mean trace and RMSE with 95%% intervals, mean return "
            "and the ratio of mean trace to GSR's (GSR is evaluated as the reference even if "
            "not listed); writes OUT/results.json (a list, one object per policy), "
            "OUT/episodes.json and OUT/mean_trace.png."
        ),
    )
    p.add_argument("--scenario", default="paper", choices=sorted(PRESETS), help="preset")
    p.add_argument(
        "--policy",
        action="append",
        required=True,
        metavar="NAME|PATH",
        help="gsr, gsr-restarts, gbes, rm or PATH/policy.zip (repeatable)",
    )
    p.add_argument("--episodes", type=_positive_int, default=100, help="number of seeds")
    p.add_argument("--seed", type=_nonneg_int, default=1000, help="first held-out seed")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: none)")
    p.add_argument("--no-plot", action="store_true", help="do not write mean_trace.png")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=_cmd_evaluate)


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from activetrack.baselines.evaluation import run_evaluation

    run_evaluation(
        args.policy,
        args.scenario,
        args.episodes,
        args.seed,
        out_dir=args.out,
        plot=not args.no_plot,
        progress=not args.no_progress,
    )
    return 0


# train ------------------------------------------------------------------------------------
def _add_train(sub: argparse._SubParsersAction) -> None:
    """Register ``train bc|dagger|ppo``; defaults equal the library's (a test checks it)."""
    from activetrack.scenarios import PRESETS

    p = sub.add_parser(
        "train",
        help="train a policy: imitation of GSR (bc, dagger) or PPO (the [rl] extra)",
        description="Train a policy and write OUT/policy.zip, which 'activetrack evaluate "
        "--policy OUT/policy.zip' loads. See the README for commands and budgets.",
    )
    methods = p.add_subparsers(dest="method", metavar="METHOD", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--scenario", default="paper", choices=sorted(PRESETS), help="preset")
    common.add_argument("--seed", type=_nonneg_int, default=0, help="training seed")
    common.add_argument("--out", type=Path, required=True, help="output folder")
    common.add_argument(
        "--hidden", type=_positive_int, nargs="+", default=[256, 256], help="MLP hidden sizes"
    )
    common.add_argument("--activation", choices=("tanh", "relu", "elu"), default="tanh")
    common.add_argument(
        "--action-gain",
        default="100",
        help="saturation gain of the mean action (per sensor, m / max(|m|, 1/K)); "
        "'none' for SB3's linear mean (default 100)",
    )
    common.add_argument("--threads", type=_positive_int, default=1, help="torch threads")
    common.add_argument("--no-progress", action="store_true", help="hide the progress bar")

    def imitation(name: str, help_text: str, episodes: int, epochs: int, iterations: int):
        q = methods.add_parser(name, parents=[common], help=help_text, description=help_text)
        q.add_argument(
            "--episodes",
            type=_positive_int,
            default=episodes,
            help=f"expert-labelled episodes in total: the label budget (default {episodes})",
        )
        q.add_argument(
            "--epochs",
            type=_positive_int,
            default=epochs,
            help=f"passes over the data (per DAgger round) (default {epochs})",
        )
        q.add_argument("--batch-size", type=_positive_int, default=256, help="(default 256)")
        q.add_argument("--lr", type=_positive_float, default=1e-3, help="Adam (default 1e-3)")
        q.add_argument("--weight-decay", type=float, default=0.0, help="Adam (default 0)")
        if name == "dagger":
            q.add_argument(
                "--iterations",
                type=_positive_int,
                default=iterations,
                help=f"rounds; the episodes are split over them (default {iterations})",
            )
            q.add_argument(
                "--beta",
                type=float,
                default=0.5,
                help="round i executes the expert with probability beta**i (default 0.5)",
            )
        q.set_defaults(func=_cmd_train)

    imitation("bc", "behaviour cloning of GSR", episodes=100, epochs=100, iterations=1)
    imitation("dagger", "DAgger with GSR labels", episodes=100, epochs=40, iterations=5)

    q = methods.add_parser(
        "ppo",
        parents=[common],
        help="PPO (stable-baselines3), from scratch or from --init PATH/policy.zip",
        description="PPO with parameter sharing over the PettingZoo env (default) or on the "
        "centralized Gymnasium view; TensorBoard logs in OUT/tb, checkpoints in "
        "OUT/checkpoints.",
    )
    q.add_argument("--total-timesteps", type=_positive_int, default=1_000_000)
    q.add_argument("--init", type=Path, default=None, help="warm start from a policy.zip")
    q.add_argument(
        "--critic-warmup",
        type=_nonneg_int,
        default=50_000,
        help="timesteps of critic-only training after --init (default 50000)",
    )
    q.add_argument("--log-std-init", type=float, default=None, help="initial log std")
    q.add_argument("--view", choices=("shared", "centralized"), default="shared")
    q.add_argument("--n-copies", type=_positive_int, default=8, help="environment copies")
    q.add_argument("--n-steps", type=_positive_int, default=256, help="rollout length per slot")
    q.add_argument("--batch-size", type=_positive_int, default=512)
    q.add_argument("--n-epochs", type=_positive_int, default=10)
    q.add_argument("--lr", type=_positive_float, default=3e-4, help="learning rate")
    q.add_argument(
        "--lr-schedule",
        choices=("constant", "linear"),
        default="constant",
        help="linear: decay to 0 over the run (default constant)",
    )
    q.add_argument("--gamma", type=float, default=0.99)
    q.add_argument("--gae-lambda", type=float, default=0.95)
    q.add_argument("--clip-range", type=float, default=0.2)
    q.add_argument("--ent-coef", type=float, default=0.0)
    q.add_argument("--target-kl", type=float, default=None)
    q.add_argument(
        "--no-normalize-reward",
        action="store_true",
        help="train on the raw reward instead of VecNormalize's scaled one",
    )
    q.add_argument("--checkpoint-every", type=_nonneg_int, default=100_000, help="timesteps")
    q.add_argument(
        "--eval-every",
        type=_nonneg_int,
        default=0,
        help="validate the deterministic policy every N timesteps on validation seeds",
    )
    q.add_argument("--eval-episodes", type=_positive_int, default=20)
    q.add_argument(
        "--keep-best", action="store_true", help="save the best validated policy, not the last"
    )
    q.set_defaults(func=_cmd_train)


def _cmd_train(args: argparse.Namespace) -> int:
    from activetrack.train.cli import run_train

    return run_train(args)


#: Functions that register one subcommand each (add yours here).
COMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [
    _add_simulate,
    _add_evaluate,
    _add_train,
]


def build_parser() -> argparse.ArgumentParser:
    """Return the ``activetrack`` argument parser with every registered subcommand."""
    from activetrack import __version__

    parser = argparse.ArgumentParser(
        prog="activetrack",
        description="Multi-robot active target tracking (range-bearing, speed and distance "
        "limits): planners, simulation and environments.",
    )
    parser.add_argument("--version", action="version", version=f"activetrack {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for register in COMMANDS:
        register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except ValueError as exc:  # bad input deep in the library: report it, no traceback
        print(f"activetrack {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
