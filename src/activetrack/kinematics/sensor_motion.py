"""Sensor motion: proposed next positions to executed ones, eq. (13)-(16).

Every sensor ends a step within its reach ``r_i = vmax_i dt`` of where it was (eq. 13/15)
and outside the ``rho_i`` disk around the *predicted* target ``p_T(k+1|k)`` (eq. 14/16). Two
ways to propose a move reach the same rule:

- :func:`apply_actions`: an agent's action ``a_i`` is its displacement as a fraction of its
  reach, ``p_S_i(k+1) = p_S_i(k) + r_i a_i``; vectors longer than 1 are first scaled onto
  the unit disk (without overflow, however large);
- :func:`move_to`: a planner's absolute next positions; a displacement longer than the
  reach is scaled onto the speed circle.

A move that would end inside the ``rho_i`` disk then goes to the nearest feasible point
(:func:`activetrack.kinematics.geometry.project_feasible`); a sensor with ``r_i = 0`` stays.

Both tests carry a relative tolerance of 1e-12, so that a planner's exact boundary point
(on the speed circle or on the ``rho`` circle, up to rounding) passes unchanged.
:func:`actions_to_reach` is the inverse of :func:`apply_actions`, for users who need the
actions behind a planner's positions (for example imitation labels).

The functions are pure and broadcast over leading batch axes (sensor axis second to last);
the arithmetic is compiled, one sensor at a time (:mod:`activetrack.kinematics._kernels`).
"""

from __future__ import annotations

import numpy as np

from activetrack._jit import as_rows, per_sensor_rows
from activetrack.kinematics import _kernels as mk
from activetrack.linalg2 import as_complex
from activetrack.validation import FloatArray

#: Relative tolerance of the unit-disk and minimum-distance tests.
TOL = mk.TOL
_LONG, _INSIDE = mk.LONG, mk.INSIDE


def keep_distance(
    new: FloatArray, sensors: FloatArray, target_pred: FloatArray, r: FloatArray, rho: FloatArray
) -> tuple[FloatArray, np.ndarray]:
    """Return ``(positions, projected)``: moves within reach pushed out of the ``rho`` disks.

    ``new`` (..., M, 2) must lie within reach of ``sensors``; ``projected`` (..., M) marks
    the moves that ended inside their disk and were moved to the nearest feasible point.
    ``target_pred`` is one predicted target (..., 2), or K of them (..., K, 2): then a sensor
    keeps ``rho`` from every one (:func:`activetrack.kinematics.feasible_set.project`).
    """
    new = np.asarray(new, np.float64)
    if target_pred.ndim == new.ndim:
        return _keep_distances(new, sensors, target_pred, r, rho)
    batch, m = new.shape[:-2], new.shape[-2]
    out = np.empty(new.shape)
    inside = np.empty(new.shape[:-1], bool)
    mk.keep_rows(
        as_rows(new, batch, (m, 2)), as_rows(sensors, batch, (m, 2)),
        as_rows(target_pred, batch, (2,)), per_sensor_rows(r, batch, m),
        per_sensor_rows(rho, batch, m),
        out.reshape(-1, m, 2), inside.reshape(-1, m),
    )  # fmt: skip
    return out, inside


def _moves(x: FloatArray, sensors: FloatArray, r: FloatArray, absolute: bool) -> FloatArray:
    """Return positions within reach (:func:`activetrack.kinematics._kernels.moves_rows`)."""
    x = np.asarray(x, np.float64)
    batch, m = x.shape[:-2], x.shape[-2]
    out = np.empty(x.shape)
    mk.moves_rows(
        as_rows(x, batch, (m, 2)), as_rows(sensors, batch, (m, 2)), per_sensor_rows(r, batch, m),
        absolute, out.reshape(-1, m, 2),
    )  # fmt: skip
    return out


