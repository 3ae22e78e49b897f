"""The baselines' commands: ``activetrack simulate`` and ``activetrack evaluate``.

- ``simulate``: the closed-loop comparison of planners of Section V (Monte Carlo over
  seeds), a results table, ``OUT/results.json``, a Fig. 4 style ``OUT/trajectories.png``
  (the first seed) and ``OUT/comparison.png`` (every run: the traces over time);
- ``evaluate``: policies (planners or trained ``policy.zip`` files) in the environment on
  held-out seeds (:mod:`activetrack.baselines.evaluation`).

The planners' options take their defaults from the planner dataclasses (:class:`GSR`,
:class:`GBES`) and ``evaluate``'s from :func:`run_evaluation`. Everything is checked
before computing: the planners' settings, the policies, ``--workers``/``--address`` (Ray
installed when they ask for it) and the output folder (one that holds results needs
``--overwrite``); the outputs are committed together. With ``--workers N`` or ``--address``
the runs are Ray tasks (:mod:`activetrack.baselines.distributed`), with the same results.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
from pathlib import Path
from typing import Any

from activetrack.baselines import GBES, GSR, RandomMotion, evaluation, run_monte_carlo, simulation
from activetrack.baselines.distributed import check_options
from activetrack.baselines.evaluation import run_evaluation
from activetrack.baselines.lookahead import Lookahead, LookaheadPlanner
from activetrack.cli import (
    COMMANDS,
    add_output_arguments,
    field_default,
    positive_float,
    positive_int,
    seed_int,
)
from activetrack.files import prepare_output_dir
from activetrack.world.scenarios import PRESETS, make_scenario

#: Planner names accepted by ``simulate --planner``, and those run when none is given.
PLANNERS = ("gsr", "gsr-restarts", "gbes", "rm", "lookahead")
DEFAULT_PLANNERS = ("gsr", "gbes", "rm")
#: The files ``simulate`` writes in its output folder.
SIMULATE_OUTPUTS = ("results.json", "trajectories.png", "comparison.png")
#: ``simulate``'s own defaults (no library function has them).
SIMULATE_RUNS, SIMULATE_OUT = 20, "results/simulate"


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Add ``simulate`` and ``evaluate`` to the ``activetrack`` subparsers ``sub``."""
    _add_simulate(sub)
    _add_evaluate(sub)


def _add_simulate(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "simulate",
        help=COMMANDS["simulate"][1],
        description=(
            "Run every --planner on --runs seeds (seed, seed+1, ...) of a scenario, print mean "
            "trace and RMSE with 95% intervals of the mean, and write OUT/results.json, "
            "OUT/trajectories.png (the first seed, Fig. 4 style) and OUT/comparison.png (the "
            "planners' traces over time, mean and 95% band, over all runs)."
        ),
    )
    p.add_argument("--scenario", default="paper", choices=sorted(PRESETS), help="preset")
    p.add_argument(
        "--planner",
        action="append",
        choices=PLANNERS,
        help=f"planner to run (repeatable; default: {', '.join(DEFAULT_PLANNERS)})",
    )
    p.add_argument(
        "--runs",
        type=positive_int,
        default=SIMULATE_RUNS,
        help="number of seeds (default %(default)s)",
    )
    seed = inspect.signature(simulation.run_monte_carlo).parameters["seed"].default
    p.add_argument("--seed", type=seed_int, default=seed, help="first seed (default %(default)s)")
    add_output_arguments(p, Path(SIMULATE_OUT))
    p.add_argument(
        "--steps", type=positive_int, default=None, help="override the scenario's n_steps"
    )
    add_gbes_arguments(p)
    p.add_argument(
        "--gsr-tol",
        type=float,
        default=None,
        help=f"GSR relative tolerance (default {field_default(GSR, 'tol'):g})",
    )
    p.add_argument(
        "--gsr-max-sweeps",
        type=positive_int,
        default=None,
        help=f"GSR sweep cap (default {field_default(GSR, 'max_sweeps')})",
    )
    p.add_argument(
        "--lookahead-horizon",
        type=positive_int,
        default=None,
        help="look-ahead planner's horizon in steps "
        f"(default {field_default(Lookahead, 'horizon')})",
    )
    p.add_argument(
        "--no-plot", action="store_true", help="do not write trajectories.png and comparison.png"
    )
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    add_ray_arguments(p, "runs")
    p.set_defaults(func=_cmd_simulate, parser=p)


