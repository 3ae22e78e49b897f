"""Environment throughput: activetrack's ParallelEnv beside PettingZoo MPE simple_spread.

Measures env steps per second under random actions for M = 3 sensors (the paper's
scenario), without rendering and with ``rgb_array`` rendering of every step, and MPE's
``simple_spread_v3.parallel_env(N=3, continuous_actions=True)`` in the same run (same
episode length, 50 steps, so both reset equally often). Actions are drawn from the
action spaces beforehand, so only ``step`` and ``reset`` (and ``render``) are timed. The
environments are timed in interleaved quarter-second chunks, so a fluctuating machine
load affects all of them alike.

Run::

    .venv/bin/python benchmarks/bench_env.py            # about 20 s (5 s each)
    .venv/bin/python benchmarks/bench_env.py --seconds 5 --json out.json
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from collections.abc import Callable
from typing import Any

import numpy as np


class _Runner:
    """Steps one ParallelEnv with pre-drawn random actions, in timed chunks."""

    def __init__(self, make: Callable[[], Any], render: bool = False, pool: int = 512) -> None:
        self.env = make()
        self.render = render
        self.env.reset(seed=0)
        agents = list(self.env.possible_agents)
        for i, a in enumerate(agents):
            self.env.action_space(a).seed(i)
        self.actions = [{a: self.env.action_space(a).sample() for a in agents} for _ in range(pool)]
        self.n = 0
        self.chunk = 1  # steps per timed chunk, set by measure()
        self.steps = 0
        self.seconds = 0.0
        self.run(20)  # warm up (the first render builds the figure)
        self.steps, self.seconds = 0, 0.0

    def run(self, n: int) -> None:
        env, actions, pool = self.env, self.actions, len(self.actions)
        start = time.perf_counter()
        for _ in range(n):
            if not env.agents:
                env.reset()
            env.step(actions[self.n % pool])
            if self.render:
                env.render()
            self.n += 1
        self.seconds += time.perf_counter() - start
        self.steps += n

    @property
    def rate(self) -> float:
        return self.steps / self.seconds


def measure(runners: dict[str, _Runner], seconds: float, chunk: float = 0.25) -> dict[str, float]:
    """Return steps per second of each runner, timed in interleaved chunks of ``chunk`` s.

    Interleaving gives every environment the same share of a fluctuating machine load,
    so the ratios are stable even when the absolute figures are not.
    """
    for r in runners.values():  # chunk sizes from a first estimate of each rate
        r.run(10)
        r.chunk = max(1, int(chunk * r.rate))
        r.steps, r.seconds = 0, 0.0
    while min(r.seconds for r in runners.values()) < seconds:
        for r in runners.values():
            r.run(r.chunk)
    for r in runners.values():
        r.env.close()
    return {name: r.rate for name, r in runners.items()}


def main(argv: list[str] | None = None) -> dict[str, float]:
    """Print (and return) steps per second of each environment and the ratios."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="timing per measurement")
    parser.add_argument("--json", help="also write the figures to this JSON file")
    args = parser.parse_args(argv)

    from mpe2 import simple_spread_v3

    from activetrack.envs import parallel_env

    def tracking(render: bool) -> Callable[[], Any]:
        return lambda: parallel_env(scenario="paper", render_mode="rgb_array" if render else None)

    def mpe() -> Any:
        return simple_spread_v3.parallel_env(N=3, continuous_actions=True, max_cycles=50)

    results = measure(
        {
            "activetrack_M3": _Runner(tracking(False)),
            "activetrack_M3_rgb_array": _Runner(tracking(True), render=True),
            "mpe_simple_spread_N3": _Runner(mpe),
        },
        args.seconds,
    )
    results["ratio_no_render"] = results["activetrack_M3"] / results["mpe_simple_spread_N3"]
    results["ratio_rgb_array"] = (
        results["activetrack_M3_rgb_array"] / results["mpe_simple_spread_N3"]
    )
    print(f"python {platform.python_version()}, numpy {np.__version__}, {platform.machine()}")
    print(f"{'environment':38s} {'steps/s':>10s}")
    for key in ("activetrack_M3", "activetrack_M3_rgb_array", "mpe_simple_spread_N3"):
        print(f"{key:38s} {results[key]:10.0f}")
    print(f"ratio activetrack / simple_spread (no render): {results['ratio_no_render']:.2f}")
    print(f"ratio activetrack rgb_array / simple_spread:    {results['ratio_rgb_array']:.3f}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    return results


if __name__ == "__main__":
    main()