def _keep_distances(
    new: FloatArray, sensors: FloatArray, targets: FloatArray, r: FloatArray, rho: FloatArray
) -> tuple[FloatArray, np.ndarray]:
    """:func:`keep_distance` for K predicted targets ``targets`` (..., K, 2)."""
    from activetrack.kinematics import feasible_set  # noqa: PLC0415 (only several-target scenarios)

    rho = np.asarray(rho, dtype=np.float64)
    dist = np.abs(as_complex(new[..., None, :, :] - targets[..., :, None, :]))  # (..., K, M)
    near = dist < rho[..., None, :] * _INSIDE
    if not np.count_nonzero(near):  # the common case: nothing to project
        return new, np.zeros(new.shape[:-1], dtype=bool)
    inside = np.any(near, axis=-2)
    rho = np.broadcast_to(rho, inside.shape)
    if np.count_nonzero(inside):
        r = np.broadcast_to(np.asarray(r, dtype=np.float64), inside.shape)
        inside &= r > 0.0  # a sensor that cannot move (r = 0) stays, even inside
        each = np.broadcast_to(targets[..., None, :, :], (*new.shape[:-1], *targets.shape[-2:]))
        # Only the moves that ended inside are projected (the projection is elementwise,
        # so a sensor's result does not depend on which others are projected with it).
        sensors = np.broadcast_to(sensors, new.shape)
        new = np.array(new)  # a copy: the caller's array stays as it was
        new[inside] = feasible_set.project(
            new[inside], sensors[inside], r[inside], each[inside], rho[inside]
        )
    return new, inside


def apply_actions(
    actions: FloatArray,
    sensors: FloatArray,
    target_pred: FloatArray,
    r: FloatArray,
    rho: FloatArray,
) -> tuple[FloatArray, np.ndarray]:
    """Return ``(next_positions, projected)`` for actions in units of the reach.

    Shapes: ``actions`` and ``sensors`` (..., M, 2), ``target_pred`` (..., 2), ``r`` and
    ``rho`` broadcastable to (..., M). ``projected`` (..., M) marks the moves that were
    moved out of the ``rho`` disk. Inputs are not validated (finite values assumed).
    """
    return keep_distance(_moves(actions, sensors, r, False), sensors, target_pred, r, rho)


def move_to(
    positions: FloatArray,
    sensors: FloatArray,
    target_pred: FloatArray,
    r: FloatArray,
    rho: FloatArray,
) -> tuple[FloatArray, np.ndarray]:
    """Return ``(next_positions, projected)`` for proposed absolute next positions.

    A displacement longer than ``r_i (1 + TOL)`` is scaled onto the speed circle, then the
    ``rho`` rule applies; feasible positions (a planner's) come back unchanged. Shapes as
    in :func:`apply_actions`; inputs are not validated.
    """
    return keep_distance(_moves(positions, sensors, r, True), sensors, target_pred, r, rho)


def actions_to_reach(next_positions: FloatArray, sensors: FloatArray, r: FloatArray) -> FloatArray:
    """Return float64 actions that move ``sensors`` to ``next_positions`` through the env.

    The inverse of :func:`apply_actions` for positions within reach and outside the
    ``rho`` disks (a planner's output): ``a = (p_next - p) / r``, its norm capped at 1
    only beyond ``1 + 1e-12``. Floating-point rounding of ``p + r a`` is then corrected
    so that :func:`apply_actions` gives ``next_positions`` bit for bit whenever a float
    action can (sensors with ``r = 0`` get a zero action). Batched like
    :func:`apply_actions`.
    """
    next_positions = np.asarray(next_positions, dtype=np.float64)
    sensors = np.asarray(sensors, dtype=np.float64)
    r = np.broadcast_to(np.asarray(r, dtype=np.float64), sensors.shape[:-1])[..., None]
    moving = r > 0.0
    safe = np.where(moving, r, 1.0)
    a = np.where(moving, (next_positions - sensors) / safe, 0.0)
    norm = np.abs(as_complex(a))[..., None]  # the same norm as in apply_actions
    capped = norm > _LONG
    if capped.any():
        a = np.where(capped, a / np.where(capped, norm, 1.0), a)
    free = moving & ~capped
    for _ in range(8):
        err = next_positions - (sensors + a * r)
        wrong = free & (err != 0.0)
        if not wrong.any():
            break
        # Step by the residual, and by at least one ulp towards it (tiny residuals).
        stepped = a + err / safe
        ulp = np.nextafter(a, np.where(err > 0.0, np.inf, -np.inf))
        towards = np.where(err > 0.0, np.maximum(stepped, ulp), np.minimum(stepped, ulp))
        a = np.where(wrong, towards, a)
    return a
