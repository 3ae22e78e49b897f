"""Restarts for GSR: relax from other starts and keep the best (``GSR(restarts=True)``).

Each GSR step is the exact optimum of one sensor given the others, so GSR ends in a
configuration no single sensor can improve, which need not be the team optimum. The
objective depends on each sensor's information, i.e. on its distance and its direction
modulo pi; near the target the sensors sit on the ``rho`` circle and the team's job is to
spread its directions. When two sensors' feasible arcs overlap, "A takes the low end, B
the high end" and the swapped assignment are both stable: moving one sensor alone to the
other assignment stacks it onto its partner, which is worse, so coordinate descent cannot
swap roles; near-ties between such basins make the basin GSR lands in depend on the order
of the sweep. ``benchmarks/bench_gsr_restarts.py`` measures how often each variant
reaches the GBES grid optimum.

The starts (:data:`STARTS`), each relaxed by the same scalar sweep as plain GSR
(:class:`activetrack.baselines.gsr.Relaxation`):

- ``"grid"`` (the default) looks at the joint problem coarsely: an exhaustive search over
  a coarse grid of the curves ADB (about :data:`GRID_BUDGET` combinations, vectorized, no
  solves) gives its best point and, if within :data:`GRID_SECOND`, the best point of a
  second basin; each is refined by finer local grids to the bottom of its basin before
  the sweeps, which never raise the objective, so a refined start cannot slide into a
  worse basin. Teams too large for a grid of :data:`GRID_MIN_POINTS` points per sensor
  use ``"greedy-reversed"`` instead.
- ``"mirror"``: the warm start reflected across the prior's principal axis, under which
  the objective is invariant (Lemma 2).
- ``"independent"``: every sensor at its own optimum given the prior alone.
- ``"greedy"`` / ``"greedy-reversed"``: sensors placed one by one, in sensor order or
  reversed, each at its optimum given the prior and the sensors placed before it.

A restart that comes within :data:`MERGE_TOL` of a solution already found is stopped
there (it is in that solution's basin); grid points near a known solution are dropped.
Grid combinations are scored with the problem's objective (``of_entries``).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np

from activetrack import geometry
from activetrack.objective import lemma2_rotation, sensor_information
from activetrack.validation import FloatArray

if TYPE_CHECKING:
    from activetrack.baselines.gsr import Relaxation

#: A restart closer than this (times the reach r) to a solution already found is stopped.
MERGE_TOL = 1e-2

#: Combinations of the coarse grid start (about 27 points per sensor for M = 3).
GRID_BUDGET = 20000

#: Fewer grid points per sensor than this: the grid start is replaced by greedy.
GRID_MIN_POINTS = 5
#: A second grid start is used if it is within this (relative) of the grid optimum ...
GRID_SECOND = 1e-3
#: ... and some sensor lies more than this many grid steps away from the optimum.
GRID_AWAY = 3

#: The restart starts GSR knows (see the module docstring).
STARTS = ("grid", "mirror", "independent", "greedy", "greedy-reversed")


def best_of_restarts(
    run: Relaxation,
    warm: FloatArray,
    first: tuple[FloatArray, float, bool],
    starts: tuple[str, ...],
    accelerate: bool,
) -> tuple[FloatArray, float, bool, str]:
    """Return ``(s, value, converged, start)``: the best of ``first`` (the relaxed warm
    start) and the relaxed ``starts``, by objective (the first found wins ties)."""
    s, val, conv = first
    start = "warm"
    found = [s]
    for name, s0, feasible in restart_points(run, warm, starts, found):
        rs, rval, rconv = run.relax(s0, feasible, accelerate, found)
        found.append(rs)
        if rval < val:
            s, val, conv, start = rs, rval, rconv, name
    return s, val, conv, start


def restart_points(
    run: Relaxation, warm: FloatArray, kinds: tuple[str, ...], known: list[FloatArray]
) -> Iterator[tuple[str, FloatArray, bool]]:
    """Yield ``(name, start, feasible)`` for the restarts named in ``kinds``.

    ``known`` holds the solutions found so far (it may grow while iterating).
    """
    for kind in kinds:
        if kind == "mirror":
            yield kind, mirror(run, warm), False
        elif kind == "independent":
            yield kind, independent(run), True
        elif kind == "greedy":
            yield kind, greedy(run, run.free_idx), True
        elif kind == "grid" and grid_points(run) >= GRID_MIN_POINTS:
            for start in coarse_grid(run, known):
                yield kind, start, True
        elif kind == "grid":  # too many sensors for a useful grid
            yield "greedy-reversed", greedy(run, run.free_idx[::-1]), True
        elif kind == "greedy-reversed":
            yield kind, greedy(run, run.free_idx[::-1]), True


def merged(run: Relaxation, s: FloatArray, known: FloatArray) -> bool:
    """Return whether every free sensor of ``s`` is within :data:`MERGE_TOL` of ``known``.

    Positions are compared up to ``s -> -s`` (the same information).
    """
    f = run.free
    d = np.minimum(np.hypot(*(s[f] - known[f]).T), np.hypot(*(s[f] + known[f]).T))
    return bool(np.all(d <= MERGE_TOL * np.maximum(np.asarray(run.r)[f], 1e-300)))


def independent(run: Relaxation) -> FloatArray:
    """Return every free sensor at its own optimum given the prior alone, (M, 2)."""
    s = run.fixed_rel.copy()
    for i in run.free_idx:
        s[i] = run.solve(run.prior, i)
    return s


def greedy(run: Relaxation, order: list[int]) -> FloatArray:
    """Return the sequential greedy start: free sensors placed one by one in ``order``.

    Each sensor takes its optimum given the prior and the sensors placed before it.
    """
    s = run.fixed_rel.copy()
    fixed = ~run.free
    total = run.prior + sensor_information(s[fixed], run.sd2[fixed], run.st2[fixed]).sum(axis=0)
    for i in order:
        s[i] = run.solve(total, i)
        total = total + run.info(s[i], i)
    return s


def mirror(run: Relaxation, s: FloatArray) -> FloatArray:
    """Return the free sensors of ``s`` reflected across the prior's principal axis.

    With ``F`` that reflection, ``F P11^{-1} F = P11^{-1}`` and ``F info(s) F = info(F s)``,
    so the objective ``tr((F X F)^{-1}) = tr(X^{-1})`` is unchanged (Lemma 2).
    """
    phi0, _ = lemma2_rotation(run.prior)
    c2, s2 = math.cos(2.0 * float(phi0)), math.sin(2.0 * float(phi0))
    out = s.copy()
    out[run.free] = s[run.free] @ np.array([[c2, s2], [s2, -c2]])
    return out


def grid_points(run: Relaxation, budget: int = GRID_BUDGET) -> int:
    """Return the points per free sensor of the coarse grid start."""
    return int(budget ** (1.0 / max(run.n_free, 1)) + 1e-9)


class _Curve:
    """One sensor's curve ADB (Lemma 3) parametrized by arc length ``u`` in ``[0, length]``."""

    def __init__(self, arcs: list[geometry.Arc]) -> None:
        self.arcs = arcs
        self.cum = np.concatenate([[0.0], np.cumsum([a.length for a in arcs])])
        self.length = float(self.cum[-1])

    def points(self, u: FloatArray) -> FloatArray:
        """Return the points at arc lengths ``u`` (K,) (clipped to the curve), (K, 2)."""
        u = np.clip(u, 0.0, self.length)
        k = np.clip(np.searchsorted(self.cum, u, side="right") - 1, 0, len(self.arcs) - 1)
        out = np.empty((len(u), 2))
        for j, arc in enumerate(self.arcs):
            m = k == j
            if np.any(m):
                frac = np.clip((u[m] - self.cum[j]) / max(arc.length, 1e-300), 0.0, 1.0)
                out[m] = arc.points(arc.t0 + frac * (arc.t1 - arc.t0))
        return out


