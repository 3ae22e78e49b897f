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
``1 / (d^2 sigma_theta^2)`` unbounded. Sensors left out of an update (``mask`` False)
contribute no information either. Bearing innovations are wrapped to ``[-pi, pi)``. The
pure functions broadcast over leading batch axes and are shared by the single and the
batched environment; :class:`ExtendedKalmanFilter` is a small validated stateful wrapper
around them.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from activetrack import measurement, sensor_models
from activetrack.linalg2 import as_complex, inv2
from activetrack.measurement import ZERO_DISTANCE2
from activetrack.motion import LinearMotionModel
from activetrack.motion import predict as predict  # re-exported: eq. (3)
from activetrack.validation import FloatArray, as_finite, per_sensor, spd

#: Floor of the conditional variance ``p11 - p01^2 / p00`` of a prior's position block,
#: relative to ``p11``: the rounding level of the stored entries, so the 2x2 Cholesky factor
#: of a prior that is positive definite in floating point is never singular.
_FLOOR = 1e-15
#: The iterated EKF stops when the position moves less than this (times 1 + |position|).
ITERATION_TOL = 1e-10


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

    Other sensor models (:mod:`activetrack.sensor_models`): ``models`` (..., M) codes and
    ``weights = (w_d, w_theta)`` (zero for a component a sensor does not measure; then the
    variances are not read); ``pose_cov`` (..., M, 2, 2): the sensors' position fixes are
    uncertain and the measurement noise becomes ``R + H_s Sigma H_s^T``
    (:func:`activetrack.sensor_models.update_terms`). Without ``pose_cov`` the arithmetic
    below applies, with the weights in place of ``1/sigma^2`` (a zero weight removes a
    component exactly; its ``z`` entry must be finite).

    Shapes: ``x`` (..., n), ``P`` (..., n, n), ``z`` and ``sensor_pos`` (..., M, 2),
    variances and ``orientation`` broadcastable to (..., M), ``mask`` (..., M) bool or None.
    ``P`` must be symmetric (as :func:`predict` returns it); the posterior is then exactly
    symmetric. A sensor at zero distance from the estimate contributes no information (see
    the module docstring). Written with elementwise 2x2 algebra (the sensor offsets as
    complex numbers, so one filter costs few NumPy calls) because the batched environment
    runs it on thousands of filters per call and the single environment once per step.

    ``iterations`` > 1: the iterated EKF (module docstring), at most that many
    linearizations; 1 (the paper's EKF) is the arithmetic above, unchanged.
    """
    args = (z, sensor_pos, sigma_d2, sigma_theta2, orientation, mask, models, weights, pose_cov)
    x_post, P_post = _posterior(x, P, *_terms(x[..., :2], *args))
    if iterations == 1:
        return x_post, P_post
    if x.ndim != 2:  # one filter (or several batch axes): every row iterates together
        return _relinearized(x, P, x_post, P_post, args, iterations - 1)
    # A batch (B, n): each filter iterates until its own position settles (most settle
    # after two or three linearizations; filters that saw nothing after one).
    x_post, P_post = x_post.copy(), P_post.copy()
    rows = np.arange(x.shape[0])
    for _ in range(iterations - 1):
        sub = _take(args, rows)
        lin = x_post[rows, :2]
        xr, Pr = _relinearized(x[rows], P[rows], x_post[rows], P_post[rows], sub, 1)
        x_post[rows], P_post[rows] = xr, Pr
        step = np.max(np.abs(xr[:, :2] - lin), axis=1)
        rows = rows[step > ITERATION_TOL * (1.0 + np.max(np.abs(lin), axis=1))]
        if rows.size == 0:
            break
    return x_post, P_post


def _relinearized(
    x: FloatArray, P: FloatArray, x_post: FloatArray, P_post: FloatArray, args: tuple, n: int
) -> tuple[FloatArray, FloatArray]:
    """Return the posterior after at most ``n`` more linearizations, at the last estimate
    ``x_post`` first (all filters together; stops when every position has settled)."""
    for _ in range(n):
        # Relinearize at the last estimate: the innovation z - h(x_i) - H_i (x - x_i) gives
        # b_i - Y_i (p - p_i) for the terms (Y_i, b_i) at p_i (the prior x, P stay).
        lin = x_post[..., :2]
        yxx, yxy, yyy, bx, by = _terms(lin, *args)
        d0, d1 = x[..., 0] - lin[..., 0], x[..., 1] - lin[..., 1]
        x_new, P_post = _posterior(
            x, P, yxx, yxy, yyy, bx - (yxx * d0 + yxy * d1), by - (yxy * d0 + yyy * d1)
        )
        step = np.max(np.abs(x_new[..., :2] - lin))
        x_post = x_new
        if step <= ITERATION_TOL * (1.0 + np.max(np.abs(lin))):
            break
    return x_post, P_post


def _take(args: tuple, rows: np.ndarray) -> tuple:
    """Return ``update``'s arguments ``args`` at the filters ``rows`` of a batch (B, n):
    measurements and positions of shape (B, M, 2), per-sensor values of shape (B, M) and
    pose covariances of shape (B, M, 2, 2) are indexed, shared ones (M,) kept."""
    # The batch axis by position in the argument list (a shape alone is ambiguous when B = M).
    batched_ndim = (3, 3, 2, 2, 2, 2, 2, 2, 4)

    def one(a: Any, nd: int) -> Any:
        if isinstance(a, tuple):
            return tuple(one(v, nd) for v in a)
        return a[rows] if isinstance(a, np.ndarray) and a.ndim == nd else a

    return tuple(one(a, nd) for a, nd in zip(args, batched_ndim, strict=True))


def _terms(
    target: FloatArray,
    z: FloatArray,
    sensor_pos: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    orientation: FloatArray | float,
    mask: FloatArray | None,
    models: FloatArray | None,
    weights: tuple[FloatArray, FloatArray] | None,
    pose_cov: FloatArray | None,
) -> tuple[Any, Any, Any, Any, Any]:
    """Return ``(Y_xx, Y_xy, Y_yy, b_x, b_y)``: the measurement information ``Y`` and the
    gradient term ``b = H^T R^{-1} nu`` linearized at the target position ``target``
    (..., 2) (Python numbers for one filter)."""
    if pose_cov is not None:
        wd, wt = weights if weights is not None else (1.0 / sigma_d2, 1.0 / sigma_theta2)
        if mask is not None:
            wd, wt = wd * mask, wt * mask
        codes = 0 if models is None else models
        Yi, bi = sensor_models.update_terms(
            z, target, sensor_pos, codes, wd, wt, orientation, pose_cov
        )
        Y, b = Yi.sum(axis=-3), bi.sum(axis=-2)
        terms = (Y[..., 0, 0], Y[..., 0, 1], Y[..., 1, 1], b[..., 0], b[..., 1])
        if target.ndim == 1:  # Python numbers, as the single filter's path below uses
            terms = tuple(float(t) for t in terms)
        return terms
    # Offsets d = p_T_hat - p_S = -p of eq. (10) as complex numbers dx + i dy, (..., M).
    d = as_complex(target)[..., None] - as_complex(sensor_pos)
    dist = np.abs(d)
    if weights is None:
        wd = 1.0 / sigma_d2
        wt = 1.0 / sigma_theta2
    else:
        wd, wt = weights
    if mask is not None:
        wd = wd * mask
        wt = wt * mask
    n2 = dist * dist
    if np.count_nonzero(n2 < ZERO_DISTANCE2):
        # A sensor at zero distance gives no information this step (module docstring).
        # Its weights vanish; any positive distance keeps the arithmetic finite (d ~ 0).
        far = n2 >= ZERO_DISTANCE2
        dist = np.where(far, dist, 1.0)
        n2 = np.where(far, n2, 1.0)
        wd = wd * far
        wt = wt * far
    nu_t = z[..., 1] - np.arctan2(d.imag, d.real)
    nu_t += orientation
    measurement.wrap_angle(nu_t, inplace=True)
    # Y = sum_i H_i^T R_i^{-1} H_i (eq. 12) with h_d = -p/|p|, h_theta = J p/|p|^2 (eq. 9):
    # since p p^T + (J p)(J p)^T = |p|^2 I, Y = sum_i g_i d d^T + (sum_i h_i) I with
    # h = w_theta / |p|^2 and g = (w_d - h) / |p|^2; and d d^T = (|d|^2 I + [[Re d^2,
    # Im d^2], [Im d^2, -Re d^2]]) / 2 with sum_i g_i |d_i|^2 = sum_i (w_d - h)_i. The
    # gradient term b = H_e^T R^{-1} nu = sum_i e_i d + f_i J^T d (e = w_d nu_d / |p|,
    # f = h nu_theta) is Re + i Im of sum_i (e_i + i f_i) d_i. All sums are one reduction
    # over the rows [h + i w_d, g d^2, (e + i f) d] (..., 3, M).
    h = wt / n2
    m = d.shape[-1]
    terms = np.empty(d.shape[:-1] + (3, m), dtype=np.complex128)
    terms.real[..., 0, :] = h
    terms.imag[..., 0, :] = wd
    np.multiply((wd - h) / n2, d * d, out=terms[..., 1, :])
    ef = terms[..., 2, :]
    np.divide(wd * (z[..., 0] - dist), dist, out=ef.real)
    np.multiply(h, nu_t, out=ef.imag)
    ef *= d
    # einsum: NumPy's sum over a short last axis is ~5-9x slower on large batches, and a
    # BLAS matrix-vector product with ones may start threads (100x slower under load).
    single = target.ndim == 1
    if single:  # Python numbers: the 2x2 algebra below is several times cheaper on them
        # (and the ufunc's reduce directly: einsum's wrapper costs more than 3 terms)
        s0, gsum, bsum = np.add.reduce(terms, axis=-1).tolist()
    else:
        sums = np.einsum("...ij->...i", terms)
        s0, gsum, bsum = sums[..., 0], sums[..., 1], sums[..., 2]
    hs, swd = s0.real, s0.imag
    half = 0.5 * (swd + hs)
    yxx = half + 0.5 * gsum.real
    yyy = half - 0.5 * gsum.real
    yxy = 0.5 * gsum.imag
    bx, by = bsum.real, bsum.imag
    return yxx, yxy, yyy, bx, by


def _posterior(
    x: FloatArray,
    P: FloatArray,
    yxx: FloatArray,
    yxy: FloatArray,
    yyy: FloatArray,
    bx: FloatArray,
    by: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """Return eq. (11)'s posterior from the measurement information ``Y`` (its entries) and
    the gradient term ``b = H^T R^{-1} nu`` (the square-root form of the module docstring)."""
    single = P.ndim == 2  # then the entries are Python numbers (cheaper 2x2 algebra)
    # Square-root form. P11 = L L^T (Cholesky, L lower); K = L^T Y L; I + K = M M^T.
    # Then (Woodbury) P11+ = L (I + K)^{-1} L^T and the posterior is
    #   P+ = Z Z^T + blockdiag(0, S22),  Z = Pc L^{-T} M^{-T},  S22 = P22 - F F^T,
    # with Pc = P[:, :2] and F = P21 L^{-T} (so S22 is the prior's Schur complement, the
    # covariance of the unobserved states given the position, which the measurement
    # leaves unchanged). Both terms are positive semidefinite: a sum, never a difference.
    # The clamps below change nothing in exact arithmetic (each clamped quantity is a
    # Schur complement or a quadratic form of a PSD matrix); they keep L and M nonsingular.
    if single:
        p00, p01, p11 = P.item(0), P.item(1), P.item(P.shape[1] + 1)
        s = p11 - p01 * p01 / p00
        s = s if s > _FLOOR * p11 else _FLOOR * p11
    else:
        p00, p01, p11 = P[..., 0, 0], P[..., 0, 1], P[..., 1, 1]
        s = np.maximum(p11 - p01 * p01 / p00, _FLOOR * p11)
    l00, l11 = p00**0.5, s**0.5
    l10 = p01 / l00
    yl00, yl10 = yxx * l00 + yxy * l10, yxy * l00 + yyy * l10  # Y L, first column
    k00 = l00 * yl00 + l10 * yl10
    m10 = l11 * yl10
    if single:
        m00 = (1.0 + k00) ** 0.5 if k00 > 0.0 else 1.0
        m10 /= m00
        e = l11 * l11 * yyy - m10 * m10
        m11 = (1.0 + e) ** 0.5 if e > 0.0 else 1.0
    else:
        m00 = np.sqrt(1.0 + np.maximum(k00, 0.0))
        m10 /= m00
        m11 = np.sqrt(1.0 + np.maximum(l11 * l11 * yyy - m10 * m10, 0.0))
    # T = L^{-T} and U = M^{-T}, both upper triangular.
    t00, t11 = 1.0 / l00, 1.0 / l11
    t01 = -l10 * t00 * t11
    u00, u11 = 1.0 / m00, 1.0 / m11
    u01 = -m10 * u00 * u11
    # State correction K nu = Pc T (I + K)^{-1} L^T b with (I + K)^{-1} = U U^T.
    c0, c1 = l00 * bx + l10 * by, l11 * by
    w0, w1 = u00 * c0, u01 * c0 + u11 * c1
    v0, v1 = u00 * w0 + u01 * w1, u11 * w1
    # Z^T = (T U)^T P[:2, :], the correction g^T P[:2, :] with g = T v, and F = P21 T
    # (rows of P: P is symmetric and its rows are contiguous).
    z00, z10, z11 = t00 * u00, t00 * u01 + t01 * u11, t11 * u11
    g0, g1 = t00 * v0 + t01 * v1, t11 * v1
    if single:
        # One product of the stacked rows [Z^T; g^T; F^T] with P[:2, :]: fewest NumPy calls.
        V = np.array([z00, 0.0, z10, z11, g0, g1, t00, 0.0, t01, t11]).reshape(5, 2)
        W = V @ P[:2, :]
        Zt, Ft = W[:2], W[3:, 2:]
        P_post = Zt.T @ Zt  # A^T A of one operand: BLAS syrk, exactly symmetric
        P_post[2:, 2:] += P[2:, 2:] - Ft.T @ Ft
        return x + W[2], P_post
    # A batch: elementwise, with the batch as the innermost axis, i.e. on (n, ..., ) views
    # of P's rows (NumPy loops over the last axis; a length-n inner loop per filter, or a
    # stacked matmul with one BLAS call per filter, would be several times slower).
    rows = np.moveaxis(P[..., :2, :], (-2, -1), (0, 1))  # (2, n, ...)
    r0, r1 = rows[0], rows[1]
    z0 = z00 * r0  # the rows of Z^T, (n, ...)
    z1 = z10 * r0
    z1 += z11 * r1
    f0 = t00 * r0[2:]  # the rows of F^T, (n - 2, ...)
    f1 = t01 * r0[2:]
    f1 += t11 * r1[2:]
    # Outer products term by term: exactly symmetric (products commute), (n, n, ...).
    out = z0[:, None] * z0[None, :]
    out += z1[:, None] * z1[None, :]
    s22 = np.moveaxis(P[..., 2:, 2:], (-2, -1), (0, 1)) - f0[:, None] * f0[None, :]
    s22 -= f1[:, None] * f1[None, :]
    out[2:, 2:] += s22
    correction = g0 * r0
    correction += g1 * r1
    P_post = np.ascontiguousarray(np.moveaxis(out, (0, 1), (-2, -1)))
    return x + np.moveaxis(correction, 0, -1), P_post


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
