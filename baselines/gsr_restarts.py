"""Restarts for GSR: relax from other starts, polish, keep the best (``GSR(restarts=True)``).

Each GSR step is the exact optimum of one sensor given the others, so GSR ends in a
configuration no single sensor can improve, which need not be the team optimum. The
objective depends on each sensor's information, i.e. on its distance and its direction
modulo pi; near the target the sensors sit on the ``rho`` circle and the team's job is to
spread its directions. GSR misses the optimum in two ways:

- **Another basin.** When two sensors' feasible arcs overlap, "A takes the low end, B
  the high end" and the swapped assignment are both stable: moving one sensor alone to
  the other assignment stacks it onto its partner, which is worse, so coordinate descent
  cannot swap roles. Optima also sit at corners of the curves ADB (a ``rho`` arc meeting
  a reach arc, Fig. 3) or at an arc's end, where one sensor would need to jump to the
  other end of its arc (its directions modulo pi wrap around) while the others turn.
  Basins come within 1e-5 of each other.
- **A valley.** When the prior is weak or nearly isotropic next to the sensors'
  information (sensors close to the target), turning the whole team together barely
  changes the objective while moving one sensor alone does: coordinate descent then
  crawls along the valley by small steps and stops (``tol`` per sweep, or
  ``max_sweeps``) far from its bottom, up to 2e-4 above it.

The starts (:data:`STARTS`), each relaxed by the same scalar sweep as plain GSR
(:class:`activetrack.baselines.gsr.Relaxation`), at most :data:`RESTART_SWEEPS` sweeps:

- ``"grid"`` (the default) looks at the joint problem coarsely: an exhaustive search over
  a coarse grid of the curves ADB (about :data:`GRID_BUDGET` combinations, vectorized, no
  solves). The grid is spaced by how much a sensor's information changes (its direction
  seen from the target and its log distance, :class:`_Curve`), not by metres, so a small
  ``rho`` circle gets as many points as a large one, and it contains every corner. Its
  best point and the best other local minima within :data:`GRID_WINDOW` (the coarse
  grid's own error reaches 2e-3 at a smooth minimum) are refined by finer local grids
  to the bottom of their basin; those within :data:`GRID_SECOND` of the best refined
  one are relaxed. Teams too large for a grid of :data:`GRID_MIN_POINTS` points per
  sensor use ``"greedy-reversed"`` instead.
- ``"mirror"``: the warm start reflected across the prior's principal axis, under which
  the objective is invariant (Lemma 2).
- ``"independent"``: every sensor at its own optimum given the prior alone.
- ``"greedy"`` / ``"greedy-reversed"``: sensors placed one by one, in sensor order or
  reversed, each at its optimum given the prior and the sensors placed before it.

A restart that comes within :data:`MERGE_TOL` of a solution already found is stopped
there (it is in that solution's basin); grid points near a known solution are dropped.
The best answers (:data:`POLISH_ANSWERS`, within :data:`POLISH_WINDOW` of the best) are
then polished (:func:`polish`): a projected Newton method over all free sensors' angles
on their arcs at once goes down the valley, and sweeps follow. Grid combinations are
scored with the problem's objective (``of_entries``); the polish is written for the
trace (eq. 17), which GSR requires.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np

from activetrack.kinematics import geometry
from activetrack.models.objective import lemma2_rotation, sensor_information
from activetrack.validation import FloatArray

if TYPE_CHECKING:
    from activetrack.baselines.gsr import Relaxation

#: A restart closer than this (times the reach r) to a solution already found is stopped.
MERGE_TOL = 1e-2

#: Combinations of the coarse grid start (about 27 points per sensor for M = 3).
GRID_BUDGET = 20000

#: Fewer grid points per sensor than this: the grid start is replaced by greedy.
GRID_MIN_POINTS = 5
#: Grid local minima within this (relative) of the grid optimum are refined ...
GRID_WINDOW = 1e-2
#: ... at most this many, each with some sensor more than GRID_AWAY grid steps away from
#: its place in every one taken before.
GRID_CANDIDATES = 8
GRID_AWAY = 3
#: Refined, those within this (relative) of the best refined one are relaxed, at most
#: GRID_BASINS.
GRID_SECOND = 1e-3
GRID_BASINS = 3

#: Points per sensor and rounds of the local grids that refine a grid start.
REFINE_POINTS = 17
REFINE_ROUNDS = 2

#: Sweeps per run of the restarts (and of polish) at most, below ``GSR.max_sweeps``.
RESTART_SWEEPS = 20
#: Rounds of :func:`polish` (joint refinement, then sweeps) at most.
POLISH_ROUNDS = 4
#: The best answers of the starts, at most this many, ...
POLISH_ANSWERS = 3
#: ... within this (relative) of the best are polished.
POLISH_WINDOW = 1e-3

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
    start) and the relaxed ``starts``, the best of them polished (:func:`polish`), by
    objective (the first found wins ties). Never worse than ``first``."""
    results = [(first[1], 0, first[0], first[2], "warm", False)]
    found = [first[0]]
    max_sweeps = run.max_sweeps
    # A crawling run is finished by the joint refinement of polish, not by more sweeps.
    run.max_sweeps = min(max_sweeps, RESTART_SWEEPS)
    try:
        for name, s0, feasible in restart_points(run, warm, starts, found):
            rs, rval, rconv = run.relax(s0, feasible, accelerate, found)
            # A run stopped in a known solution's basin needs no polish of its own.
            same = any(merged(run, rs, k) for k in found)
            found.append(rs)
            results.append((rval, len(results), rs, rconv, name, same))
        # Polish the answers near the best: a crawling run may have stopped above the
        # bottom of a basin that is in fact the lowest.
        results.sort(key=lambda r: r[:2])
        best = results[0][0]
        polished = []
        for val, k, s, conv, name, same in results[:POLISH_ANSWERS]:
            if val <= (1.0 + POLISH_WINDOW) * best and not (same and k > 0 and val > best):
                s, val, conv = polish(run, s, val, conv)
            polished.append((val, k, s, conv, name))
    finally:
        run.max_sweeps = max_sweeps
    val, _, s, conv, name = min(polished, key=lambda r: r[:2])
    return s, val, conv, name


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

    Positions are compared up to ``s -> -s`` (:func:`apart`).
    """
    return all(apart(run, i, s[i], known[i]) <= MERGE_TOL * run.r[i] for i in run.free_idx)


def apart(run: Relaxation, i: int, a: FloatArray, b: FloatArray) -> float:
    """Return how far sensor ``i``'s positions ``a`` and ``b`` are apart.

    Up to ``b -> -b`` (the same information) if ``-b`` is reachable too: on a ``rho``
    arc whose two ends are nearly opposite, a point near one end and the reflection of a
    point near the other carry nearly the same information but lie in different basins.
    """
    d = math.hypot(a[0] - b[0], a[1] - b[1])
    c = run.c[i]
    if math.hypot(b[0] + c[0], b[1] + c[1]) <= run.r[i] * (1.0 + 1e-9):
        d = min(d, math.hypot(a[0] + b[0], a[1] + b[1]))
    return d


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
    """One sensor's curve ADB (Lemma 3) parametrized by ``u`` in ``[0, length]``.

    ``u`` measures how much the sensor's information changes along the curve, not metres:
    on each arc it grows uniformly in the arc's angle, at a rate that makes its increase
    over the arc the turn of the sensor's direction seen from the target plus the change
    of the log of its distance (eq. 17: the information depends on the direction modulo
    pi and on the distance, the bearing part as its inverse square). A small ``rho``
    circle is short in metres but not in ``u``. An arc of a ``rho`` circle turning by
    more than pi is cut to pi: its points pi apart carry the same information.
    """

    def __init__(self, arcs: list[geometry.Arc]) -> None:
        self.arcs = [_fold(a) for a in arcs]
        self.cum = np.concatenate([[0.0], np.cumsum([_change(a) for a in self.arcs])])
        self.length = float(self.cum[-1])

    def points(self, u: FloatArray) -> FloatArray:
        """Return the points at parameters ``u`` (K,) (clipped to the curve), (K, 2)."""
        u = np.clip(u, 0.0, self.length)
        k = np.clip(np.searchsorted(self.cum, u, side="right") - 1, 0, len(self.arcs) - 1)
        out = np.empty((len(u), 2))
        for j, arc in enumerate(self.arcs):
            m = k == j
            if np.any(m):
                span = self.cum[j + 1] - self.cum[j]
                frac = np.clip((u[m] - self.cum[j]) / max(span, 1e-300), 0.0, 1.0)
                out[m] = arc.points(arc.t0 + frac * (arc.t1 - arc.t0))
        return out


def _fold(arc: geometry.Arc) -> geometry.Arc:
    """Return ``arc`` cut to an angle of pi if it is a circle about the target (a rho arc)."""
    if arc.center == (0.0, 0.0) and arc.t1 - arc.t0 > math.pi:
        return geometry.Arc(arc.center, arc.radius, arc.t0, arc.t0 + math.pi)
    return arc


def _change(arc: geometry.Arc, n: int = 9) -> float:
    """Return the turn of the direction plus the change of log distance along ``arc``."""
    if arc.center == (0.0, 0.0):  # a rho arc: the distance is constant
        return arc.t1 - arc.t0
    turn = logd = 0.0
    prev = None
    for k in range(n):
        t = arc.t0 + (arc.t1 - arc.t0) * k / (n - 1)
        x = arc.center[0] + arc.radius * math.cos(t)
        y = arc.center[1] + arc.radius * math.sin(t)
        ang, ld = math.atan2(y, x), 0.5 * math.log(x * x + y * y)
        if prev is not None:
            turn += abs((ang - prev[0] + math.pi) % (2.0 * math.pi) - math.pi)
            logd += abs(ld - prev[1])
        prev = (ang, ld)
    return turn + logd


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

    The first is the grid optimum. The others are the next best local minima of the grid
    (no better neighbour one grid step along any sensor's curve) within
    :data:`GRID_WINDOW` (relative) of the optimum, each with some sensor more than
    :data:`GRID_AWAY` grid steps (in distance, :func:`apart`) from its place in every one
    chosen before: other basins that the coarse grid cannot tell apart from the first (its
    error at a smooth minimum is of that order), at most :data:`GRID_CANDIDATES` in all.
    """
    val = combination_values(run, cands)
    idx, v = _local_minima(val)
    order = np.argsort(v, kind="stable")
    best = float(v[order[0]])
    steps = [
        float(np.median(np.hypot(*np.diff(pts, axis=0).T))) if len(pts) > 1 else 0.0
        for pts in cands
    ]
    out: list[tuple[int, ...]] = []
    for j in order:
        if len(out) >= GRID_CANDIDATES or v[j] > (1.0 + GRID_WINDOW) * best:
            break
        k = tuple(int(q) for q in idx[j])
        if all(_away(run, cands, steps, k, o) for o in out):
            out.append(k)
    return out


