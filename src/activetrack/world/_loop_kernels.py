"""Compiled closed-loop arithmetic: target motion (eq. 2), measurements (eq. 4), the
prediction (eq. 3), and one copy's whole step, one copy at a time.

The kernels behind :func:`activetrack.world.tracking.move_target`,
:func:`activetrack.world.tracking.measure` and :func:`activetrack.models.motion.predict` (written
for one
target or one filter, looped over rows in compiled code), and :func:`advance_rows`, the
step of :class:`activetrack.world.World` for copies whose sensors know their positions and
track one target that every sensor measures, with no occluders: the sensors' moves
(eq. 13-16, :mod:`activetrack.kinematics._kernels`), the target's motion, the measurements,
the EKF update (eq. 11, :mod:`activetrack.estimation._kernels`), the prediction and the trace of
the posterior position covariance, all in one call; :func:`advance_observe_row` also
writes the agents' observations (the single environment's step). The other tasks run the
same kernels one stage at a time.

Rounding: each product is rounded and the sums run in index order, so results can differ
in the last bit from NumPy's matrix products (BLAS, with its own order and fused
multiply-adds); a distance is libm's ``hypot`` (``np.hypot``), which differs in the last
bit from NumPy's complex ``abs`` for many inputs.
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import inline_kernel, kernel
from activetrack.estimation import _kernels as ek
from activetrack.kinematics import _kernels as mk
from activetrack.kinematics import _unicycle_kernels as uk
from activetrack.models._motion_kernels import (
    move_target_into,
    predict_into,
)
from activetrack.world import _observation_kernels as obk


@kernel
def measure_point(tx, ty, sx, sy, phi, noise_d, noise_t, std_d, std_t, use_d, use_t):
    """Return one sensor's noisy ``(d, theta)`` (eq. 4) of the target at ``(tx, ty)`` from
    ``(sx, sy)`` with orientation ``phi``: the standard normals times the standard
    deviations added, the bearing wrapped to ``[-pi, pi)`` after the noise, and a component
    the sensor does not measure (``use_d``, ``use_t`` False) exactly 0."""
    dx, dy = tx - sx, ty - sy
    d = math.hypot(dx, dy) + noise_d * std_d
    t = ek.wrap((math.atan2(dy, dx) - phi) + noise_t * std_t)
    return (d if use_d else 0.0), (t if use_t else 0.0)


@kernel
def measure_into(tx, ty, sensors, orientation, std, uses, noise, out):
    """Write every sensor's :func:`measure_point` of one target into ``out`` (M, 2);
    ``noise`` (2M,) sensor-major, ``std`` (M, 2), ``uses`` (M, 2) bool."""
    for i in range(sensors.shape[0]):
        out[i, 0], out[i, 1] = measure_point(
            tx, ty, sensors[i, 0], sensors[i, 1], orientation[i], noise[2 * i],
            noise[2 * i + 1], std[i, 0], std[i, 1], uses[i, 0], uses[i, 1],
        )  # fmt: skip


@kernel
def measure_rows(positions, sensors, orientation, std, uses, noise, out):
    """Write the measurements of K targets at ``positions`` (B, K, 2) by sensors (B, M, 2)
    into ``out`` (B, K, M, 2); ``noise`` (B, 2MK) target-major."""
    m = sensors.shape[1]
    for b in range(positions.shape[0]):
        for k in range(positions.shape[1]):
            measure_into(
                positions[b, k, 0], positions[b, k, 1], sensors[b], orientation, std, uses,
                noise[b, 2 * m * k : 2 * m * (k + 1)], out[b, k],
            )  # fmt: skip


#: Columns of the per-sensor table of :func:`advance_row`: reach, minimum distance,
#: orientation, measurement noise standard deviations, whether the range and the bearing
#: are measured (1 or 0), the filter's weights ``(w_d, w_theta)``.
R, RHO, ORIENTATION, STD_D, STD_T, USE_D, USE_T, W_D, W_T = range(9)
TABLE_COLUMNS = 9


@inline_kernel
def advance_row(
    moves, absolute, sensors, x_true, x_pred, P_pred, noise, table, mats, sensors_out,
    projected, x_true_out, x_post, P_post, x_next, P_next, scratch, z, every,
):  # fmt: skip
    """Return ``(trace, n_projected)`` after one step of one copy (one target, known
    sensor positions, every sensor measures): the trace of the posterior position
    covariance and the number of moves pushed out of a ``rho`` disk; write the step: the
    sensors' moves (:func:`activetrack.kinematics._kernels.move_point` of the actions or
    absolute positions ``moves`` (M, 2), then :func:`activetrack.kinematics._kernels.keep_point`
    about the predicted target ``x_pred[:2]``) into ``sensors_out`` and ``projected``; the
    target's motion (:func:`move_target_into`, the first ``n`` standard normals of
    ``noise`` (n + 2M,)) into ``x_true_out``; the measurements from the new positions
    (:func:`measure_into`, the next ``2M``) into ``z`` (M, 2); the EKF posterior (eq. 11,
    :func:`activetrack.estimation._kernels.update_row`, every sensor: ``every`` (M,) True) into
    ``x_post``, ``P_post``; the prediction (:func:`predict_into`, ``scratch`` (n, n)) into
    ``x_next``, ``P_next``. ``table`` (M, :data:`TABLE_COLUMNS`) holds the sensors'
    constants, ``mats`` (3, n, n) the target's ``Phi``, noise factor and ``Q``."""
    tx, ty = x_pred[0], x_pred[1]
    count = 0
    for i in range(sensors.shape[0]):
        sx, sy, r = sensors[i, 0], sensors[i, 1], table[i, R]
        nx, ny = mk.move_point(moves[i, 0], moves[i, 1], sx, sy, r, absolute)
        px, py, hit = mk.keep_point(nx, ny, sx, sy, tx, ty, r, table[i, RHO])
        sensors_out[i, 0], sensors_out[i, 1], projected[i] = px, py, hit
        count += hit
    trace = advance_moved_row(
        x_true, x_pred, P_pred, noise, table, mats, sensors_out, x_true_out, x_post, P_post,
        x_next, P_next, scratch, z, every,
    )  # fmt: skip
    return trace, count