def combination_values(run: Relaxation, cands: list[FloatArray]) -> FloatArray:
    """Return the objective of every combination of per-sensor candidates, (K_1, ..., K_M)."""
    m = len(cands)
    prior = run.prior
    tot = [prior[0, 0], prior[0, 1], prior[1, 1]]
    for i, pts in enumerate(cands):
        info = sensor_information(pts, run.sd2[i], run.st2[i])
        shape = [1] * m
        shape[i] = len(pts)
        for e, (u, v) in enumerate(((0, 0), (0, 1), (1, 1))):
            tot[e] = tot[e] + info[:, u, v].reshape(shape)
    return run.objective.of_entries(*np.broadcast_arrays(*tot))


def grid_starts(run: Relaxation, cands: list[FloatArray]) -> list[tuple[int, ...]]:
    """Return the indices of the best combinations of small candidate sets, by broadcasting.

    The first is the grid optimum. The second, if its objective is within
    :data:`GRID_SECOND` (relative) of the first, is the best combination in which some
    sensor lies more than :data:`GRID_AWAY` grid steps (in distance) from its place in the
    optimum: a second basin that the coarse grid cannot tell apart from the first.
    """
    m = len(cands)
    val = combination_values(run, cands)
    best = np.unravel_index(int(np.argmin(val)), val.shape)
    out = [tuple(int(k) for k in best)]
    near = np.ones(val.shape, dtype=bool)
    for i, pts in enumerate(cands):
        if len(pts) < 2:
            continue
        step = float(np.median(np.hypot(*np.diff(pts, axis=0).T)))
        dist = np.hypot(*(pts - pts[best[i]]).T)
        shape = [1] * m
        shape[i] = len(pts)
        near = near & (dist <= (GRID_AWAY + 0.5) * step).reshape(shape)
    far = np.where(near, np.inf, val)
    k = np.unravel_index(int(np.argmin(far)), val.shape)
    if far[k] <= (1.0 + GRID_SECOND) * float(val[best]):
        out.append(tuple(int(j) for j in k))
    return out