def _local_minima(val: FloatArray) -> tuple[np.ndarray, FloatArray]:
    """Return the indices (K, M) and values (K,) of the grid points no worse than any
    neighbour one step along one axis."""
    loc = np.ones(val.shape, dtype=bool)
    for ax, n in enumerate(val.shape):
        if n < 2:
            continue
        lo = [slice(None)] * val.ndim
        hi = [slice(None)] * val.ndim
        lo[ax], hi[ax] = slice(0, n - 1), slice(1, n)
        lo, hi = tuple(lo), tuple(hi)
        loc[hi] &= val[hi] <= val[lo]
        loc[lo] &= val[lo] <= val[hi]
    return np.argwhere(loc), val[loc]


def _away(run: Relaxation, cands: list[FloatArray], steps: list[float], k: tuple, o: tuple) -> bool:
    """Return whether some sensor of grid point ``k`` is over GRID_AWAY steps from ``o``'s."""
    return any(
        apart(run, i, pts[k[i]], pts[o[i]]) > (GRID_AWAY + 0.5) * steps[i]
        for i, pts in enumerate(cands)
        if len(pts) > 1
    )


def coarse_grid(
    run: Relaxation, known: list[FloatArray], budget: int = GRID_BUDGET
) -> list[FloatArray]:
    """Return starts (M, 2) from a coarse grid of every free sensor's curve ADB.

    Each free sensor gets about ``budget ** (1 / n_free)`` points evenly spaced in the
    parameter of :class:`_Curve`, its corners included, and every combination is evaluated
    (no solves). The grid's best local minima (:func:`grid_starts`) are refined by finer
    local grids (:func:`refine`); the refined ones within :data:`GRID_SECOND` of the best
    refined one, at most :data:`GRID_BASINS`, best first, are returned. A grid point
    within 1.5 grid steps of a ``known`` solution is in that solution's basin and is
    dropped.
    """
    k = grid_points(run, budget)
    curves = {i: _Curve(_arcs_of(run, i)) for i in run.free_idx}
    # The arcs' end points (the corners A, B of Fig. 3, where optima often sit) are grid
    # points too: near a corner the objective changes to first order, so a grid that
    # straddles it can misjudge that basin by more than the gap between basins.
    grid_u = {
        i: np.union1d(np.linspace(0.0, cv.length, max(k + 2 - len(cv.cum), 2)), cv.cum)
        for i, cv in curves.items()
    }
    cands = [
        curves[i].points(grid_u[i]) if run.free[i] else run.fixed_rel[i : i + 1]
        for i in range(len(run.c))
    ]
    step = {i: cv.length / (k - 1) for i, cv in curves.items()}
    metres = {i: float(np.median(np.hypot(*np.diff(cands[i], axis=0).T))) for i in run.free_idx}
    refined = []
    for idx in grid_starts(run, cands):
        s = np.stack([cands[i][idx[i]] for i in range(len(run.c))])
        if any(_near(run, s, x, metres) for x in known):
            continue
        u = {i: float(grid_u[i][idx[i]]) for i in run.free_idx}
        s = refine(run, s, u, curves, step)
        refined.append((run.value(s), len(refined), s))
    refined.sort(key=lambda vks: vks[:2])
    return [s for v, _, s in refined[:GRID_BASINS] if v <= (1.0 + GRID_SECOND) * refined[0][0]]