@inline_kernel
def advance_moved_row(
    x_true, x_pred, P_pred, noise, table, mats, sensors, x_true_out, x_post, P_post, x_next,
    P_next, scratch, z, every,
):  # fmt: skip
    """Return the trace of the posterior position covariance after the rest of
    :func:`advance_row`'s step, from the sensors' new positions ``sensors`` (M, 2): the
    target's motion, the measurements, the EKF update and the prediction (the arguments
    are :func:`advance_row`'s)."""
    n, m = x_true.shape[0], sensors.shape[0]
    Phi, F, Q = mats[0], mats[1], mats[2]
    move_target_into(Phi, F, x_true, noise[:n], x_true_out)
    tx, ty = x_true_out[0], x_true_out[1]
    for i in range(m):
        z[i, 0], z[i, 1] = measure_point(
            tx, ty, sensors[i, 0], sensors[i, 1], table[i, ORIENTATION],
            noise[n + 2 * i], noise[n + 2 * i + 1], table[i, STD_D], table[i, STD_T],
            table[i, USE_D] != 0.0, table[i, USE_T] != 0.0,
        )  # fmt: skip
    ek.update_row(
        x_pred, P_pred, z, sensors, table[:, W_D], table[:, W_T], table[:, ORIENTATION],
        every, 1, x_post, P_post,
    )  # fmt: skip
    predict_into(x_post, P_post, Phi, Q, x_next, P_next, scratch)
    return P_post[0, 0] + P_post[1, 1]


@kernel
def advance_rows(
    moves, absolute, sensors, x_true, x_pred, P_pred, noise, table, mats, sensors_out,
    projected, x_true_out, x_post, P_post, x_next, P_next, trace,
):  # fmt: skip
    """Write :func:`advance_row` of B copies (rows of ``moves`` (B, M, 2), ``sensors``,
    ``x_true``, ``x_pred``, ``P_pred``, ``noise``) into the rows of the outputs, the
    traces into ``trace`` (B,); return the number of moves pushed out of a ``rho`` disk."""
    n, m = x_true.shape[1], sensors.shape[1]
    scratch = np.empty((n, n))
    z = np.empty((m, 2))
    every = np.ones(m, np.bool_)
    count = 0
    for b in range(moves.shape[0]):
        trace[b], c = advance_row(
            moves[b], absolute, sensors[b], x_true[b], x_pred[b], P_pred[b], noise[b], table,
            mats, sensors_out[b], projected[b], x_true_out[b], x_post[b], P_post[b],
            x_next[b], P_next[b], scratch, z, every,
        )  # fmt: skip
        count += c
    return count


