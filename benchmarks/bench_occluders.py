"""Time of the occluder kernels for a batch of N copies x M sensors against a few rectangles.

A seeded :func:`activetrack.models.occluders.random_layout` of ``--rects`` rectangles (sides 1 to 4)
in the square ``[-10, 10]^2``; ``N x M`` sensors uniform in the square outside the
rectangles. Timed (median of ``--repeats``, after a warm-up):

- ``blocked``: line of sight from each sensor to a target uniform in the square;
- ``project_move``: each sensor's straight move to a point uniform in its reach disk
  (``--reach``), projected where blocked;
- ``inside`` of the same points, and ``ray_distances`` with 16 rays.

Then the same four kernels on a batch of per-copy layouts (:meth:`Occluders.stack` of
``--copies`` seeded layouts of ``--batch-rects`` rectangles, sensors outside their own
copy's): one batched call vs a Python loop of unbatched calls over ``occ[i]`` (the layouts
taken out beforehand; median of ``--loop-repeats``).

Run with numpy single-threaded::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_occluders.py
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from activetrack.models import occluders as oc


def median_ms(fn, repeats: int) -> float:
    """Return the median wall time of ``fn()`` in milliseconds (after one warm-up call)."""
    fn()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--copies", type=int, default=1024)
    ap.add_argument("--sensors", type=int, default=4)
    ap.add_argument("--rects", type=int, default=5)
    ap.add_argument("--reach", type=float, default=1.0)
    ap.add_argument("--repeats", type=int, default=21)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--batch-rects", type=int, default=4)
    ap.add_argument("--loop-repeats", type=int, default=3)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    occ = oc.random_layout(rng, args.rects, (-10, -10, 10, 10), (1.0, 4.0))
    shape = (args.copies, args.sensors)
    n = args.copies * args.sensors
    pts = rng.uniform(-10, 10, (4 * n, 2))
    start = pts[~oc.inside(pts, occ)][:n].reshape(shape + (2,))
    target, r, desired = _moves(rng, start, args.reach)
    dirs = np.stack([np.cos(a := np.arange(16) * np.pi / 8), np.sin(a)], -1)

    los = oc.blocked(start, target, occ)
    _, proj = oc.project_move(start, desired, occ, r)
    print(
        f"{args.copies} x {args.sensors} segments, {occ.n_polygons} rectangles "
        f"({occ.n_edges} edges); lines of sight blocked {los.mean():.1%}, "
        f"moves projected {proj.mean():.1%}; median of {args.repeats}"
    )
    rows = [
        ("blocked (line of sight)", lambda: oc.blocked(start, target, occ)),
        ("project_move", lambda: oc.project_move(start, desired, occ, r)),
        ("inside", lambda: oc.inside(desired, occ)),
        ("ray_distances (16 rays)", lambda: oc.ray_distances(start, dirs, occ, 5.0)),
    ]
    for name, fn in rows:
        print(f"  {name:<26s} {median_ms(fn, args.repeats):8.2f} ms")
    batched(args, rng, dirs)


def _moves(
    rng: np.random.Generator, start: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return random targets, the reach and desired moves uniform in each reach disk."""
    shape = start.shape[:-1]
    target = rng.uniform(-10, 10, shape + (2,))
    rad = reach * np.sqrt(rng.uniform(size=shape))
    ang = rng.uniform(0, 2 * np.pi, shape)
    desired = start + rad[..., None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    return target, np.full(shape, reach), desired


def batched(args: argparse.Namespace, rng: np.random.Generator, dirs: np.ndarray) -> None:
    """Print the batched kernels' times beside a Python loop over the layouts."""
    n, m = args.copies, args.sensors
    layouts = [
        oc.random_layout(rng, args.batch_rects, (-10, -10, 10, 10), (1.0, 4.0)) for _ in range(n)
    ]
    occ = oc.Occluders.stack(layouts)
    pts = rng.uniform(-10, 10, (n, 8 * m, 2))
    keep = np.argsort(oc.inside(pts, occ), axis=1, kind="stable")[:, :m]  # outside first
    start = np.take_along_axis(pts, keep[..., None], axis=1)
    assert not oc.inside(start, occ).any()
    target, r, desired = _moves(rng, start, args.reach)
    per = [occ[i] for i in range(n)]
    _, proj = oc.project_move(start, desired, occ, r)
    print(
        f"batched: {n} layouts of {args.batch_rects} rectangles, {m} sensors each; "
        f"moves projected {proj.mean():.1%}; batched median of {args.repeats}, "
        f"loop median of {args.loop_repeats}"
    )
    rows = [
        (
            "blocked (line of sight)",
            lambda: oc.blocked(start, target, occ),
            lambda i: oc.blocked(start[i], target[i], per[i]),
        ),
        (
            "project_move",
            lambda: oc.project_move(start, desired, occ, r),
            lambda i: oc.project_move(start[i], desired[i], per[i], r[i]),
        ),
        ("inside", lambda: oc.inside(desired, occ), lambda i: oc.inside(desired[i], per[i])),
        (
            "ray_distances (16 rays)",
            lambda: oc.ray_distances(start, dirs, occ, 5.0),
            lambda i: oc.ray_distances(start[i], dirs, per[i], 5.0),
        ),
    ]
    for name, fn, one in rows:
        t_batch = median_ms(fn, args.repeats)
        t_loop = median_ms(lambda one=one: [one(i) for i in range(n)], args.loop_repeats)
        print(
            f"  {name:<26s} batched {t_batch:8.2f} ms   loop {t_loop:8.2f} ms   "
            f"loop/batched {t_loop / t_batch:6.1f}"
        )


if __name__ == "__main__":
    main()
