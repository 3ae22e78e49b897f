"""Speed of the tasks beyond the paper, beside the peers, in one run.

For every named task (:data:`activetrack.world.scenarios.TASKS`) and the paper:

1. the single PettingZoo env (random actions) steps/s beside MPE2 ``simple_spread`` with
   as many agents (continuous actions), interleaved timing;
2. the batched env at N = 1024 copies, env-steps/s, beside VMAS ``simple_spread`` on CPU
   with as many agents at the same N (torch with one thread), timed in alternating chunks
   of 10 steps (ours with its autoresets every 50 steps, VMAS without episode ends);
3. GSR's planning time per step (ms) along a GSR-driven episode, single problem.

The peers come from the ``[bench]`` extra. Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_tasks.py          # ~3 minutes
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_tasks.py --quick
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


def interleaved_rates(steppers: dict, n: int, seconds: float, chunk: int) -> dict[str, float]:
    """Return each stepper's env-steps/s (``n`` copies a step), timed in alternating chunks
    of ``chunk`` steps (after two warm-up steps) until each ran ``seconds``: the peers see
    the same load."""
    spent = dict.fromkeys(steppers, 0.0)
    done = dict.fromkeys(steppers, 0)
    for step in steppers.values():  # warm up
        step(0)
        step(1)
    while min(spent.values()) < seconds:
        for name, step in steppers.items():
            start = time.perf_counter()
            for k in range(chunk):
                step(done[name] + k)
            spent[name] += time.perf_counter() - start
            done[name] += chunk
    return {name: n * done[name] / spent[name] for name in steppers}


def single_env(task: str, seconds: float) -> dict[str, float]:
    """Return steps/s of the task's parallel env and of MPE2 simple_spread (same M)."""
    from bench_env import _Runner, measure
    from mpe2 import simple_spread_v3

    from activetrack.envs import parallel_env

    m = parallel_env(scenario=task).n_sensors
    rates = measure(
        {
            "activetrack": _Runner(lambda: parallel_env(scenario=task)),
            "simple_spread": _Runner(
                lambda: simple_spread_v3.parallel_env(N=m, continuous_actions=True, max_cycles=50)
            ),
        },
        seconds,
    )
    rates["ratio"] = rates["activetrack"] / rates["simple_spread"]
    return rates


def batched_env(task: str, n: int, seconds: float, chunk: int = 10) -> dict[str, float]:
    """Return env-steps/s of the task's batched env and of VMAS simple_spread (same M, N),
    timed in alternating chunks of ``chunk`` steps until each has run ``seconds`` (both
    then share the machine's fluctuating load; ours with its autoresets)."""
    from throughput import vmas_stepper

    from activetrack.envs.batched import BatchedActiveTracking

    env = BatchedActiveTracking(n, scenario=task)
    env.reset(seed=0)
    m = env.n_sensors
    rng = np.random.default_rng(0)
    pool = [rng.uniform(-1, 1, (n, 2 * m)).astype(np.float32) for _ in range(8)]
    steppers = {"activetrack": lambda k: env.step(pool[k % 8]), "vmas": vmas_stepper(n, m)}
    rates = interleaved_rates(steppers, n, seconds, chunk)
    return {**rates, "ratio": rates["activetrack"] / rates["vmas"]}


def gsr_ms(task: str, episodes: int) -> float:
    """Return GSR's mean planning time (ms) per step along GSR-driven episodes."""
    from activetrack.baselines import GSR
    from activetrack.world import World

    world, planner, total, steps = World(task), GSR(), 0.0, 0
    for seed in range(episodes):
        world.reset(seeds=[seed])
        while not (world.get("truncated", 0) or world.get("terminated", 0)):
            problem = world.planning_problem(0)
            start = time.perf_counter()
            positions = planner.plan(problem)
            total += time.perf_counter() - start
            steps += 1
            world.step(positions)
    return 1e3 * total / steps


def main(argv: list[str] | None = None) -> dict:
    """Print every figure and ratio; return them as a dict."""
    import torch

    from activetrack.world.scenarios import TASKS

    torch.set_num_threads(1)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (noisier)")
    parser.add_argument("--json", help="also write the figures to this JSON file")
    parser.add_argument("--tasks", nargs="*", default=["paper", *TASKS])
    args = parser.parse_args(argv)
    seconds, episodes = (1.0, 2) if args.quick else (4.0, 5)
    out: dict = {}
    for task in args.tasks:
        row = {
            "single": single_env(task, seconds),
            "batched_1024": batched_env(task, 1024, seconds),
            "gsr_ms_per_step": gsr_ms(task, episodes),
        }
        out[task] = row
        s, b = row["single"], row["batched_1024"]
        gsr = row["gsr_ms_per_step"]
        print(
            f"{task:16s} single {s['activetrack']:8.0f}/s vs MPE2 {s['simple_spread']:7.0f}/s "
            f"(x{s['ratio']:.2f}) | batched N=1024 {b['activetrack'] / 1e3:7.1f}k/s vs VMAS "
            f"{b['vmas'] / 1e3:7.1f}k/s (x{b['ratio']:.2f}) | GSR {gsr:.2f} ms/step",
            flush=True,
        )
    if args.json:
        from activetrack.files import atomic_write_json

        atomic_write_json(args.json, out)
    return out


if __name__ == "__main__":
    main()
