"""Sensor measurement models in one place: range-and-bearing, range-only, bearing-only.

Each sensor ``i`` of a team has a model code (:class:`SensorCode`, the code a built-in
:class:`activetrack.SensorModel` carries): range and bearing
(the paper's eq. 4), range only, or bearing only; a team mixes them freely through a
per-sensor code array of shape (..., M).

**Layout.** A team's measurement is always an array (..., M, 2) with columns
``[d_i, theta_i]`` (eq. 4): ``d_i = ||p_T - p_S_i||``, ``theta_i = atan2(dy, dx) - phi_i``.
A component a sensor does not measure is exactly ``0.0`` in the measurement, in the
noise-free prediction and in the innovation, and it carries zero weight. The EKF of
:mod:`activetrack.estimation.ekf` works in information form with per-component weights
``w_d = 1/sigma_d^2``, ``w_theta = 1/sigma_theta^2``; a zero weight removes a component
exactly, so every model reuses the same arrays, shapes and arithmetic (a packed layout
would change the measurement length with the team and make batched arrays ragged).

**Jacobians** (eq. 9) of the stacked measurement with respect to the target position:
rows ``h_d = -p / |p|`` and ``h_theta = J p / |p|^2`` with ``p = p_S - p_T`` (eq. 10),
``J = C(-pi/2)``; the row of an unused component is zero (that component is the constant
0). With respect to the sensor position the Jacobian is ``H_s = -H`` (both enter through
``p_T - p_S`` only).

**Fisher information** of sensor ``i`` about the target position (eq. 12, 17): with
``u = p / |p|``, ``v = J p / |p|`` (orthonormal),
``J0_i = H_i^T W_i H_i = w_d u u^T + (w_theta / |p|^2) v v^T``, where ``W_i`` holds the
weights with zeros for unused components. Range only is ``w_theta = 0`` and bearing only
``w_d = 0``: the same formula as today's eq. (17), so passing those weights (or
``sigma^2 = inf``) through today's code gives these models (equal to rounding).

**Uncertain sensor poses.** The believed sensor position has error ``e ~ N(0, Sigma_s)``
(2x2 PSD, per sensor); linearized, the measurement noise becomes
``R_eff = R + H_s Sigma_s H_s^T = R + H Sigma_s H^T``. The information is
``H^T R_eff^{-1} H = (I + J0 Sigma_s)^{-1} J0`` (push-through identity, valid for singular
``R^{-1} = W``: only used components enter), and for 2x2 matrices in closed form::

    J_eff = (J0 + det(J0) adj(Sigma_s)) / (1 + tr(J0 Sigma_s) + det(J0) det(Sigma_s)),

with ``adj([[s11, s12], [s12, s22]]) = [[s22, -s12], [-s12, s11]]`` (for invertible J0
this is ``(J0^{-1} + Sigma_s)^{-1}``). The numerator is a sum of two PSD matrices and the
denominator is >= 1, so ``J_eff`` is PSD by construction, ``J_eff <= J0``, and it equals
``J0`` exactly for ``Sigma_s = 0``. ``det(J0) = w_d w_theta / |p|^2`` and
``tr(J0 Sigma_s) = w_d u^T Sigma_s u + (w_theta / |p|^2) v^T Sigma_s v`` are evaluated
in these nonnegative forms. The EKF's gradient term is ``b_i = H^T R_eff^{-1} nu =
J_eff delta`` with ``delta = -nu_d u + |p| nu_theta v`` (the innovation in position units,
``H delta = nu`` on the used rows; for ``Sigma_s = 0`` this is ``H^T W nu``).

**Zero distance** (the EKF's rule, :data:`activetrack.models.measurement.ZERO_DISTANCE2`): a
sensor at (numerically) zero distance from the target has zero Jacobian rows and
contributes no information, never NaN.

Kernels (lower-case functions) are unchecked and broadcast over leading axes; the sensor
axis is the last of ``(..., M)``. :class:`SensorTeam` validates a team once.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from activetrack.linalg2 import as_complex
from activetrack.models.measurement import ZERO_DISTANCE2, wrap_angle
from activetrack.validation import FloatArray, as_finite, positive


class SensorCode(IntEnum):
    """The code of a built-in measurement model, stored per sensor for the compiled kernels
    (:attr:`activetrack.SensorModel.code`; the model itself is :class:`activetrack.SensorModel`)."""

    RANGE_BEARING = 0  #: distance and bearing, eq. (4)
    RANGE = 1  #: distance only
    BEARING = 2  #: bearing only


#: ``USES[code] = (measures distance, measures bearing)``, shape (3, 2).
USES = np.array([[True, True], [True, False], [False, True]])
USES.setflags(write=False)


def uses(models: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Return boolean arrays ``(uses_range, uses_bearing)`` of the codes' shape."""
    table = USES[np.asarray(models)]
    return table[..., 0], table[..., 1]


