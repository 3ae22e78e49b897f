"""Search for problems where GSR(restarts=True) ends above the global optimum.

Problems of the class of ``tests/baselines/test_gsr_restarts_gap.py`` (:func:`close_problem`:
three sensors within 1.5 reaches of the predicted target, differing ``r`` and ``rho``), one
per seed. Each is screened against the GBES grid optimum at pi/200 (fast); with
``--reference`` every problem (else only those above the grid by more than ``--rtol``) is
compared with the test's independent refined global optimum. Prints one line per miss
(seed, gap to the reference, the start that won, sweeps) and a summary.

    .venv/bin/python tools/search_gsr_gap.py --seeds 0 2000 [--reference] [--old FILE]

``--old FILE`` runs GSR with another version of ``baselines/gsr_restarts.py`` (e.g. the
one before the fix, ``git show d6b3f70:baselines/gsr_restarts.py > /tmp/old.py``).
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from activetrack.baselines import GBES, GSR, gsr  # noqa: E402
from tests.baselines.test_gsr_restarts_gap import close_problem, reference_optimum  # noqa: E402


def use_restarts_module(path: str) -> None:
    """Make GSR use the restarts module at ``path`` instead of the installed one."""
    spec = importlib.util.spec_from_file_location("gsr_restarts_old", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    gsr.gsr_restarts = mod


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs=2, default=(0, 500), metavar=("FIRST", "STOP"))
    ap.add_argument("--rtol", type=float, default=1e-9, help="miss tolerance (relative)")
    ap.add_argument("--reference", action="store_true", help="reference on every problem")
    ap.add_argument("--old", help="another gsr_restarts.py to run")
    args = ap.parse_args()
    if args.old:
        use_restarts_module(args.old)
    planner = GSR(restarts=True)
    misses, worst, cpu = 0, 0.0, 0.0
    for seed in range(*args.seeds):
        p = close_problem(np.random.default_rng(seed))
        c0 = time.process_time()
        res = planner.plan_with_info(p)
        cpu += time.process_time() - c0
        grid = GBES().search(p).value
        if not args.reference and res.value <= grid * (1 + args.rtol):
            continue
        ref, _ = reference_optimum(p)
        gap = res.value / ref - 1.0
        worst = max(worst, gap)
        if gap > args.rtol:
            misses += 1
            print(
                f"seed {seed}: {gap:.3e} above the reference ({res.value / grid - 1:+.3e} "
                f"vs GBES), start {res.start}, sweeps {res.sweeps}, converged {res.converged}",
                flush=True,
            )
    n = args.seeds[1] - args.seeds[0]
    print(
        f"{n} problems, seeds {args.seeds[0]}-{args.seeds[1] - 1}: {misses} misses over "
        f"{args.rtol:g}, worst {worst:.3e}; GSR(restarts=True) {cpu / n * 1e3:.2f} ms CPU/problem"
    )


if __name__ == "__main__":
    main()