def coarse_grid(
    run: Relaxation, known: list[FloatArray], budget: int = GRID_BUDGET
) -> list[FloatArray]:
    """Return starts (M, 2) from a coarse grid of every free sensor's curve ADB.

    Each free sensor gets about ``budget ** (1 / n_free)`` points evenly spaced along its
    curve and every combination is evaluated (no solves). The best one or two
    (:func:`grid_starts`) are then refined by finer local grids (:func:`refine`). A grid
    point within 1.5 grid steps of a ``known`` solution is in that solution's basin and is
    dropped.
    """
    k = grid_points(run, budget)
    curves = {
        i: _Curve(geometry.facing_boundary(run.c[i], run.r[i], run.rho[i])) for i in run.free_idx
    }
    grid_u = {i: np.linspace(0.0, cv.length, k) for i, cv in curves.items()}
    cands = [
        curves[i].points(grid_u[i]) if run.free[i] else run.fixed_rel[i : i + 1]
        for i in range(len(run.c))
    ]
    step = {i: cv.length / (k - 1) for i, cv in curves.items()}
    starts = []
    for idx in grid_starts(run, cands):
        s = np.stack([cands[i][idx[i]] for i in range(len(run.c))])
        if any(_near(run, s, x, step) for x in known):
            continue
        u = {i: float(grid_u[i][idx[i]]) for i in run.free_idx}
        starts.append(refine(run, s, u, curves, step))
    return starts


def _near(run: Relaxation, s: FloatArray, known: FloatArray, step: dict) -> bool:
    """Return whether every free sensor of ``s`` is within 1.5 grid steps of ``known``."""
    for i in run.free_idx:
        d = min(np.hypot(*(s[i] - known[i])), np.hypot(*(s[i] + known[i])))
        if d > 1.5 * step[i]:
            return False
    return True


def refine(
    run: Relaxation, s: FloatArray, u: dict, curves: dict, step: dict, rounds: int = 2
) -> FloatArray:
    """Return ``s`` refined by exhaustive local grids along the curves, (M, 2).

    Each round tries every combination of ``u_i + step_i * t``, ``t`` in 17 points of
    ``[-1, 1]`` (``t = 0`` included, so the objective never increases), then divides the
    steps by 8: two rounds reach 1/64 of the coarse grid step.
    """
    t = np.linspace(-1.0, 1.0, 17)
    s, u, step = s.copy(), dict(u), dict(step)
    for _ in range(rounds):
        trial = {i: np.clip(u[i] + step[i] * t, 0.0, curves[i].length) for i in u}
        cands = [curves[i].points(trial[i]) if i in u else s[i : i + 1] for i in range(len(s))]
        best = np.unravel_index(
            int(np.argmin(combination_values(run, cands))), tuple(len(c) for c in cands)
        )
        for i in u:
            u[i], s[i] = float(trial[i][best[i]]), cands[i][best[i]]
            step[i] /= 8.0
    return s
