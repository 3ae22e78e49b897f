"""Search for problems where GSR(restarts=True) ends above the global optimum, and time it.

Problems, one per seed: by default those of ``tests/baselines/test_gsr_restarts_gap.py``
(:func:`close_problem`: three sensors within 1.5 reaches of the predicted target,
differing ``r`` and ``rho``); with ``--random`` those of ``bench_gsr_restarts.py``
(:func:`activetrack.baselines.random_problem`, sensors 1-4 m away). Each answer is screened
against the GBES grid optimum at pi/200; with ``--reference`` every answer (else only those
above the grid by more than ``--rtol``) is compared with the test's independent refined
global optimum. Prints one line per miss and a summary with CPU times.

``--old FILE`` also runs GSR with another version of ``baselines/gsr_restarts.py`` (e.g.
``git show d6b3f70:baselines/gsr_restarts.py > /tmp/old.py``), interleaved with plain
GSR and the installed restarts on every problem, so that machine load affects all alike.

    OPENBLAS_NUM_THREADS=1 .venv/bin/python tools/search_gsr_gap.py --seeds 0 300 \\
        [--reference] [--random] [--old /tmp/old.py]
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
import time
from pathlib import Path
from types import ModuleType

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from activetrack.baselines import GBES, GSR, gsr, random_problem  # noqa: E402
from tests.baselines.test_gsr_restarts_gap import close_problem, reference_optimum  # noqa: E402


def load_module(path: str) -> ModuleType:
    """Return the restarts module at ``path``."""
    spec = importlib.util.spec_from_file_location("gsr_restarts_other", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs=2, default=(0, 300), metavar=("FIRST", "STOP"))
    ap.add_argument("--rtol", type=float, default=1e-9, help="miss tolerance (relative)")
    ap.add_argument("--reference", action="store_true", help="reference on every problem")
    ap.add_argument("--random", action="store_true", help="random_problem instead")
    ap.add_argument("--old", help="another gsr_restarts.py to compare with")
    args = ap.parse_args()
    modules = {"new": gsr.gsr_restarts}
    if args.old:
        modules["old"] = load_module(args.old)
    cpu = {"plain": 0.0, **{k: 0.0 for k in modules}}
    misses = {k: 0 for k in modules}
    worst = {k: 0.0 for k in modules}
    for seed in range(*args.seeds):
        rng = np.random.default_rng(seed)
        p = random_problem(rng, 3) if args.random else close_problem(rng)
        c0 = time.process_time()
        GSR().plan_with_info(p)
        cpu["plain"] += time.process_time() - c0
        res = {}
        for name, mod in modules.items():
            gsr.gsr_restarts = mod
            c0 = time.process_time()
            res[name] = GSR(restarts=True).plan_with_info(p)
            cpu[name] += time.process_time() - c0
        gsr.gsr_restarts = modules["new"]
        grid = GBES().search(p).value
        if not args.reference and all(r.value <= grid * (1 + args.rtol) for r in res.values()):
            continue
        ref, _ = reference_optimum(p)
        for name, r in res.items():
            gap = r.value / ref - 1.0
            worst[name] = max(worst[name], gap)
            if gap > args.rtol:
                misses[name] += 1
                print(
                    f"{name} seed {seed}: {gap:.3e} above the reference "
                    f"({r.value / grid - 1:+.3e} vs GBES), start {r.start}, "
                    f"sweeps {r.sweeps}, converged {r.converged}",
                    flush=True,
                )
    n = args.seeds[1] - args.seeds[0]
    kind = "random_problem" if args.random else "close_problem"
    print(f"{n} problems ({kind}, seeds {args.seeds[0]}-{args.seeds[1] - 1}):")
    for name in modules:
        print(
            f"  restarts ({name}): {misses[name]} misses over {args.rtol:g}, worst "
            f"{worst[name]:.3e}; {cpu[name] / n * 1e3:.2f} ms CPU/problem, "
            f"{cpu[name] / cpu['plain']:.2f}x plain GSR"
        )
    print(f"  plain GSR: {cpu['plain'] / n * 1e3:.2f} ms CPU/problem")
    if args.old:
        print(f"  restarts new / old CPU: {cpu['new'] / cpu['old']:.2f}")


if __name__ == "__main__":
    main()
