"""Speed of this checkout beside another one (e.g. the commit before a refactor), interleaved.

Each measurement runs in a fresh worker process of each checkout's own interpreter, in
alternating rounds, so both see the same machine load; the table gives the median rate of
each side and their ratio (new / old; > 1 is faster). Measured:

- ``single``: the parallel env (``paper``, M = 3) stepped with random actions, steps/s;
- ``two-targets``, ``urban``: the same with the ``two_targets`` and ``urban`` presets;
- ``batched-1024``, ``batched-8192``: the batched env, env-steps/s (copies x steps);
- ``gsr``: a GSR plan (M = 3) on the states of a ``paper`` episode, ms/plan;
- ``batched-gsr``: GSR over the 1024 copies of a batched env per call, plans/s.

The worker adapts to either API (expert positions through ``step_positions``, or the
older ``BatchedGSRPolicy`` actions). Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/side_by_side.py --old ../baseline

where ``../baseline`` is a checkout with its own ``.venv`` (``git worktree add ../baseline
<commit> && make -C ../baseline install``). On a shared virtual machine wall-clock rates
can swing by 30% between rounds.

``--instructions`` counts executed instructions instead (valgrind's callgrind, which
must be installed: ``apt-get install valgrind``): a fixed number of calls of each kind,
minus a run with a few calls, so start-up cancels (:data:`COUNTS`). The count does not
depend on the machine's load, and it is the stable way to compare two checkouts within a
few percent. Valgrind's virtual CPU has fewer instruction sets than the host (no AVX-512),
and numba keys its cached machine code by the CPU, so the tool asks valgrind which CPU it
shows, compiles every kernel for that CPU once, natively (an untimed warm-up run of each
worker, into a numba cache folder of its own, ``--cache-dir``), and refuses a count during
which numba compiled anything. The two sides run at the same time (``--jobs``). All
seven kinds take about 30 minutes on a loaded 2-core machine when the kernels are not yet
cached for valgrind's CPU (the first run of a checkout), less afterwards.
``--callgrind-out DIR`` keeps the profiles; ``benchmarks/callgrind_diff.py DIR KIND`` then
says which functions' instructions per call differ between the sides.

Any two checkouts, neither of them this one (each with its own ``.venv``)::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/side_by_side.py \
        --old ../baseline --new ../other --instructions --json instructions.json

``--compile`` times a cold compile instead: every kernel of each checkout
(``activetrack.kernel_cache.compile_all``, what ``activetrack kernels`` runs) into a fresh
empty ``NUMBA_CACHE_DIR``, ``--rounds`` alternating times per side; the table gives the
median wall and CPU seconds of the whole process (interpreter start included) and their
spread.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

KINDS = (
    "single",
    "batched-1024",
    "batched-8192",
    "gsr",
    "batched-gsr",
    "two-targets",
    "urban",
)
#: The preset of each kind that steps one parallel env with random actions.
STEP_PRESETS = {"single": "paper", "two-targets": "two_targets", "urban": "urban"}

#: Calls of each kind for ``--instructions`` (per-call cost = difference / (hi - lo)).
COUNTS = {
    "single": (100, 1100),
    "two-targets": (100, 600),
    "urban": (100, 600),
    "batched-1024": (2, 32),
    "batched-8192": (2, 12),
    "gsr": (20, 120),
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
    if kind in STEP_PRESETS:
        env = envs.parallel_env(scenario=STEP_PRESETS[kind])
        env.reset(seed=0)
        agents = list(env.possible_agents)
        acts = rng.uniform(-1, 1, (4096, len(agents), 2))
        i = [0]

        def step() -> None:
            if not env.agents:
                env.reset()
            a = acts[i[0] % 4096]
            i[0] += 1
            env.step(dict(zip(agents, a, strict=True)))

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


def compiled_in_process() -> int:
    """Return how many signatures numba compiled (not loaded from its cache) in this
    process, over the library's kernels (``activetrack._jit.KERNELS``, in either API)."""
    from activetrack._jit import KERNELS

    misses = 0
    for k in KERNELS:
        stats = getattr(k._compiled, "stats", None)
        if stats is not None:
            misses += sum(stats.cache_misses.values())
    return misses


