"""Interacting multiple model (IMM) filter for a target that switches between motion models.

The target follows one of r linear Gaussian models (eq. 2; e.g. constant velocity, eq. 39,
and coordinated turns of given rates, :func:`activetrack.models.behaviour.coordinated_turn`),
the mode ``m_k`` a Markov chain with ``Pi[i, j] = P(m_k = j | m_{k-1} = i)`` (the jump Markov
system of :class:`activetrack.Maneuvering`). The exact posterior is a mixture of r^k
Gaussians; the IMM (Blom and Bar-Shalom, "The interacting multiple model algorithm for
systems with Markovian switching coefficients", IEEE TAC 33(8), 1988; Bar-Shalom, Li and
Kirubarajan, *Estimation with Applications to Tracking and Navigation*, 2001, ch. 11.6)
keeps one Gaussian ``N(x_j, P_j)`` per mode and the mode probabilities ``mu_j``, a cycle:

1. *Mixing* (BLK eq. 11.6.6-11.6.7): ``c_j = sum_i Pi[i, j] mu_i`` (the predicted mode
   probabilities), ``mu_{i|j} = Pi[i, j] mu_i / c_j``, ``x0_j = sum_i mu_{i|j} x_i``,
   ``P0_j = sum_i mu_{i|j} (P_i + (x_i - x0_j)(x_i - x0_j)^T)`` (:func:`mix`);
2. *Mode-matched prediction*, eq. (3) with mode j's ``(Phi_j, Q_j)`` from ``(x0_j, P0_j)``
   (:func:`activetrack.models.motion.predict`, :func:`predict`); the predicted state is the
   mixture ``sum_j c_j N(x_j(k|k-1), P_j(k|k-1))``, whose moments (:func:`combine`) are the
   *predicted mixture covariance* the planners use (Lemma 1 needs only its position block);
3. *Mode-matched update*, eq. (11) for each mode with the library's EKF (the compiled
   :func:`activetrack.estimation.ekf.update` for built-in sensors, else
   :func:`activetrack.estimation.generic.update`: the square-root form, symmetric positive
   definite by construction), and the likelihood of the measurements under each mode,
   ``Lambda_j = N(nu_j; 0, S_j)`` with ``nu_j`` the stacked residuals at mode j's predicted
   position and ``S_j = H_j P11_j H_j^T + R_j`` (BLK eq. 11.6.9; :func:`log_likelihoods`);
4. *Mode probabilities* ``mu_j = Lambda_j c_j / sum_l Lambda_l c_l`` (BLK eq. 11.6.10, in
   the log domain) and the *combined* estimate, the moments of the mixture
   ``sum_j mu_j N(x_j, P_j)`` (BLK eq. 11.6.11-11.6.12): a convex combination of symmetric
   positive definite matrices plus the spread of the means (outer products), so symmetric
   positive definite by construction.

The IMM is exact for the first step from a common Gaussian prior and whenever ``Pi`` is the
identity (a bank of independent Kalman filters); otherwise the mixing step's merge of the
r^2 hypotheses into r Gaussians is its approximation. Sensors the EKF leaves out of an
update (``mask``, zero distance, the built-ins' near-distance rule of
:mod:`activetrack.estimation.ekf`) are left out of the likelihood as well, so both use the
same measurements. :class:`IMMFilter` is the validated stateful wrapper, the counterpart of
:class:`activetrack.ExtendedKalmanFilter`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from activetrack.estimation import ekf, generic
from activetrack.models import sensor_models as sm
from activetrack.models.behaviour import distribution, stochastic_matrix
from activetrack.models.measurement import INFORMATION_RATIO_MAX, ZERO_DISTANCE2
from activetrack.models.motion import LinearMotionModel
from activetrack.models.motion import predict as motion_predict
from activetrack.models.sensor import SensorModel, as_sensor_model
from activetrack.validation import FloatArray, as_finite, check_int, per_sensor, spd

_LOG_2PI = math.log(2.0 * math.pi)


def mix(
    mu: FloatArray, transition: FloatArray, x: FloatArray, P: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return the IMM's mixing ``(c, x0, P0)``: the predicted mode probabilities ``c``
    (..., r) and each mode's mixed initial mean (..., r, n) and covariance (..., r, n, n)
    from the mode-conditioned ``x`` (..., r, n), ``P`` (..., r, n, n) with probabilities
    ``mu`` (..., r) (BLK eq. 11.6.6-11.6.7; leading axes: independent filters). A mode of
    predicted probability 0 keeps its own estimate."""
    w = transition * mu[..., :, None]  # w[i, j] = Pi[i, j] mu_i
    # (a sum, not mu @ transition: BLAS rounds a vector's product and a stack's apart, and
    # a batch of filters must equal each filter alone bit for bit)
    c = w.sum(axis=-2)
    pos = c[..., None, :] > 0.0
    w = np.where(pos, w / np.where(pos, c[..., None, :], 1.0), np.eye(mu.shape[-1]))
    x0 = np.einsum("...ij,...in->...jn", w, x)  # w[i, j] = mu_{i|j}: columns sum to 1
    d = x[..., None, :, :] - x0[..., :, None, :]  # d[j, i] = x_i - x0_j
    P0 = np.einsum("...ij,...inm->...jnm", w, P) + np.einsum("...ij,...jin,...jim->...jnm", w, d, d)
    return c, x0, 0.5 * (P0 + np.swapaxes(P0, -1, -2))


