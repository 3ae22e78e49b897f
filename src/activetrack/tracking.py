"""The step kernel of the closed tracking loop (Section V), pure and batchable.

:func:`advance` is one step after the sensors have moved: the true target moves with
process noise (eq. 2), every sensor draws its distance and bearing (eq. 4) and the EKF
updates (eq. 11). :class:`LoopParams` holds the scenario's arrays it uses. The stateful
loop around it (initial conditions, random streams, scoring, episode ends, prediction)
is :class:`activetrack.world.World`.
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
    measurement.wrap_angle(z[..., 1], inplace=True)  # wrapped once, after the noise
    x_post, P_post = ekf.update(
        x_pred, P_pred, z, sensors, params.sigma_d2, params.sigma_theta2, params.orientation
    )
    return x_next, z, x_post, P_post
