"""Trace against horizon and against planning time for the look-ahead planner's searches.

For each scenario and each search setting, the closed loop runs on the held-out seeds
(all copies in one batched world, ``activetrack.world.World``) paired with GSR on the
same seeds: the ratio of mean traces with a paired bootstrap 95% interval
(:func:`activetrack.baselines.evaluation.paired_ratio_ci`), and the episodes whose
sensors ended inside the true target's ``rho`` disk (count, deepest). Planning time per
step is CPU time (``time.process_time``) of the single-problem path (one episode at a
time, the policy's path) on ``--timing-episodes`` episodes, GSR timed in the same loop
(interleaved). Writes ``OUT/lookahead.json`` and ``OUT/trace_vs_horizon.png``,
``OUT/trace_vs_ms.png`` (each file to a temporary file, renamed into place).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_lookahead.py --out results/lookahead
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

from activetrack.baselines import GSR, Lookahead
from activetrack.baselines.evaluation import paired_ratio_ci
from activetrack.baselines.lookahead import run_batched
from activetrack.world import World

#: The searches compared: label -> Lookahead settings (the horizon is varied separately).
#: The first five have neither the terminal tail nor the pair pass (the README's table).
_PLAIN = {"tail": 0, "pair_passes": 0}
SEARCHES = {
    "GSR rollout + shifted plan": {"headings": 0, "bearings": 0, "passes": 1, **_PLAIN},
    "headings 8": {"headings": 8, "bearings": 0, "passes": 1, **_PLAIN},
    "headings 16": {"headings": 16, "bearings": 0, "passes": 1, **_PLAIN},
    "headings 16, 2 passes": {"headings": 16, "bearings": 0, "passes": 2, **_PLAIN},
    "headings 16 + bearings 16": {"headings": 16, "bearings": 16, "passes": 1, **_PLAIN},
    "headings 16 + tail + pair pass": {"headings": 16, "bearings": 0, "passes": 1},
}
DEFAULT_SEARCH = "headings 16"
HORIZONS = (1, 3, 5, 10, 15)


def closed_loop(scenario: str, seeds: list[int], planner: Lookahead | None) -> dict:
    """Return each seed's mean trace and deepest realized rho violation (GSR if None)."""
    mean_trace, deepest = run_batched(scenario, seeds, planner)
    return {"mean_trace": mean_trace, "violation": deepest}


def timing(scenario: str, seeds: list[int], planner: Lookahead) -> tuple[float, float]:
    """Return the mean CPU ms per step of ``planner`` and of GSR, timed in the same loop."""
    gsr = GSR()
    t_la = t_gsr = 0.0
    steps = 0
    for seed in seeds:
        world = World(scenario, 1)
        world.reset(seeds=[seed])
        prev = None
        while not world.truncated[0]:
            problem = world.planning_problem(0)
            t0 = time.process_time()
            gsr.plan(problem)
            t1 = time.process_time()
            res = planner.plan_prediction(
                problem,
                world.get("x_pred", 0),
                world.get("P_pred", 0),
                world.params.Phi,
                world.params.Q,
                prev,
            )
            t2 = time.process_time()
            t_gsr += t1 - t0
            t_la += t2 - t1
            prev = res.plan
            world.step(res.positions[None])
            steps += 1
    return 1e3 * t_la / steps, 1e3 * t_gsr / steps