def _near(run: Relaxation, s: FloatArray, known: FloatArray, step: dict) -> bool:
    """Return whether every free sensor of ``s`` is within 1.5 grid steps of ``known``."""
    return all(apart(run, i, s[i], known[i]) <= 1.5 * step[i] for i in run.free_idx)


def refine(
    run: Relaxation, s: FloatArray, u: dict, curves: dict, step: dict, rounds: int | None = None
) -> FloatArray:
    """Return ``s`` refined by exhaustive local grids along the curves, (M, 2).

    Each round tries every combination of ``u_i + step_i * t``, ``t`` in
    :data:`REFINE_POINTS` (odd) points of ``[-1, 1]`` (``t = 0`` included, so the
    objective never increases), then divides the steps by ``(REFINE_POINTS - 1) / 2``, the
    local grid's own step: :data:`REFINE_ROUNDS` rounds.
    """
    t = np.linspace(-1.0, 1.0, REFINE_POINTS)
    shrink = (REFINE_POINTS - 1) / 2.0
    s, u, step = s.copy(), dict(u), dict(step)
    for _ in range(REFINE_ROUNDS if rounds is None else rounds):
        trial = {i: np.clip(u[i] + step[i] * t, 0.0, curves[i].length) for i in u}
        cands = [curves[i].points(trial[i]) if i in u else s[i : i + 1] for i in range(len(s))]
        best = np.unravel_index(
            int(np.argmin(combination_values(run, cands))), tuple(len(c) for c in cands)
        )
        for i in u:
            u[i], s[i] = float(trial[i][best[i]]), cands[i][best[i]]
            step[i] /= shrink
    return s