def cold_compile() -> dict:
    """Return ``activetrack.kernel_cache.compile_all()``'s report (every kernel compiled
    or loaded, through the library's entry points)."""
    from activetrack.kernel_cache import compile_all

    return compile_all()


# --------------------------------------------------------------------------- the driver


_CPU_PROBE = (
    "from numba.core.registry import cpu_target\n"
    "_, name, features = cpu_target.target_context.codegen().magic_tuple()\n"
    "print(name); print(features)\n"
)


def _environment(cache_dir: Path | None = None, cpu: tuple[str, str] | None = None) -> dict:
    """Return the environment of a worker: one BLAS thread, a fixed hash seed (the same
    dict and set orders in every run), and optionally numba's cache folder and CPU."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "PYTHONHASHSEED": "0"}
    if cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = str(cache_dir)
    if cpu is not None:
        env["NUMBA_CPU_NAME"], env["NUMBA_CPU_FEATURES"] = cpu
    return env


def _valgrind_cpu(python: Path) -> tuple[str, str]:
    """Return the CPU name and features numba (LLVM) sees under valgrind."""
    out = subprocess.run(
        ["valgrind", "--tool=none", str(python), "-c", _CPU_PROBE],
        env=_environment(),
        capture_output=True,
        text=True,
        check=True,
    )
    name, features = out.stdout.strip().splitlines()[-2:]
    return name, features


def _worker_cmd(python: Path, *args: str) -> list[str]:
    return [str(python), str(Path(__file__).resolve()), *args]


def _run(python: Path, cwd: Path, kind: str, seconds: float) -> float:
    """Return the worker's rate (wall clock)."""
    cmd = _worker_cmd(python, "--worker", kind, "--seconds", str(seconds))
    out = subprocess.run(cmd, cwd=cwd, env=_environment(), capture_output=True, text=True)
    if out.returncode:
        raise RuntimeError(f"worker {kind} in {cwd} failed:\n{out.stderr[-3000:]}")
    return float(out.stdout.strip().splitlines()[-1])


