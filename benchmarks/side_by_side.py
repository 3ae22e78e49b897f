"""Speed of this checkout beside another one (e.g. the commit before a refactor), interleaved.

Each measurement runs in a fresh worker process of each checkout's own interpreter, in
alternating rounds, so both see the same machine load; the table gives the median rate of
each side and their ratio (new / old; > 1 is faster). Measured:

- ``single``: the parallel env (``paper``, M = 3) stepped with random actions, steps/s;
- ``batched-1024``, ``batched-8192``: the batched env, env-steps/s (copies x steps);
- ``gsr``: a GSR plan (M = 3) on the states of a ``paper`` episode, ms/plan;
- ``batched-gsr``: GSR over the 1024 copies of a batched env per call, plans/s.

The worker adapts to either API (expert positions through ``step_positions``, or the
older ``BatchedGSRPolicy`` actions). Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/side_by_side.py --old ../baseline

On a shared virtual machine wall-clock rates can swing by 30% between rounds.
``--instructions`` counts executed instructions instead (valgrind's callgrind, which
must be installed: ``apt-get install valgrind``): a fixed number of calls of each kind,
minus a run with a few calls, so start-up cancels. The count does not depend on the
machine's load, and it is the stable way to compare two checkouts within a few percent.

where ``../baseline`` is a checkout with its own ``.venv`` (``git worktree add ../baseline
<commit> && make -C ../baseline install``).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

KINDS = ("single", "batched-1024", "batched-8192", "gsr", "batched-gsr")


#: Calls of each kind for ``--instructions`` (per-call cost = difference / (hi - lo)).
COUNTS = {
    "single": (100, 1100),
    "batched-1024": (2, 32),
    "batched-8192": (2, 12),
    "gsr": (20, 220),
    "batched-gsr": (2, 12),
}


def _rate(step, seconds: float) -> float:
    """Return calls per second of ``step()`` over about ``seconds`` (after a warm-up).

    With a negative ``seconds``, make exactly ``-seconds`` calls and return 0 (for counts).
    """
    if seconds < 0:
        for _ in range(int(-seconds)):
            step()
        return 0.0
    step()
    n, t0 = 0, time.perf_counter()
    while (elapsed := time.perf_counter() - t0) < seconds:
        step()
        n += 1
    return n / elapsed


def worker(kind: str, seconds: float) -> float:
    """Return this checkout's rate for ``kind`` (see the module docstring)."""
    import numpy as np

    from activetrack import envs

    rng = np.random.default_rng(0)
    if kind == "single":
        env = envs.parallel_env(scenario="paper")
        env.reset(seed=0)
        acts = rng.uniform(-1, 1, (4096, 3, 2))
        i = [0]

        def step() -> None:
            if not env.agents:
                env.reset()
            a = acts[i[0] % 4096]
            i[0] += 1
            env.step({"sensor_0": a[0], "sensor_1": a[1], "sensor_2": a[2]})

        return _rate(step, seconds)
    if kind.startswith("batched-") and kind != "batched-gsr":
        n = int(kind.split("-")[1])
        env = envs.BatchedActiveTracking(n, "paper")
        env.reset(seed=0)
        acts = rng.uniform(-1, 1, (8, n, 6)).astype(np.float32)
        i = [0]

        def step() -> None:
            env.step(acts[i[0] % 8])
            i[0] += 1

        return _rate(step, seconds) * n
    if kind == "gsr":
        from activetrack.baselines import GSR

        env = envs.parallel_env(scenario="paper")
        gsr = GSR()
        env.reset(seed=0)
        problems = []
        while env.agents:
            problems.append(env.planning_problem())
            env.step({a: np.array([0.1, 0.2]) for a in env.agents})
        i = [0]

        def plan() -> None:
            gsr.plan(problems[i[0] % len(problems)])
            i[0] += 1

        rate = _rate(plan, seconds)
        return 1e3 / rate if rate else 0.0  # ms per plan
    if kind == "batched-gsr":
        n = 1024
        env = envs.BatchedActiveTracking(n, "paper")
        env.reset(seed=0)
        if hasattr(env, "step_positions"):
            from activetrack.baselines import GSR

            gsr = GSR()

            def step() -> None:
                env.step_positions(gsr.plan(env.planning_problem()))
        else:
            from activetrack.baselines.batched_gsr import BatchedGSRPolicy

            policy = BatchedGSRPolicy()

            def step() -> None:
                env.step(policy.act(env).reshape(n, -1))

        return _rate(step, seconds) * n
    raise ValueError(f"unknown kind {kind!r}")