def add_gbes_arguments(p: argparse.ArgumentParser) -> None:
    """Add ``--gbes-spacing`` (simulate and evaluate)."""
    p.add_argument(
        "--gbes-spacing",
        type=positive_float,
        default=None,
        help="GBES grid spacing on the curves ADB in metres "
        f"(default {field_default(GBES, 'spacing'):.6g}, pi/200, the paper's, widened per "
        "problem where the grid would exceed GBES's max_combinations: GBES.adapt)",
    )


def add_ray_arguments(p: argparse.ArgumentParser, what: str) -> None:
    """Add ``--workers`` and ``--address`` (Ray; :mod:`activetrack.baselines.distributed`)."""
    p.add_argument(
        "--workers",
        type=positive_int,
        default=1,
        help=f"spread the {what} over this many Ray workers on this machine (default "
        "%(default)s: no Ray); needs the [ray] extra",
    )
    p.add_argument(
        "--address",
        default=None,
        metavar="ADDR",
        help=f"run the {what} on the Ray cluster at ADDR (HOST:PORT of 'ray start --head', "
        "or 'auto'); its CPUs replace --workers",
    )


def _given(**kwargs: Any) -> dict[str, Any]:
    """Return the keyword arguments that were given (not None): the rest keep their defaults."""
    return {k: v for k, v in kwargs.items() if v is not None}


def make_planner(name: str, args: argparse.Namespace) -> tuple[Any, dict[str, Any]]:
    """Return the planner called ``name`` and its configuration (JSON-friendly).

    Options not given keep the planner dataclass's defaults; a bad value raises the
    planner's ``ValueError``.
    """
    if name in ("gsr", "gsr-restarts"):
        gsr = GSR(
            **_given(tol=args.gsr_tol, max_sweeps=args.gsr_max_sweeps),
            restarts=name == "gsr-restarts",
        )
        cfg = {"tol": gsr.tol, "max_sweeps": gsr.max_sweeps, "restarts": gsr.restarts}
        return gsr, {"type": "GSR", **cfg}
    if name == "gbes":
        gbes = GBES(**_given(spacing=args.gbes_spacing))
        return gbes, {"type": "GBES", "spacing": gbes.spacing}
    if name == "rm":
        return RandomMotion(), {"type": "RandomMotion"}
    if name == "lookahead":
        planner = LookaheadPlanner(
            make_scenario(args.scenario), **_given(horizon=args.lookahead_horizon)
        )
        cfg = dataclasses.asdict(planner.search)
        cfg.pop("_gsr", None)
        return planner, {"type": "Lookahead", **cfg}
    raise ValueError(f"unknown planner {name!r}: use one of {list(PLANNERS)}")