def _start_count(
    python: Path, cwd: Path, kind: str, calls: int, env: dict, valgrind: bool, out_file: str
) -> subprocess.Popen:
    """Start a worker making exactly ``calls`` calls (under callgrind with ``valgrind``)."""
    cmd = _worker_cmd(python, "--worker", kind, "--seconds", str(-calls), "--report-compiled")
    if valgrind:
        cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out_file}", *cmd]
    return subprocess.Popen(
        cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


def _finish_count(proc: subprocess.Popen, what: str, valgrind: bool) -> float:
    """Return the instructions of a finished callgrind worker (or 0 without valgrind);
    raise if it failed, or if numba compiled a kernel during a counted run."""
    stdout, stderr = proc.communicate()
    if proc.returncode:
        raise RuntimeError(f"{what} failed:\n{stderr[-3000:]}")
    if not valgrind:
        return 0.0
    compiled = int(re.search(r"compiled (\d+)", stdout).group(1))
    if compiled:
        raise RuntimeError(f"{what}: numba compiled {compiled} signatures during the count")
    match = re.search(r"Collected : (\d+)", stderr)
    if match is None:
        raise RuntimeError(f"no instruction count from callgrind ({what}):\n{stderr[-2000:]}")
    return float(match.group(1))


def _instructions(
    sides: dict[str, Path], kind: str, envs: dict[str, dict], jobs: int, out_dir: Path | None
) -> dict[str, float]:
    """Return each side's instructions per call of ``kind`` (fixed call counts, start-up
    cancelled): a native warm-up of each side first, then the counts, ``jobs`` at a time."""
    lo, hi = COUNTS[kind]
    for valgrind in (False, True):
        runs = [(side, calls) for side in sides for calls in (lo, hi)]
        if not valgrind:
            runs = [(side, hi) for side in sides]  # the warm-up: compiles what hi calls need
        counts: dict[tuple[str, int], float] = {}
        while runs:
            batch, runs = runs[:jobs], runs[jobs:]
            procs = []
            for side, calls in batch:
                out_file = "/dev/null"
                if valgrind and out_dir is not None:
                    out_file = str(out_dir / f"callgrind.{side}.{kind}.{calls}")
                root = sides[side]
                procs.append(
                    _start_count(
                        root / ".venv/bin/python", root, kind, calls, envs[side], valgrind, out_file
                    )
                )
            for (side, calls), proc in zip(batch, procs, strict=True):
                what = f"{kind} ({side}, {calls} calls)"
                counts[side, calls] = _finish_count(proc, what, valgrind)
    return {side: (counts[side, hi] - counts[side, lo]) / (hi - lo) for side in sides}


def _cold_compile(root: Path) -> dict:
    """Return wall and CPU seconds of a process compiling every kernel of ``root`` into
    a fresh empty numba cache, with the library's own report."""
    with tempfile.TemporaryDirectory(prefix="cold-numba-") as cache:
        cmd = _worker_cmd(root / ".venv/bin/python", "--cold-compile")
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            cmd,
            cwd=root,
            env=_environment(Path(cache)),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        proc.returncode = os.waitstatus_to_exitcode(status)
        stdout, stderr = proc.stdout.read(), proc.stderr.read()
        if proc.returncode:
            raise RuntimeError(f"cold compile in {root} failed:\n{stderr[-3000:]}")
    report = json.loads(stdout.strip().splitlines()[-1])
    return {"wall": wall, "cpu": usage.ru_utime + usage.ru_stime, **report}


def _default_cache_dir() -> Path:
    return Path(tempfile.gettempdir()) / "side_by_side_numba"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, help="the old checkout (with its .venv)")
    parser.add_argument(
        "--new", type=Path, help="the new checkout (default: the one holding this script)"
    )
    parser.add_argument("--kinds", nargs="+", default=list(KINDS), choices=KINDS)
    parser.add_argument("--rounds", type=int, default=3, help="alternating rounds per kind")
    parser.add_argument("--seconds", type=float, default=3.0, help="per measurement")
    parser.add_argument("--worker", choices=KINDS, help=argparse.SUPPRESS)
    parser.add_argument("--report-compiled", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--cold-compile", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--json", type=Path, help="also write the table as JSON here")
    parser.add_argument(
        "--instructions", action="store_true", help="count instructions (callgrind) instead"
    )
    parser.add_argument(
        "--compile", action="store_true", help="time a cold compile of every kernel instead"
    )
    parser.add_argument(
        "--cache-dir",
        type=Path,
        default=_default_cache_dir(),
        help="numba's cache for --instructions (kept between runs; default %(default)s)",
    )
    parser.add_argument("--jobs", type=int, default=2, help="callgrind runs at a time")
    parser.add_argument(
        "--callgrind-out", type=Path, help="keep callgrind's profiles in this folder"
    )
    args = parser.parse_args()
    if args.cold_compile:
        print(json.dumps(cold_compile()))
        return
    if args.worker:
        print(worker(args.worker, args.seconds))
        if args.report_compiled:
            print(f"compiled {compiled_in_process()}")
        return
    if args.old is None:
        parser.error("--old is required")
    if args.instructions and args.compile:
        parser.error("--instructions and --compile are exclusive")
    if args.jobs < 1:
        parser.error("--jobs must be >= 1")
    if args.json and not args.json.parent.is_dir():
        parser.error(f"--json: no folder {args.json.parent}")
    if args.json and args.json.exists():
        parser.error(f"--json: {args.json} exists (results are not overwritten)")
    if args.callgrind_out and any(args.callgrind_out.glob("callgrind.*")):
        parser.error(f"--callgrind-out: {args.callgrind_out} holds profiles already")
    new_root = (args.new or Path(__file__).resolve().parents[1]).resolve()
    sides = {"old": args.old.resolve(), "new": new_root}
    for side, root in sides.items():
        if not (root / ".venv/bin/python").exists():
            parser.error(f"--{side}: no {root / '.venv/bin/python'}")
    rows: dict[str, dict] = {"checkouts": {}}
    for side, root in sides.items():
        head = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
        ).stdout.strip()
        rows["checkouts"][side] = {"path": str(root), "commit": head, "modified": bool(dirty)}
        print(f"{side}: {root} at {head or '?'}{' (modified)' if dirty else ''}")
    if args.compile:
        results: dict[str, list[dict]] = {"old": [], "new": []}
        for r in range(args.rounds):
            for side in ("old", "new") if r % 2 == 0 else ("new", "old"):
                results[side].append(_cold_compile(sides[side]))
        for side, runs in results.items():
            walls, cpus = [x["wall"] for x in runs], [x["cpu"] for x in runs]
            rows[side] = {
                "wall_median": statistics.median(walls),
                "wall_range": [min(walls), max(walls)],
                "cpu_median": statistics.median(cpus),
                "cpu_range": [min(cpus), max(cpus)],
                "runs": runs,
            }
            print(
                f"{side}: cold compile wall {rows[side]['wall_median']:.1f} s "
                f"({min(walls):.1f}-{max(walls):.1f}), CPU {rows[side]['cpu_median']:.1f} s "
                f"({min(cpus):.1f}-{max(cpus):.1f}); {runs[0]['kernels']} kernels, "
                f"{runs[0]['signatures']} signatures, {runs[0]['cache_misses']} compiled"
            )
        rows["ratio"] = {
            k: rows["new"][f"{k}_median"] / rows["old"][f"{k}_median"] for k in ("wall", "cpu")
        }
        print(f"new/old: wall {rows['ratio']['wall']:.3f}, CPU {rows['ratio']['cpu']:.3f}")
    elif args.instructions:
        cpu = _valgrind_cpu(sides["new"] / ".venv/bin/python")
        print(f"numba compiles for valgrind's CPU: {cpu[0]}")
        envs = {}
        for side, root in sides.items():
            digest = hashlib.sha256(str(root).encode()).hexdigest()[:12]
            envs[side] = _environment(args.cache_dir / f"{side}-{digest}", cpu)
        if args.callgrind_out:
            args.callgrind_out.mkdir(parents=True, exist_ok=True)
        for kind in args.kinds:
            got = _instructions(sides, kind, envs, args.jobs, args.callgrind_out)
            old, new = got["old"], got["new"]
            rows[kind] = {"old": old, "new": new, "ratio": new / old, "unit": "instructions"}
            print(f"{kind:14s} old {old:12.4g}  new {new:12.4g} instructions per call, "
                  f"new/old {new / old:.3f}")  # fmt: skip
            sys.stdout.flush()
    else:
        for kind in args.kinds:
            rates: dict[str, list[float]] = {"old": [], "new": []}
            for r in range(args.rounds):
                for side in ("old", "new") if r % 2 == 0 else ("new", "old"):
                    root = sides[side]
                    rates[side].append(_run(root / ".venv/bin/python", root, kind, args.seconds))
            old, new = (statistics.median(rates[s]) for s in ("old", "new"))
            lower_is_better = kind == "gsr"
            ratio = old / new if lower_is_better else new / old
            unit = "ms/plan" if lower_is_better else "per s"
            rows[kind] = {"old": old, "new": new, "speed_ratio": ratio, "unit": unit}
            print(f"{kind:14s} old {old:12.4g}  new {new:12.4g} {unit:8s} "
                  f"speed new/old {ratio:.3f}")  # fmt: skip
            sys.stdout.flush()
    if args.json:
        tmp = args.json.with_suffix(".tmp")
        tmp.write_text(json.dumps(rows, indent=2))
        tmp.replace(args.json)


if __name__ == "__main__":
    main()
