"""The compiled kernels' disk cache: compile everything now, say where it went, clear it.

``activetrack kernels`` (this module's command) compiles every kernel the library's entry
points use, through those entry points, and reports the time and numba's cache folders;
``activetrack kernels --clear`` deletes the cached machine code of the library's kernels
instead (numba then compiles again on first use). Useful before timing anything, in a
container image build, or after changing numba or the CPU. An edit of a kernel source needs
no clearing: it makes every cached kernel stale by itself (:mod:`activetrack._jit` says
how the cache works).

Part of the command line (like :mod:`activetrack.cli`): to compile GSR's kernels through
their entry point it imports the baselines' planner, inside a function, the one arrow from
the core up besides the front door's (``tests/test_layers.py``).
"""

from __future__ import annotations

import argparse
import importlib
import time
from pathlib import Path
from typing import Any

import numpy as np

from activetrack._jit import KERNEL_MODULES as KERNEL_MODULES  # what compile_all imports
from activetrack._jit import KERNELS


def compile_all() -> dict[str, Any]:
    """Return ``{"seconds", "kernels", "signatures", "cache_hits", "cache_misses"}`` after
    calling every entry point that runs kernels once (compiling or loading from the cache)."""
    for name in KERNEL_MODULES:
        importlib.import_module(name)
    from activetrack.solvers.analytic import (
        case1_critical_points,
        solve_single_sensor,
        solve_single_sensor_batch,
    )
    from activetrack.solvers.companion import monic_roots, real_roots_scalar

    start = time.perf_counter()
    prior = np.array([[2.0, 0.3], [0.3, 1.0]])
    for check in (True, False):
        solve_single_sensor(prior, np.array([5.0, 1.0]), 1.0, 0.5, 0.1, 0.01, check=check)
        solve_single_sensor_batch(
            prior[None], np.array([[5.0, 1.0]]), 1.0, 0.5, 0.1, 0.01, check=check
        )
    case1_critical_points(prior, np.array([5.0, 1.0]), 1.0, 0.1, 0.01)
    monic_roots(np.ones((1, 10)))
    real_roots_scalar(tuple(float(k) for k in range(11)))
    _world_and_planners()
    seconds = time.perf_counter() - start
    used = [k for k in KERNELS if k._compiled is not None]
    stats = [k.dispatcher.stats for k in used if hasattr(k.dispatcher, "stats")]
    return {
        "seconds": seconds,
        "kernels": len(used),
        "signatures": sum(len(getattr(k.dispatcher, "signatures", ())) for k in used),
        "cache_hits": sum(sum(s.cache_hits.values()) for s in stats),
        "cache_misses": sum(sum(s.cache_misses.values()) for s in stats),
    }


def _world_and_planners() -> None:
    """Run the entry points of the world's kernels (moves, EKF, occluders, rays) and of
    GSR's sweeps once: a step of one copy and of two copies of every kind of task, an
    occluder layout drawn, GSR on a single and on a batched problem."""
    from activetrack.baselines import GSR  # noqa: PLC0415 (the planners' layer, lazily)
    from activetrack.world import (
        World,  # noqa: PLC0415
        observation,  # noqa: PLC0415
    )

    for scenario in ("paper", "uncertain_poses", "urban", "urban_random"):
        for copies in (1, 2):
            world = World(scenario, copies)
            world.reset(seeds=range(copies))
            world.step_actions(np.full((copies, world.n_sensors, 2), 0.5))
            world.observe()
            world.state()
    from activetrack.kinematics.unicycle import Unicycle  # noqa: PLC0415
    from activetrack.world.scenarios import make_scenario  # noqa: PLC0415

    robots = make_scenario("paper", kinematics=Unicycle(0.0, 10.0, np.pi))  # its team step
    for copies in (1, 2):
        world = World(robots, copies)
        world.reset(seeds=range(copies))
        world.step_actions(np.full((copies, world.n_sensors, 2), 0.5))
    observation.observations(np.zeros((1, 5)), np.zeros((1, 2, 6)), observation.cyclic_order(2))
    world = World("paper", 2)
    world.reset(seeds=[0, 1])
    world.step(GSR().plan(world.planning_problem()))
    GSR().plan(world.planning_problem(0))
    GSR(restarts=True).plan(world.planning_problem(0))  # the sensors' modes, the warm start


def cache_folders() -> list[Path]:
    """Return the folders where numba caches the library's kernels (one per source folder)."""
    for name in KERNEL_MODULES:
        importlib.import_module(name)
    folders = set()
    for k in KERNELS:
        cache = getattr(k.dispatcher, "_cache", None)  # numba's FunctionCache
        path = getattr(cache, "cache_path", None)
        if path:
            folders.add(Path(path))
    return sorted(folders)


def clear_cache() -> int:
    """Delete the cached machine code of the library's kernels; return how many files."""
    folders = cache_folders()  # imports every kernel module first
    stems = {Path(k.py_func.__code__.co_filename).stem for k in KERNELS}
    removed = 0
    for folder in folders:
        for path in folder.glob("*.nb[ic]"):
            if path.name.split(".", 1)[0] in stems:
                path.unlink(missing_ok=True)
                removed += 1
    return removed


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Add the ``kernels`` command."""
    parser = sub.add_parser(
        "kernels",
        help="compile the numba kernels now (or clear their cache) and report time and folder",
        description=__doc__.splitlines()[0],
    )
    parser.add_argument(
        "--clear", action="store_true", help="delete the cached kernels instead of compiling"
    )
    parser.set_defaults(func=_run, parser=parser)


def _run(args: argparse.Namespace) -> int:
    if args.clear:
        print(f"removed {clear_cache()} cached files")
        return 0
    report = compile_all()
    print(
        f"kernels ready in {report['seconds']:.1f} s: {report['cache_misses']} compiled, "
        f"{report['cache_hits']} loaded from the cache"
    )
    for folder in cache_folders():
        print(f"cache: {folder}")
    return 0
