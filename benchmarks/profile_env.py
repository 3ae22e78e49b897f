"""Where a step of the batched environment spends its time: cProfile of random steps.

Prints the environment steps per second and the functions with the largest cumulative
time (the breakdown quoted in the README for the urban tasks). Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/profile_env.py --scenario urban
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import time

import numpy as np

from activetrack.envs.batched import BatchedActiveTracking


def main() -> None:
    """Profile ``--steps`` random steps of ``--num-envs`` copies of ``--scenario``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="urban")
    ap.add_argument("--num-envs", type=int, default=1024)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--top", type=int, default=15)
    args = ap.parse_args()
    env = BatchedActiveTracking(scenario=args.scenario, num_envs=args.num_envs)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (args.steps, *env.action_space.shape)).astype(np.float32)
    for a in actions[:3]:  # warm up
        env.step(a)
    profile = cProfile.Profile()
    start = time.perf_counter()
    profile.enable()
    for a in actions:
        env.step(a)
    profile.disable()
    rate = args.steps * args.num_envs / (time.perf_counter() - start)
    print(f"{args.scenario}, N = {args.num_envs}: {rate:,.0f} env-steps/s (under cProfile)")
    pstats.Stats(profile).sort_stats("cumtime").print_stats(args.top)


if __name__ == "__main__":
    main()
