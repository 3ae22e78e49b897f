"""``activetrack train selfplay`` and ``activetrack train selfplay-evaluate``: the
command lines of :mod:`activetrack.train.selfplay` (the two-team ``pursuit`` game)."""

from __future__ import annotations

import argparse
from typing import Any

from activetrack.cli import add_output_arguments, field_default, seed_int
from activetrack.files import prepare_output_dir
from activetrack.train import selfplay as sp
from activetrack.train.utils import DEFAULT_THREADS, MAX_THREADS, check_int

#: Scenarios with a controlled target (the two-team game's presets).
SCENARIOS = ("pursuit",)
#: What ``selfplay-evaluate`` writes.
EVAL_OUTPUTS = ("pursuit_eval.json", "pursuit_eval.md")
#: The most held-out episodes ``selfplay-evaluate`` runs.
MAX_EPISODES = 100_000


def add_selfplay_parsers(methods: argparse._SubParsersAction) -> None:
    """Add ``selfplay`` and ``selfplay-evaluate`` to the ``train`` methods ``methods``."""
    text = (
        "self-play on the two-team game pursuit: an evader (PPO) trained against the sensors "
        "(a planner, then, with --sensor-steps, the sensors trained against it), in rounds"
    )
    q = methods.add_parser("selfplay", help=text, description=text)
    q.add_argument("--scenario", choices=SCENARIOS, default="pursuit", help="(default %(default)s)")
    q.add_argument("--seed", type=seed_int, default=0, help="training seed (default %(default)s)")
    add_output_arguments(q, None, required=True)
    for option, name, type_ in (
        ("--rounds", "rounds", int),
        ("--evader-steps", "evader_steps", int),
        ("--sensor-steps", "sensor_steps", int),
        ("--n-steps", "n_steps", int),
        ("--batch-size", "batch_size", int),
        ("--lr", "learning_rate", float),
        ("--gamma", "gamma", float),
        ("--ent-coef", "ent_coef", float),
        ("--eval-episodes", "eval_episodes", int),
    ):
        q.add_argument(option, dest=name, type=type_, default=None,
                       help=f"(default {field_default(sp.SelfPlayConfig, name)})")  # fmt: skip
    q.add_argument(
        "--sensors",
        choices=sp.PLANNERS,
        default=None,
        help="the planner playing the sensors until they are trained (default gsr)",
    )
    q.add_argument("--hidden", type=int, nargs="+", default=None, help="MLP sizes (default 64 64)")
    q.add_argument("--threads", type=int, default=DEFAULT_THREADS,
                   help=f"torch threads, 1 to {MAX_THREADS} (default %(default)s)")  # fmt: skip
    q.set_defaults(func=run_selfplay, parser=q)

    text = (
        "evaluate planners against the scripted evader and a learned one (evader.zip of "
        "'train selfplay') on held-out episodes: the protocol's statistics"
    )
    e = methods.add_parser("selfplay-evaluate", help=text, description=text)
    e.add_argument("--scenario", choices=SCENARIOS, default="pursuit", help="(default %(default)s)")
    e.add_argument("--evader", required=True, help="an evader.zip of 'train selfplay'")
    e.add_argument(
        "--policy",
        action="append",
        choices=sp.PLANNERS,
        default=None,
        help="a planner for the sensors (repeat; default gsr and lookahead)",
    )
    e.add_argument("--episodes", type=int, default=100, help="(default %(default)s)")
    e.add_argument("--seed", type=seed_int, default=1000,
                   help="first held-out episode seed (default %(default)s)")  # fmt: skip
    add_output_arguments(e, None, required=True)
    e.set_defaults(func=run_selfplay_evaluate, parser=e)


def run_selfplay(args: argparse.Namespace) -> int:
    """Run ``activetrack train selfplay``; return the exit code."""
    given: dict[str, Any] = {
        k: getattr(args, k)
        for k in ("rounds", "evader_steps", "sensor_steps", "n_steps", "batch_size",
                  "learning_rate", "gamma", "ent_coef", "eval_episodes", "sensors", "hidden")
        if getattr(args, k) is not None
    }  # fmt: skip
    cfg = sp.SelfPlayConfig(**given)
    threads = check_int("threads", args.threads, 1, MAX_THREADS)
    with prepare_output_dir(args.out, sp.OUTPUTS, args.overwrite) as outputs:
        result = sp.train_selfplay(args.scenario, seed=args.seed, config=cfg, threads=threads)
        record = {"scenario": args.scenario, "seed": args.seed, **sp.config_dict(cfg)}
        path = sp.save_selfplay(result, outputs, record)
    for h in result.history:
        before, after = sum(h["before"]) / len(h["before"]), sum(h["after"]) / len(h["after"])
        print(f"round {h['round']} {h['side']} vs {h['opponent']}: mean return per step "
              f"{before:.4f} -> {after:.4f}")  # fmt: skip
    print(f"selfplay: {result.seconds:.1f} s -> {path}")
    return 0


def run_selfplay_evaluate(args: argparse.Namespace) -> int:
    """Run ``activetrack train selfplay-evaluate``; return the exit code."""
    episodes = check_int("episodes", args.episodes, 1, MAX_EPISODES)
    evader = sp.load_evader(args.evader)
    planners = list(dict.fromkeys(args.policy or ["gsr", "lookahead"]))
    seeds = list(range(args.seed, args.seed + episodes))
    with prepare_output_dir(args.out, EVAL_OUTPUTS, args.overwrite) as outputs:
        rows = sp.evaluate_against_evaders(planners, evader, seeds, args.scenario)
        table = sp.format_rows(rows)
        with outputs:
            outputs.write_json("pursuit_eval.json", {
                "scenario": args.scenario, "evader": str(args.evader), "seeds": seeds,
                "rows": rows})  # fmt: skip
            outputs.write_text("pursuit_eval.md", table + "\n")
            outputs.commit()
    print(table)
    return 0