def format_table(summaries: dict[str, dict[str, Any]]) -> str:
    """Return the results as an aligned text table (means with 95% intervals)."""
    head = (
        "planner",
        "mean trace (m^2) [95% CI]",
        "IQM [95% CI]",
        "median [95% CI]",
        "RMSE (m) [95% CI]",
        "NEES",
        "plan ms (median)",
        "ratio to GSR [paired 95% CI]",
        "IQM ratio to GSR",
    )
    rows = [head]

    def ci(s: dict[str, Any], key: str, digits: int) -> str:  # "-": none (no track held)
        if s.get(key) is None:
            return "-"
        lo, hi = s[f"{key}_ci95"]
        return f"{s[key]:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"

    for name, s in summaries.items():
        nees = "-" if s["nees"] is None else f"{s['nees']:.2f}"
        ms = f"{s['plan_time_ms_median']:.2f}"
        traces = (ci(s, k, 4) for k in ("mean_trace", "iqm_trace", "median_trace"))
        ratios = (ci(s, k, 4) for k in ("ratio_to_gsr", "iqm_ratio_to_gsr"))
        rows.append((name, *traces, ci(s, "rmse", 4), nees, ms, *ratios))
    widths = [max(len(r[k]) for r in rows) for k in range(len(head))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def json_default(obj: Any) -> Any:
    """Return a JSON-friendly version of numpy scalars and arrays."""
    import numpy as np

    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serializable: {type(obj).__name__}")


def _cmd_simulate(args: argparse.Namespace) -> int:
    # Everything checked before computing: scenario, planners, output folder.
    overrides = {} if args.steps is None else {"n_steps": args.steps}
    scenario = make_scenario(args.scenario, **overrides)
    names = list(dict.fromkeys(args.planner or DEFAULT_PLANNERS))
    planners, configs = {}, {}
    for name in names:
        planners[name], configs[name] = make_planner(name, args)
    workers, address = check_options(args.workers, args.address)
    with prepare_output_dir(args.out, SIMULATE_OUTPUTS, args.overwrite) as outputs:
        results = run_monte_carlo(
            scenario,
            planners,
            args.runs,
            args.seed,
            progress=not args.no_progress,
            workers=workers,
            address=address,
        )
        summaries = {}
        for name, res in results.items():
            s = res.summary(results.get("gsr"))  # the paired ratios to GSR, if it ran
            s["seed"] = args.seed
            s["config"] = {"planner": configs[name], "scenario": scenario.to_dict()}
            summaries[name] = s
        last = args.seed + args.runs - 1
        print(
            f"scenario {scenario.name!r}, {args.runs} runs (seeds {args.seed}..{last}), "
            f"{scenario.n_steps} steps"
        )
        print(format_table(summaries))
        outputs.write_json("results.json", summaries, default=json_default)
        if not args.no_plot:
            from activetrack.baselines.plotting import plot_comparison, plot_trajectories

            first = {name: res.records[0] for name, res in results.items()}
            plot_trajectories(
                first,
                outputs.staged("trajectories.png"),
                title=f"scenario {scenario.name!r}, seed {args.seed} (one run)",
            )
            plot_comparison(
                results,
                outputs.staged("comparison.png"),
                title=f"scenario {scenario.name!r}, {args.runs} runs (seeds {args.seed}..{last})",
            )
        written = outputs.commit()
    for path in written.values():
        print(f"wrote {path}")
    return 0


def _add_evaluate(sub: argparse._SubParsersAction) -> None:
    defaults = inspect.signature(evaluation.run_evaluation).parameters
    p = sub.add_parser(
        "evaluate",
        help=COMMANDS["evaluate"][1],
        description=(
            "Run every --policy (gsr, gsr-restarts, gbes, rm, lookahead, gsr-single-model, "
            "lookahead-single-model, distributed-gsr, distributed-lookahead, or the path of a "
            "policy.zip written by 'activetrack train') in the environment on the same "
            "--episodes seeds (seed, seed+1, ...). Prints mean trace and RMSE with 95% "
            "intervals, the IQM and median trace with bootstrap 95% intervals, mean return, "
            "the ratios of the mean and IQM trace to GSR's (GSR is evaluated as the reference "
            "even if not listed) and, with limited sensing, the track-loss rate; writes "
            "OUT/results.json (a list, one object per policy), "
            "OUT/episodes.json and OUT/mean_trace.png. Every policy file is checked before "
            "the first episode."
        ),
    )
    p.add_argument(
        "--scenario",
        default=defaults["scenario"].default,
        choices=sorted(PRESETS),
        help="preset (default %(default)s)",
    )
    p.add_argument(
        "--policy",
        action="append",
        required=True,
        metavar="NAME|PATH",
        help="gsr, gsr-restarts, gbes, rm, lookahead, gsr-single-model, "
        "lookahead-single-model (planning from the IMM's first mode alone: see --estimator), "
        "distributed-gsr (each robot on its own estimate, inside its group of a "
        "decentralized team), distributed-lookahead (per group, by its leader) or "
        "PATH/policy.zip (repeatable); "
        "lookahead costs about 0.35-0.7 s of CPU per step on urban and urban_random "
        "(benchmarks/time_lookahead.py --scenario urban): use --batched there",
    )
    p.add_argument(
        "--estimator",
        choices=("ekf", "imm"),
        default=None,
        help="the filter: the scenario's (default), ekf, or imm (an IMM of the scenario's "
        "target_behaviour modes, e.g. maneuvering); the planners plan from its mixture, "
        "the *-single-model names from its first mode",
    )
    p.add_argument(
        "--episodes",
        type=positive_int,
        default=defaults["episodes"].default,
        help="number of seeds (default %(default)s)",
    )
    p.add_argument(
        "--seed",
        type=seed_int,
        default=defaults["seed"].default,
        help="first held-out seed (default %(default)s)",
    )
    add_output_arguments(p, None)
    p.add_argument("--no-plot", action="store_true", help="do not write mean_trace.png")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.add_argument(
        "--batched",
        action="store_true",
        help="run gsr, lookahead and learned policies (policy.zip) on all episodes at once "
        "in a batched world (far faster; a planner's rows equal the serial ones to its "
        "tolerance, a network's to float32 rounding; rm runs episode by episode)",
    )
    p.add_argument(
        "--loss-trace",
        type=positive_float,
        default=None,
        metavar="M2",
        help="track-loss threshold (m^2): a target is lost in a step where no sensor "
        "measured it and its position trace is above this (default: each target's prior "
        "position trace, tr P0[:2, :2])",
    )
    p.add_argument(
        "--pool",
        action="append",
        default=None,
        type=_pool,
        metavar="NAME=POLICY[,POLICY...]",
        help="add a row NAME pooling these --policy values (one policy's training seeds) "
        "as a runs x episodes matrix: IQM, median and mean with bootstrap intervals over "
        "runs and episodes, ratios to GSR (repeatable)",
    )
    add_gbes_arguments(p)
    add_ray_arguments(p, "episodes")
    p.set_defaults(func=_cmd_evaluate, parser=p)


def _pool(text: str) -> tuple[str, list[str]]:
    """Parse ``NAME=POLICY[,POLICY...]`` (argparse ``type``)."""
    name, sep, members = text.partition("=")
    parts = [m for m in members.split(",") if m]
    if not sep or not name or not parts:
        raise argparse.ArgumentTypeError(f"must be NAME=POLICY[,POLICY...], got {text!r}")
    return name, parts


def _cmd_evaluate(args: argparse.Namespace) -> int:
    policies: Any = args.policy
    if any(p.lower() == "lookahead" for p in policies) or args.gbes_spacing is not None:
        # The look-ahead policy recovers the full prediction with the scenario's model.
        from activetrack.baselines.policies import GBESPolicy, LookaheadPolicy

        def made(p: str) -> Any:
            if p.lower() == "lookahead":
                return LookaheadPolicy(scenario=args.scenario)
            if p.lower() == "gbes" and args.gbes_spacing is not None:
                return GBESPolicy(spacing=args.gbes_spacing)
            return p

        policies = {p: made(p) for p in policies}
    run_evaluation(
        policies,
        args.scenario,
        args.episodes,
        args.seed,
        out_dir=args.out,
        plot=not args.no_plot,
        progress=not args.no_progress,
        overwrite=args.overwrite,
        workers=args.workers,
        address=args.address,
        batched=args.batched,
        loss_trace=args.loss_trace,
        pools=_pools(args),
        **({} if args.estimator is None else {"estimator": args.estimator}),
    )
    return 0


def _pools(args: argparse.Namespace) -> dict[str, list[str]] | None:
    """Return the ``--pool`` options as a mapping; raise ValueError if a name repeats."""
    if args.pool is None:
        return None
    names = [name for name, _ in args.pool]
    if len(set(names)) != len(names):
        raise ValueError(f"--pool: each NAME once, got {names}")
    return dict(args.pool)
