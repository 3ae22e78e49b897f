"""Gauss-Seidel relaxation (GSR), the paper's multi-sensor planner (Section IV-B, eq. 38).

GSR minimizes the objective of eq. (17)/(19) one sensor at a time: sensor ``i`` solves
the single-sensor problem of Section IV-A (Pi_4, eq. 38) exactly, with the information of
all other sensors, at their latest positions, folded into the prior,
``(P_i)^{-1} = P11^{-1} + sum_{j != i} info_j``. Sweeps over the sensors repeat until a
sweep improves the trace by less than ``tol`` (relative) or ``max_sweeps`` is reached. A
running information sum makes a sweep cost linear in M. Each update is kept only if it
lowers the objective, so the result is never worse than the (feasible) warm start: the
sensors' current positions, or for a sensor inside its ``rho`` disk its projection onto
the feasible set.

Why GSR stops short, and ``GSR(restarts=True)``. Each step is the exact optimum of one
sensor given the others, so GSR ends in a configuration no single sensor can improve,
which need not be the team optimum. The objective depends on each sensor's information,
i.e. on its distance and its direction modulo pi; near the target the sensors sit on the
``rho`` circle and the team's job is to spread its directions. When two sensors' feasible
arcs overlap, "A takes the low end, B the high end" and the swapped assignment are both
stable: moving one sensor alone to the other assignment stacks it onto its partner,
which is worse, so coordinate descent cannot swap roles. Near-ties between such basins
(1e-5 relative apart) also occur, and then which basin GSR lands in depends on the order
of the sweep. Measured on random 3-sensor problems with ``rho`` active
(``benchmarks/bench_gsr_restarts.py``), plain GSR misses the GBES grid optimum by more
than 1e-6 on about 2% of problems (up to 3% worse). Informed starts that do not look at
the joint problem (the warm start's mirror image across the prior's principal axis, under
which the objective is invariant by Lemma 2; every sensor at its own optimum; sequential
greedy placement in either order) still missed 1-3 problems in 500. The default restart
therefore looks at the joint problem coarsely: an exhaustive search over a coarse grid
of the curves ADB (about ``_GRID_BUDGET`` combinations, vectorized, no solves), its best
point and, if within 1e-3, the best point of a second basin, each refined locally along
the curves to the bottom of its basin, then relaxed by GSR; the best answer is kept.
Because the sweeps never raise the objective, a refined start cannot slide into a worse
basin. Teams too large for a grid of at least 5 points per sensor use the greedy start
in reverse order instead. ``accelerate`` adds Hooke-Jeeves pattern moves (a sweep from
the extrapolated configuration, kept if better), which help in valleys where sensors
must move together, at about 1.4x the solves.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from activetrack import geometry
from activetrack.baselines._common import sensor_modes
from activetrack.objective import lemma2_rotation, sensor_information
from activetrack.problem import PlanningProblem
from activetrack.solver import solve_single_sensor
from activetrack.validation import FloatArray

#: A restart closer than this (times the reach r) to a solution already found is stopped.
_MERGE_TOL = 1e-2

#: Combinations of the coarse grid start (about 27 points per sensor for M = 3).
_GRID_BUDGET = 20000

#: Fewer grid points per sensor than this: the grid start is replaced by greedy.
_GRID_MIN_POINTS = 5
#: A second grid start is used if it is within this (relative) of the grid optimum ...
_GRID_SECOND = 1e-3
#: ... and some sensor lies more than this many grid steps away from the optimum.
_GRID_AWAY = 3

#: The restart starts ``GSR`` knows (see the module docstring).
STARTS = ("grid", "mirror", "independent", "greedy", "greedy-reversed")


@dataclass(frozen=True)
class GSRResult:
    """What one GSR planning call returns.

    Attributes:
        positions: next absolute sensor positions (M, 2).
        value: their objective, eq. (17).
        sweeps: sweeps over the sensors, all starts together.
        n_solves: single-sensor problems solved.
        start: which start gave ``positions``: ``"warm"`` or ``"mirror"``.
        converged: whether the run that gave ``positions`` met ``tol`` before ``max_sweeps``.
        warm_value: objective of the warm start.
        warm_feasible: whether the warm start was feasible (no sensor inside its rho disk).
    """

    positions: FloatArray
    value: float
    sweeps: int
    n_solves: int
    start: str
    converged: bool
    warm_value: float
    warm_feasible: bool


@dataclass
class GSR:
    """Gauss-Seidel relaxation planner (Section IV-B).

    Attributes:
        tol: stop when a sweep lowers the trace by less than ``tol`` times its value (>= 0).
        max_sweeps: at most this many sweeps per start (>= 1).
        restarts: also run from the ``starts`` and keep the best (see the module docstring).
        starts: the restart starts, any of :data:`STARTS`; ``"grid"`` (the default) is the
            coarse exhaustive grid, ``"mirror"`` the warm start reflected across the
            prior's principal axis, ``"independent"`` every sensor at its own optimum,
            ``"greedy"``/``"greedy-reversed"`` sequential placement in sensor order or
            reversed.
        accelerate: use Hooke-Jeeves pattern moves.
        last_result: the :class:`GSRResult` of the latest :meth:`plan` call.
    """

    tol: float = 1e-9
    max_sweeps: int = 100
    restarts: bool = False
    starts: tuple[str, ...] = ("grid",)
    accelerate: bool = False
    last_result: GSRResult | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if not (isinstance(self.tol, (int, float)) and math.isfinite(self.tol)) or self.tol < 0:
            raise ValueError(f"tol must be a finite number >= 0, got {self.tol!r}")
        if not isinstance(self.max_sweeps, (int, np.integer)) or self.max_sweeps < 1:
            raise ValueError(f"max_sweeps must be an integer >= 1, got {self.max_sweeps!r}")
        self.starts = tuple(self.starts)
        unknown = [k for k in self.starts if k not in STARTS]
        if unknown or not self.starts:
            raise ValueError(f"starts must be a non-empty tuple of {STARTS}, got {self.starts!r}")

    @property
    def last_sweeps(self) -> int:
        """Return the sweeps used by the latest :meth:`plan` call (0 before any)."""
        return 0 if self.last_result is None else self.last_result.sweeps

    def plan(self, problem: PlanningProblem, rng: np.random.Generator | None = None) -> FloatArray:
        """Return the next absolute sensor positions, shape (M, 2) (``rng`` is not used)."""
        return self.plan_with_info(problem).positions

    def plan_with_info(self, problem: PlanningProblem) -> GSRResult:
        """Return the GSR solution of ``problem`` with its statistics."""
        run = _Relaxation(problem, self.tol, self.max_sweeps)
        accelerate = self.accelerate
        warm, warm_feasible = run.warm_start()
        s, val, conv = run.relax(warm, True, accelerate)
        warm_value = run.start_value
        start = "warm"
        # One free sensor: the solve is already the global optimum, nothing to restart.
        if self.restarts and run.n_free > 1:
            found = [s]
            for name, s0, feasible in run.restart_points(warm, self.starts, found):
                rs, rval, rconv = run.relax(s0, feasible, accelerate, found)
                found.append(rs)
                if rval < val:
                    s, val, conv, start = rs, rval, rconv, name
        positions = s + problem.target
        result = GSRResult(
            positions=positions,
            value=float(val),
            sweeps=run.sweeps,
            n_solves=run.n_solves,
            start=start,
            converged=bool(conv),
            warm_value=float(warm_value),
            warm_feasible=warm_feasible,
        )
        self.last_result = result
        return result


def _trace_inv(total: FloatArray) -> FloatArray:
    """Return ``tr(total^{-1})`` of 2x2 information matrices (..., 2, 2)."""
    a, b, c = total[..., 0, 0], total[..., 0, 1], total[..., 1, 1]
    return (a + c) / (a * c - b * b)


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


def _combination_values(
    prior: FloatArray, cands: list[FloatArray], sd2: FloatArray, st2: FloatArray
) -> FloatArray:
    """Return the objective of every combination of per-sensor candidates, (K_1, ..., K_M)."""
    m = len(cands)
    tot = [prior[0, 0], prior[0, 1], prior[1, 1]]
    for i, pts in enumerate(cands):
        info = sensor_information(pts, sd2[i], st2[i])
        shape = [1] * m
        shape[i] = len(pts)
        for e, (u, v) in enumerate(((0, 0), (0, 1), (1, 1))):
            tot[e] = tot[e] + info[:, u, v].reshape(shape)
    a, b, c = np.broadcast_arrays(*tot)
    return (a + c) / (a * c - b * b)


def _grid_starts(
    prior: FloatArray, cands: list[FloatArray], sd2: FloatArray, st2: FloatArray
) -> list[tuple[int, ...]]:
    """Return the indices of the best combinations of small candidate sets, by broadcasting.

    The first is the grid optimum. The second, if its objective is within
    ``_GRID_SECOND`` (relative) of the first, is the best combination in which some sensor
    lies more than ``_GRID_AWAY`` grid steps (in distance) from its place in the optimum:
    a second basin that the coarse grid cannot tell apart from the first.
    """
    m = len(cands)
    val = _combination_values(prior, cands, sd2, st2)
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
        near = near & (dist <= (_GRID_AWAY + 0.5) * step).reshape(shape)
    far = np.where(near, np.inf, val)
    k = np.unravel_index(int(np.argmin(far)), val.shape)
    if far[k] <= (1.0 + _GRID_SECOND) * float(val[best]):
        out.append(tuple(int(j) for j in k))
    return out


class _Relaxation:
    """GSR's working state for one problem: sensor data, counters and the sweeps."""

    def __init__(self, problem: PlanningProblem, tol: float, max_sweeps: int) -> None:
        self.free, self.fixed_rel = sensor_modes(problem)
        self.free_idx = np.flatnonzero(self.free).tolist()
        self.n_free = len(self.free_idx)
        self.c = problem.rel_sensors
        self.r, self.rho = problem.r.tolist(), problem.rho.tolist()
        self.sd2, self.st2 = problem.sigma_d2, problem.sigma_theta2
        self.prior = problem.prior_info
        self.tol, self.max_sweeps = tol, max_sweeps
        self.sweeps = 0
        self.n_solves = 0
        self.start_value = math.nan

    def solve(self, others: FloatArray, i: int) -> FloatArray:
        """Return sensor ``i``'s optimum given the information ``others`` (eq. 38), (2,)."""
        self.n_solves += 1
        sol = solve_single_sensor(
            others, self.c[i], self.r[i], self.rho[i], self.sd2[i], self.st2[i], check=False
        )
        return np.asarray(sol.s, dtype=np.float64)

    def info(self, s: FloatArray, i: int) -> FloatArray:
        """Return sensor ``i``'s information at relative position ``s`` (eq. 17), (2, 2)."""
        return sensor_information(s, self.sd2[i], self.st2[i])

    def warm_start(self) -> tuple[FloatArray, bool]:
        """Return the warm start (M, 2) relative to the target, and whether it is feasible.

        Free sensors start where they are; one inside its ``rho`` disk starts from its
        projection onto the feasible set instead, so that the start is always feasible.
        """
        s = self.fixed_rel.copy()
        nc = np.hypot(self.c[:, 0], self.c[:, 1])
        inside = self.free & (nc < np.asarray(self.rho))
        s[self.free] = self.c[self.free]
        if np.any(inside):
            r, rho = np.asarray(self.r), np.asarray(self.rho)
            s[inside] = geometry.project_feasible(
                self.c[inside], self.c[inside], r[inside], rho[inside]
            )
        return s, not bool(np.any(inside))

    def independent(self) -> FloatArray:
        """Return every free sensor at its own optimum given the prior alone, (M, 2)."""
        s = self.fixed_rel.copy()
        for i in self.free_idx:
            s[i] = self.solve(self.prior, i)
        return s

    def restart_points(self, warm: FloatArray, kinds: tuple[str, ...], known: list[FloatArray]):
        """Yield ``(name, start, feasible)`` for the restarts named in ``kinds``.

        ``known`` holds the solutions found so far (it may grow while iterating).
        """
        for kind in kinds:
            if kind == "mirror":
                yield kind, self.mirror(warm), False
            elif kind == "independent":
                yield kind, self.independent(), True
            elif kind == "greedy":
                yield kind, self.greedy(self.free_idx), True
            elif kind == "grid" and self.grid_points() >= _GRID_MIN_POINTS:
                for start in self.coarse_grid(known):
                    yield kind, start, True
            elif kind == "grid":  # too many sensors for a useful grid
                yield "greedy-reversed", self.greedy(self.free_idx[::-1]), True
            elif kind == "greedy-reversed":
                yield kind, self.greedy(self.free_idx[::-1]), True

    def grid_points(self, budget: int = _GRID_BUDGET) -> int:
        """Return the points per free sensor of the coarse grid start."""
        return int(budget ** (1.0 / max(self.n_free, 1)) + 1e-9)

    def coarse_grid(self, known: list[FloatArray], budget: int = _GRID_BUDGET) -> list[FloatArray]:
        """Return starts (M, 2) from a coarse grid of every free sensor's curve ADB.

        Each free sensor gets about ``budget ** (1 / n_free)`` points evenly spaced along
        its curve and every combination is evaluated (no solves). The best one or two
        (:func:`_grid_starts`) are then refined by finer local grids (:meth:`refine`) so
        that the start lies at the bottom of its basin: the sweeps that follow never raise
        the objective, so they cannot fall into a worse basin. A grid point within 1.5
        grid steps of a ``known`` solution is in that solution's basin and is dropped.
        """
        k = self.grid_points(budget)
        curves = {
            i: _Curve(geometry.facing_boundary(self.c[i], self.r[i], self.rho[i]))
            for i in self.free_idx
        }
        grid_u = {i: np.linspace(0.0, cv.length, k) for i, cv in curves.items()}
        cands = [
            curves[i].points(grid_u[i]) if self.free[i] else self.fixed_rel[i : i + 1]
            for i in range(len(self.c))
        ]
        step = {i: cv.length / (k - 1) for i, cv in curves.items()}
        starts = []
        for idx in _grid_starts(self.prior, cands, self.sd2, self.st2):
            s = np.stack([cands[i][idx[i]] for i in range(len(self.c))])
            if any(self._near(s, x, step) for x in known):
                continue
            u = {i: float(grid_u[i][idx[i]]) for i in self.free_idx}
            starts.append(self.refine(s, u, curves, step))
        return starts

    def _near(self, s: FloatArray, known: FloatArray, step: dict) -> bool:
        """Return whether every free sensor of ``s`` is within 1.5 grid steps of ``known``."""
        for i in self.free_idx:
            d = min(np.hypot(*(s[i] - known[i])), np.hypot(*(s[i] + known[i])))
            if d > 1.5 * step[i]:
                return False
        return True

    def refine(
        self, s: FloatArray, u: dict, curves: dict, step: dict, rounds: int = 2
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
                int(np.argmin(_combination_values(self.prior, cands, self.sd2, self.st2))),
                tuple(len(c) for c in cands),
            )
            for i in u:
                u[i], s[i] = float(trial[i][best[i]]), cands[i][best[i]]
                step[i] /= 8.0
        return s

    def greedy(self, order: list[int]) -> FloatArray:
        """Return the sequential greedy start: free sensors placed one by one in ``order``.

        Each sensor takes its optimum given the prior and the sensors placed before it.
        """
        s = self.fixed_rel.copy()
        total = self.prior + sensor_information(
            s[~self.free], self.sd2[~self.free], self.st2[~self.free]
        ).sum(axis=0)
        for i in order:
            s[i] = self.solve(total, i)
            total = total + self.info(s[i], i)
        return s

    def mirror(self, s: FloatArray) -> FloatArray:
        """Return the free sensors of ``s`` reflected across the prior's principal axis.

        With ``F`` that reflection, ``F P11^{-1} F = P11^{-1}`` and ``F info(s) F = info(F s)``,
        so the objective ``tr((F X F)^{-1}) = tr(X^{-1})`` is unchanged (Lemma 2).
        """
        phi0, _ = lemma2_rotation(self.prior)
        c2, s2 = math.cos(2.0 * float(phi0)), math.sin(2.0 * float(phi0))
        out = s.copy()
        out[self.free] = s[self.free] @ np.array([[c2, s2], [s2, -c2]])
        return out

    def value(self, s: FloatArray) -> float:
        """Return the objective of a relative configuration ``s`` (M, 2)."""
        return _trace_inv(self.prior + sensor_information(s, self.sd2, self.st2).sum(axis=0))

    def sweep(
        self, s: FloatArray, info: FloatArray, force: bool, stale: list[bool] | None = None
    ) -> tuple[FloatArray, FloatArray, float, list[bool]]:
        """Return one Gauss-Seidel sweep from ``s`` (eq. 38 for each free sensor in turn).

        ``info`` (M, 2, 2) is the sensors' information at ``s``. An update is kept only if
        it lowers the objective, so the objective never increases; with ``force`` (``s`` is
        not a feasible configuration: a mirror image or a pattern point) every sensor takes
        its solution. ``stale[k]`` says whether the k-th free sensor's problem changed since
        it was last solved; one that did not is skipped (its solution would be the same).
        Returns the new configuration, its information, its objective and ``stale``.
        """
        s, info = s.copy(), info.copy()
        total = self.prior + info.sum(axis=0)  # rebuilt every sweep: no drift
        cur = _trace_inv(total)
        stale = [True] * self.n_free if stale is None else list(stale)
        for k, i in enumerate(self.free_idx):
            if not stale[k]:
                continue
            others = total - info[i]
            new_s = self.solve(others, i)
            stale[k] = False
            new = self.info(new_s, i)
            cand = others + new
            val = _trace_inv(cand)
            if force or val < cur:
                changed = bool(np.any(new_s != s[i]))
                s[i], info[i], total, cur = new_s, new, cand, val
                if changed:  # every other sensor now faces a new problem
                    stale = [True] * self.n_free
                    stale[k] = False
        self.sweeps += 1
        return s, info, cur, stale

    def relax(
        self,
        s0: FloatArray,
        feasible: bool,
        accelerate: bool,
        known: list[FloatArray] | None = None,
    ) -> tuple[FloatArray, float, bool]:
        """Return ``(s, value, converged)``: sweeps from ``s0`` until the tolerance is met.

        ``feasible`` says whether ``s0`` is a feasible configuration; if not, the first
        sweep replaces every free sensor and the tolerance is tested from the second on.
        With ``accelerate``, Hooke-Jeeves pattern moves (a sweep from ``x1 + (x1 - x0)``,
        kept only if it beats ``x1``) alternate with plain sweeps. A restart that comes
        within ``_MERGE_TOL`` (relative to the sensors' reach) of a ``known`` solution is
        stopped there: it is in that solution's basin. Sets ``start_value``, the objective
        of ``s0``.
        """
        info0 = sensor_information(s0, self.sd2, self.st2)
        self.start_value = _trace_inv(self.prior + info0.sum(axis=0))
        if self.n_free == 0:
            return s0, self.start_value, True
        x0, f0 = s0, (self.start_value if feasible else math.inf)
        x1, i1, f1, stale = self.sweep(s0, info0, force=not feasible)
        n = 1
        pattern_failed = False
        while (
            n < self.max_sweeps
            and any(stale)
            and not self._converged(f0, f1)
            and not any(self._merged(x1, k) for k in (known or ()))
        ):
            if accelerate and math.isfinite(f0) and not pattern_failed:
                pattern = x1.copy()
                pattern[self.free] = 2.0 * x1[self.free] - x0[self.free]
                if np.all(np.hypot(pattern[:, 0], pattern[:, 1]) > 0.0):
                    pinfo = sensor_information(pattern, self.sd2, self.st2)
                    y, iy, fy, st = self.sweep(pattern, pinfo, force=True)
                    n += 1
                    if fy < f1:
                        x0, f0, x1, i1, f1, stale = x1, f1, y, iy, fy, st
                        continue
                    pattern_failed = True  # sweep plainly from x1 next
                    continue
            pattern_failed = False
            y, iy, fy, stale = self.sweep(x1, i1, force=False, stale=stale)
            n += 1
            x0, f0, x1, i1, f1 = x1, f1, y, iy, fy
        return x1, f1, self._converged(f0, f1) or not any(stale)

    def _converged(self, f0: float, f1: float) -> bool:
        """Return whether a sweep from value ``f0`` to ``f1`` met the relative tolerance."""
        return math.isfinite(f0) and f0 - f1 <= self.tol * f0

    def _merged(self, s: FloatArray, known: FloatArray) -> bool:
        """Return whether every free sensor of ``s`` is within the merge tolerance of ``known``.

        Positions are compared up to ``s -> -s`` (the same information).
        """
        f = self.free
        d = np.minimum(np.hypot(*(s[f] - known[f]).T), np.hypot(*(s[f] + known[f]).T))
        return bool(np.all(d <= _MERGE_TOL * np.maximum(np.asarray(self.r)[f], 1e-300)))
