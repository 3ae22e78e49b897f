"""What a sensor measures: :class:`SensorModel`, the public base, and its three built-ins.

A sensor model says what one sensor measures of a target at ``p_T`` from its position
``p_S`` (:meth:`SensorModel.function`), the noise of that measurement
(:meth:`SensorModel.noise_covar`), its Jacobian with respect to the target position
(:meth:`SensorModel.jacobian`) and the Fisher information it carries about that position
(:meth:`SensorModel.information`, with the pose-uncertainty and detection factors of
:mod:`activetrack.models.sensor_models`). The filter, the planners, the observation and the
rendering ask the model; composed per sensor by a scenario (``make_scenario(...,
sensor_model=RangeOnly())`` or a tuple with one model per sensor), as Stone Soup composes an
updater from a measurement model.

**Layout.** A measurement is two slots ``[distance-like, angle-like]`` per sensor, the
world's (..., M, 2) arrays; :attr:`SensorModel.slots` says which slots a model fills (an
unused slot is exactly 0 everywhere and carries no weight) and :attr:`SensorModel.angular`
which slots are angles (wrapped to ``[-pi, pi)``). The world draws two standard normals
per sensor and target for the measurement noise whatever the model, so a model measures
at most two components.

**The built-ins** (:class:`RangeBearing`, :class:`RangeOnly`, :class:`BearingOnly`, eq. 4)
carry the :attr:`SensorModel.code` their compiled kernels use (the int codes of
:class:`~activetrack.models.sensor_models.SensorCode`): a scenario whose every sensor is
built-in takes the compiled paths, bit for bit as before
(:attr:`activetrack.world.capabilities.Capabilities.builtin_sensors`). A model of your own
(a subclass with ``code = None``) runs through the generic NumPy path
(:mod:`activetrack.estimation.generic`). Its noise variances are the scenario's per-sensor
``sigma_d2`` (slot 0) and ``sigma_theta2`` (slot 1), handed to :meth:`noise_covar`, which a
subclass may make depend on the geometry.

The noise is Gaussian and the information is ``H^T R_eff^+ H`` with ``R_eff = R + H
Sigma_s H^T`` (``Sigma_s`` the pose covariance): the EKF's information. A model whose noise
depends on the target's position has a further term in its exact Fisher information; a
subclass overrides :meth:`information` to include it (the planners then plan with it).
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from activetrack.models import sensor_models as sm
from activetrack.models.measurement import ZERO_DISTANCE2, wrap_angle
from activetrack.models.sensor_models import SensorCode
from activetrack.validation import ComparedByValue, FloatArray

#: Step of the central differences of the default :meth:`SensorModel.jacobian`, relative to
#: the distance (the truncation error is O(step^2), the rounding O(eps / step)).
FD_STEP = 1e-6


class SensorModel(ComparedByValue):
    """The measurement model of one sensor: subclass it to define a new sensor.

    A subclass sets :attr:`name` (a short identifier, not a built-in's), :attr:`slots` and
    :attr:`angular`, and implements :meth:`function`; every other method has a default
    built on it (the Jacobian by central differences, a diagonal noise of the scenario's
    variances on the used slots, the information ``H^T R_eff^+ H``). Methods are
    vectorized: ``target`` and ``sensor`` broadcast over leading axes (..., 2).

    The codes of the old enum stay here as class attributes
    (``SensorModel.RANGE_BEARING == 0``, ``RANGE``, ``BEARING``).
    """

    #: A short identifier (recorded by ``Scenario.to_dict``).
    name: ClassVar[str] = ""
    #: The compiled kernels' code of a built-in (0, 1, 2); None for a model of your own.
    code: ClassVar[int | None] = None
    #: Which of the two measurement slots ``[distance-like, angle-like]`` the model fills.
    slots: ClassVar[tuple[bool, bool]] = (True, True)
    #: Which slots are angles (wrapped to ``[-pi, pi)`` in measurements and residuals).
    angular: ClassVar[tuple[bool, bool]] = (False, True)
    #: The Matplotlib marker of its sensors in the rendering, and their legend label
    #: (empty: the name).
    marker: ClassVar[str] = "o"
    label: ClassVar[str] = ""

    RANGE_BEARING: ClassVar[SensorCode] = SensorCode.RANGE_BEARING
    RANGE: ClassVar[SensorCode] = SensorCode.RANGE
    BEARING: ClassVar[SensorCode] = SensorCode.BEARING

    # -- what a subclass defines ---------------------------------------------------------
    def function(
        self, target: FloatArray, sensor: FloatArray, orientation: FloatArray | float = 0.0
    ) -> FloatArray:
        """Return the noise-free measurement (..., 2) of a target at ``target`` (..., 2)
        from a sensor at ``sensor`` (..., 2) facing ``orientation``: unused slots 0, angular
        slots unwrapped or wrapped (the residual wraps them)."""
        raise NotImplementedError(f"{type(self).__name__} must define function()")

    # -- defaults ------------------------------------------------------------------------
    def noise_covar(
        self,
        target: FloatArray,
        sensor: FloatArray,
        sigma_d2: FloatArray | float,
        sigma_theta2: FloatArray | float,
    ) -> FloatArray:
        """Return the measurement noise covariance ``R`` (..., 2, 2), zero rows and columns
        on unused slots: by default ``diag(sigma_d2, sigma_theta2)`` on the used slots."""
        shape = np.broadcast_shapes(
            np.shape(target)[:-1], np.shape(sensor)[:-1], np.shape(sigma_d2), np.shape(sigma_theta2)
        )
        R = np.zeros(shape + (2, 2))
        R[..., 0, 0] = np.broadcast_to(sigma_d2, shape) if self.slots[0] else 0.0
        R[..., 1, 1] = np.broadcast_to(sigma_theta2, shape) if self.slots[1] else 0.0
        return R

    def jacobian(
        self, target: FloatArray, sensor: FloatArray, orientation: FloatArray | float = 0.0
    ) -> FloatArray:
        """Return ``dh / dp_T`` (..., 2, 2) (rows: slots; zero rows for unused slots and at
        zero distance): by default central differences of :meth:`function`, a step of
        :data:`FD_STEP` times the distance, angular differences wrapped."""
        target, sensor = np.asarray(target, np.float64), np.asarray(sensor, np.float64)
        target, sensor = np.broadcast_arrays(target, sensor)
        rel = target - sensor
        n2 = rel[..., 0] ** 2 + rel[..., 1] ** 2
        far = n2 >= ZERO_DISTANCE2
        h = FD_STEP * np.sqrt(np.where(far, n2, 1.0))
        cols = []
        for k in range(2):
            e = np.zeros(2)
            e[k] = 1.0
            step = h[..., None] * e
            diff = self.residual(
                self.function(target + step, sensor, orientation),
                self.function(target - step, sensor, orientation),
            )
            cols.append(diff / (2.0 * h[..., None]))
        H = np.stack(cols, -1)
        return np.where(far[..., None, None], H, 0.0)

    def residual(self, z: FloatArray, z_hat: FloatArray) -> FloatArray:
        """Return ``z - z_hat`` (..., 2): angular slots wrapped, unused slots 0."""
        nu = np.asarray(z, np.float64) - np.asarray(z_hat, np.float64)
        for k in range(2):
            if not self.slots[k]:
                nu[..., k] = 0.0
            elif self.angular[k]:
                nu[..., k] = wrap_angle(nu[..., k])
        return nu

    def measure(
        self,
        target: FloatArray,
        sensor: FloatArray,
        sigma_d2: FloatArray | float,
        sigma_theta2: FloatArray | float,
        normals: FloatArray,
        orientation: FloatArray | float = 0.0,
    ) -> FloatArray:
        """Return a noisy measurement (..., 2): :meth:`function` plus a square root of
        :meth:`noise_covar` times ``normals`` (..., 2) standard normals; angular slots
        wrapped, unused slots 0."""
        z = self.function(target, sensor, orientation)
        R = self.noise_covar(target, sensor, sigma_d2, sigma_theta2)
        used = np.array(self.slots, dtype=np.float64)
        # Cholesky of R on the used slots (a unit diagonal on the unused ones, zeroed after).
        L = np.linalg.cholesky(R + np.diag(1.0 - used)) * used[:, None] * used[None, :]
        z = z + np.einsum("...ij,...j->...i", L, np.asarray(normals, np.float64))
        for k in range(2):
            if not self.slots[k]:
                z[..., k] = 0.0
            elif self.angular[k]:
                z[..., k] = wrap_angle(z[..., k])
        return z

    def _effective(
        self,
        target: FloatArray,
        sensor: FloatArray,
        sigma_d2: FloatArray | float,
        sigma_theta2: FloatArray | float,
        orientation: FloatArray | float,
        pose_cov: FloatArray | None,
    ) -> tuple[FloatArray, FloatArray]:
        """Return ``(H, R_eff^+)`` (..., 2, 2): the Jacobian and the pseudo-inverse of the
        effective noise on the used slots (``R + H Sigma_s H^T``: the sensor's position
        error enters as minus the target's, ``dh/dp_S = -H``)."""
        H = self.jacobian(target, sensor, orientation)
        R = self.noise_covar(target, sensor, sigma_d2, sigma_theta2)
        if pose_cov is not None:
            R = R + H @ np.asarray(pose_cov, np.float64) @ H.mT
        used = np.array(self.slots, dtype=np.float64)
        mask = used[:, None] * used[None, :]
        W = np.linalg.inv(R * mask + np.diag(1.0 - used)) * mask
        return H, W

    def information(
        self,
        rel: FloatArray,
        sigma_d2: FloatArray | float,
        sigma_theta2: FloatArray | float,
        pose_cov: FloatArray | None = None,
        detect: tuple | None = None,
        orientation: FloatArray | float = 0.0,
    ) -> FloatArray:
        """Return the information about the target position (..., 2, 2), PSD, of a sensor
        at offset ``rel = p_S - p_T`` (..., 2) (eq. 10): ``H^T R_eff^+ H``, times the
        detection factor ``p_detect 1[|rel| <= max_range]`` (and the line of sight) when
        ``detect = (p_detect, max_range**2[, seen])``."""
        rel = np.asarray(rel, np.float64)
        target = np.zeros_like(rel)
        H, W = self._effective(target, rel, sigma_d2, sigma_theta2, orientation, pose_cov)
        J = H.mT @ W @ H
        J = 0.5 * (J + J.mT)
        if detect is not None:
            f = sm.detection_factor(rel, detect[0], detect[1])
            if len(detect) > 2:
                f = np.where(detect[2], f, 0.0)
            J = J * np.asarray(f)[..., None, None]
        return J

    def update_terms(
        self,
        z: FloatArray,
        target_hat: FloatArray,
        sensor: FloatArray,
        sigma_d2: FloatArray | float,
        sigma_theta2: FloatArray | float,
        orientation: FloatArray | float = 0.0,
        pose_cov: FloatArray | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """Return the EKF's information terms ``(H^T R_eff^+ H, H^T R_eff^+ nu)`` (..., 2,
        2), (..., 2) at the estimate ``target_hat``, ``nu`` the residual of ``z``."""
        H, W = self._effective(target_hat, sensor, sigma_d2, sigma_theta2, orientation, pose_cov)
        nu = self.residual(z, self.function(target_hat, sensor, orientation))
        HW = H.mT @ W
        Y = HW @ H
        return 0.5 * (Y + Y.mT), np.einsum("...ij,...j->...i", HW, nu)

    # -- identity ------------------------------------------------------------------------
    @property
    def builtin(self) -> bool:
        """Whether this is a built-in model (its compiled kernels apply)."""
        return self.code is not None

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in vars(self).items())
        return f"{type(self).__name__}({args})"


class _BuiltIn(SensorModel):
    """A built-in model: the closed forms of :mod:`activetrack.models.sensor_models`."""

    def function(self, target: Any, sensor: Any, orientation: Any = 0.0) -> FloatArray:
        target, sensor = np.broadcast_arrays(
            np.asarray(target, np.float64), np.asarray(sensor, np.float64)
        )
        phi = np.asarray(orientation, np.float64)[..., None]  # against the sensor axis
        return sm.measure(target, sensor[..., None, :], self.code, phi)[..., 0, :]

    def jacobian(self, target: Any, sensor: Any, orientation: Any = 0.0) -> FloatArray:
        target, sensor = np.broadcast_arrays(
            np.asarray(target, np.float64), np.asarray(sensor, np.float64)
        )
        return sm.jacobian_target(target, sensor[..., None, :], self.code)[..., 0, :, :]

    def information(
        self,
        rel: Any,
        sigma_d2: Any,
        sigma_theta2: Any,
        pose_cov: Any = None,
        detect: tuple | None = None,
        orientation: Any = 0.0,
    ) -> FloatArray:
        w_d, w_t = sm.weights(self.code, sigma_d2, sigma_theta2)
        rel = np.asarray(rel, np.float64)
        return sm._matrix(*sm.information_entries(rel, w_d, w_t, pose_cov, detect))

    def update_terms(
        self,
        z: Any,
        target_hat: Any,
        sensor: Any,
        sigma_d2: Any,
        sigma_theta2: Any,
        orientation: Any = 0.0,
        pose_cov: Any = None,
    ) -> tuple[FloatArray, FloatArray]:
        w_d, w_t = sm.weights(self.code, sigma_d2, sigma_theta2)
        target_hat, sensor = np.broadcast_arrays(
            np.asarray(target_hat, np.float64), np.asarray(sensor, np.float64)
        )
        cov = None if pose_cov is None else np.asarray(pose_cov)[..., None, :, :]
        Y, b = sm.update_terms(
            np.asarray(z)[..., None, :], target_hat, sensor[..., None, :], self.code,
            np.asarray(w_d)[..., None], np.asarray(w_t)[..., None],
            np.asarray(orientation, np.float64)[..., None], cov,
        )  # fmt: skip
        return Y[..., 0, :, :], b[..., 0, :]


class RangeBearing(_BuiltIn):
    """Distance and bearing, eq. (4): ``[|p_T - p_S|, atan2(dy, dx) - phi]``."""

    name = "range_bearing"
    code = int(SensorCode.RANGE_BEARING)
    slots = (True, True)
    marker = "o"
    label = "range & bearing"


class RangeOnly(_BuiltIn):
    """Distance only: ``[|p_T - p_S|, 0]``."""

    name = "range"
    code = int(SensorCode.RANGE)
    slots = (True, False)
    marker = "s"
    label = "range only"


class BearingOnly(_BuiltIn):
    """Bearing only: ``[0, atan2(dy, dx) - phi]``."""

    name = "bearing"
    code = int(SensorCode.BEARING)
    slots = (False, True)
    marker = "^"
    label = "bearing only"


#: The built-in models by name (the strings a scenario accepts), in code order.
BUILT_IN: dict[str, SensorModel] = {m.name: m for m in (RangeBearing(), RangeOnly(), BearingOnly())}


def as_sensor_model(value: object) -> SensorModel:
    """Return the model a scenario's ``sensor_model`` entry names: a built-in's name, or a
    :class:`SensorModel` instance (validated: a name, two slots, not a built-in's name)."""
    if isinstance(value, str):
        if value in BUILT_IN:
            return BUILT_IN[value]
        raise ValueError(
            f"sensor_model must be one of {list(BUILT_IN)} or a SensorModel, got {value!r}"
        )
    if isinstance(value, type) and issubclass(value, SensorModel):
        raise ValueError(
            f"sensor_model must be a SensorModel instance, got the class {value.__name__} (call it)"
        )
    if not isinstance(value, SensorModel):
        raise ValueError(
            f"sensor_model must be one of {list(BUILT_IN)} or a SensorModel, got {value!r}"
        )
    if value.code is not None:
        if type(value) is not type(BUILT_IN.get(value.name)):  # its overrides would not run
            raise ValueError(
                f"sensor_model {type(value).__name__} carries a built-in's code {value.code}:"
                " a model of one's own subclasses SensorModel (code None)"
            )
        return BUILT_IN[value.name]
    if not isinstance(value.name, str) or not value.name or value.name in BUILT_IN:
        raise ValueError(
            f"sensor_model {type(value).__name__}.name must be a new identifier (not one of "
            f"{list(BUILT_IN)}), got {value.name!r}"
        )
    if not any(value.slots) or len(value.slots) != 2 or len(value.angular) != 2:
        raise ValueError(
            f"sensor_model {value.name!r}: slots and angular must be two booleans with at "
            f"least one slot used, got {value.slots!r} and {value.angular!r}"
        )
    return value


def checked(model: SensorModel) -> SensorModel:
    """Return a model of one's own after trying it once on a plain geometry (a sensor 5
    away, unit variances): its measurement (2,), noise (2, 2) and information (2, 2) must
    be finite, the information symmetric PSD; else a ``ValueError`` naming
    ``sensor_model`` (its bug found at validation, not deep inside a step)."""
    target, sensor = np.zeros(2), np.array([3.0, 4.0])
    try:
        z = np.asarray(model.function(target, sensor, 0.0), np.float64)
        R = np.asarray(model.noise_covar(target, sensor, 1.0, 1.0), np.float64)
        J = np.asarray(model.information(sensor - target, 1.0, 1.0), np.float64)
    except Exception as err:  # noqa: BLE001 (any bug of the user's model, reported)
        raise ValueError(
            f"sensor_model {model.name!r} failed on a plain geometry: {type(err).__name__}: {err}"
        ) from err
    shapes = (z.shape, R.shape, J.shape)
    if shapes != ((2,), (2, 2), (2, 2)):
        raise ValueError(
            f"sensor_model {model.name!r}: function, noise_covar and information must return"
            f" shapes (2,), (2, 2), (2, 2) for one sensor, got {shapes}"
        )
    if not (np.all(np.isfinite(z)) and np.all(np.isfinite(R)) and np.all(np.isfinite(J))):
        raise ValueError(f"sensor_model {model.name!r} returned NaN or inf on a plain geometry")
    scale = max(float(np.abs(J).max()), 1e-300)
    if abs(J[0, 1] - J[1, 0]) > 1e-9 * scale or np.linalg.eigvalsh(J)[0] < -1e-9 * scale:
        raise ValueError(f"sensor_model {model.name!r}: information must be symmetric PSD")
    return model


def check_team(name: str, value: object, m: int) -> None:
    """Check that ``value`` is a tuple of ``m`` :class:`SensorModel` (else a ``ValueError``
    naming ``name``)."""
    if (
        not isinstance(value, tuple)
        or len(value) != m
        or not all(isinstance(v, SensorModel) for v in value)
    ):
        raise ValueError(
            f"{name} must be a tuple of {m} activetrack.SensorModel or None, got {value!r}"
        )


def slot_code(model: SensorModel) -> int:
    """Return a model's code, or for a model of one's own the code of the built-in that
    fills the same slots (0 both, 1 the first, 2 the second): what the observation's
    one-hot and the slot masks read (the kernels never run on it)."""
    if model.code is not None:
        return int(model.code)
    return {(True, True): 0, (True, False): 1, (False, True): 2}[tuple(map(bool, model.slots))]


def record(v: object) -> object:
    """Return a ``sensor_model`` entry (or tuple) for a scenario's record: a model of one's
    own as ``{"name": its name, "class": "module.QualifiedName"}``, a name as itself."""
    if isinstance(v, tuple):
        return tuple(record(e) for e in v)
    if isinstance(v, SensorModel):
        cls = type(v)
        return {"name": v.name, "class": f"{cls.__module__}.{cls.__qualname__}"}
    return v
