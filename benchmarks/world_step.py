"""Time of one closed-loop step of a single copy, and of one observation and one reset of
N copies.

``World.step_actions`` on one copy (random actions, autoresets), microseconds per step,
the median of three runs of ``--steps`` steps; ``World.observe()`` of ``--copies`` copies,
milliseconds, the median of 200 calls; ``World.reset()`` of all ``--copies`` copies (new
seeds; random occluder layouts drawn anew), milliseconds, the median of three. Run (also
with PYTHONPATH at an export of another commit, to compare)::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/world_step.py
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from activetrack.world import World


def step_us(scenario: str, steps: int) -> float:
    """Return the median microseconds per single-copy step over three runs."""
    world = World(scenario)
    world.reset(seeds=[0])
    actions = np.random.default_rng(0).uniform(-1, 1, (steps + 100, world.n_sensors, 2))

    def run(chunk: np.ndarray) -> None:
        for a in chunk:
            world.step_actions(a)
            if world.get("truncated", 0) or world.get("terminated", 0):
                world.reset()

    run(actions[:100])  # kernels loaded, caches warm
    runs = []
    for _ in range(3):
        start = time.perf_counter()
        run(actions[100:])
        runs.append((time.perf_counter() - start) / steps * 1e6)
    return float(np.median(runs))


def observe_ms(scenario: str, copies: int) -> float:
    """Return the median milliseconds of ``World.observe()`` for ``copies`` copies."""
    world = World(scenario, copies)
    world.reset(seeds=range(copies))
    rng = np.random.default_rng(0)
    for _ in range(20):
        world.step_actions(rng.uniform(-1, 1, (copies, world.n_sensors, 2)))
    times = []
    for _ in range(200):
        start = time.perf_counter()
        world.observe()
        times.append(time.perf_counter() - start)
    return float(np.median(times) * 1e3)


def reset_ms(scenario: str, copies: int) -> float:
    """Return the median milliseconds of resetting all ``copies`` copies (three resets)."""
    world = World(scenario, copies)
    world.reset(seeds=range(copies))
    times = []
    for k in range(1, 4):
        start = time.perf_counter()
        world.reset(seeds=range(k * copies, (k + 1) * copies))
        times.append(time.perf_counter() - start)
    return float(np.median(times) * 1e3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenarios", nargs="+", default=["paper", "uncertain_poses", "urban"])
    parser.add_argument("--steps", type=int, default=2000)
    parser.add_argument("--copies", type=int, default=1024)
    args = parser.parse_args()
    for name in args.scenarios:
        print(
            f"{name:16s} step {step_us(name, args.steps):7.1f} us (one copy) | "
            f"observe {observe_ms(name, args.copies):6.2f} ms | reset "
            f"{reset_ms(name, args.copies):7.1f} ms ({args.copies} copies)",
            flush=True,
        )


if __name__ == "__main__":
    main()
