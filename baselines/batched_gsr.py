"""Gauss-Seidel relaxation over a batch of independent problems (Section IV-B, eq. 38).

The same algorithm as :class:`activetrack.baselines.GSR` without restarts, with one
difference only in how it is computed: each step of a sweep solves sensor ``i`` of
*every* copy at once with the vectorized kernel of
:func:`activetrack.solver.solve_single_sensor_batch` (stacked companion matrices). Per
copy it follows the scalar rules exactly: warm start from the current positions (a
sensor inside its ``rho`` disk from its projection), an update is kept only if it lowers
the trace, a sensor whose problem has not changed since its last solve is skipped, and a
copy stops when a sweep improves its trace by at most ``tol`` (relative), when no sensor
is left to re-solve, or after ``max_sweeps``. Copies that have stopped are left out of
later solves.

Between sweeps a sensor's subproblem changes only by the other sensors' moves, so the
roots of its degree-10 polynomial f3 (eq. 33) move little: each copy keeps, per sensor,
the roots of its last solve and hands them to the solver as starting points for its
root finding (in the first sweep the solver seeds rows from other rows of the call). A
row so started is used only when certified to have the same roots, each to within 1e-10
(see :mod:`activetrack.solver`); every other row takes the companion-matrix eigenvalues
as before. This changes how the roots are computed, not the method: each solve agrees
with the eigenvalue path to rounding (``warm_roots=False`` forces the eigenvalues), though
a last-bit difference can change a copy's sweep count by one, as a 1-ulp change of its
input can.

This is how an expert labels a whole batched environment per call
(:class:`BatchedGSRPolicy`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from activetrack import geometry
from activetrack.linalg2 import inv2
from activetrack.objective import sensor_information
from activetrack.solver import CircleRoots, _solve_batch_unchecked
from activetrack.validation import FloatArray


@dataclass(frozen=True)
class BatchedGSRResult:
    """Solutions of a batch: ``positions`` (B, M, 2) absolute, ``value`` (B,), ``sweeps`` (B,)."""

    positions: FloatArray
    value: FloatArray
    sweeps: np.ndarray


def _trace_inv(total: FloatArray) -> FloatArray:
    """Return ``tr(total^{-1})`` for (..., 2, 2) information matrices."""
    a, b, c = total[..., 0, 0], total[..., 0, 1], total[..., 1, 1]
    return (a + c) / (a * c - b * b)


@dataclass
class BatchedGSR:
    """Plain GSR (no restarts) for B problems with the same number of sensors M.

    Attributes:
        tol: relative improvement per sweep below which a copy stops (>= 0).
        max_sweeps: at most this many sweeps per copy (>= 1).
        warm_roots: find the roots of f3 from starting points (the sensor's previous
            solve; in the first sweep other copies'), used only where certified (see the
            module docstring); False: the companion-matrix eigenvalues always.
    """

    tol: float = 1e-9
    max_sweeps: int = 100
    warm_roots: bool = True

    def __post_init__(self) -> None:
        if not (isinstance(self.tol, (int, float)) and math.isfinite(self.tol)) or self.tol < 0:
            raise ValueError(f"tol must be a finite number >= 0, got {self.tol!r}")
        if not isinstance(self.max_sweeps, (int, np.integer)) or self.max_sweeps < 1:
            raise ValueError(f"max_sweeps must be an integer >= 1, got {self.max_sweeps!r}")
        if not isinstance(self.warm_roots, (bool, np.bool_)):
            raise ValueError(f"warm_roots must be a bool, got {self.warm_roots!r}")

    def plan_batch(
        self,
        prior_cov: FloatArray,
        target: FloatArray,
        sensors: FloatArray,
        r: FloatArray,
        rho: FloatArray,
        sigma_d2: FloatArray,
        sigma_theta2: FloatArray,
    ) -> BatchedGSRResult:
        """Return GSR's next positions for B problems.

        Shapes: ``prior_cov`` (B, 2, 2) predicted position covariances, ``target`` (B, 2),
        ``sensors`` (B, M, 2); the per-sensor parameters are (M,) or (B, M).
        """
        sensors = np.asarray(sensors, dtype=np.float64)
        B, M = sensors.shape[:2]
        c = sensors - target[:, None, :]
        r, rho, sd2, st2 = (
            np.broadcast_to(np.asarray(v, dtype=np.float64), (B, M))
            for v in (r, rho, sigma_d2, sigma_theta2)
        )
        free, s = _modes(c, r, rho)
        prior = inv2(np.asarray(prior_cov, dtype=np.float64))
        info = sensor_information(s, sd2, st2)
        f0 = _trace_inv(prior + info.sum(axis=1))
        stale = free.copy()
        active = free.any(axis=1)
        sweeps = np.zeros(B, dtype=np.int64)
        f1 = f0.copy()
        # Per sensor, each copy's roots of f3 from its last solve (NaN: none yet).
        roots = np.full((M, B, 10), np.nan, dtype=np.complex128) if self.warm_roots else None
        swap = np.zeros((M, B), dtype=bool)
        while active.any():
            f_before = f1.copy()
            self._sweep(prior, c, r, rho, sd2, st2, free, s, info, f1, stale, active, roots, swap)
            sweeps += active
            stop = (
                (sweeps >= self.max_sweeps)
                | ~stale.any(axis=1)
                | (f_before - f1 <= self.tol * f_before)
            )
            active &= ~stop
        return BatchedGSRResult(s + target[:, None, :], f1, sweeps)

    @staticmethod
    def _sweep(prior, c, r, rho, sd2, st2, free, s, info, cur, stale, active, roots, swap) -> None:
        """Run one Gauss-Seidel sweep in place on the ``active`` copies (eq. 38).

        ``roots`` (M, B, 10) and ``swap`` (M, B) are each sensor's roots of f3 from its
        last solve and their variable, the solver's starting points, updated in place
        (``roots=None``: none, companion eigenvalues only).
        """
        total = prior + info.sum(axis=1)  # rebuilt every sweep, as the scalar GSR does
        cur[active] = _trace_inv(total[active])
        M = s.shape[1]
        for i in range(M):
            idx = np.flatnonzero(active & stale[:, i])
            if idx.size == 0:
                continue
            others = total[idx] - info[idx, i]
            guess = None
            if roots is not None:
                guess = CircleRoots(roots[i][idx], swap[i][idx], np.zeros(idx.size, dtype=bool))
            sol, used = _solve_batch_unchecked(
                others, c[idx, i], r[idx, i], rho[idx, i], sd2[idx, i], st2[idx, i], guess
            )
            if roots is not None:
                roots[i][idx] = used.roots
                swap[i][idx] = used.swap
            new_s = sol.s
            stale[idx, i] = False
            new_info = sensor_information(new_s, sd2[idx, i], st2[idx, i])
            cand = others + new_info
            val = _trace_inv(cand)
            keep = val < cur[idx]
            k = idx[keep]
            changed = k[np.any(new_s[keep] != s[k, i], axis=1)]
            s[k, i] = new_s[keep]
            info[k, i] = new_info[keep]
            total[k] = cand[keep]
            cur[k] = val[keep]
            stale[changed] = free[changed]  # the others now face a new problem
            stale[changed, i] = False


def _modes(c: FloatArray, r: FloatArray, rho: FloatArray) -> tuple[np.ndarray, FloatArray]:
    """Return ``(free, warm)``: which sensors GSR optimizes and the warm start (B, M, 2).

    As :func:`activetrack.baselines._common.sensor_modes`: a sensor with ``r = 0`` stays,
    one that cannot reach ``rho`` goes to the reachable point farthest from the target;
    a free sensor inside its ``rho`` disk starts from its projection onto the feasible set.
    """
    nc = np.hypot(c[..., 0], c[..., 1])
    stay = r <= 0.0
    unreachable = ~stay & (nc + r < rho)
    free = ~stay & ~unreachable
    if np.any(free & (rho <= 0.0) & (nc <= r)):
        raise ValueError("rho must be > 0 for a sensor that can reach the predicted target")
    warm = np.where(unreachable[..., None], geometry.unreachable_fallback(c, r), c)
    inside = free & (nc < rho)
    if inside.any():
        warm[inside] = geometry.project_feasible(c[inside], c[inside], r[inside], rho[inside])
    return free, warm


class BatchedGSRPolicy:
    """The GSR expert for a :class:`~activetrack.envs.batched.BatchedActiveTracking`.

    :meth:`act` returns the actions (N, M, 2) that move every copy's sensors to GSR's
    positions exactly (:func:`activetrack.envs.dynamics.actions_to_reach`).
    """

    def __init__(self, tol: float = 1e-9, max_sweeps: int = 100) -> None:
        self.planner = BatchedGSR(tol, max_sweeps)
        self.last_result: BatchedGSRResult | None = None

    def act(self, env) -> FloatArray:
        """Return every copy's expert actions, shape (N, M, 2)."""
        from activetrack.envs.dynamics import actions_to_reach

        p = env.params
        res = self.planner.plan_batch(
            env.P_pred[:, :2, :2],
            env.x_pred[:, :2],
            env.sensors,
            p.r,
            p.rho,
            p.sigma_d2,
            p.sigma_theta2,
        )
        self.last_result = res
        return actions_to_reach(res.positions, env.sensors, p.r)
