"""The closed tracking loop of Section V as pure, batchable functions.

One time step, in the paper's order: from the prediction ``x_hat(k+1|k), P(k+1|k)`` a
planner chooses the sensors' next positions; then :func:`advance` moves the true target
with process noise (eq. 2), draws every sensor's distance and bearing (eq. 4), updates
the EKF (eq. 11) and returns the posterior; :func:`~activetrack.motion.predict` gives the
next prediction (eq. 3).

Randomness: each step consumes exactly ``n + 2M`` standard normals from the episode's
generator (``n`` process, then ``2M`` measurement noise, sensor-major), so that the
simulation runner, the single environment and the batched environment reproduce one
another draw for draw from the same seed. :func:`initial_conditions` consumes ``2M``
uniforms for the sensors, then ``n`` normals if the target's start is drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from activetrack import ekf, measurement
from activetrack.scenarios import Scenario
from activetrack.validation import FloatArray


@dataclass(frozen=True, eq=False)
class LoopParams:
    """The scenario's arrays used at every step (built once from a :class:`Scenario`)."""

    Phi: FloatArray
    Q: FloatArray
    noise_factor: FloatArray
    sigma_d2: FloatArray
    sigma_theta2: FloatArray
    orientation: FloatArray
    r: FloatArray
    rho: FloatArray

    @property
    def noise_std(self) -> FloatArray:
        """Return the (M, 2) measurement noise standard deviations ``[sigma_d, sigma_theta]``."""
        std = self.__dict__.get("_std")
        if std is None:
            std = np.stack([np.sqrt(self.sigma_d2), np.sqrt(self.sigma_theta2)], -1)
            object.__setattr__(self, "_std", std)
        return std

    @classmethod
    def from_scenario(cls, sc: Scenario) -> LoopParams:
        """Return the loop arrays of ``sc``."""
        m = sc.model
        return cls(
            m.Phi,
            m.Q,
            m.noise_factor,
            sc.per_sensor("sigma_d2"),
            sc.per_sensor("sigma_theta2"),
            sc.per_sensor("orientation"),
            sc.r,
            sc.per_sensor("rho"),
        )

    @property
    def n_noise(self) -> int:
        """Return the number of standard normals one step consumes: n + 2M."""
        return self.Phi.shape[0] + 2 * self.sigma_d2.shape[0]


def initial_conditions(
    sc: Scenario, rng: np.random.Generator
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Return ``(x_true(0), x_hat(0|0), P(0|0), sensors(0))`` drawn for one episode."""
    m = sc.n_sensors
    u = rng.random((m, 2))
    radius = sc.sensor_radius * np.sqrt(u[:, 0])  # uniform by area
    angle = 2.0 * np.pi * u[:, 1]
    sensors = np.asarray(sc.sensor_center) + radius[:, None] * np.stack(
        [np.cos(angle), np.sin(angle)], -1
    )
    x_hat = np.asarray(sc.x0_hat, dtype=np.float64).copy()
    P0 = sc.initial_cov
    if sc.target_init == "gaussian":
        x_true = x_hat + np.linalg.cholesky(P0) @ rng.standard_normal(x_hat.shape[0])
    else:
        x_true = np.asarray(sc.x0, dtype=np.float64).copy()
    return x_true, x_hat, P0, sensors


def advance(
    params: LoopParams,
    x_true: FloatArray,
    x_pred: FloatArray,
    P_pred: FloatArray,
    sensors: FloatArray,
    noise: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Return ``(x_true(k+1), z(k+1), x_hat(k+1|k+1), P(k+1|k+1))``, batched over leading axes.

    ``sensors`` are the sensors' new positions ``p_S(k+1)`` and ``noise`` holds the step's
    ``n + 2M`` standard normals (shape (..., n + 2M)).
    """
    n = x_true.shape[-1]
    x_next = x_true @ params.Phi.T + noise[..., :n] @ params.noise_factor.T
    z = measurement.range_bearing(x_next[..., :2], sensors, params.orientation, wrap=False)
    z += noise[..., n:].reshape(*noise.shape[:-1], -1, 2) * params.noise_std
    z[..., 1] = measurement.wrap_angle(z[..., 1])  # wrapped once, after the noise
    x_post, P_post = ekf.update(
        x_pred, P_pred, z, sensors, params.sigma_d2, params.sigma_theta2, params.orientation
    )
    return x_next, z, x_post, P_post