def predict(
    models: Sequence[LinearMotionModel], x0: FloatArray, P0: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Return each mode's prediction (eq. 3 with its own model) from the mixed initial
    conditions ``x0`` (..., r, n), ``P0`` (..., r, n, n): ``(x, P)`` of the same shapes."""
    out = [
        motion_predict(x0[..., j, :], P0[..., j, :, :], m.Phi, m.Q) for j, m in enumerate(models)
    ]
    return np.stack([o[0] for o in out], axis=-2), np.stack([o[1] for o in out], axis=-3)


def combine(weights: FloatArray, x: FloatArray, P: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Return the mean (..., n) and covariance (..., n, n) of the Gaussian mixture
    ``sum_j weights_j N(x_j, P_j)`` (moment matching, BLK eq. 11.6.11-11.6.12; ``weights``
    (..., r), ``x`` (..., r, n), ``P`` (..., r, n, n)): exactly symmetric, positive definite
    when every ``P_j`` is."""
    xm = np.einsum("...j,...jn->...n", weights, x)
    d = x - xm[..., None, :]
    Pm = np.einsum("...j,...jnm->...nm", weights, P) + np.einsum(
        "...j,...jn,...jm->...nm", weights, d, d
    )
    return xm, 0.5 * (Pm + np.swapaxes(Pm, -1, -2))


def _used(
    team: Sequence[SensorModel],
    position: FloatArray,
    P11: FloatArray,
    sensors: FloatArray,
    sigma_theta2: FloatArray,
    mask: np.ndarray,
) -> np.ndarray:
    """Return which sensors (..., r, M) the EKF takes for each mode's predicted
    ``position`` (..., r, 2) and ``P11`` (..., r, 2, 2), sensors at ``sensors`` (..., M, 2)
    with ``mask`` (..., M): measured, not at zero distance, not within a built-in
    bearing's near distance (:mod:`activetrack.estimation.ekf`)."""
    rel = sensors[..., None, :, :] - position[..., :, None, :]
    n2 = rel[..., 0] ** 2 + rel[..., 1] ** 2
    near = (P11[..., 0, 0] + P11[..., 1, 1])[..., None] / INFORMATION_RATIO_MAX
    bearing = np.array([m.builtin and m.slots[1] for m in team])
    too_near = bearing & (near / sigma_theta2 > n2)
    return mask[..., None, :] & (n2 >= ZERO_DISTANCE2) & ~too_near


def log_likelihoods(
    team: Sequence[SensorModel],
    z: FloatArray,
    x: FloatArray,
    P: FloatArray,
    sensors: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    orientation: FloatArray,
    mask: np.ndarray,
    pose_cov: FloatArray | None = None,
) -> FloatArray:
    """Return each mode's ``log N(nu; 0, S)`` (..., r) of the measurements ``z`` (..., M,
    2): ``nu`` the stacked residuals of the used slots of the sensors the EKF takes
    (:func:`_used`) at the mode's predicted position ``x[..., j, :2]`` and ``S = H P11 H^T
    + R`` (with ``H Sigma_s H^T`` added to each sensor's ``R`` for uncertain sensor
    positions, ``pose_cov`` (..., M, 2, 2)), from each sensor model's function, Jacobian,
    noise and residual (one call per distinct model); ``x`` (..., r, n), ``P`` (..., r, n,
    n), ``sensors`` (..., M, 2), ``mask`` (..., M), per-sensor arrays (M,). A slot left out
    is a unit-variance dummy with zero residual and Jacobian (it adds nothing)."""
    batch, r, m = x.shape[:-2], x.shape[-2], sensors.shape[-2]
    z = np.broadcast_to(z, batch + (m, 2))
    sensors = np.broadcast_to(sensors, batch + (m, 2))
    mask = np.broadcast_to(mask, batch + (m,))
    p, P11 = x[..., :2], P[..., :2, :2]
    keep = _used(team, p, P11, sensors, sigma_theta2, mask)  # (..., r, M)
    nu, H, R = (
        np.zeros(keep.shape + (2,)),
        np.zeros(keep.shape + (2, 2)),
        np.zeros(keep.shape + (2, 2)),
    )
    slot = np.zeros((m, 2), bool)
    for model, idx in generic.groups(team):
        pt, s, phi = p[..., :, None, :], sensors[..., None, idx, :], orientation[idx]
        H[..., idx, :, :] = model.jacobian(pt, s, phi)
        R[..., idx, :, :] = model.noise_covar(pt, s, sigma_d2[idx], sigma_theta2[idx])
        nu[..., idx, :] = model.residual(z[..., None, idx, :], model.function(pt, s, phi))
        slot[idx] = model.slots
    if pose_cov is not None:
        R = R + H @ np.asarray(pose_cov)[..., None, :, :, :] @ H.mT
    used = keep[..., None] & slot  # (..., r, M, 2)
    nu = np.where(used, nu, 0.0).reshape(batch + (r, 2 * m))
    H = np.where(used[..., None], H, 0.0).reshape(batch + (r, 2 * m, 2))
    R = np.where(used[..., None] & used[..., None, :], R, 0.0)
    R = R + np.where(used, 0.0, 1.0)[..., None] * np.eye(2)  # the dummies' unit variance
    S = H @ P11 @ H.mT
    for i in range(m):  # block diagonal: the sensors measure independently
        S[..., 2 * i : 2 * i + 2, 2 * i : 2 * i + 2] += R[..., i, :, :]
    L = np.linalg.cholesky(0.5 * (S + S.mT))
    u = np.linalg.solve(L, nu[..., None])[..., 0]
    d = used.reshape(batch + (r, 2 * m)).sum(axis=-1)
    logdet = np.sum(np.log(np.diagonal(L, axis1=-2, axis2=-1)), axis=-1)
    return -0.5 * np.sum(u * u, axis=-1) - logdet - 0.5 * d * _LOG_2PI


def update(
    team: Sequence[SensorModel],
    x: FloatArray,
    P: FloatArray,
    z: FloatArray,
    sensors: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    orientation: FloatArray,
    mask: np.ndarray,
    pose_cov: FloatArray | None = None,
    iterations: int = 1,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return each mode's EKF posterior (eq. 11) and log-likelihood: ``(x (..., r, n), P
    (..., r, n, n), log_lik (..., r))`` from the predictions ``x`` (..., r, n), ``P`` (...,
    r, n, n); one sensor model per sensor (``team``, M), ``z`` and ``sensors`` (..., M, 2),
    ``mask`` (..., M), ``pose_cov`` (..., M, 2, 2) or None, the rest per sensor (M,).
    Built-in teams take the compiled :func:`activetrack.estimation.ekf.update` (the
    world's), others :func:`activetrack.estimation.generic.update`."""
    ll = log_likelihoods(
        team, z, x, P, sensors, sigma_d2, sigma_theta2, orientation, mask, pose_cov
    )
    # The measurements are every mode's: a mode axis before the sensors'.
    z, sensors, mask = z[..., None, :, :], sensors[..., None, :, :], mask[..., None, :]
    if pose_cov is not None:
        pose_cov = np.asarray(pose_cov)[..., None, :, :, :]
    if all(m.builtin for m in team):
        codes = np.array([m.code for m in team], np.int8)
        if not np.any(codes) and pose_cov is None:  # range and bearing: the EKF's own call
            xp, Pp = ekf.update(
                x, P, z, sensors, sigma_d2, sigma_theta2, orientation, mask,
                iterations=iterations,
            )  # fmt: skip
        else:
            xp, Pp = ekf.update(
                x, P, z, sensors, sigma_d2, sigma_theta2, orientation, mask, models=codes,
                weights=sm.weights(codes, sigma_d2, sigma_theta2), pose_cov=pose_cov,
                iterations=iterations,
            )  # fmt: skip
    else:
        xp, Pp = generic.update(
            team, x, P, z, sensors, sigma_d2, sigma_theta2, orientation, mask, pose_cov,
            iterations,
        )  # fmt: skip
    return xp, Pp, ll


def mode_probabilities(c: FloatArray, log_lik: FloatArray) -> FloatArray:
    """Return ``mu_j = Lambda_j c_j / sum_l Lambda_l c_l`` (BLK eq. 11.6.10) from the
    predicted probabilities ``c`` (..., r) and the log-likelihoods, in the log domain (no
    underflow when every likelihood is tiny)."""
    with np.errstate(divide="ignore"):
        a = np.log(c) + log_lik
    w = np.exp(a - np.max(a, axis=-1, keepdims=True))
    return w / w.sum(axis=-1, keepdims=True)


class IMMFilter:
    """A validated, stateful IMM filter (module docstring) over r motion models.

    ``models``: the modes' :class:`~activetrack.LinearMotionModel` (one state dimension;
    e.g. :attr:`activetrack.Maneuvering.models`); ``transition`` (r, r) row-stochastic;
    ``x0`` (n,), ``P0`` (n, n) the prior of every mode; ``mode_probs`` (r,) the prior mode
    probabilities (default uniform); ``sensor_model`` one
    :class:`~activetrack.SensorModel` (or built-in name) for every sensor, or a tuple of
    one per sensor; ``iterations`` the EKF's linearizations (1: eq. 11).

    Attributes: ``xs`` (r, n) and ``Ps`` (r, n, n) the mode-conditioned estimates, ``mu``
    (r,) the mode probabilities (after :meth:`predict`, the predicted ones ``c``); ``x``,
    ``P`` the combined mixture estimate, after :meth:`predict` the *predicted mixture*
    (what the planners plan with), after :meth:`update` the posterior one.
    """

    def __init__(
        self,
        models: Sequence[LinearMotionModel],
        transition: ArrayLike,
        x0: ArrayLike,
        P0: ArrayLike,
        mode_probs: ArrayLike | None = None,
        sensor_model: object = "range_bearing",
        iterations: int = 1,
    ) -> None:
        models = tuple(models) if isinstance(models, (list, tuple)) else ()
        if not models or not all(isinstance(m, LinearMotionModel) for m in models):
            raise ValueError("models must be a non-empty sequence of activetrack.LinearMotionModel")
        n = models[0].dim
        if any(m.dim != n for m in models):
            raise ValueError(
                f"models must share one state dimension, got {[m.dim for m in models]}"
            )
        r = len(models)
        self.models = models
        self.transition = stochastic_matrix("transition", transition, r)
        x0 = as_finite("x0", x0, (n,))
        P0 = spd("P0", P0)
        if P0.shape != (n, n):
            raise ValueError(f"P0 must have shape ({n}, {n}), got {P0.shape}")
        self.mu = distribution(
            "mode_probs", np.full(r, 1.0 / r) if mode_probs is None else mode_probs, r
        )
        self.xs = np.tile(x0, (r, 1))
        self.Ps = np.tile(0.5 * (P0 + P0.T), (r, 1, 1))
        if isinstance(sensor_model, tuple):
            self.sensor_model: object = tuple(as_sensor_model(m) for m in sensor_model)
        else:
            self.sensor_model = as_sensor_model(sensor_model)
        self.iterations = check_int("iterations", iterations, 1)
        self.x, self.P = combine(self.mu, self.xs, self.Ps)

    @property
    def n_modes(self) -> int:
        """Return the number of modes r."""
        return len(self.models)

    @property
    def position(self) -> FloatArray:
        """Return the combined estimate's position, shape (2,)."""
        return self.x[:2].copy()

    @property
    def position_cov(self) -> FloatArray:
        """Return the 2x2 position block of the combined covariance (after :meth:`predict`
        the predicted mixture's, the planners' ``P11``)."""
        return self.P[:2, :2].copy()

    def predict(self) -> None:
        """Mix, predict every mode (eq. 3) and set ``x``, ``P`` to the predicted mixture."""
        c, x0, P0 = mix(self.mu, self.transition, self.xs, self.Ps)
        self.xs, self.Ps = predict(self.models, x0, P0)
        self.mu = c
        self.x, self.P = combine(c, self.xs, self.Ps)

    def predicted(self) -> tuple[FloatArray, FloatArray]:
        """Return the next step's predicted mixture ``(x(k+1|k), P(k+1|k))`` without
        changing the filter: what a planner deciding the next sensor positions plans with
        (its position block is Lemma 1's ``P11``)."""
        c, x0, P0 = mix(self.mu, self.transition, self.xs, self.Ps)
        return combine(c, *predict(self.models, x0, P0))

    def update(
        self,
        z: ArrayLike,
        sensor_pos: ArrayLike,
        sigma_d2: ArrayLike,
        sigma_theta2: ArrayLike,
        orientation: ArrayLike = 0.0,
        sensors: ArrayLike | None = None,
        pose_cov: ArrayLike | None = None,
    ) -> None:
        """Update every mode with measurements ``z`` (M, 2) from sensors at ``sensor_pos``
        (M, 2) (eq. 11), then the mode probabilities and the combined estimate.

        ``sensors`` optionally selects the sensors that measured: a boolean mask (M,) or
        indices; ``pose_cov`` (M, 2, 2) the covariance of the sensors' position fixes.
        """
        sensor_pos = as_finite("sensor_pos", sensor_pos)
        if sensor_pos.ndim != 2 or sensor_pos.shape[1] != 2:
            raise ValueError(f"sensor_pos must have shape (M, 2), got {sensor_pos.shape}")
        m = sensor_pos.shape[0]
        z = as_finite("z", z, (m, 2))
        sd2 = per_sensor("sigma_d2", sigma_d2, m)
        st2 = per_sensor("sigma_theta2", sigma_theta2, m)
        phi = np.broadcast_to(as_finite("orientation", orientation), (m,))
        mask = _selection(sensors, m)
        cov = None if pose_cov is None else as_finite("pose_cov", pose_cov, (m, 2, 2))
        team = self.sensor_model
        if not isinstance(team, tuple):
            team = (team,) * m
        elif len(team) != m:
            raise ValueError(f"sensor_model must hold one model per sensor ({m}), got {len(team)}")
        self.xs, self.Ps, ll = update(
            team, self.xs, self.Ps, z, sensor_pos, sd2, st2, phi, mask, cov, self.iterations
        )
        self.mu = mode_probabilities(self.mu, ll)
        self.x, self.P = combine(self.mu, self.xs, self.Ps)


def _selection(sensors: ArrayLike | None, m: int) -> np.ndarray:
    """Return the (M,) bool mask of a selection: None (all), a mask, or indices."""
    if sensors is None:
        return np.ones(m, dtype=bool)
    sel = np.asarray(sensors)
    if sel.dtype == bool:
        if sel.shape != (m,):
            raise ValueError(f"sensors mask must have shape ({m},), got {sel.shape}")
        return sel
    if sel.dtype.kind not in "iu" or np.any((sel < 0) | (sel >= m)):
        raise ValueError(f"sensors indices must be integers in [0, {m - 1}], got {sensors!r}")
    mask = np.zeros(m, dtype=bool)
    mask[sel] = True
    return mask
