"""Sensor motion of the tracking environments: actions to next positions, eq. (13)-(16).

An agent's action ``a_i`` is its displacement as a fraction of its reach
``r_i = vmax_i dt`` (eq. 13): ``p_S_i(k+1) = p_S_i(k) + r_i a_i``. Vectors longer than 1
are first scaled onto the unit disk, so the speed limit (eq. 13/15) always holds. A move
that would end inside the ``rho_i`` disk around the *predicted* target
``p_T(k+1|k)`` (eq. 14/16) goes to the nearest feasible point
(:func:`activetrack.geometry.project_feasible`).

Both tests carry a relative tolerance of 1e-12, so that a planner's exact boundary point
(on the speed circle or on the ``rho`` circle, up to rounding) passes unchanged: an expert
reproduces its planned positions bit for bit through :func:`actions_to_reach`.

The functions are pure and broadcast over leading batch axes (sensor axis second to
last): the single and the batched environment share them.
"""

from __future__ import annotations

import numpy as np

from activetrack.geometry import project_feasible
from activetrack.linalg2 import as_complex
from activetrack.validation import FloatArray

#: Relative tolerance of the unit-disk and minimum-distance tests.
TOL = 1e-12
_LONG = 1.0 + TOL
_INSIDE = 1.0 - TOL


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
    a = np.asarray(actions, dtype=np.float64)
    norm = np.abs(as_complex(a))
    long = norm > _LONG
    if np.count_nonzero(long):  # outside the unit disk: keep the direction, cap the length
        a = a / np.where(long, norm, 1.0)[..., None]
    r = np.asarray(r, dtype=np.float64)
    new = sensors + a * r[..., None]
    q = new - target_pred[..., None, :]
    inside = np.abs(as_complex(q)) < np.asarray(rho, dtype=np.float64) * _INSIDE
    if np.count_nonzero(inside):
        inside &= r > 0.0  # a sensor that cannot move (r = 0) stays, even inside rho
        c = sensors - target_pred[..., None, :]
        fixed = project_feasible(q, c, r, rho) + target_pred[..., None, :]
        new = np.where(inside[..., None], fixed, new)
    return new, inside


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