def weights(
    models: ArrayLike, sigma_d2: ArrayLike, sigma_theta2: ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """Return the component weights ``(w_d, w_theta)`` (..., M): ``1/sigma^2`` or exactly 0.

    A component the sensor's model does not measure gets weight 0 whatever its variance.
    """
    use_d, use_t = uses(models)
    sd2, st2 = np.asarray(sigma_d2, dtype=np.float64), np.asarray(sigma_theta2, dtype=np.float64)
    shape = np.broadcast_shapes(use_d.shape, sd2.shape, st2.shape)
    w_d = np.zeros(shape)
    w_t = np.zeros(shape)
    np.divide(1.0, sd2, out=w_d, where=np.broadcast_to(use_d, shape))
    np.divide(1.0, st2, out=w_t, where=np.broadcast_to(use_t, shape))
    return w_d, w_t


def measure(
    target_pos: FloatArray,
    sensor_pos: FloatArray,
    models: ArrayLike,
    orientation: FloatArray | float = 0.0,
    *,
    wrap: bool = True,
) -> FloatArray:
    """Return the noise-free measurements ``[d, theta]`` (..., M, 2), unused components 0.

    ``target_pos`` (..., 2), ``sensor_pos`` (..., M, 2), ``models`` and ``orientation``
    broadcastable to (..., M). The bearing is wrapped to ``[-pi, pi)`` unless ``wrap=False``.
    """
    # One complex difference per sensor: its modulus (hypot) and argument (atan2), eq. (4).
    delta = as_complex(target_pos[..., None, :] - sensor_pos)
    use_d, use_t = uses(models)
    out = np.empty(np.broadcast_shapes(delta.shape, use_d.shape) + (2,))
    out[..., 0] = np.abs(delta)
    out[..., 1] = np.arctan2(delta.imag, delta.real) - orientation
    if wrap:
        wrap_angle(out[..., 1], inplace=True)
    # np.where, not a product: an unused component is +0.0, never -0.0.
    out[..., 0] = np.where(use_d, out[..., 0], 0.0)
    out[..., 1] = np.where(use_t, out[..., 1], 0.0)
    return out


def _unit(rel: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Return ``(ux, uy, n2, far)`` for offsets ``rel = p_S - p_T`` (..., M, 2).

    ``u = p / |p|``; at zero distance (``far`` False) ``u = 0`` and ``n2 = 1`` so that every
    derived quantity is finite and the caller zeroes the sensor's contribution.
    """
    x, y = rel[..., 0], rel[..., 1]
    n2 = x * x + y * y
    far = n2 >= ZERO_DISTANCE2
    if not np.all(far):
        x, y = np.where(far, x, 0.0), np.where(far, y, 0.0)
        n2 = np.where(far, n2, 1.0)
    n = np.sqrt(n2)
    return x / n, y / n, n2, far


def jacobian_target(
    target_pos: FloatArray, sensor_pos: FloatArray, models: ArrayLike
) -> FloatArray:
    """Return ``dh / dp_T`` of :func:`measure`, (..., M, 2, 2): rows ``[h_d^T; h_theta^T]`` (eq. 9).

    The row of an unused component is zero; a sensor at zero distance gets zero rows.
    """
    ux, uy, n2, far = _unit(sensor_pos - target_pos[..., None, :])
    use_d, use_t = uses(models)
    n = np.sqrt(n2)
    kd = np.where(use_d & far, -1.0, 0.0)  # h_d = -u
    kt = np.where(use_t & far, 1.0 / n, 0.0)  # h_theta = J p / |p|^2 = v / |p|, v = (uy, -ux)
    return np.stack([np.stack([kd * ux, kd * uy], -1), np.stack([kt * uy, -kt * ux], -1)], axis=-2)


def jacobian_sensor(
    target_pos: FloatArray, sensor_pos: FloatArray, models: ArrayLike
) -> FloatArray:
    """Return ``dh / dp_S`` (..., M, 2, 2): minus :func:`jacobian_target` (h is of p_T - p_S)."""
    return -jacobian_target(target_pos, sensor_pos, models)


def innovation(
    z: FloatArray,
    target_pos: FloatArray,
    sensor_pos: FloatArray,
    models: ArrayLike,
    orientation: FloatArray | float = 0.0,
) -> FloatArray:
    """Return ``z - h(p_T_hat)`` (..., M, 2), bearing wrapped to ``[-pi, pi)``, unused 0.

    Unused components are 0 whatever ``z`` holds there (they carry no weight).
    """
    nu = z - measure(target_pos, sensor_pos, models, orientation, wrap=False)
    wrap_angle(nu[..., 1], inplace=True)
    use_d, use_t = uses(models)
    nu[..., 0] = np.where(use_d, nu[..., 0], 0.0)
    nu[..., 1] = np.where(use_t, nu[..., 1], 0.0)
    return nu


def sample(
    target_pos: FloatArray,
    sensor_pos: FloatArray,
    models: ArrayLike,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    rng: np.random.Generator,
    orientation: FloatArray | float = 0.0,
) -> FloatArray:
    """Return noisy measurements (..., M, 2) from the true positions: bearing wrapped, unused 0."""
    z = measure(target_pos, sensor_pos, models, orientation, wrap=False)
    use_d, use_t = uses(models)
    std = np.stack(
        np.broadcast_arrays(np.sqrt(sigma_d2) * use_d, np.sqrt(sigma_theta2) * use_t), axis=-1
    )
    z = z + rng.standard_normal(z.shape) * std
    wrap_angle(z[..., 1], inplace=True)
    return z


def effective_noise(
    target_pos: FloatArray,
    sensor_pos: FloatArray,
    models: ArrayLike,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    pose_cov: FloatArray | None = None,
) -> FloatArray:
    """Return ``R_eff = R + H_s Sigma_s H_s^T`` (..., M, 2, 2) on the used components.

    Rows and columns of unused components are zero (that component is the constant 0).
    """
    use_d, use_t = uses(models)
    shape = np.broadcast_shapes(sensor_pos.shape[:-1], use_d.shape)
    R = np.zeros(shape + (2, 2))
    R[..., 0, 0] = np.broadcast_to(sigma_d2 * use_d, shape)
    R[..., 1, 1] = np.broadcast_to(sigma_theta2 * use_t, shape)
    if pose_cov is not None:
        Hs = jacobian_sensor(target_pos, sensor_pos, models)
        R = R + Hs @ pose_cov @ Hs.mT
    return R


def _j0_terms(rel: FloatArray, w_d: FloatArray, w_theta: FloatArray) -> tuple[FloatArray, ...]:
    """Return ``(a0, b0, c0, ux, uy, n2, wd, wv)``: ``J0``'s entries and the unit offset.

    ``wd`` and ``wv = w_theta / |p|^2`` are the weights of ``u u^T`` and ``v v^T``, zero at
    zero distance.
    """
    ux, uy, n2, far = _unit(rel)
    wd = w_d * far
    wv = (w_theta * far) / n2  # weight of v v^T, v = (uy, -ux)
    uxx, uxy, uyy = ux * ux, ux * uy, uy * uy
    return wd * uxx + wv * uyy, (wd - wv) * uxy, wd * uyy + wv * uxx, ux, uy, n2, wd, wv


def _pose_denominator(
    ux: FloatArray, uy: FloatArray, wd: FloatArray, wv: FloatArray, pose_cov: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Return ``(det(J0), 1 + tr(J0 Sigma) + det(J0) det(Sigma))``, both >= 0 by construction."""
    s11, s12, s22 = pose_cov[..., 0, 0], pose_cov[..., 0, 1], pose_cov[..., 1, 1]
    # Quadratic forms of Sigma_s (nonnegative in exact arithmetic; clamp the rounding).
    cross = 2.0 * s12 * ux * uy
    q_u = np.maximum(s11 * ux * ux + cross + s22 * uy * uy, 0.0)
    q_v = np.maximum(s11 * uy * uy - cross + s22 * ux * ux, 0.0)
    det_s = np.maximum(s11 * s22 - s12 * s12, 0.0)
    det_j = wd * wv
    return det_j, 1.0 + wd * q_u + wv * q_v + det_j * det_s


def information_entries(
    rel: FloatArray,
    w_d: FloatArray,
    w_theta: FloatArray,
    pose_cov: FloatArray | None = None,
    detect: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return each sensor's information entries ``(a, b, c)`` = ``(J11, J12, J22)``, (..., M).

    ``rel = p_S - p_T_hat`` (..., M, 2) (eq. 10), weights (..., M) from :func:`weights`,
    ``pose_cov`` (..., M, 2, 2) PSD or None. ``J = J_eff`` of the module docstring
    (``J0`` of eq. 17 when ``pose_cov`` is None or zero); a sensor at zero distance gives 0.
    ``detect = (p_detect, max_range**2)`` (..., M): the expected information of a sensor
    that measures with probability ``p_detect`` when within ``max_range``,
    ``p_detect 1[|p| <= max_range] J`` (:func:`detection_factor`); None: always. A third
    entry, (..., M) bool, is the line of sight (False: an occluder hides the target).
    """
    a, b, c, ux, uy, _, wd, wv = _j0_terms(rel, w_d, w_theta)
    if pose_cov is not None:
        det_j, den = _pose_denominator(ux, uy, wd, wv, pose_cov)
        s11, s12, s22 = pose_cov[..., 0, 0], pose_cov[..., 0, 1], pose_cov[..., 1, 1]
        a, b, c = (a + det_j * s22) / den, (b - det_j * s12) / den, (c + det_j * s11) / den
    if detect is None:
        return a, b, c
    f = detection_factor(rel, *detect[:2])
    if len(detect) > 2:  # the line of sight (..., M) bool, computed by the caller
        f = np.where(detect[2], f, 0.0)
    return a * f, b * f, c * f


def detection_factor(rel: FloatArray, p_detect: FloatArray, range2: FloatArray) -> FloatArray:
    """Return the probability that a sensor at offset ``rel`` (..., M, 2) measures the
    target: ``p_detect`` within the range (:func:`in_range`), else 0; (..., M)."""
    return np.where(in_range(rel, range2), p_detect, 0.0)


def in_range(rel: FloatArray, range2: FloatArray) -> np.ndarray:
    """Return whether offsets ``rel`` (..., 2) are within the sensing range,
    ``|rel|^2 <= range2`` (the rule of the world's detections and of the planners)."""
    return rel[..., 0] * rel[..., 0] + rel[..., 1] * rel[..., 1] <= range2


def _matrix(a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
    return np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)


def fisher_information(
    rel: FloatArray,
    w_d: FloatArray,
    w_theta: FloatArray,
    pose_cov: FloatArray | None = None,
) -> FloatArray:
    """Return each sensor's information ``H_i^T R_eff_i^{-1} H_i`` (..., M, 2, 2), PSD.

    Arguments as :func:`information_entries`.
    """
    return _matrix(*information_entries(rel, w_d, w_theta, pose_cov))


def team_entries(
    prior_info: FloatArray,
    rel: FloatArray,
    w_d: FloatArray,
    w_theta: FloatArray,
    pose_cov: FloatArray | None = None,
    detect: tuple[FloatArray, FloatArray] | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return the entries ``(a, b, c)`` (...) of ``Y = P11^{-1} + sum_i J_i`` (eq. 12).

    The form :meth:`activetrack.models.objective.TraceObjective.of_entries` and ``tangent`` take.
    ``prior_info`` (..., 2, 2) broadcasts against the leading axes of ``rel`` (..., M, 2);
    ``detect`` as in :func:`information_entries` (the expected information).
    """
    a, b, c = information_entries(rel, w_d, w_theta, pose_cov, detect)
    return (
        prior_info[..., 0, 0] + a.sum(axis=-1),
        prior_info[..., 0, 1] + b.sum(axis=-1),
        prior_info[..., 1, 1] + c.sum(axis=-1),
    )


def team_information(
    rel: FloatArray,
    w_d: FloatArray,
    w_theta: FloatArray,
    pose_cov: FloatArray | None = None,
    prior_info: FloatArray | None = None,
) -> FloatArray:
    """Return ``sum_i J_i`` (..., 2, 2), plus ``prior_info`` when given (then eq. 12's ``Y``)."""
    zero = np.zeros((2, 2)) if prior_info is None else prior_info
    return _matrix(*team_entries(zero, rel, w_d, w_theta, pose_cov))


def update_terms(
    z: FloatArray,
    target_hat: FloatArray,
    sensor_pos: FloatArray,
    models: ArrayLike,
    w_d: FloatArray,
    w_theta: FloatArray,
    orientation: FloatArray | float = 0.0,
    pose_cov: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Return the EKF's per-sensor information terms ``(Y_i, b_i)``: (..., M, 2, 2), (..., M, 2).

    ``Y_i = H_i^T R_eff_i^{-1} H_i`` and ``b_i = H_i^T R_eff_i^{-1} nu_i`` at the estimate
    ``target_hat`` (..., 2). Their sums over sensors are the ``Y`` and ``b`` of
    :func:`activetrack.estimation.ekf.update` (which then applies eq. 11 in square-root form); with
    sensor independence ``R_eff`` is block diagonal, so the sums are exact. A mask of the
    sensors that measured multiplies the weights.
    """
    rel = sensor_pos - target_hat[..., None, :]
    nu = innovation(z, target_hat, sensor_pos, models, orientation)
    ux, uy, n2, _ = _unit(rel)
    # b_i = J_i delta_i with delta = -nu_d u + |p| nu_theta v, the innovation in position
    # units (H delta = nu on the used rows): H^T W nu = J0 delta, and with pose uncertainty
    # H^T R_eff^{-1} nu = (I + J0 Sigma)^{-1} J0 delta = J_eff delta. J_eff is bounded where
    # (I + J0 Sigma)^{-1} J0 delta would cancel large terms (a sensor close to the target).
    kd, kt = -nu[..., 0], np.sqrt(n2) * nu[..., 1]
    dx, dy = kd * ux + kt * uy, kd * uy - kt * ux
    a, b, c = information_entries(rel, w_d, w_theta, pose_cov)
    return _matrix(a, b, c), np.stack([a * dx + b * dy, b * dx + c * dy], -1)


def _codes(value: Any) -> np.ndarray:
    """Return model codes as an int8 array; names (``"range"``) and members are accepted."""
    names = {m.name.lower(): int(m) for m in SensorCode}
    flat = np.asarray(value, dtype=object)
    out = np.empty(flat.shape, dtype=np.int8)
    allowed = ", ".join(f"{m.name} ({int(m)})" for m in SensorCode)
    for idx, v in np.ndenumerate(flat):
        if isinstance(v, str) and v.lower() in names:
            out[idx] = names[v.lower()]
        elif isinstance(v, (int, np.integer)) and not isinstance(v, bool) and 0 <= v <= 2:
            out[idx] = int(v)
        else:
            raise ValueError(f"models must hold sensor models {allowed}, got {v!r}")
    return out


@dataclass(frozen=True, eq=False)
class SensorTeam:
    """A validated team of M sensors: model codes, noise and optional pose covariances.

    Attributes (float64 / int8, broadcast to (..., M), read-only):
        models: per-sensor :class:`SensorCode` codes (names such as ``"range"`` accepted).
        sigma_d2: range noise variances, finite > 0 (ignored for bearing-only sensors).
        sigma_theta2: bearing noise variances, finite > 0 (ignored for range-only sensors).
        pose_cov: per-sensor 2x2 PSD covariance of the believed position (..., M, 2, 2),
            or None (poses known exactly).
    """

    models: np.ndarray
    sigma_d2: FloatArray
    sigma_theta2: FloatArray
    pose_cov: FloatArray | None = None

    def __post_init__(self) -> None:
        models = _codes(self.models)
        sd2 = positive("sigma_d2", self.sigma_d2)
        st2 = positive("sigma_theta2", self.sigma_theta2)
        if models.ndim < 1:
            raise ValueError(f"models must have shape (..., M), got {models.shape}")
        try:
            shape = np.broadcast_shapes(models.shape, sd2.shape, st2.shape)
        except ValueError:
            raise ValueError(
                f"models {models.shape}, sigma_d2 {sd2.shape} and sigma_theta2 {st2.shape} "
                "must broadcast to (..., M)"
            ) from None
        values: dict[str, Any] = {
            "models": models,
            "sigma_d2": sd2,
            "sigma_theta2": st2,
            "pose_cov": None,
        }
        if self.pose_cov is not None:
            cov = as_finite("pose_cov", self.pose_cov)
            if cov.ndim < 2 or cov.shape[-2:] != (2, 2):
                raise ValueError(f"pose_cov must have shape (..., M, 2, 2), got {cov.shape}")
            try:
                shape = np.broadcast_shapes(shape, cov.shape[:-2])
            except ValueError:
                raise ValueError(
                    f"pose_cov {cov.shape} must have shape (..., M, 2, 2) with M = {shape[-1]}"
                ) from None
            scale = np.maximum(np.abs(cov).max(axis=(-2, -1)), 1e-300)
            if np.any(np.abs(cov[..., 0, 1] - cov[..., 1, 0]) > 1e-9 * scale):
                raise ValueError("pose_cov must be symmetric")
            det = cov[..., 0, 0] * cov[..., 1, 1] - cov[..., 0, 1] * cov[..., 1, 0]
            if (
                np.any(cov[..., 0, 0] < 0)
                or np.any(cov[..., 1, 1] < 0)
                or np.any(det < -1e-12 * scale * scale)
            ):
                raise ValueError("pose_cov must be positive semidefinite (eigenvalues >= 0)")
            sym = 0.5 * (cov + cov.mT)
            values["pose_cov"] = np.array(np.broadcast_to(sym, shape + (2, 2)))
        for name in ("models", "sigma_d2", "sigma_theta2"):
            values[name] = np.array(np.broadcast_to(values[name], shape))
        for name, value in values.items():
            if value is not None:
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_sensors(self) -> int:
        """Return M."""
        return int(self.models.shape[-1])

    def weights(self) -> tuple[FloatArray, FloatArray]:
        """Return ``(w_d, w_theta)`` (..., M), zero for unused components (:func:`weights`)."""
        return weights(self.models, self.sigma_d2, self.sigma_theta2)


def __getattr__(name: str) -> Any:
    # ``sensor_models.SensorModel`` was the enum of codes; it is now the public base class
    # (whose RANGE_BEARING, RANGE and BEARING are still the codes). Resolved lazily: the
    # class is defined on top of this module.
    if name == "SensorModel":
        from activetrack.models.sensor import SensorModel  # noqa: PLC0415

        return SensorModel
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