def polish(
    run: Relaxation, s: FloatArray, val: float, converged: bool
) -> tuple[FloatArray, float, bool]:
    """Return ``(s, value, converged)`` refined jointly, never worse than ``(s, val)``.

    Coordinate descent crawls along a valley (the team turning together, see the module
    docstring) and may stop far from its bottom. Each round
    places every free sensor on the arc of its curve ADB it lies on (at a corner, the arc
    into which the objective descends), minimizes the objective over all their angles on
    those arcs at once (:func:`_newton`), then sweeps (the exact single-sensor solves,
    which may move a sensor onto another arc). Rounds stop when one improves by at most
    1e-13 (relative), or when ``s`` came from sweeps that ``converged`` and the joint
    step gains nothing. Returns ``converged`` of the last sweeps.
    """
    conv, conv_sweeps = converged, converged
    for _ in range(POLISH_ROUNDS):
        par = _arc_params(run, s)
        if not par:
            break
        arcs = _ArcSet(run, s, par)
        try:
            theta, f = _newton(arcs, np.array([_angle(a, s[i]) for i, a in par]))
        except np.linalg.LinAlgError:
            # The total information is singular in float64 (one sensor's rank-one
            # information 1e30 or more times the rest, which the single-sensor solves
            # handle): no joint step; the sweeps' answer stands.
            break
        if val - f <= 1e-13 * val and conv_sweeps:
            break  # no sensor can improve alone (swept before) nor all together on their arcs
        start, fstart = (arcs.positions(theta), f) if f < val else (s, val)
        rs, rval, conv = run.relax(start, True, False)
        conv_sweeps = True
        if rval >= fstart:
            rs, rval = start, fstart
        gain = val - rval
        if gain > 0:
            s, val = rs, rval
        if gain <= 1e-13 * val:
            break
    return s, val, conv


