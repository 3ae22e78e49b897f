"""The planning problem of one time step, eq. (15)-(17), and the planner protocol.

At step k every planner sees the predicted target position ``p_T(k+1|k)`` with its 2x2
covariance, the sensors' current positions and their parameters, and returns the
sensors' next absolute positions minimizing the trace of eq. (17).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from activetrack.linalg2 import inv2, trace_inv2
from activetrack.objective import total_information
from activetrack.validation import FloatArray, as_finite, per_sensor, spd


@dataclass(frozen=True, eq=False)
class PlanningProblem:
    """What every planner needs at one step (arrays are float64, validated on creation).

    Attributes:
        prior_cov: predicted target position covariance ``P(k+1|k)_11``, (2, 2).
        target: predicted target position ``p_T(k+1|k)``, (2,).
        sensors: current sensor positions ``p_S_i(k)``, (M, 2).
        r: per-sensor reach ``vmax_i dt``, (M,) (a scalar broadcasts).
        rho: per-sensor minimum distance to the predicted target, (M,).
        sigma_d2: range noise variances, (M,).
        sigma_theta2: bearing noise variances, (M,).
    """

    prior_cov: FloatArray
    target: FloatArray
    sensors: FloatArray
    r: FloatArray
    rho: FloatArray
    sigma_d2: FloatArray
    sigma_theta2: FloatArray

    def __post_init__(self) -> None:
        sensors = as_finite("sensors", self.sensors)
        if sensors.ndim != 2 or sensors.shape[1] != 2 or sensors.shape[0] < 1:
            raise ValueError(f"sensors must have shape (M, 2) with M >= 1, got {sensors.shape}")
        m = sensors.shape[0]
        prior_cov = spd("prior_cov", self.prior_cov)
        if prior_cov.shape != (2, 2):
            raise ValueError(f"prior_cov must have shape (2, 2), got {prior_cov.shape}")
        fields = {
            "prior_cov": prior_cov,
            "target": as_finite("target", self.target, (2,)),
            "sensors": sensors,
            "r": per_sensor("r", self.r, m, allow_zero=True),
            "rho": per_sensor("rho", self.rho, m, allow_zero=True),
            "sigma_d2": per_sensor("sigma_d2", self.sigma_d2, m),
            "sigma_theta2": per_sensor("sigma_theta2", self.sigma_theta2, m),
        }
        for name, value in fields.items():
            value = np.array(value, dtype=np.float64)
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_sensors(self) -> int:
        """Return M."""
        return int(self.sensors.shape[0])

    @property
    def prior_info(self) -> FloatArray:
        """Return the prior position information ``P(k+1|k)_11^{-1}``."""
        return inv2(self.prior_cov)

    @property
    def rel_sensors(self) -> FloatArray:
        """Return the current sensor positions relative to the predicted target (the ``c_i``)."""
        return self.sensors - self.target

    def trace(self, next_positions: ArrayLike) -> FloatArray:
        """Return the objective of eq. (17) for absolute next positions (..., M, 2)."""
        rel = np.asarray(next_positions, dtype=np.float64) - self.target
        info = total_information(self.prior_info, rel, self.sigma_d2, self.sigma_theta2)
        return trace_inv2(info)

    def violation(self, next_positions: ArrayLike) -> FloatArray:
        """Return each sensor's largest constraint violation (0 when feasible), shape (..., M)."""
        p = np.asarray(next_positions, dtype=np.float64)
        step = np.linalg.norm(p - self.sensors, axis=-1) - self.r
        dist = self.rho - np.linalg.norm(p - self.target, axis=-1)
        return np.maximum(np.maximum(step, dist), 0.0)


@runtime_checkable
class Planner(Protocol):
    """Anything that maps a :class:`PlanningProblem` to next absolute positions (M, 2)."""

    def plan(self, problem: PlanningProblem, rng: np.random.Generator) -> FloatArray: ...
