"""CPU time per step of the look-ahead policy beside GSR on the same states.

Each step of a few held-out episodes of ``--scenario`` (default ``paper``; the look-ahead's
own closed loop) is planned by ``GSRPolicy`` and ``LookaheadPolicy`` on the same planning
problem; the median and mean CPU milliseconds per step are printed for both.
``--settings`` (JSON objects of :class:`~activetrack.baselines.lookahead.Lookahead`'s
keywords, default ``{}``) times each setting in its own closed loop, GSR beside it. Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/time_lookahead.py [--episodes 4]
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/time_lookahead.py --scenario urban
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/time_lookahead.py \\
        --settings '{}' '{"tail": 0, "pair_passes": 0, "margin": 0.5}'
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from activetrack.baselines import GSRPolicy, LookaheadPolicy
from activetrack.world import World


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--seed", type=int, default=1000, help="first held-out seed")
    parser.add_argument("--settings", nargs="+", default=["{}"], help="Lookahead keywords")
    parser.add_argument("--scenario", default="paper", help="a preset (default paper)")
    args = parser.parse_args()
    settings = [json.loads(s) for s in args.settings]
    policies = [LookaheadPolicy(scenario=None, **kw) for kw in settings]  # bad keywords fail
    for kw, lookahead in zip(settings, policies, strict=True):
        print(f"scenario {args.scenario}, settings {json.dumps(kw)}")
        time_policies(lookahead, GSRPolicy(), args.seed, args.episodes, args.scenario)


def time_policies(
    lookahead: LookaheadPolicy, gsr: GSRPolicy, first: int, episodes: int, scenario: str = "paper"
) -> None:
    """Print both policies' CPU ms per step on the look-ahead's closed loop."""
    times: dict[str, list[float]] = {"gsr": [], "lookahead": []}
    warm = World(scenario)  # load the compiled kernels before timing
    warm.reset(seeds=[0])
    gsr.plan(warm.planning_problem(0))
    lookahead.plan(warm.planning_problem(0))
    for seed in range(first, first + episodes):
        world = World(scenario)
        world.reset(seeds=[seed])
        lookahead.reset()  # a new episode: no warm start from the last one's plan
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
