"""Gauss-Seidel relaxation beyond the paper: every sensor's step by the numerical solver.

GSR (Section IV-B, eq. 38) minimizes the objective one sensor at a time with the other
sensors' information folded into the prior. On the paper's problem the single-sensor
step is the exact solve of Section IV-A (:mod:`activetrack.baselines.gsr`). On every other
problem (K targets, range-only or bearing-only sensors, uncertain position fixes, the
worst-trace or log-determinant objective) the step is the global numerical solver of
:mod:`activetrack.solver_numeric`: with sensor ``i``'s information removed, each target's
information entries ``(a0, b0, c0)`` are the base, and the solver minimizes
``objective.of_targets(a0 + a_i(s), ...)`` over sensor ``i``'s feasible set (its reach
disk outside every target's ``rho`` disk), never returning worse than the best candidate
it evaluated.

The rules are GSR's: sensors with ``r = 0`` stay; the warm start is the current positions
(a sensor inside a ``rho`` disk from its nearest feasible point,
:func:`activetrack.feasible_set.project`); a sensor's update is kept only if it lowers
the objective, so the result is never worse than the warm start; sweeps stop when one
improves the objective by at most ``tol`` (relative; by ``tol`` in absolute terms for an
objective that may be negative, the log-determinant), or after ``max_sweeps``. A batch is
relaxed in one vectorized sweep over the copies (copies that have stopped are carried).
"""

from __future__ import annotations

import numpy as np

from activetrack import feasible_set, sensor_models
from activetrack.problem import PlanningProblem
from activetrack.solver_numeric import solve_sensor
from activetrack.validation import FloatArray


def relax(
    problem: PlanningProblem, tol: float, max_sweeps: int
) -> tuple[FloatArray, FloatArray, np.ndarray, FloatArray]:
    """Return ``(positions, value, sweeps, warm_value)``: GSR with numerical steps.

    Shapes: ``positions`` ``batch_shape + (M, 2)`` absolute, ``value``, ``sweeps`` and the
    warm start's value ``batch_shape``.
    """
    shape = problem.batch_shape
    B = int(np.prod(shape, dtype=np.int64))
    M, K = problem.n_sensors, problem.n_targets
    targets = problem.targets.reshape(B, K, 2)
    prior = problem.prior_infos.reshape(B, K, 2, 2)
    current = problem.sensors.reshape(B, M, 2)
    r = problem.r.reshape(B, M)
    rho = problem.rho.reshape(B, M)
    w_d, w_t = (w.reshape(B, M) for w in problem.weights)
    pose = None if problem.pose_cov is None else problem.pose_cov.reshape(B, M, 2, 2)
    s = _warm_start(current, r, targets, rho)
    entries = _entries(s, targets, w_d, w_t, pose)  # 3 x (B, K, M)
    base = (prior[..., 0, 0], prior[..., 0, 1], prior[..., 1, 1])
    totals = [base[e] + entries[e].sum(axis=-1) for e in range(3)]
    value = problem.objective.of_targets(*totals)
    warm = value.copy()
    sweeps = np.zeros(B, dtype=np.int64)
    active = np.ones(B, dtype=bool)
    free = r > 0.0
    for _ in range(max_sweeps):
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        before = value[rows].copy()
        sweeps[rows] += 1
        for i in range(M):
            sub = rows[free[rows, i]]
            if sub.size == 0:
                continue
            others = tuple(totals[e][sub] - entries[e][sub, :, i] for e in range(3))
            cov = None if pose is None else pose[sub, i]
            pos, val = solve_sensor(
                others, current[sub, i], r[sub, i], targets[sub], rho[sub, i],
                w_d[sub, i], w_t[sub, i], cov, problem.objective,
            )  # fmt: skip
            better = val < value[sub]
            if not np.any(better):
                continue
            keep = sub[better]
            s[keep, i] = pos[better]
            one = slice(i, i + 1)
            cov1 = None if pose is None else pose[keep, one]
            new = _entries(s[keep, one], targets[keep], w_d[keep, one], w_t[keep, one], cov1)
            for e in range(3):
                entries[e][keep, :, i] = new[e][..., 0]
                # Rebuilt from the parts (not updated by differences): no drift over sweeps.
                totals[e][keep] = base[e][keep] + entries[e][keep].sum(axis=-1)
            value[keep] = problem.objective.of_targets(*(t[keep] for t in totals))
        gain = before - value[rows]
        scale = np.maximum(np.abs(before), 1.0) if problem.objective.name == "logdet" else before
        active[rows] = gain > tol * scale
    return s.reshape(*shape, M, 2), value.reshape(shape), sweeps.reshape(shape), warm.reshape(shape)


def _warm_start(
    current: FloatArray, r: FloatArray, targets: FloatArray, rho: FloatArray
) -> FloatArray:
    """Return the current positions, each sensor inside a ``rho`` disk at its nearest
    feasible point (sensors that cannot move stay)."""
    each = np.broadcast_to(targets[:, None], (*current.shape[:-1], *targets.shape[-2:]))
    start = feasible_set.project(current, current, r, each, rho)
    return np.where((r > 0.0)[..., None], start, current)


def _entries(
    s: FloatArray,
    targets: FloatArray,
    w_d: FloatArray,
    w_t: FloatArray,
    pose: FloatArray | None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return the sensors' information entries about every target, 3 x (B, K, M)."""
    rel = s[:, None, :, :] - targets[:, :, None, :]  # (B, K, M, 2)
    cov = None if pose is None else pose[:, None]
    return sensor_models.information_entries(rel, w_d[:, None], w_t[:, None], cov)
