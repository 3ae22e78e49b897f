"""Extended Kalman filter for range-bearing target tracking, eq. (3), (5)-(11).

The measurement Jacobian has the block structure ``H = [H_e, 0]`` of eq. (6): only the
target position is observed. The update of eq. (11) is therefore computed with 2x2
algebra only, exactly (no 2M x 2M innovation matrix), and in Joseph form so that the
covariance stays symmetric positive definite:

- ``Y = H_e^T R^{-1} H_e = sum_i h_i R_i^{-1} h_i^T`` (the measurement information, eq. 12),
- ``N = (I + P11 Y)^{-1}``; then by the Woodbury identity
  ``K nu = P[:, :2] N^T H_e^T R^{-1} nu``, ``K H = P[:, :2] N^T Y E`` and
  ``K R K^T = P[:, :2] N^T Y N P[:, :2]^T``,
- ``P+ = (I - K H) P (I - K H)^T + K R K^T`` (Joseph form of eq. 11).

Sensors left out of an update (``mask`` False) contribute no information. Bearing
innovations are wrapped to ``[-pi, pi)``. The pure functions broadcast over leading batch
axes and are shared by the single and the batched environment; :class:`ExtendedKalmanFilter`
is a small validated stateful wrapper around them.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from activetrack import measurement
from activetrack.linalg2 import inv2, symmetrize
from activetrack.motion import LinearMotionModel
from activetrack.motion import predict as predict  # re-exported: eq. (3)
from activetrack.validation import FloatArray, as_finite, per_sensor, spd


def update(
    x: FloatArray,
    P: FloatArray,
    z: FloatArray,
    sensor_pos: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    orientation: FloatArray | float = 0.0,
    mask: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Return the EKF posterior ``(x(k+1|k+1), P(k+1|k+1))`` of eq. (11), batched, unchecked.

    Shapes: ``x`` (..., n), ``P`` (..., n, n), ``z`` and ``sensor_pos`` (..., M, 2),
    variances and ``orientation`` broadcastable to (..., M), ``mask`` (..., M) bool or None.
    """
    pos = x[..., :2]
    H = measurement.jacobian(pos, sensor_pos)  # (..., M, 2, 2): rows h_d^T, h_theta^T
    nu = z - measurement.range_bearing(pos, sensor_pos, orientation)
    nu[..., 1] = measurement.wrap_angle(nu[..., 1])
    w = np.stack(
        np.broadcast_arrays(1.0 / np.asarray(sigma_d2), 1.0 / np.asarray(sigma_theta2)), -1
    )
    if mask is not None:
        w = w * np.asarray(mask, dtype=np.float64)[..., None]
    w = np.broadcast_to(w, nu.shape)
    # Y = sum_i H_i^T R_i^{-1} H_i and b = sum_i H_i^T R_i^{-1} nu_i.
    Y = np.einsum("...mki,...mk,...mkj->...ij", H, w, H)
    b = np.einsum("...mki,...mk->...i", H, w * nu)
    Pc = P[..., :, :2]
    eye2 = np.eye(2)
    N = inv2(eye2 + P[..., :2, :2] @ Y)
    Nt = np.swapaxes(N, -1, -2)
    x_post = x + np.einsum("...ij,...j->...i", Pc @ Nt, b)
    L = np.broadcast_to(np.eye(x.shape[-1]), P.shape).copy()
    L[..., :, :2] -= Pc @ (Nt @ Y)
    P_post = L @ P @ np.swapaxes(L, -1, -2) + Pc @ (Nt @ Y @ N) @ np.swapaxes(Pc, -1, -2)
    return x_post, symmetrize(P_post)


def position_nees(x_true: FloatArray, x_est: FloatArray, P: FloatArray) -> FloatArray:
    """Return the normalized estimation error squared of the position, ``e^T P11^{-1} e``."""
    e = x_true[..., :2] - x_est[..., :2]
    return np.einsum("...i,...ij,...j->...", e, inv2(P[..., :2, :2]), e)


class ExtendedKalmanFilter:
    """A validated, stateful EKF over a :class:`~activetrack.motion.LinearMotionModel`.

    Attributes ``x`` and ``P`` hold the current estimate; :attr:`position` and
    :attr:`position_cov` expose the position block used by the planners (Lemma 1).
    """

    def __init__(self, model: LinearMotionModel, x0: ArrayLike, P0: ArrayLike) -> None:
        n = model.dim
        self.model = model
        self.x = as_finite("x0", x0, (n,)).copy()
        self.P = spd("P0", P0).copy()
        if self.P.shape != (n, n):
            raise ValueError(f"P0 must have shape ({n}, {n}), got {self.P.shape}")

    @property
    def position(self) -> FloatArray:
        """Return the estimated target position, shape (2,)."""
        return self.x[:2].copy()

    @property
    def position_cov(self) -> FloatArray:
        """Return the 2x2 position block ``P_11`` of the covariance."""
        return self.P[:2, :2].copy()

    def predict(self) -> None:
        """Propagate the estimate one step, eq. (3)."""
        self.x, self.P = predict(self.x, self.P, self.model.Phi, self.model.Q)

    def update(
        self,
        z: ArrayLike,
        sensor_pos: ArrayLike,
        sigma_d2: ArrayLike,
        sigma_theta2: ArrayLike,
        orientation: ArrayLike = 0.0,
        sensors: ArrayLike | None = None,
    ) -> None:
        """Update with measurements ``z`` (M, 2) from sensors at ``sensor_pos`` (M, 2), eq. (11).

        ``sensors`` optionally selects a subset: a boolean mask of shape (M,) or indices.
        """
        sensor_pos = as_finite("sensor_pos", sensor_pos)
        if sensor_pos.ndim != 2 or sensor_pos.shape[1] != 2:
            raise ValueError(f"sensor_pos must have shape (M, 2), got {sensor_pos.shape}")
        m = sensor_pos.shape[0]
        z = as_finite("z", z, (m, 2))
        sd2 = per_sensor("sigma_d2", sigma_d2, m)
        st2 = per_sensor("sigma_theta2", sigma_theta2, m)
        phi = np.broadcast_to(as_finite("orientation", orientation), (m,))
        mask = np.ones(m, dtype=bool)
        if sensors is not None:
            sel = np.asarray(sensors)
            mask = np.zeros(m, dtype=bool)
            if sel.dtype == bool:
                if sel.shape != (m,):
                    raise ValueError(f"sensors mask must have shape ({m},), got {sel.shape}")
                mask = sel
            else:
                if np.any((sel < 0) | (sel >= m)):
                    raise ValueError(f"sensors indices must lie in [0, {m - 1}], got {sel}")
                mask[sel] = True
        dist = np.hypot(*(sensor_pos - self.x[:2]).T)
        if np.any(dist[mask] == 0.0):
            raise ValueError(
                "sensor_pos must differ from the estimated target position (zero distance)"
            )
        self.x, self.P = update(self.x, self.P, z, sensor_pos, sd2, st2, phi, mask)
