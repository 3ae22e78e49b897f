"""Extended Kalman filter for range-bearing target tracking, eq. (3), (5)-(11).

The measurement Jacobian has the block structure ``H = [H_e, 0]`` of eq. (6): only the
target position is observed. The update of eq. (11) is therefore computed with 2x2
algebra only, exactly (no 2M x 2M innovation matrix), in square-root form so that the
covariance stays symmetric positive definite by construction:

- ``Y = H_e^T R^{-1} H_e = sum_i h_i R_i^{-1} h_i^T`` (the measurement information, eq. 12)
  and ``b = H_e^T R^{-1} nu``;
- ``P11 = L L^T`` (2x2 Cholesky), ``K = L^T Y L``, ``I + K = M M^T``; by the Woodbury
  identity the Kalman gain of eq. (11) gives ``P11+ = L (I + K)^{-1} L^T`` and
  ``x+ = x + P[:, :2] L^{-T} (I + K)^{-1} L^T b``;
- ``P+ = Z Z^T + blockdiag(0, S22)`` with ``Z = P[:, :2] L^{-T} M^{-T}`` and
  ``S22 = P22 - F F^T``, ``F = P21 L^{-T}``: the prior's Schur complement (the covariance
  of velocity etc. given the position, which a position measurement leaves unchanged).

This equals the textbook ``P - K S K^T`` and the Joseph form ``(I - K H) P (I - K H)^T +
K R K^T`` in exact arithmetic, but is computed as a sum of two positive semidefinite terms
(a Gram matrix with the nonsingular top block ``L M^{-T}``, and the prior's Schur
complement), never as a difference: the expanded Joseph form subtracts and lost
definiteness for large process noise. Every clamp in the code only rounds a quantity that
is nonnegative in exact arithmetic up to zero (or, for ``P11``'s conditional variance, up
to its rounding level), so ``L`` and ``M`` are nonsingular and the result is exactly
symmetric.

Iterated EKF (``iterations`` > 1; beyond the paper, for tasks where a prediction can be
meters off when a target is measured again after a long gap, so that eq. (11)'s
linearization at the prediction is poor): the update is repeated with ``H`` and the
innovation relinearized at the last estimate ``x_i`` (``nu_i = z - h(x_i) - H_i (x - x_i)``;
Gauss-Newton on the posterior density of the prior and the measurements), from the same
prior, until the position moves less than :data:`ITERATION_TOL` (relative) or after
``iterations`` linearizations; the covariance is the last linearization's. Its fixed point
is the posterior mode; convergence is linear, slow where a sensor within a meter or two of
the target curves its measurement strongly across the posterior, so the cap bounds the
cost. With one iteration it is eq. (11) exactly.

Zero-distance rule: a sensor at (numerically) zero distance from the estimated target,
``|p_T_hat - p_S|^2 < ZERO_DISTANCE2``, contributes no information that step, exactly as
if it had been left out: its bearing is undefined there and its bearing information
``1 / (d^2 sigma_theta^2)`` unbounded. Near-distance rule: likewise a sensor so near that
its bearing information exceeds the prior's position information scale ``1 / tr(P11)``
:data:`~activetrack.models.measurement.INFORMATION_RATIO_MAX` times (``d^2 < w_theta tr(P11) /
INFORMATION_RATIO_MAX``; about 1e-4 m in the presets): one such update would shrink the
position covariance by more than float64 keeps positive definite (the ratio the
scenarios already bound for the range information), and a linearization that near the
estimate means nothing. Sensors left out of an update (``mask`` False)
contribute no information either. Bearing innovations are wrapped to ``[-pi, pi)``.
:func:`update` broadcasts over leading batch axes; the arithmetic is compiled, one filter
at a time (:mod:`activetrack.estimation._kernels`), and shared by the single and the batched
environment; :class:`ExtendedKalmanFilter` is a small validated stateful wrapper around it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from activetrack._jit import as_rows, per_sensor_rows
from activetrack.estimation import _kernels as ek
from activetrack.estimation._kernels import ITERATION_TOL as ITERATION_TOL  # re-exported
from activetrack.linalg2 import inv2
from activetrack.models import sensor_models
from activetrack.models.motion import LinearMotionModel
from activetrack.models.motion import predict as predict  # re-exported: eq. (3)
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
    *,
    models: FloatArray | None = None,
    weights: tuple[FloatArray, FloatArray] | None = None,
    pose_cov: FloatArray | None = None,
    iterations: int = 1,
) -> tuple[FloatArray, FloatArray]:
    """Return the EKF posterior ``(x(k+1|k+1), P(k+1|k+1))`` of eq. (11), batched, unchecked.

    Other sensor models (:mod:`activetrack.models.sensor_models`): ``models`` (..., M) codes and
    ``weights = (w_d, w_theta)`` (zero for a component a sensor does not measure; then the
    variances are not read); ``pose_cov`` (..., M, 2, 2): the sensors' position fixes are
    uncertain and the measurement noise becomes ``R + H_s Sigma H_s^T``
    (:func:`activetrack.models.sensor_models.update_terms`). Without ``pose_cov`` the compiled
    kernels of :mod:`activetrack.estimation._kernels` compute everything, with the weights in place
    of ``1/sigma^2`` (a zero weight removes a component exactly; its ``z`` entry must be
    finite); with it, the terms come from ``update_terms`` and the posterior from the
    same kernels.

    Shapes: ``x`` (..., n), ``P`` (..., n, n), ``z`` and ``sensor_pos`` (..., M, 2),
    variances and ``orientation`` broadcastable to (..., M), ``mask`` (..., M) bool or None.
    ``P`` must be symmetric (as :func:`predict` returns it); the posterior is then exactly
    symmetric. A sensor at zero distance from the estimate contributes no information (see
    the module docstring). ``iterations`` > 1: the iterated EKF (module docstring), at most
    that many linearizations, each filter until its own position settles; 1 (the paper's
    EKF) is eq. (11).
    """
    x, P = np.asarray(x, np.float64), np.asarray(P, np.float64)
    z, sensor_pos = np.asarray(z, np.float64), np.asarray(sensor_pos, np.float64)
    n, m = x.shape[-1], sensor_pos.shape[-2]
    batch = x.shape[:-1]
    if not (P.shape[:-2] == z.shape[:-2] == sensor_pos.shape[:-2] == batch):  # (rare)
        batch = np.broadcast_shapes(batch, P.shape[:-2], z.shape[:-2], sensor_pos.shape[:-2])
    wd, wt = weights if weights is not None else (1.0 / sigma_d2, 1.0 / sigma_theta2)
    xf, Pf = as_rows(x, batch, (n,)), as_rows(P, batch, (n, n))
    x_out, P_out = np.empty(xf.shape), np.empty(Pf.shape)
    if pose_cov is not None:  # the terms in NumPy, on the arrays as given
        if mask is not None:
            wd, wt = wd * mask, wt * mask
        codes = 0 if models is None else models
        args = (z, sensor_pos, codes, wd, wt, orientation, pose_cov)
        _update_with_poses(xf, Pf, batch, args, int(iterations), x_out, P_out)
        return x_out.reshape(batch + (n,)), P_out.reshape(batch + (n, n))
    zf, sf = as_rows(z, batch, (m, 2)), as_rows(sensor_pos, batch, (m, 2))
    per = [per_sensor_rows(v, batch, m, np.float64) for v in (wd, wt, orientation)]
    per.append(np.ones((1, m), bool) if mask is None else per_sensor_rows(mask, batch, m, np.bool_))
    ek.update_rows(xf, Pf, zf, sf, *per, int(iterations), x_out, P_out)
    return x_out.reshape(batch + (n,)), P_out.reshape(batch + (n, n))


def _update_with_poses(
    x: FloatArray, P: FloatArray, batch: tuple[int, ...], args: tuple, iterations: int,
    x_out: FloatArray, P_out: FloatArray,
) -> None:  # fmt: skip
    """Write the posteriors of filters (rows ``x``, ``P`` of a batch of shape ``batch``)
    whose sensors' positions are uncertain: the terms of
    :func:`activetrack.models.sensor_models.update_terms` on ``args`` = ``(z, sensors, codes, w_d,
    w_theta, orientation, pose_cov)`` as given (broadcasting over ``batch``), the kernels'
    posterior; each filter relinearized until its position settles, at most ``iterations``
    linearizations."""
    every = np.arange(x.shape[0])
    m = np.shape(args[1])[-2]
    tails = ((m, 2), (m, 2), (m,), (m,), (m,), (m,), (m, 2, 2))

    def terms(rows: np.ndarray, lin: FloatArray) -> FloatArray:
        if batch == ():  # one filter: the arrays as given
            sub = args
            lin = lin[0]
        else:  # the rows' values of every batched argument
            sub = tuple(
                a if np.ndim(a) <= len(t) else as_rows(a, batch, t, np.asarray(a).dtype)[rows]
                for a, t in zip(args, tails, strict=True)
            )
        Yi, bi = sensor_models.update_terms(sub[0], lin, *sub[1:])
        Y, b = Yi.sum(axis=-3), bi.sum(axis=-2)
        out = np.empty((rows.size, 5))
        out[:, 0], out[:, 1], out[:, 2] = Y[..., 0, 0], Y[..., 0, 1], Y[..., 1, 1]
        out[:, 3:] = b
        return out

    active = every
    ek.posterior_rows(x, P, terms(active, x[:, :2]), active, False, x_out, P_out)
    for _ in range(iterations - 1):
        moving = ek.posterior_rows(
            x, P, terms(active, x_out[active, :2]), active, True, x_out, P_out
        )
        active = active[moving]
        if active.size == 0:
            break


def position_nees(x_true: FloatArray, x_est: FloatArray, P: FloatArray) -> FloatArray:
    """Return the normalized estimation error squared of the position, ``e^T P11^{-1} e``."""
    e = x_true[..., :2] - x_est[..., :2]
    return np.einsum("...i,...ij,...j->...", e, inv2(P[..., :2, :2]), e)


class ExtendedKalmanFilter:
    """A validated, stateful EKF over a :class:`~activetrack.models.motion.LinearMotionModel`.

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

        ``sensors`` optionally selects a subset: a boolean mask of shape (M,) or indices. A
        sensor at zero distance from the estimate contributes nothing (module docstring).
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
        self.x, self.P = update(self.x, self.P, z, sensor_pos, sd2, st2, phi, mask)
