"""Range-bearing measurement model, eq. (4)-(10).

Sensor ``i`` at ``p_S_i`` with orientation ``phi_i`` measures the distance and bearing
to the target at ``p_T``: ``d_i = ||p_T - p_S_i||``,
``theta_i = atan2(dy, dx) - phi_i`` (eq. 4), with noise ``R_i = diag(sigma_d_i^2,
sigma_theta_i^2)``. The Jacobian rows with respect to the target position are eq. (9):
``h_d = -p / ||p||`` and ``h_theta = J p / (p^T p)``, with ``p = p_S - p_T`` (eq. 10) and
``J = C(-pi/2)``. All functions broadcast over leading batch axes; the sensor axis is the
second to last.
"""

from __future__ import annotations

import numpy as np

from activetrack.linalg2 import as_complex
from activetrack.validation import FloatArray

#: Squared distance (m^2) below which a sensor is at the target: no information (1e-100 m).
ZERO_DISTANCE2 = 1e-200
#: Largest ratio of one sensor's bearing information ``w_theta / d^2`` to the prior's
#: position information scale ``1 / tr(P11)`` that the EKF takes (the near-distance rule of
#: :mod:`activetrack.estimation.ekf`), the same bound the scenarios put on the range information
#: (``scenarios.INFORMATION_RATIO_MAX``): a closer sensor's bearing would shrink the
#: position covariance beyond what float64 keeps positive definite.
INFORMATION_RATIO_MAX = 1e10

#: ``J = C(-pi/2)`` of eq. (9).
J = np.array([[0.0, 1.0], [-1.0, 0.0]])
_TWO_PI = 2.0 * np.pi


def wrap_angle(angle: FloatArray | float, *, inplace: bool = False) -> FloatArray:
    """Return ``angle`` wrapped to ``[-pi, pi)``: a new array, or with ``inplace`` (for a
    float64 array the caller owns) ``angle`` itself, wrapped in place."""
    a = np.asarray(angle, dtype=np.float64)
    # Bearings and innovations are mostly in range already: one test costs fewer NumPy
    # calls than the wrap itself for the single environment's few angles.
    if a.ndim and not np.count_nonzero(np.abs(a) >= np.pi):
        return a if inplace else a.copy()
    # floor is several times faster than np.mod on large arrays
    wrapped = a - _TWO_PI * np.floor((a + np.pi) / _TWO_PI)
    if inplace and a.ndim:
        a[...] = wrapped
        return a
    return wrapped


def range_bearing(
    target_pos: FloatArray,
    sensor_pos: FloatArray,
    orientation: FloatArray | float = 0.0,
    *,
    wrap: bool = True,
) -> FloatArray:
    """Return noise-free ``[d_i, theta_i]`` of eq. (4), shape (..., M, 2).

    ``target_pos`` has shape (..., 2), ``sensor_pos`` (..., M, 2), ``orientation`` (..., M).
    At zero distance the bearing is ``atan2(0, 0) - phi_i = -phi_i`` (finite; the EKF
    ignores such a sensor). The bearing is wrapped to ``[-pi, pi)`` unless ``wrap=False``
    (then it is ``atan2(dy, dx) - phi_i``, for callers that add noise and wrap once).
    """
    delta = as_complex(target_pos[..., None, :] - sensor_pos)
    out = np.empty(delta.shape + (2,))
    np.abs(delta, out=out[..., 0])
    np.subtract(np.arctan2(delta.imag, delta.real), orientation, out=out[..., 1])
    if wrap:
        wrap_angle(out[..., 1], inplace=True)
    return out


def jacobian(target_pos: FloatArray, sensor_pos: FloatArray) -> FloatArray:
    """Return the per-sensor Jacobians ``[h_d^T; h_theta^T]`` of eq. (9), shape (..., M, 2, 2).

    Derivatives are with respect to the target position; the velocity columns of eq. (6)
    are zero and left out. A sensor at zero distance (``d^2 < ZERO_DISTANCE2``) gets zero
    rows: it carries no information (the EKF's zero-distance rule), never NaN.
    """
    p = sensor_pos - target_pos[..., None, :]
    n2 = p[..., 0] ** 2 + p[..., 1] ** 2
    # Zero distance (the EKF's rule): no information, so
    # zero rows instead of 0/0; any positive stand-in distance gives them with p = 0.
    zero = n2 < ZERO_DISTANCE2
    if np.any(zero):
        p = np.where(zero[..., None], 0.0, p)
        n2 = np.where(zero, 1.0, n2)
    n = np.sqrt(n2)
    h_d = -p / n[..., None]
    h_theta = np.stack([p[..., 1], -p[..., 0]], axis=-1) / n2[..., None]
    return np.stack([h_d, h_theta], axis=-2)


def sample(
    target_pos: FloatArray,
    sensor_pos: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    rng: np.random.Generator,
    orientation: FloatArray | float = 0.0,
) -> FloatArray:
    """Return noisy measurements of eq. (4), shape (..., M, 2), bearing wrapped."""
    z = range_bearing(target_pos, sensor_pos, orientation)
    std = np.stack(np.broadcast_arrays(np.sqrt(sigma_d2), np.sqrt(sigma_theta2)), axis=-1)
    z = z + rng.standard_normal(z.shape) * std
    wrap_angle(z[..., 1], inplace=True)
    return z
