"""Planning time per step of GSR (M = 1..64) and GBES (M = 1..3): the scaling table.

GSR is timed on each problem alone and, in the rows "GSR (batch)", on all the problems of
a team size stacked into one batched :class:`activetrack.PlanningProblem` (one call; the
time per plan is the call's time over the number of problems).

Problems are random one-step planning problems (:func:`activetrack.baselines.random_problem`:
prior eigenvalues log-uniform in [0.05, 20], sensors at 1-4 m from the predicted target,
r = 1, rho = 2, heterogeneous noise, so the minimum distance is often active), the same
problems for every planner of a team size. Times are CPU times of this process
(``time.process_time``), which other processes on a shared machine disturb much less than
wall time; on an idle machine the two agree for these single-threaded planners.

    .venv/bin/python benchmarks/bench_planners.py [--problems 40] [--seed 0]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from activetrack.baselines import GBES, GSR, random_problem
from activetrack.world.problem import PlanningProblem


def cpu_times(planner, problems) -> tuple[np.ndarray, list]:
    """Return per-problem CPU times (s) and the planner's per-problem results."""
    times, results = [], []
    for p in problems:
        t0 = time.process_time()
        planner.plan(p, None)
        times.append(time.process_time() - t0)
        results.append(planner.last_result)
    return np.array(times), results


def row(name: str, m: int, spacing: str, t: np.ndarray, extra: str) -> str:
    """Return one Markdown table row."""
    return (
        f"| {name} | {m} | {spacing} | {np.median(t) * 1e3:.2f} | {np.mean(t) * 1e3:.2f} | "
        f"{np.mean(t) / m * 1e3:.3f} | {extra} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--problems", type=int, default=40, help="problems per team size")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    def problems(m: int) -> list:
        rng = np.random.default_rng([args.seed, m])
        return [random_problem(rng, m) for _ in range(args.problems)]

    # Load (or compile) every planner's kernels first: the first call of a process pays it.
    warm = problems(3)[:2]
    for planner in (GSR(), GSR(restarts=True), GBES(spacing=math.pi / 100)):
        for p in warm:
            planner.plan(p, None)
        GSR().plan_with_info(PlanningProblem.stack(warm))
    print(f"{args.problems} random problems per team size (seed {args.seed}), CPU time\n")
    print(
        "| planner | M | GBES spacing (m) | median ms/step | mean ms/step | mean ms/sensor | "
        "details |"
    )
    print("|---|---|---|---|---|---|---|")
    for m in (1, 2, 3, 4, 8, 16, 32, 64):
        probs = problems(m)
        variants = [("GSR", GSR())] + ([("GSR restarts", GSR(restarts=True))] if m == 3 else [])
        for name, planner in variants:
            t, res = cpu_times(planner, probs)
            solves = sum(r.n_solves for r in res)
            extra = (
                f"{np.mean([r.sweeps for r in res]):.1f} sweeps, "
                f"{solves / len(res) / m:.2f} solves/sensor, {t.sum() / solves * 1e6:.0f} us/solve"
            )
            print(row(name, m, "-", t, extra))
        batch = PlanningProblem.stack(probs)
        gsr = GSR()
        t0 = time.process_time()
        res = gsr.plan_with_info(batch)
        per_plan = (time.process_time() - t0) / len(probs)
        print(
            f"| GSR (batch) | {m} | - | - | {per_plan * 1e3:.2f} | {per_plan / m * 1e3:.3f} | "
            f"{np.mean(res.sweeps):.1f} sweeps, {len(probs)} problems in one call |"
        )
    for m, spacing in (
        (1, math.pi / 200),
        (2, math.pi / 200),
        (3, math.pi / 200),
        (3, math.pi / 100),
    ):
        t, res = cpu_times(GBES(spacing=spacing), problems(m))
        combos = np.mean([r.n_combinations for r in res])
        evaluated = np.mean([r.n_evaluated / r.n_combinations for r in res])
        label = "pi/200" if spacing < 0.02 else "pi/100"
        extra = f"{combos:.3g} combinations, {100 * evaluated:.1f}% evaluated"
        print(row("GBES", m, label, t, extra))


if __name__ == "__main__":
    main()