@kernel
def advance_unicycle_rows(
    actions, sensors, motion, x_true, x_pred, P_pred, noise, table, mats, v_min, v_max, w_max,
    dt, rho_inside, sensors_out, projected, x_true_out, x_post, P_post, x_next, P_next, trace,
    heading, pending,
):  # fmt: skip
    """Return the number of copies marked ``pending``, or -1 if a new position is not
    finite; write one step of B copies whose sensors are unicycles, from their positions
    ``sensors`` (B, M, 2), headings ``motion`` (B, M, 1) and normalized ``actions``
    (B, M, 2): each sensor's :func:`activetrack.kinematics._unicycle_kernels.arc_step` into
    ``sensors_out`` (B, M, 2) and ``heading`` (B, M, 1), and into ``projected`` (B, M)
    whether it ends closer than ``rho_inside`` (M,) to the predicted target
    ``x_pred[:, :2]``. A copy with such a move is marked in ``pending`` (B,) and not
    advanced: its moves are the caller's to project, then :func:`advance_listed_rows`
    advances it. Every other copy is advanced from its new positions by
    :func:`advance_moved_row` (the rest of :func:`advance_row`; the other arguments are
    its), its trace into ``trace`` (B,)."""
    n, m = x_true.shape[1], sensors.shape[1]
    scratch = np.empty((n, n))
    z = np.empty((m, 2))
    every = np.ones(m, np.bool_)
    count = 0
    for b in range(actions.shape[0]):
        tx, ty = x_pred[b, 0], x_pred[b, 1]
        hit = False
        for i in range(m):
            x, y, th = uk.arc_step(
                actions[b, i, 0], actions[b, i, 1], sensors[b, i, 0], sensors[b, i, 1],
                motion[b, i, 0], v_min, v_max, w_max, dt,
            )  # fmt: skip
            if not (math.isfinite(x) and math.isfinite(y)):
                return -1
            sensors_out[b, i, 0], sensors_out[b, i, 1], heading[b, i, 0] = x, y, th
            # (hypot only near the disk: far outside, the squared distance says it exactly)
            dx, dy, near = x - tx, y - ty, rho_inside[i] * (1.0 + 1e-9)
            inside = dx * dx + dy * dy <= near * near and math.hypot(dx, dy) < rho_inside[i]
            projected[b, i] = inside
            hit = hit or inside
        pending[b] = hit
        if hit:
            count += 1
            continue
        trace[b] = advance_moved_row(
            x_true[b], x_pred[b], P_pred[b], noise[b], table, mats, sensors_out[b],
            x_true_out[b], x_post[b], P_post[b], x_next[b], P_next[b], scratch, z, every,
        )  # fmt: skip
    return count


@kernel
def advance_listed_rows(
    rows, x_true, x_pred, P_pred, noise, table, mats, sensors, x_true_out, x_post, P_post,
    x_next, P_next, trace,
):  # fmt: skip
    """Write :func:`advance_moved_row` of the copies ``rows`` (indices), from their new
    positions ``sensors`` (B, M, 2), into those rows of the outputs (the arguments are
    :func:`advance_rows`'), the traces into ``trace`` (B,)."""
    n, m = x_true.shape[1], sensors.shape[1]
    scratch = np.empty((n, n))
    z = np.empty((m, 2))
    every = np.ones(m, np.bool_)
    for b in rows:
        trace[b] = advance_moved_row(
            x_true[b], x_pred[b], P_pred[b], noise[b], table, mats, sensors[b],
            x_true_out[b], x_post[b], P_post[b], x_next[b], P_next[b], scratch, z, every,
        )  # fmt: skip


@kernel
def advance_observe_row(
    moves, absolute, sensors, x_true, x_pred, P_pred, noise, table, mats, sensors_out,
    projected, x_true_out, x_post, P_post, x_next, P_next, scratch, z, every, constants, dt,
    L, extended, detected, target, sensor, order, obs,
):  # fmt: skip
    """:func:`advance_row`, then every agent's observation of the new state into ``obs``
    (M, D) float32 (:func:`activetrack.world._observation_kernels.features_row` of the prediction
    ``x_next``, ``P_next`` and the new positions, in the agents' views
    :func:`activetrack.world._observation_kernels.windows_row`; ``target``, ``sensor`` its work
    arrays, no detection flags; the unbounded entries clipped as there): the single
    environment's step in one call."""
    out = advance_row(
        moves, absolute, sensors, x_true, x_pred, P_pred, noise, table, mats, sensors_out,
        projected, x_true_out, x_post, P_post, x_next, P_next, scratch, z, every,
    )  # fmt: skip
    n = x_next.shape[0]
    obk.features_row(
        x_next.reshape(1, n), P_next.reshape(1, n, n), sensors_out, constants, dt, L, extended,
        detected, 0, target, sensor,
    )  # fmt: skip
    obk.windows_row(target, sensor, order, obs)
    return out