class _ArcSet:
    """The objective over the free sensors' angles on given arcs (trace objective, eq. 17).

    ``derivatives`` returns the value, the gradient and the Hessian in the angles: with
    ``Y`` the total information, ``W = Y^{-1}`` and ``I_i(theta_i)`` sensor ``i``'s
    information, ``d tr(W) / d theta_i = -tr(W I_i' W)`` and
    ``d^2 tr(W) / d theta_i d theta_j = 2 tr(W I_i' W I_j' W) - delta_ij tr(W I_i'' W)``.
    ``I_i'`` is exact (complex step); ``I_i''`` a central difference of it.
    """

    def __init__(self, run: Relaxation, s: FloatArray, par: list) -> None:
        self.s = s
        self.idx = [i for i, _ in par]
        arcs = [a for _, a in par]
        self.lo = np.array([a.t0 for a in arcs])
        self.hi = np.array([a.t1 for a in arcs])
        self.cx = np.array([a.center[0] for a in arcs])
        self.cy = np.array([a.center[1] for a in arcs])
        self.rad = np.array([a.radius for a in arcs])
        self.sd2, self.st2 = run.sd2[self.idx], run.st2[self.idx]
        others = [i for i in range(len(s)) if i not in self.idx]
        self.base = run.prior + sensor_information(s[others], run.sd2[others], run.st2[others]).sum(
            axis=0
        )

    def positions(self, theta: FloatArray) -> FloatArray:
        """Return the configuration (M, 2) with the free sensors at angles ``theta``."""
        out = self.s.copy()
        out[self.idx, 0] = self.cx + self.rad * np.cos(theta)
        out[self.idx, 1] = self.cy + self.rad * np.sin(theta)
        return out

    def _info(self, theta) -> np.ndarray:
        """Return the sensors' information at angles ``theta`` (..., n) as (..., n, 2, 2)."""
        x = self.cx + self.rad * np.cos(theta)
        y = self.cy + self.rad * np.sin(theta)
        return sensor_information(np.stack([x, y], -1), self.sd2, self.st2)

    def value(self, theta: FloatArray) -> float:
        """Return the objective at angles ``theta``."""
        y = self.base + self._info(theta).sum(axis=0)
        return float((y[0, 0] + y[1, 1]) / (y[0, 0] * y[1, 1] - y[0, 1] ** 2))

    def derivatives(self, theta: FloatArray) -> tuple[float, FloatArray, FloatArray]:
        """Return the objective, its gradient (n,) and Hessian (n, n) at angles ``theta``."""
        h, d = 1e-30, 1e-5
        shifts = np.array([0.0, d, -d])[:, None]
        info = self._info(theta[None, :] + shifts + 1j * h)  # (3, n, 2, 2) complex
        i0 = info[0].real
        di = info.imag / h  # I' at theta, theta + d, theta - d
        ddi = (di[1] - di[2]) / (2.0 * d)
        y = self.base + i0.sum(axis=0)
        w = np.linalg.inv(y)
        wa = w @ di[0]  # (n, 2, 2)
        f = float(np.trace(w))
        g = -np.einsum("ab,nbc,ca->n", w, di[0], w)
        hess = 2.0 * np.einsum("iab,jbc,ca->ij", wa, wa, w)
        hess[np.diag_indices_from(hess)] -= np.einsum("ab,nbc,ca->n", w, ddi, w)
        return f, g, hess


