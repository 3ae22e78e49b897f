"""Speed-up of a GSR Monte Carlo study on Ray workers: serial, 1 worker and 2 workers.

The study is ``run_monte_carlo`` of GSR on the ``paper`` preset over ``--runs`` seeds
(200 by default), the computation of ``activetrack simulate --planner gsr --runs 200``.
Each mode is timed ``--repeats`` times, interleaved (serial, 1 worker, 2 workers, then
again), and the median is reported with the speed-up over the serial loop:

- *serial*: ``workers=1``, no Ray (the default code path);
- *ray N*: a local Ray with ``num_cpus=N``, started and warmed up (its worker processes
  running and the library imported in them) before the clock starts, so the figure is
  the study's; Ray's start-up is reported on its own line.

Every Ray study is checked against the serial one (same mean traces, to the last bit).
Run with numpy single-threaded, as the workers are::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ray.py           # ~2 min
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ray.py --runs 40 --repeats 1
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time

import numpy as np


def study(runs: int, workers: int) -> tuple[float, np.ndarray]:
    """Return the seconds of one GSR study and its per-run mean traces."""
    from activetrack import make_scenario
    from activetrack.baselines import GSR, run_monte_carlo

    scenario = make_scenario("paper")
    t0 = time.perf_counter()
    res = run_monte_carlo(scenario, {"gsr": GSR()}, runs, 0, progress=False, workers=workers)
    return time.perf_counter() - t0, res["gsr"].mean_trace


def on_ray(runs: int, workers: int) -> tuple[float, float, np.ndarray]:
    """Return (Ray start-up seconds, study seconds, mean traces) with a fresh local Ray."""
    import ray

    t0 = time.perf_counter()
    ray.init(address="local", num_cpus=workers, include_dashboard=False, logging_level="error")
    try:
        study(2 * workers, max(workers, 2))  # warm up: start the workers, import the library
        startup = time.perf_counter() - t0
        seconds, traces = study(runs, max(workers, 2))  # >1 selects Ray; this Ray has N CPUs
    finally:
        ray.shutdown()
    return startup, seconds, traces


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    times: dict[str, list[float]] = {"serial": [], "ray 1": [], "ray 2": []}
    startups: dict[str, list[float]] = {"ray 1": [], "ray 2": []}
    for _ in range(args.repeats):
        seconds, reference = study(args.runs, 1)
        times["serial"].append(seconds)
        for n in (1, 2):
            startup, seconds, traces = on_ray(args.runs, n)
            if not np.array_equal(traces, reference):
                raise SystemExit(f"ray {n}: results differ from the serial study")
            times[f"ray {n}"].append(seconds)
            startups[f"ray {n}"].append(startup)

    serial = statistics.median(times["serial"])
    print(
        f"GSR Monte Carlo, paper preset, {args.runs} runs; median of {args.repeats} "
        f"(machine: {os.cpu_count()} CPUs, {platform.processor() or platform.machine()}; "
        f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')})"
    )
    print(f"{'mode':<8} {'seconds':>8} {'runs/s':>8} {'speed-up':>9} {'ray start-up s':>15}")
    summary = {}
    for mode, values in times.items():
        med = statistics.median(values)
        start = f"{statistics.median(startups[mode]):15.1f}" if mode in startups else " " * 15
        print(f"{mode:<8} {med:8.2f} {args.runs / med:8.1f} {serial / med:8.2f}x {start}")
        summary[mode] = {"seconds": values, "speedup": serial / med}
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
