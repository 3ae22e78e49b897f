"""How often GSR reaches the GBES grid optimum, with and without restarts.

500 random 3-sensor problems (:func:`activetrack.baselines.random_problem`: sensors at
1-4 m from the predicted target with r = 1 and rho = 2, so the minimum distance is active
for about two thirds of the sensors; random prior and heterogeneous noise). For each,
the GBES grid optimum at pi/200 (exact over the grid) is the reference: a GSR answer
counts as a hit when its trace is at most 1e-6 (relative) above it. GSR being below the
grid optimum is normal: GSR optimizes on the continuous curves.

The restart starts are described in :mod:`activetrack.baselines.gsr_restarts`. Cost is
reported as single-sensor solves and as wall time, relative to plain GSR.

    .venv/bin/python benchmarks/bench_gsr_restarts.py [--problems 500] [--seed 0]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from activetrack.baselines import GBES, GSR, random_problem


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", type=int, default=500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--rtol", type=float, default=1e-6, help="hit tolerance (relative)")
    ap.add_argument("--all-starts", action="store_true", help="also the other restart starts")
    args = ap.parse_args()

    variants = {
        "GSR (plain)": GSR(),
        "GSR (pattern moves)": GSR(accelerate=True),
        "GSR (restarts: grid, default)": GSR(restarts=True),
    }
    if args.all_starts:
        variants["GSR (restarts: mirror + independent)"] = GSR(
            restarts=True, starts=("mirror", "independent")
        )
        variants["GSR (restarts: greedy both orders)"] = GSR(
            restarts=True, starts=("greedy", "greedy-reversed")
        )
    rng = np.random.default_rng(args.seed)
    problems = [random_problem(rng, 3) for _ in range(args.problems)]
    ref = np.array([GBES().search(p).value for p in problems])
    vals = {k: [] for k in variants}
    solves = {k: [] for k in variants}
    wall = {k: 0.0 for k in variants}
    cpu = {k: 0.0 for k in variants}
    starts = []
    # Interleaved (every variant on a problem, then the next problem) so that machine load
    # affects all variants alike; CPU time is less sensitive to other processes than wall.
    for p in problems:
        for name, planner in variants.items():
            t0, c0 = time.perf_counter(), time.process_time()
            res = planner.plan_with_info(p)
            wall[name] += time.perf_counter() - t0
            cpu[name] += time.process_time() - c0
            vals[name].append(res.value)
            solves[name].append(res.n_solves)
            if name == "GSR (restarts: grid, default)":
                starts.append(res.start)
    base = "GSR (plain)"
    n = args.problems
    print(f"{n} random 3-sensor problems (seed {args.seed}); reference: GBES at pi/200\n")
    print(
        "| planner | within 1e-6 of GBES (or better) | worst ratio to GBES | mean solves | "
        "solves vs plain | mean ms (wall) | CPU time vs plain |"
    )
    print("|---|---|---|---|---|---|---|")
    for name in variants:
        ratio = np.array(vals[name]) / ref
        miss = int(np.sum(ratio > 1 + args.rtol))
        print(
            f"| {name} | {100 * (1 - miss / n):.1f}% ({miss} misses) | {ratio.max():.6f} | "
            f"{np.mean(solves[name]):.1f} | {np.mean(solves[name]) / np.mean(solves[base]):.2f}x | "
            f"{wall[name] / n * 1e3:.2f} | {cpu[name] / cpu[base]:.2f}x |"
        )
    won = {s: starts.count(s) for s in dict.fromkeys(starts)}
    print(f"\nrestarts (grid): the best answer came from {won}")
    better = np.mean(np.array(vals[base]) / ref < 1 - 1e-9) * 100
    print(f"plain GSR strictly below the grid optimum (continuous beats grid): {better:.0f}%")


if __name__ == "__main__":
    main()