def _newton(arcs: _ArcSet, theta: FloatArray, iters: int = 50) -> tuple[FloatArray, float]:
    """Return ``(theta, value)``: a bounded local minimum of ``arcs`` from ``theta``.

    Projected Newton: angles at a bound whose gradient points outward are held; the
    others take a Newton step with the Hessian's eigenvalues made positive (a saddle
    point repels), projected onto the bounds and halved until the objective decreases.
    Stops when no step decreases it or a step gains at most 1e-15 (relative).
    """
    theta = np.clip(theta, arcs.lo, arcs.hi)
    f = math.inf
    for _ in range(iters):
        f, g, hess = arcs.derivatives(theta)
        eps = 1e-12 * (1.0 + np.abs(theta))
        held = ((theta <= arcs.lo + eps) & (g > 0)) | ((theta >= arcs.hi - eps) & (g < 0))
        move = ~held
        if not move.any():
            break
        lam, vec = np.linalg.eigh(hess[np.ix_(move, move)])
        lam = np.maximum(np.abs(lam), 1e-9 * max(float(np.max(np.abs(lam))), 1e-300))
        proj = vec.T @ g[move]
        if 0.5 * float(proj @ (proj / lam)) <= 1e-15 * f:
            break  # the model predicts no gain beyond rounding: a stationary point
        step = np.zeros_like(theta)
        step[move] = -vec @ (proj / lam)
        for _ in range(30):  # halve the step until the objective decreases
            trial = np.clip(theta + step, arcs.lo, arcs.hi)
            ft = arcs.value(trial)
            if ft < f:
                break
            step *= 0.5
        else:
            break
        gain = f - ft
        theta, f = trial, ft
        if gain <= 1e-15 * f:
            break
    return theta, f


def _angle(arc: geometry.Arc, p: FloatArray) -> float:
    """Return the angle of ``p`` on ``arc``, in ``[t0, t1]``."""
    t = math.atan2(p[1] - arc.center[1], p[0] - arc.center[0])
    t = arc.t0 + (t - arc.t0) % (2.0 * math.pi)
    if t > arc.t1:  # past the end: the nearer end
        t = arc.t1 if t - arc.t1 < arc.t0 + 2.0 * math.pi - t else arc.t0
    return t


def _arc_params(run: Relaxation, s: FloatArray) -> list[tuple[int, geometry.Arc]]:
    """Return ``(sensor, arc)`` for the free sensors of ``s`` on an arc of their curve ADB.

    A sensor at a corner (on two arcs) takes the arc along which the objective, with the
    others fixed, descends from the corner; a sensor on no arc (to 1e-9) is left out.
    """
    out = []
    base = None
    for i in run.free_idx:
        on = []
        for arc in _arcs_of(run, i):
            t = _angle(arc, s[i])
            px = arc.center[0] + arc.radius * math.cos(t)
            py = arc.center[1] + arc.radius * math.sin(t)
            if math.hypot(px - s[i, 0], py - s[i, 1]) <= 1e-9 * (1.0 + arc.radius):
                on.append((arc, t))
        if len(on) == 1:
            out.append((i, on[0][0]))
        elif on:
            base = run.value(s) if base is None else base
            out.append((i, min(on, key=lambda at: _one_sided(run, s, i, at, base))[0]))
    return out


def _arcs_of(run: Relaxation, i: int) -> list[geometry.Arc]:
    """Return sensor ``i``'s curve ADB (:func:`activetrack.kinematics.geometry.facing_boundary`),
    cached
    on ``run``."""
    cache = run.__dict__.setdefault("_adb_arcs", {})
    if i not in cache:
        cache[i] = geometry.facing_boundary(run.c[i], run.r[i], run.rho[i])
    return cache[i]


def _one_sided(run: Relaxation, s: FloatArray, i: int, at: tuple, base: float) -> float:
    """Return the objective change of moving sensor ``i`` a little into arc ``at[0]``."""
    arc, t = at
    span = arc.t1 - arc.t0
    step = min(1e-6, 0.5 * span) * (1.0 if t - arc.t0 <= arc.t1 - t else -1.0)
    trial = s.copy()
    trial[i] = arc.points(np.array([t + step]))[0]
    return run.value(trial) - base
