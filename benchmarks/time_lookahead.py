"""CPU time per step of the look-ahead policy beside GSR on the same states (``paper``).

Each step of a few held-out ``paper`` episodes (the look-ahead's own closed loop) is planned
by ``GSRPolicy`` and ``LookaheadPolicy`` (default settings) on the same planning problem;
the median and mean CPU milliseconds per step are printed for both. Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/time_lookahead.py [--episodes 4]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from activetrack.baselines import GSRPolicy, LookaheadPolicy
from activetrack.world import World


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--seed", type=int, default=1000, help="first held-out seed")
    args = parser.parse_args()
    lookahead, gsr = LookaheadPolicy(), GSRPolicy()
    times: dict[str, list[float]] = {"gsr": [], "lookahead": []}
    warm = World("paper")  # load the compiled kernels before timing
    warm.reset(seeds=[0])
    gsr.plan(warm.planning_problem(0))
    lookahead.plan(warm.planning_problem(0))
    for seed in range(args.seed, args.seed + args.episodes):
        world = World("paper")
        world.reset(seeds=[seed])
        while not (world.get("truncated", 0) or world.get("terminated", 0)):
            problem = world.planning_problem(0)
            t0 = time.process_time()
            gsr.plan(problem)
            times["gsr"].append(time.process_time() - t0)
            t0 = time.process_time()
            positions = lookahead.plan(problem)
            times["lookahead"].append(time.process_time() - t0)
            world.step(positions)
    for name, t in times.items():
        ms = 1e3 * np.asarray(t)
        median, mean = np.median(ms), ms.mean()
        print(f"{name:10s} median {median:6.2f} ms/step  mean {mean:6.2f}  ({ms.size} steps)")


if __name__ == "__main__":
    main()
