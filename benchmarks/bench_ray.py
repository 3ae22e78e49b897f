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

On a shared machine the wall clock measures the scheduler as much as the code, so the
CPU time is reported beside it (Linux ``/proc``): the serial loop's, and each Ray
worker's during the study. ``cpu speed-up`` = serial CPU s / the busiest worker's CPU s,
the speed-up the study would have with a core per worker and nothing else running.
Run with numpy single-threaded, as the workers are::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_ray.py           # a few minutes
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


def study(runs: int, workers: int) -> tuple[float, float, np.ndarray]:
    """Return the wall and this process's CPU seconds of one GSR study, and its mean traces."""
    from activetrack import make_scenario
    from activetrack.baselines import GSR, run_monte_carlo

    scenario = make_scenario("paper")
    t0, c0 = time.perf_counter(), time.process_time()
    res = run_monte_carlo(scenario, {"gsr": GSR()}, runs, 0, progress=False, workers=workers)
    return time.perf_counter() - t0, time.process_time() - c0, res["gsr"].mean_trace


def _cpu_seconds(pid: int) -> float:
    """Return the user + system CPU seconds of process ``pid`` (Linux /proc)."""
    fields = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _pid(_: int) -> int:
    time.sleep(0.3)  # long enough that every worker takes one
    return os.getpid()


def on_ray(runs: int, workers: int) -> tuple[float, float, float, np.ndarray]:
    """Return (start-up s, study wall s, busiest worker's CPU s, mean traces), a fresh Ray."""
    import ray

    t0 = time.perf_counter()
    ray.init(address="local", num_cpus=workers, include_dashboard=False, logging_level="error")
    try:
        study(2 * workers, max(workers, 2))  # warm up: start the workers, import the library
        pids = set(ray.get([ray.remote(_pid).remote(k) for k in range(3 * workers)]))
        startup = time.perf_counter() - t0
        before = {p: _cpu_seconds(p) for p in pids}
        seconds, _, traces = study(runs, max(workers, 2))  # >1 selects Ray; it has N CPUs
        cpu = max(_cpu_seconds(p) - before[p] for p in pids)
    finally:
        ray.shutdown()
    return startup, seconds, cpu, traces


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    times: dict[str, list[float]] = {"serial": [], "ray 1": [], "ray 2": []}
    cpus: dict[str, list[float]] = {mode: [] for mode in times}
    startups: dict[str, list[float]] = {"ray 1": [], "ray 2": []}
    study(2, 1)  # warm up the serial path too (lazy imports, first-call caches)
    for _ in range(args.repeats):
        seconds, cpu, reference = study(args.runs, 1)
        times["serial"].append(seconds)
        cpus["serial"].append(cpu)
        for n in (1, 2):
            startup, seconds, cpu, traces = on_ray(args.runs, n)
            if not np.array_equal(traces, reference):
                raise SystemExit(f"ray {n}: results differ from the serial study")
            times[f"ray {n}"].append(seconds)
            cpus[f"ray {n}"].append(cpu)
            startups[f"ray {n}"].append(startup)

    serial = statistics.median(times["serial"])
    print(
        f"GSR Monte Carlo, paper preset, {args.runs} runs; median of {args.repeats} "
        f"(machine: {os.cpu_count()} CPUs, {platform.processor() or platform.machine()}; "
        f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')})"
    )
    serial_cpu = statistics.median(cpus["serial"])
    print(
        f"{'mode':<8} {'seconds':>8} {'runs/s':>8} {'speed-up':>9} {'cpu s':>7} "
        f"{'cpu speed-up':>13} {'ray start-up s':>15}"
    )
    summary = {}
    for mode, values in times.items():
        med, cpu = statistics.median(values), statistics.median(cpus[mode])
        start = f"{statistics.median(startups[mode]):15.1f}" if mode in startups else " " * 15
        print(
            f"{mode:<8} {med:8.2f} {args.runs / med:8.1f} {serial / med:8.2f}x {cpu:7.2f} "
            f"{serial_cpu / cpu:12.2f}x {start}"
        )
        summary[mode] = {"seconds": values, "cpu_seconds": cpus[mode], "speedup": serial / med}
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
