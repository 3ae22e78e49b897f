"""Gauss-Seidel relaxation (GSR), the paper's multi-sensor planner (Section IV-B, eq. 38).

GSR minimizes the objective of eq. (17)/(19) one sensor at a time: sensor ``i`` solves
the single-sensor problem of Section IV-A (Pi_4, eq. 38) exactly, with the information of
all other sensors, at their latest positions, folded into the prior,
``(P_i)^{-1} = P11^{-1} + sum_{j != i} info_j``. The rules, the same for one problem and
for a batch:

- Sensor modes (:func:`activetrack.baselines._common.sensor_modes`): sensors that cannot
  move or cannot keep ``rho`` are fixed; the others are free.
- Warm start (:func:`warm_start`): free sensors where they are; one inside its ``rho``
  disk from its projection onto the feasible set, so the start is always feasible.
- A sweep visits the free sensors in order; an update is kept only if it lowers the
  objective (``problem.objective``), so the result is never worse than the warm start. A
  sensor whose subproblem has not changed since its last solve is skipped (its solution
  would be the same). A running information sum, rebuilt every sweep, makes a sweep cost
  linear in M.
- Sweeps stop when one improves the objective by at most ``tol`` (relative), when no
  sensor is left to re-solve, or after ``max_sweeps``.

The sweeps are compiled (:mod:`activetrack.baselines.gsr_kernel`): one problem
(:func:`relax_single`) and every copy of a batched problem (:func:`relax_batch`, a compiled
loop over the copies) run the same kernel, so a copy's plan is bit for bit the single
problem's. The restarts and the Hooke-Jeeves pattern moves run the same rules in Python
(:class:`Relaxation`); both share the sensor modes, the warm start, the objective and the
stopping test.

GSR ends in a configuration no single sensor can improve, which need not be the team
optimum; ``GSR(restarts=True)`` also relaxes from other starts and keeps the best
(:mod:`activetrack.baselines.gsr_restarts`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from activetrack._jit import as_rows
from activetrack.baselines import gsr_kernel as gk
from activetrack.baselines import gsr_restarts, gsr_separation
from activetrack.baselines._common import raise_for_status, sensor_modes, sensor_modes_of
from activetrack.models.objective import is_trace, sensor_information
from activetrack.solvers._scalar import NO_ROOTS, ROOTS_SIZE, ROOTS_TAG, solve_point
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem

STARTS = gsr_restarts.STARTS


@dataclass(frozen=True)
class GSRResult:
    """What one GSR planning call on a single problem returns.

    Attributes:
        positions: next absolute sensor positions (M, 2).
        value: their objective, eq. (17).
        sweeps: sweeps over the sensors, all starts together.
        n_solves: single-sensor problems solved.
        start: which start gave ``positions``: ``"warm"`` or a restart of
            :data:`activetrack.baselines.gsr_restarts.STARTS`.
        converged: whether the run that gave ``positions`` met ``tol`` before ``max_sweeps``.
        warm_value: objective of the warm start.
        warm_feasible: whether the sensors' current positions were feasible (no free
            sensor inside its rho disk).
    """

    positions: FloatArray
    value: float
    sweeps: int
    n_solves: int
    start: str
    converged: bool
    warm_value: float
    warm_feasible: bool


@dataclass(frozen=True)
class GSRBatchResult:
    """What one GSR planning call on a batched problem returns.

    Attributes:
        positions: next absolute positions, ``batch_shape + (M, 2)``.
        value: their objective, ``batch_shape``.
        sweeps: sweeps per copy, ``batch_shape``.
        n_solves: single-sensor problems solved per copy, ``batch_shape`` (None when the
            copies were planned with restarts).
    """

    positions: FloatArray
    value: FloatArray
    sweeps: np.ndarray
    n_solves: np.ndarray | None = None


def warn_warm_roots(warm_roots: object) -> None:
    """Warn that ``warm_roots`` is deprecated (it has no effect) unless it is None."""
    if warm_roots is not None:
        warnings.warn(
            "warm_roots is deprecated and has no effect: every GSR starts a sensor's later "
            "solves from its previous roots (certified, else the QR); it will be removed",
            DeprecationWarning,
            stacklevel=3,
        )


def check_parameters(tol: object, max_sweeps: object) -> None:
    """Raise ValueError unless ``tol`` is in [0, 1) and ``max_sweeps`` an int >= 1.

    ``tol`` is a relative improvement: 1 or more would stop before any sweep counts.
    """
    if (
        isinstance(tol, bool)
        or not (isinstance(tol, (int, float, np.floating)) and math.isfinite(tol))
        or not 0 <= tol < 1
    ):
        raise ValueError(f"tol must be a number in [0, 1), got {tol!r}")
    if not isinstance(max_sweeps, (int, np.integer)) or max_sweeps < 1:
        raise ValueError(f"max_sweeps must be an integer >= 1, got {max_sweeps!r}")


@dataclass
class GSR:
    """Gauss-Seidel relaxation planner (Section IV-B), for one problem or a batch.

    Attributes:
        tol: stop when a sweep lowers the objective by at most ``tol`` times its value, in
            [0, 1).
        max_sweeps: at most this many sweeps per start (>= 1).
        restarts: also run from the ``starts`` and keep the best
            (:mod:`activetrack.baselines.gsr_restarts`; a batch is planned copy by copy).
        starts: the restart starts, any of :data:`STARTS`; ``"grid"`` (the default) is a
            coarse exhaustive grid of the curves ADB, ``"mirror"`` the warm start reflected
            across the prior's principal axis, ``"independent"`` every sensor at its own
            optimum, ``"greedy"``/``"greedy-reversed"`` sequential placement in sensor
            order or reversed.
        accelerate: use Hooke-Jeeves pattern moves (single problems).
        warm_roots: deprecated, no effect (a sensor's later solves always start from its
            previous roots, certified, else the companion QR); passing it warns.
        last_result: the :class:`GSRResult` (single problem) or :class:`GSRBatchResult`
            (batch) of the latest :meth:`plan` call.
    """

    #: Keeps the team rule ``d_sep`` itself (:mod:`activetrack.baselines.gsr_separation`).
    keeps_d_sep = True

    tol: float = 1e-9
    max_sweeps: int = 100
    restarts: bool = False
    starts: tuple[str, ...] = ("grid",)
    accelerate: bool = False
    warm_roots: bool | None = None
    last_result: GSRResult | GSRBatchResult | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        check_parameters(self.tol, self.max_sweeps)
        self.starts = tuple(self.starts)
        unknown = [k for k in self.starts if k not in STARTS]
        if unknown or not self.starts:
            raise ValueError(f"starts must be a non-empty tuple of {STARTS}, got {self.starts!r}")
        warn_warm_roots(self.warm_roots)

    @property
    def last_sweeps(self) -> int:
        """Return the sweeps of the latest :meth:`plan` call (all copies together; 0 before)."""
        return 0 if self.last_result is None else int(np.sum(self.last_result.sweeps))

    def plan(self, problem: PlanningProblem, rng: np.random.Generator | None = None) -> FloatArray:
        """Return the next absolute sensor positions, ``batch_shape + (M, 2)`` (no ``rng``)."""
        return self.plan_with_info(problem).positions

    def plan_with_info(self, problem: PlanningProblem) -> GSRResult | GSRBatchResult:
        """Return GSR's solution with its statistics: a :class:`GSRResult` for a single
        problem, a :class:`GSRBatchResult` for a batched one."""
        if not problem.is_paper or gsr_separation.pair_matrix(problem) is not None:
            result = self._plan_numeric(problem)
            self.last_result = result
            return result
        _check_objective(problem)
        if problem.batch_shape:
            result = self._plan_batch(problem)
        else:
            result = self._plan_single(problem)
        self.last_result = result
        return result

    def _plan_single(self, problem: PlanningProblem) -> GSRResult:
        if not self.restarts and not self.accelerate:  # plain sweeps: compiled
            return relax_single(problem, self.tol, self.max_sweeps)
        run = Relaxation(problem, self.tol, self.max_sweeps)
        warm, warm_feasible = run.warm_start()
        s, val, conv = run.relax(warm, True, self.accelerate)  # the warm start is feasible
        warm_value = run.start_value
        start = "warm"
        # One free sensor: the solve is already the global optimum, nothing to restart.
        if self.restarts and run.n_free > 1:
            s, val, conv, start = gsr_restarts.best_of_restarts(
                run, warm, (s, val, conv), self.starts, self.accelerate
            )
        return GSRResult(
            positions=s + problem.target,
            value=float(val),
            sweeps=run.sweeps,
            n_solves=run.n_solves,
            start=start,
            converged=bool(conv),
            warm_value=float(warm_value),
            warm_feasible=warm_feasible,
        )

    def _plan_numeric(self, problem: PlanningProblem) -> GSRResult | GSRBatchResult:
        """GSR beyond the paper's problem: numerical single-sensor steps
        (:mod:`activetrack.baselines.gsr_numeric`); a kinematics of its own, and the team
        rule ``d_sep`` (each subproblem keeps the pair conditions with the others' plans,
        :mod:`activetrack.baselines.gsr_separation`), in command space
        (:mod:`activetrack.baselines.gsr_command`)."""
        if self.restarts:
            raise ValueError(
                "restarts=True runs the paper's exact solver from several starts; this problem "
                "(several targets, other sensor models, uncertain poses, another objective, "
                "a kinematics of its own or the team rule d_sep) is planned with numerical "
                "single-sensor steps, without restarts"
            )
        from activetrack.baselines import gsr_numeric  # noqa: PLC0415 (beyond the paper)

        positions, value, sweeps, warm = gsr_numeric.relax(problem, self.tol, self.max_sweeps)
        if problem.batch_shape:
            return GSRBatchResult(positions, value, sweeps)
        return GSRResult(
            positions=positions,
            value=float(value),
            sweeps=int(sweeps),
            n_solves=int(sweeps) * int(np.count_nonzero(problem.r > 0.0)),  # free sensors
            start="warm",
            converged=bool(sweeps < self.max_sweeps),
            warm_value=float(warm),
            warm_feasible=True,
        )

    def _plan_batch(self, problem: PlanningProblem) -> GSRBatchResult:
        shape = problem.batch_shape
        if self.restarts:  # restarts are scalar: copy by copy
            flat = problem[np.unravel_index(np.arange(math.prod(shape)), shape)]
            results = [self._plan_single(flat[b]) for b in range(math.prod(shape))]
            return GSRBatchResult(
                np.stack([r.positions for r in results]).reshape(problem.sensors.shape),
                np.array([r.value for r in results]).reshape(shape),
                np.array([r.sweeps for r in results], dtype=np.int64).reshape(shape),
            )
        return relax_batch(problem, self.tol, self.max_sweeps)


def _check_objective(problem: PlanningProblem) -> None:
    """Raise ValueError unless the problem's objective is the trace (the solver's, eq. 22)."""
    if not is_trace(problem.objective):
        raise ValueError(
            f"GSR's exact single-sensor step (Section IV-A) minimizes the trace objective; "
            f"got objective {problem.objective.name!r}"
        )


def warm_start(
    c: FloatArray, r: FloatArray, rho: FloatArray, free: np.ndarray, fixed_rel: FloatArray
) -> tuple[FloatArray, np.ndarray]:
    """Return the warm start (..., M, 2) relative to the target and the free sensors inside rho.

    Batched. Free sensors start where they are (``c``), fixed ones at ``fixed_rel`` (their
    next position); a free sensor inside its ``rho`` disk starts from its projection onto
    the feasible set (:func:`activetrack.baselines.gsr_kernel.warm_row`).
    """
    c = np.asarray(c, np.float64)
    batch, m = c.shape[:-2], c.shape[-2]
    s, inside = np.empty(batch + (m, 2)), np.empty(batch + (m,), bool)
    gk.warm_rows(
        as_rows(c, batch, (m, 2)), as_rows(r, batch, (m,)), as_rows(rho, batch, (m,)),
        as_rows(free, batch, (m,), np.bool_), as_rows(fixed_rel, batch, (m, 2)),
        s.reshape(-1, m, 2), inside.reshape(-1, m),
    )  # fmt: skip
    return s, inside


def small_improvement(f0, f1, tol: float):
    """Return whether a sweep from objective ``f0`` to ``f1`` improved by at most ``tol * f0``."""
    return f0 - f1 <= tol * f0


# ---------------------------------------------------------------------------------------
# A batch of problems: one vectorized sweep over the copies.
# ---------------------------------------------------------------------------------------


def relax_batch(problem: PlanningProblem, tol: float, max_sweeps: int) -> GSRBatchResult:
    """Return GSR's plans for every copy of a batched problem: positions ``batch_shape +
    (M, 2)``, values, sweeps and single-sensor solves ``batch_shape`` (the compiled modes,
    warm start and sweeps of :func:`activetrack.baselines.gsr_kernel.relax_rows`, copy by
    copy)."""
    shape, M = problem.batch_shape, problem.n_sensors
    B = math.prod(shape)
    r, rho, sd2, st2 = (
        as_rows(getattr(problem, k), shape, (M,)) for k in ("r", "rho", "sigma_d2", "sigma_theta2")
    )
    s, status = np.empty((B, M, 2)), np.empty((B, M), np.int64)
    value, sweeps, solves = np.empty(B), np.empty(B, np.int64), np.empty(B, np.int64)
    gk.relax_rows(
        as_rows(problem.prior_info, shape, (2, 2)), as_rows(problem.rel_sensors, shape, (M, 2)),
        r, rho, sd2, st2, float(tol), int(max_sweeps), s, status, value, sweeps, solves,
    )  # fmt: skip
    raise_for_status(status.reshape(shape + (M,)))
    positions = s.reshape(shape + (M, 2)) + problem.target[..., None, :]
    return GSRBatchResult(
        positions, value.reshape(shape), sweeps.reshape(shape), solves.reshape(shape)
    )


def relax_single(problem: PlanningProblem, tol: float, max_sweeps: int) -> GSRResult:
    """Return GSR's plan of one problem from its warm start, plain sweeps (compiled:
    :func:`activetrack.baselines.gsr_kernel.plan_single`)."""
    c = np.array(problem.rel_sensors, np.float64)  # kernel arrays: contiguous, writable
    r, rho, sd2, st2 = np.array(
        [problem.r, problem.rho, problem.sigma_d2, problem.sigma_theta2], np.float64
    )
    s = np.empty(c.shape)
    prior = problem.prior_info
    code, value, start, sweeps, solves, converged, warm_feasible = gk.plan_single(
        float(prior[0, 0]), float(prior[0, 1]), float(prior[1, 1]), c, r, rho, sd2, st2,
        float(tol), int(max_sweeps), s,
    )  # fmt: skip
    if code:
        sensor_modes_of(c, r, rho)  # raises, naming the sensors
    s += problem.target
    return GSRResult(
        s, float(value), int(sweeps), int(solves), "warm", bool(converged), float(start),
        bool(warm_feasible),
    )  # fmt: skip


# ---------------------------------------------------------------------------------------
# One problem: the same rules in scalar form (also the restarts' sweep).
# ---------------------------------------------------------------------------------------


class Relaxation:
    """GSR's working state for one problem: sensor data, counters and the sweeps."""

    def __init__(self, problem: PlanningProblem, tol: float, max_sweeps: int) -> None:
        self.free, self.fixed_rel = sensor_modes(problem)
        self.free_idx = np.flatnonzero(self.free).tolist()
        self.n_free = len(self.free_idx)
        self.c = problem.rel_sensors
        self.r, self.rho = problem.r.tolist(), problem.rho.tolist()
        self.sd2, self.st2 = problem.sigma_d2, problem.sigma_theta2
        self._c, self._sd2, self._st2 = self.c.tolist(), self.sd2.tolist(), self.st2.tolist()
        self.prior = problem.prior_info
        self.objective = problem.objective
        self.phi = problem.objective.of_information
        self.tol, self.max_sweeps = tol, max_sweeps
        self.sweeps = 0
        self.n_solves = 0
        self.start_value = math.nan
        self._roots = np.zeros((len(self.r), ROOTS_SIZE))  # each sensor's last f3 roots (none)

    def solve(self, others: FloatArray, i: int) -> FloatArray:
        """Return sensor ``i``'s optimum given the information ``others`` (eq. 38), (2,).

        The solver's kernel on floats (what ``solve_single_sensor(..., check=False)``
        runs, without its wrapping: GSR calls it ~10 times a plan), from the roots of the
        sensor's previous solve on this object (forgotten at each :meth:`relax`, as the
        compiled sweeps start each relaxation afresh).
        """
        self.n_solves += 1
        p11, p12, _, p22 = others.ravel().tolist()
        c1, c2 = self._c[i]
        sx, sy, _, _, _ = solve_point(
            p11, p12, p22, c1, c2, self.r[i], self.rho[i], self._sd2[i], self._st2[i],
            self._roots[i],
        )  # fmt: skip
        return np.array([sx, sy])

    def info(self, s: FloatArray, i: int) -> FloatArray:
        """Return sensor ``i``'s information at relative position ``s`` (eq. 17), (2, 2)."""
        return sensor_information(s, self.sd2[i], self.st2[i])

    def warm_start(self) -> tuple[FloatArray, bool]:
        """Return the warm start (:func:`warm_start`), (M, 2), and whether no sensor was
        inside its ``rho`` disk."""
        s, inside = warm_start(
            self.c, np.asarray(self.r), np.asarray(self.rho), self.free, self.fixed_rel
        )
        return s, not bool(np.any(inside))

    def value(self, s: FloatArray) -> float:
        """Return the objective of a relative configuration ``s`` (M, 2)."""
        return self.phi(self.prior + sensor_information(s, self.sd2, self.st2).sum(axis=0))

    def sweep(
        self, s: FloatArray, info: FloatArray, force: bool, stale: list[bool] | None = None
    ) -> tuple[FloatArray, FloatArray, float, list[bool]]:
        """Return one Gauss-Seidel sweep from ``s`` (eq. 38 for each free sensor in turn).

        ``info`` (M, 2, 2) is the sensors' information at ``s``. An update is kept only if
        it lowers the objective; with ``force`` (``s`` is not a feasible configuration: a
        mirror image or a pattern point) every sensor takes its solution.
        ``stale[k]`` says whether the k-th free sensor's problem changed since it was last
        solved; one that did not is skipped. Returns the new configuration, its
        information, its objective and ``stale``.
        """
        s, info = s.copy(), info.copy()
        total = self.prior + info.sum(axis=0)  # rebuilt every sweep: no drift
        cur = self.phi(total)
        stale = [True] * self.n_free if stale is None else list(stale)
        for k, i in enumerate(self.free_idx):
            if not stale[k]:
                continue
            others = total - info[i]
            new_s = self.solve(others, i)
            stale[k] = False
            new = self.info(new_s, i)
            cand = others + new
            val = self.phi(cand)
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

        With ``feasible`` False the first sweep replaces every free sensor and the
        tolerance is tested from the second on. With ``accelerate``, Hooke-Jeeves pattern
        moves (a sweep from ``x1 + (x1 - x0)``, kept only if it beats ``x1``) alternate
        with plain sweeps. A run that comes within
        :data:`activetrack.baselines.gsr_restarts.MERGE_TOL` (relative to the sensors'
        reach) of a ``known`` solution is stopped there: it is in that solution's basin.
        Sets ``start_value``, the objective of ``s0``.
        """
        self._roots[:, ROOTS_TAG] = NO_ROOTS  # a fresh start, as the compiled relaxation's
        info0 = sensor_information(s0, self.sd2, self.st2)
        self.start_value = self.phi(self.prior + info0.sum(axis=0))
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
            and not any(gsr_restarts.merged(self, x1, k) for k in (known or ()))
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
        return math.isfinite(f0) and small_improvement(f0, f1, self.tol)
