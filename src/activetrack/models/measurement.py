"""What every measurement model shares: the bearing wrap and the near-distance bounds.

Sensor ``i`` at ``p_S_i`` with orientation ``phi_i`` measures the distance and bearing
to the target at ``p_T``: ``d_i = ||p_T - p_S_i||``, ``theta_i = atan2(dy, dx) - phi_i``
(eq. 4), with noise ``R_i = diag(sigma_d_i^2, sigma_theta_i^2)``. The measurements, their
Jacobians (eq. 9-10) and information of every sensor model are in
:mod:`activetrack.models.sensor_models`; this module holds the angle wrap of the bearing
and the distances below which a sensor's measurement carries no (or bounded) information.
"""

from __future__ import annotations

import numpy as np

from activetrack.validation import FloatArray

#: Squared distance (m^2) below which a sensor is at the target: no information (1e-100 m).
ZERO_DISTANCE2 = 1e-200
#: Largest ratio of one sensor's bearing information ``w_theta / d^2`` to the prior's
#: position information scale ``1 / tr(P11)`` that the EKF takes (the near-distance rule of
#: :mod:`activetrack.estimation.ekf`), the same bound the scenarios put on the range information
#: (``scenarios.INFORMATION_RATIO_MAX``): a closer sensor's bearing would shrink the
#: position covariance beyond what float64 keeps positive definite.
INFORMATION_RATIO_MAX = 1e10

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
