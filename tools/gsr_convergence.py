"""How often GSR stops unconverged (at ``max_sweeps``) in closed-loop episodes.

Runs ``GSR()`` (the defaults) as the team's planner on ``--seeds`` episodes of each
scenario and prints the plans that did not meet the tolerance, and the sweeps a plan took.

Usage: ``OPENBLAS_NUM_THREADS=1 python tools/gsr_convergence.py [--seeds 20]
[--scenarios paper homogeneous]``.
"""

from __future__ import annotations

import argparse

import numpy as np

from activetrack.baselines import GSR
from activetrack.envs import parallel_env


def count(scenario: str, seeds: int) -> tuple[int, list[int]]:
    """Return the unconverged plans and every plan's sweeps over seeds ``0..seeds-1``."""
    gsr, unconverged, sweeps = GSR(), 0, []
    for seed in range(seeds):
        env = parallel_env(scenario)
        env.reset(seed=seed)
        while env.agents:
            res = gsr.plan_with_info(env.planning_problem())
            unconverged += not res.converged
            sweeps.append(res.sweeps)
            env.step_positions(res.positions)
    return unconverged, sweeps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="episodes per scenario")
    ap.add_argument("--scenarios", nargs="+", default=["paper", "homogeneous"])
    args = ap.parse_args()
    for scenario in args.scenarios:
        bad, sweeps = count(scenario, args.seeds)
        print(
            f"{scenario}: {bad} of {len(sweeps)} plans unconverged; sweeps a plan: "
            f"max {max(sweeps)}, mean {np.mean(sweeps):.2f}"
        )


if __name__ == "__main__":
    main()