def summarize(run: dict, ref: dict) -> dict:
    """Return the JSON summary of a run against GSR's (``ref``) on the same seeds."""
    lo, hi = paired_ratio_ci(run["mean_trace"], ref["mean_trace"])
    return {
        "ratio": float(run["mean_trace"].mean() / ref["mean_trace"].mean()),
        "ratio_ci95": [lo, hi],
        "mean_trace": float(run["mean_trace"].mean()),
        "violating_episodes": int(np.count_nonzero(run["violation"] > 0)),
        "deepest_violation_m": float(max(run["violation"].max(), 0.0)),
    }


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path`` and rename it into place."""
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def plot(results: dict, out: Path) -> None:
    """Write the two figures from ``results``."""
    import io

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    for name, xkey, xlabel in (
        ("trace_vs_horizon.png", "horizon", "horizon H (steps)"),
        ("trace_vs_ms.png", "ms_per_step", "planning CPU ms per step (single problem)"),
    ):
        fig, axes = plt.subplots(1, len(results), figsize=(5.5 * len(results), 4), squeeze=False)
        for ax, (scenario, rows) in zip(axes[0], results.items(), strict=True):
            groups: dict[str, list] = {}
            for row in rows["runs"]:
                if xkey == "ms_per_step" and row.get("ms_per_step") is None:
                    continue
                groups.setdefault(row["search"], []).append(row)
            for search, grp in groups.items():
                grp = sorted(grp, key=lambda r: r[xkey])
                x = [r[xkey] for r in grp]
                y = [r["ratio"] for r in grp]
                err = np.array(
                    [
                        [r["ratio"] - r["ratio_ci95"][0], r["ratio_ci95"][1] - r["ratio"]]
                        for r in grp
                    ]
                ).T
                ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=search)
                if xkey == "ms_per_step":
                    for r in grp:
                        ax.annotate(
                            f"H={r['horizon']}",
                            (r[xkey], r["ratio"]),
                            fontsize=7,
                            xytext=(4, 4),
                            textcoords="offset points",
                        )
            if xkey == "ms_per_step":
                ax.axvline(rows["gsr_ms_per_step"], color="gray", ls=":", label="GSR ms/step")
                ax.set_xlim(left=0)
            ax.axhline(1.0, color="k", lw=0.8)
            ax.axhline(0.96, color="r", lw=0.8, ls="--", label="target 0.96")
            ax.set_title(f"{scenario}: mean trace / GSR's ({rows['episodes']} seeds)")
            ax.set_xlabel(xlabel)
            ax.set_ylabel("ratio to GSR [paired 95% CI]")
            ax.legend(fontsize=8)
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110)
        plt.close(fig)
        write_atomic(out / name, buf.getvalue())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", nargs="+", default=["paper", "homogeneous"])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--seed", type=int, default=1000, help="first held-out seed")
    parser.add_argument("--timing-episodes", type=int, default=4)
    parser.add_argument("--horizons", type=int, nargs="+", default=list(HORIZONS))
    parser.add_argument("--searches", nargs="+", default=list(SEARCHES))
    parser.add_argument(
        "--margin", type=float, default=0.0, help="rho margin of every search (default 0)"
    )
    parser.add_argument("--out", type=Path, default=Path("results/lookahead"))
    parser.add_argument(
        "--plot-only",
        type=Path,
        nargs="+",
        default=None,
        help="merge these lookahead.json files into OUT/lookahead.json and plot them",
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.plot_only:
        merged: dict = {}
        for path in args.plot_only:
            merged.update(json.loads(path.read_text()))
        write_atomic(args.out / "lookahead.json", json.dumps(merged, indent=2).encode())
        plot(merged, args.out)
        return
    seeds = list(range(args.seed, args.seed + args.episodes))
    tseeds = seeds[: args.timing_episodes]
    results: dict = {}
    for scenario in args.scenarios:
        ref = closed_loop(scenario, seeds, None)
        rows = {"episodes": args.episodes, "gsr": summarize(ref, ref), "runs": []}
        gsr_ms = []
        settings = [(DEFAULT_SEARCH, h) for h in args.horizons]
        settings += [(s, 10) for s in args.searches if s != DEFAULT_SEARCH]
        for search, horizon in settings:
            planner = Lookahead(horizon=horizon, margin=args.margin, **SEARCHES[search])
            row = {"search": search, "horizon": horizon, "margin": args.margin}
            row.update(SEARCHES[search])
            row.update(summarize(closed_loop(scenario, seeds, planner), ref))
            row["ms_per_step"], g = timing(scenario, tseeds, planner) if tseeds else (None, 0)
            gsr_ms.append(g)
            rows["runs"].append(row)
            print(scenario, json.dumps(row), flush=True)
        rows["gsr_ms_per_step"] = float(np.mean(gsr_ms)) if gsr_ms else None
        results[scenario] = rows
        write_atomic(args.out / "lookahead.json", json.dumps(results, indent=2).encode())
    plot(results, args.out)
    print(f"wrote {args.out}/lookahead.json, trace_vs_horizon.png, trace_vs_ms.png")


if __name__ == "__main__":
    main()