def _run(python: Path, cwd: Path, kind: str, seconds: float, valgrind: bool = False) -> float:
    """Return the worker's rate, or with ``valgrind`` the instructions it executed."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    cmd = [str(python), str(Path(__file__).resolve()), "--worker", kind, "--seconds", str(seconds)]
    if valgrind:
        cmd = ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", *cmd]
    out = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, check=True)
    if valgrind:
        match = re.search(r"Collected : (\d+)", out.stderr)
        if match is None:
            raise RuntimeError(f"no instruction count from callgrind:\n{out.stderr[-2000:]}")
        return float(match.group(1))
    return float(out.stdout.strip().splitlines()[-1])


def _instructions(python: Path, cwd: Path, kind: str) -> float:
    """Return the instructions per call of ``kind`` (fixed call counts, start-up cancelled)."""
    lo, hi = COUNTS[kind]
    a = _run(python, cwd, kind, -lo, valgrind=True)
    b = _run(python, cwd, kind, -hi, valgrind=True)
    return (b - a) / (hi - lo)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, help="the other checkout (with its .venv)")
    parser.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds per kind")
    parser.add_argument("--seconds", type=float, default=3.0, help="per measurement")
    parser.add_argument("--worker", choices=KINDS, help=argparse.SUPPRESS)
    parser.add_argument("--json", type=Path, help="also write the table as JSON here")
    parser.add_argument(
        "--instructions", action="store_true", help="count instructions (callgrind) instead"
    )
    args = parser.parse_args()
    if args.worker:
        print(worker(args.worker, args.seconds))
        return
    if args.old is None:
        parser.error("--old is required")
    new_root = Path(__file__).resolve().parents[1]
    sides = {"old": args.old.resolve(), "new": new_root}
    rows = {}
    for kind in args.kinds:
        if args.instructions:
            old, new = (_instructions(r / ".venv/bin/python", r, kind) for r in sides.values())
            rows[kind] = {"old": old, "new": new, "ratio": new / old, "unit": "instructions"}
            print(f"{kind:14s} old {old:12.4g}  new {new:12.4g} instructions per call, "
                  f"new/old {new / old:.3f}")  # fmt: skip
            sys.stdout.flush()
            continue
        rates: dict[str, list[float]] = {"old": [], "new": []}
        for r in range(args.rounds):
            order = ("old", "new") if r % 2 == 0 else ("new", "old")
            for side in order:
                root = sides[side]
                rates[side].append(_run(root / ".venv/bin/python", root, kind, args.seconds))
        old, new = (statistics.median(rates[s]) for s in ("old", "new"))
        lower_is_better = kind == "gsr"
        ratio = old / new if lower_is_better else new / old
        unit = "ms/plan" if lower_is_better else "per s"
        rows[kind] = {"old": old, "new": new, "speed_ratio": ratio, "unit": unit}
        print(f"{kind:14s} old {old:12.4g}  new {new:12.4g} {unit:8s} speed new/old {ratio:.3f}")
        sys.stdout.flush()
    if args.json:
        tmp = args.json.with_suffix(".tmp")
        tmp.write_text(json.dumps(rows, indent=2))
        tmp.replace(args.json)


if __name__ == "__main__":
    main()
