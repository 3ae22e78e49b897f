"""The step kernel of the closed tracking loop (Section V), pure and batchable.

:func:`advance` is one step after the sensors have moved: the true target moves with
process noise (eq. 2), every sensor draws its distance and bearing (eq. 4) and the EKF
updates (eq. 11). :class:`LoopParams` holds the scenario's arrays it uses. The stateful
loop around it (initial conditions, random streams, scoring, episode ends, prediction)
is :class:`activetrack.world.World`. :func:`advance_target` is the same step for one of
several targets, with the sensors' measurement models and uncertain position fixes
(:mod:`activetrack.models.sensor_models`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from activetrack._jit import as_rows
from activetrack.estimation import ekf, generic
from activetrack.models import _motion_kernels as mtk
from activetrack.models import sensor_models
from activetrack.models.motion import matrix
from activetrack.validation import FloatArray
from activetrack.world import _loop_kernels as lk
from activetrack.world.scenarios import Scenario


@dataclass(frozen=True, eq=False)
class TargetParams:
    """One target's motion model arrays (eq. 2): ``Phi``, ``Q`` and a square root of ``Q``."""

    Phi: FloatArray
    Q: FloatArray
    noise_factor: FloatArray

    def __post_init__(self) -> None:  # the kernels' arrays: C-contiguous float64
        for name in ("Phi", "Q", "noise_factor"):
            object.__setattr__(self, name, matrix(getattr(self, name)))

    @property
    def dim(self) -> int:
        """Return the state dimension n of this target."""
        return int(self.Phi.shape[0])


@dataclass(frozen=True, eq=False)
class LoopParams:
    """The scenario's arrays used at every step (built once from a :class:`Scenario`).

    ``Phi``, ``Q`` and ``noise_factor`` are the first target's (the only one in the
    paper); ``targets`` holds every target's. ``models`` (M,) int8 and ``weights``
    ``(w_d, w_theta)`` describe the sensors' measurement models (``models`` None: all range
    and bearing, today's arithmetic; the weights are then ``1/sigma^2``); ``pose_cov``
    (M, 2, 2) is the covariance of the
    sensors' position fixes the world draws, ``filter_pose_cov`` the one the filter
    accounts for (None when it ignores it or there is none).
    """

    Phi: FloatArray
    Q: FloatArray
    noise_factor: FloatArray
    sigma_d2: FloatArray
    sigma_theta2: FloatArray
    orientation: FloatArray
    r: FloatArray
    rho: FloatArray
    targets: tuple[TargetParams, ...] = ()
    models: np.ndarray | None = None
    weights: tuple[FloatArray, FloatArray] | None = None
    pose_cov: FloatArray | None = None
    filter_pose_cov: FloatArray | None = None
    max_range: FloatArray | None = None
    p_detect: FloatArray | None = None
    occluders: Any = None  # the fixed activetrack.models.occluders.Occluders, or None
    filter_iterations: int = 1  # 1: the EKF of eq. (11); more: the iterated EKF
    # Every sensor's activetrack.SensorModel when one is not built-in (the generic path,
    # activetrack.estimation.generic), else None (the compiled kernels of the codes).
    sensor_objects: tuple | None = None

    def __post_init__(self) -> None:
        for name in ("Phi", "Q", "noise_factor"):  # as the targets' (C-contiguous float64)
            object.__setattr__(self, name, matrix(getattr(self, name)))
        if not self.targets:
            object.__setattr__(
                self, "targets", (TargetParams(self.Phi, self.Q, self.noise_factor),)
            )

    @property
    def noise_std(self) -> FloatArray:
        """Return the (M, 2) measurement noise standard deviations ``[sigma_d, sigma_theta]``
        (0 for a component a sensor does not measure)."""
        std = self.__dict__.get("_std")
        if std is None:
            std = np.stack([np.sqrt(self.sigma_d2), np.sqrt(self.sigma_theta2)], -1)
            if self.models is not None:
                std = std * sensor_models.USES[self.models]
            object.__setattr__(self, "_std", np.ascontiguousarray(std))
        return std

    @property
    def uses(self) -> np.ndarray:
        """Return the (M, 2) bool table of the components each sensor measures
        (:data:`activetrack.models.sensor_models.USES` of its model)."""
        uses = self.__dict__.get("_uses")
        if uses is None:
            m = self.n_sensors
            uses = np.ones((m, 2), bool) if self.models is None else sensor_models.USES[self.models]
            object.__setattr__(self, "_uses", np.ascontiguousarray(uses))
        return uses

    @classmethod
    def from_scenario(cls, sc: Scenario) -> LoopParams:
        """Return the loop arrays of ``sc``."""
        m = sc.model
        codes = sc.sensor_models
        models = None if not np.any(codes) else codes
        sd2, st2 = sc.per_sensor("sigma_d2"), sc.per_sensor("sigma_theta2")
        # Computed once (for range-and-bearing sensors by the division the filter did per step).
        weights = (
            (1.0 / sd2, 1.0 / st2) if models is None else sensor_models.weights(models, sd2, st2)
        )
        pose = sc.pose_covariances
        return cls(
            m.Phi,
            m.Q,
            m.noise_factor,
            sd2,
            st2,
            sc.per_sensor("orientation"),
            sc.r,
            sc.per_sensor("rho"),
            tuple(TargetParams(t.Phi, t.Q, t.noise_factor) for t in sc.target_models),
            models,
            weights,
            pose,
            pose if sc.account_pose else None,
            sc.max_ranges,
            sc.detection_probs,
            sc.occluder_set,
            sc.filter_iterations,
            None if sc.capabilities.builtin_sensors else sc.sensor_objects,
        )

    @property
    def n_sensors(self) -> int:
        """Return M."""
        return int(self.sigma_d2.shape[0])

    @property
    def n_noise(self) -> int:
        """Return the standard normals one step consumes: ``sum_k n_k + 2MK`` (process noise
        of every target, then every target's measurements, sensor-major), ``+ 2M`` for the
        sensors' position fixes when they are uncertain, ``+ MK`` for the detection draws
        when some ``p_detect < 1`` (target-major). The paper: ``n + 2M``."""
        m, kk = self.n_sensors, len(self.targets)
        pose = 2 * m if self.pose_cov is not None else 0
        detect = m * kk if self.p_detect is not None else 0
        return sum(t.dim for t in self.targets) + 2 * m * kk + pose + detect

    @property
    def detect_threshold(self) -> FloatArray | None:
        """Return the (M,) thresholds of the detection draws: a sensor detects a target
        when its standard normal is below ``Phi^{-1}(p_detect)`` (probability ``p_detect``;
        ``-inf`` for 0 and ``+inf`` for 1)."""
        if self.p_detect is None:
            return None
        t = self.__dict__.get("_threshold")
        if t is None:
            from scipy.special import ndtri  # noqa: PLC0415 (limited sensing only)

            t = ndtri(self.p_detect)
            object.__setattr__(self, "_threshold", t)
        return t


