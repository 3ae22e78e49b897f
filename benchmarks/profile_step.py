"""Where a batched env step spends its time: cProfile of ``BatchedActiveTracking.step``.

Steps the batched env (random actions, as ``throughput.py``) and prints the env-steps/s of
the best of ``--repeats`` unprofiled runs, then cProfile's functions by their own time over
a profiled run of the same length (none with ``--top 0``): the compiled kernels show as the
Python functions that wrap them.

Usage: ``OPENBLAS_NUM_THREADS=1 python benchmarks/profile_step.py [--n 8192] [--steps 200]
[--repeats 1] [--scenario paper] [--top 12]``.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

import numpy as np

from activetrack.envs.batched import BatchedActiveTracking


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=8192, help="copies")
    ap.add_argument("--steps", type=int, default=200, help="steps timed, then profiled")
    ap.add_argument("--scenario", default="paper")
    ap.add_argument("--repeats", type=int, default=1, help="unprofiled runs (the best)")
    ap.add_argument("--top", type=int, default=12, help="functions printed (0: no profile)")
    args = ap.parse_args(argv)
    env = BatchedActiveTracking(args.n, scenario=args.scenario)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    pool = [rng.uniform(-1, 1, env.action_space.shape).astype(np.float32) for _ in range(8)]
    for k in range(5):  # load the kernels
        env.step(pool[k % 8])
    seconds = float("inf")
    for _ in range(args.repeats):
        start = time.perf_counter()
        for k in range(args.steps):
            env.step(pool[k % 8])
        seconds = min(seconds, time.perf_counter() - start)
    rate = args.n * args.steps / seconds
    print(f"{args.scenario}, N = {args.n}: {rate:,.0f} env-steps/s, {1e6 / rate:.3f} us a copy")
    if args.top <= 0:
        return
    profile = cProfile.Profile()
    profile.enable()
    for k in range(args.steps):
        env.step(pool[k % 8])
    profile.disable()
    pstats.Stats(profile).sort_stats("tottime").print_stats(args.top)


if __name__ == "__main__":
    main()