def advance(
    params: LoopParams,
    x_true: FloatArray,
    x_pred: FloatArray,
    P_pred: FloatArray,
    sensors: FloatArray,
    noise: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Return ``(x_true(k+1), z(k+1), x_hat(k+1|k+1), P(k+1|k+1))``, batched over leading axes.

    One target (the first), sensors at known positions: ``sensors`` are the sensors' new
    positions ``p_S(k+1)`` and ``noise`` holds the step's ``n + 2M`` standard normals
    (shape (..., n + 2M); further normals, such as the detection draws of limited sensing,
    are not read: every sensor measures). :func:`advance_target` is the general step of
    one target.
    """
    n, m = x_true.shape[-1], params.n_sensors
    return advance_target(
        params, params.targets[0], x_true, x_pred, P_pred, sensors, sensors,
        noise[..., :n], noise[..., n : n + 2 * m],
    )  # fmt: skip


def advance_target(
    params: LoopParams,
    target: TargetParams,
    x_true: FloatArray,
    x_pred: FloatArray,
    P_pred: FloatArray,
    sensors: FloatArray,
    fixes: FloatArray,
    process_noise: FloatArray,
    measurement_noise: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Return one target's ``(x_true(k+1), z(k+1), x_hat(k+1|k+1), P(k+1|k+1))``, batched.

    The true target moves (eq. 2) with ``process_noise`` (..., n) standard normals; every
    sensor measures it from its true position ``sensors`` (..., M, 2) (eq. 4, its model's
    components; ``measurement_noise`` (..., 2M) standard normals, sensor-major); the EKF
    (eq. 11) updates at the position fixes ``fixes`` the team believes (the same array
    when poses are known), with ``params.filter_pose_cov`` in its noise.
    """
    x_next = move_target(target, x_true, process_noise)
    z = measure(params, x_next[..., :2], sensors, measurement_noise)
    x_post, P_post = filter_update(params, x_pred, P_pred, z, fixes)
    return x_next, z, x_post, P_post


def move_target(target: TargetParams, x_true: FloatArray, process_noise: FloatArray) -> FloatArray:
    """Return the true target's next state (eq. 2) from ``process_noise`` (..., n) normals
    (:func:`activetrack.models._motion_kernels.move_target_into`; the two batch shapes
    broadcast)."""
    n = target.dim
    if x_true.shape[-1:] != (n,) or process_noise.shape[-1:] != (n,):
        raise ValueError(
            f"move_target needs x_true and process_noise of shape (..., {n}), got"
            f" {x_true.shape} and {process_noise.shape}"
        )
    batch = _batch(x_true.shape[:-1], process_noise.shape[:-1])
    out = np.empty(batch + (n,))
    mtk.move_target_rows(
        target.Phi, target.noise_factor, as_rows(x_true, batch, (n,)),
        as_rows(process_noise, batch, (n,)), out.reshape(-1, n),
    )  # fmt: skip
    return out


def _batch(first: tuple[int, ...], second: tuple[int, ...]) -> tuple[int, ...]:
    """Return the batch shape two arguments broadcast to (the first when they agree)."""
    return first if first == second else np.broadcast_shapes(first, second)


def measure(
    params: LoopParams, positions: FloatArray, sensors: FloatArray, noise: FloatArray
) -> FloatArray:
    """Return every sensor's noisy measurement (eq. 4) of targets at ``positions``.

    One target: ``positions`` (..., 2), ``noise`` (..., 2M) -> (..., M, 2); K targets in one
    call: ``positions`` (..., K, 2), ``noise`` (..., 2MK) target-major -> (..., K, M, 2).
    ``sensors`` (..., M, 2) are the true positions. Bearings are wrapped once, after the
    noise; a component a sensor's model does not measure is exactly 0
    (:func:`activetrack.world._loop_kernels.measure_point`).
    """
    one = positions.ndim <= sensors.ndim - 1  # else a target axis before the sensors'
    targets = positions[..., None, :] if one else positions
    k, m = targets.shape[-2], sensors.shape[-2]
    if m != params.n_sensors or positions.shape[-1:] != (2,) or sensors.shape[-1:] != (2,):
        raise ValueError(
            f"measure needs sensors (..., {params.n_sensors}, 2) and positions (..., 2) or"
            f" (..., K, 2), got {sensors.shape} and {positions.shape}"
        )
    batch = _batch(targets.shape[:-2], sensors.shape[:-2])
    if params.sensor_objects is not None:  # a model of one's own: the generic path
        out = generic.measure(
            params.sensor_objects, targets, sensors, params.sigma_d2, params.sigma_theta2,
            params.orientation, noise,
        )  # fmt: skip
        return out[..., 0, :, :] if one else out
    out = np.empty(batch + (k, m, 2))
    lk.measure_rows(
        as_rows(targets, batch, (k, 2)), as_rows(sensors, batch, (m, 2)),
        params.orientation, params.noise_std, params.uses,
        as_rows(np.reshape(noise, batch + (2 * m * k,)), batch, (2 * m * k,)),
        out.reshape(-1, k, m, 2),
    )  # fmt: skip
    return out[..., 0, :, :] if one else out


def detections(
    params: LoopParams,
    positions: FloatArray,
    sensors: FloatArray,
    draws: FloatArray | None,
    occluders: Any = None,
) -> np.ndarray | None:
    """Return which sensor detects which target this step, (..., K, M) bool, or None (all).

    A sensor detects a target when it is within its ``max_range`` of the target's true
    position ``positions`` (..., K, 2), the segment between them is not blocked by an
    occluder of ``occluders`` (the episode's layout, an
    :class:`activetrack.models.occluders.Occluders`, batched over the leading axis when each copy
    has its own; :func:`activetrack.models.occluders.line_of_sight`), and its standard normal
    ``draws`` (..., K M, target-major) is below :attr:`LoopParams.detect_threshold`.
    """
    if params.max_range is None and params.p_detect is None and occluders is None:
        return None
    shape = positions.shape[:-1] + (params.n_sensors,)
    seen = np.ones(shape, dtype=bool)
    if params.max_range is not None:
        rel = sensors[..., None, :, :] - positions[..., :, None, :]
        seen &= sensor_models.in_range(rel, params.max_range**2)
    if params.p_detect is not None:
        seen &= draws.reshape(shape) < params.detect_threshold
    if occluders is not None:
        from activetrack.models.occluders import line_of_sight  # noqa: PLC0415 (occluded scenarios)

        seen = line_of_sight(sensors, positions, occluders, where=seen)
    return seen


def filter_update(
    params: LoopParams,
    x_pred: FloatArray,
    P_pred: FloatArray,
    z: FloatArray,
    fixes: FloatArray,
    detected: np.ndarray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Return one target's EKF posterior (eq. 11) from its measurements ``z`` (..., M, 2)
    taken by sensors the team believes at ``fixes``; only the sensors ``detected`` (..., M)
    measured it (None: every sensor)."""
    iterations = params.filter_iterations
    if params.sensor_objects is not None:  # a model of one's own: the generic path
        return generic.update(
            params.sensor_objects, x_pred, P_pred, z, fixes, params.sigma_d2,
            params.sigma_theta2, params.orientation, detected, params.filter_pose_cov,
            iterations,
        )  # fmt: skip
    if (
        params.models is None
        and params.filter_pose_cov is None
        and detected is None
        and iterations == 1
    ):
        return ekf.update(
            x_pred, P_pred, z, fixes, params.sigma_d2, params.sigma_theta2, params.orientation,
            weights=params.weights,
        )  # fmt: skip
    return ekf.update(
        x_pred, P_pred, z, fixes, params.sigma_d2, params.sigma_theta2, params.orientation,
        detected, models=params.models, weights=params.weights, pose_cov=params.filter_pose_cov,
        iterations=iterations,
    )  # fmt: skip
