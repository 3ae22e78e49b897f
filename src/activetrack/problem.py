"""The planning problem of one time step, eq. (15)-(17), and the planner protocol.

At step k every planner sees the predicted target position ``p_T(k+1|k)`` with its 2x2
covariance, the sensors' current positions and their parameters, and returns the
sensors' next absolute positions minimizing the objective of eq. (17) (by default the
trace of the posterior position covariance, :data:`activetrack.objective.TRACE`) subject
to the reach (eq. 15) and the minimum distance (eq. 16).

A :class:`PlanningProblem` holds one such problem or a batch of independent ones (an
optional leading batch axis on every array, e.g. the copies of a batched environment);
planners return next positions of shape ``batch_shape + (M, 2)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from functools import cached_property
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from activetrack.linalg2 import inv2
from activetrack.objective import TRACE, TraceObjective, total_information
from activetrack.validation import FloatArray, as_finite, positive, spd

#: The per-sensor parameters and whether 0 is allowed.
_PER_SENSOR = (("r", True), ("rho", True), ("sigma_d2", False), ("sigma_theta2", False))


@dataclass(frozen=True, eq=False)
class PlanningProblem:
    """What every planner needs at one step (arrays are float64, validated on creation).

    Every array may carry the same leading batch axes ``...`` (or axes that broadcast to
    them): then the object holds ``batch_shape`` independent problems with the same number
    of sensors M. Arrays are stored broadcast to the batch shape, read-only.

    Attributes:
        prior_cov: predicted target position covariance ``P(k+1|k)_11``, (..., 2, 2).
        target: predicted target position ``p_T(k+1|k)``, (..., 2).
        sensors: current sensor positions ``p_S_i(k)``, (..., M, 2).
        r: per-sensor reach ``vmax_i dt``, (..., M) (a scalar or (M,) broadcasts).
        rho: per-sensor minimum distance to the predicted target, (..., M).
        sigma_d2: range noise variances, (..., M).
        sigma_theta2: bearing noise variances, (..., M).
        objective: the function of the total information that planners minimize
            (:data:`activetrack.objective.TRACE`, eq. 17).
    """

    prior_cov: FloatArray
    target: FloatArray
    sensors: FloatArray
    r: FloatArray
    rho: FloatArray
    sigma_d2: FloatArray
    sigma_theta2: FloatArray
    objective: TraceObjective = TRACE

    def __post_init__(self) -> None:
        sensors = as_finite("sensors", self.sensors)
        if sensors.ndim < 2 or sensors.shape[-1] != 2 or sensors.shape[-2] < 1:
            raise ValueError(
                f"sensors must have shape (..., M, 2) with M >= 1, got {sensors.shape}"
            )
        m = sensors.shape[-2]
        prior_cov = spd("prior_cov", self.prior_cov)
        if prior_cov.shape[-2:] != (2, 2):
            raise ValueError(f"prior_cov must have shape (..., 2, 2), got {prior_cov.shape}")
        target = as_finite("target", self.target)
        if target.ndim < 1 or target.shape[-1] != 2:
            raise ValueError(f"target must have shape (..., 2), got {target.shape}")
        values = {"prior_cov": prior_cov, "target": target, "sensors": sensors}
        batch_of = {
            "prior_cov": prior_cov.shape[:-2],
            "target": target.shape[:-1],
            "sensors": sensors.shape[:-2],
        }
        for name, allow_zero in _PER_SENSOR:
            arr = positive(name, getattr(self, name), allow_zero=allow_zero)
            if arr.ndim > 0 and arr.shape[-1] != m:
                raise ValueError(
                    f"{name} must be a scalar or have shape (..., {m}) (one entry per sensor), "
                    f"got {arr.shape}"
                )
            values[name] = arr
            batch_of[name] = arr.shape[:-1]
        batch = _broadcast(batch_of)
        if not all(hasattr(self.objective, a) for a in ("name", "of_information")):
            raise ValueError(
                f"objective must be an objective such as activetrack.objective.TRACE, "
                f"got {self.objective!r}"
            )
        trailing = {"prior_cov": (2, 2), "target": (2,), "sensors": (m, 2)}
        for name, value in values.items():
            shape = batch + trailing.get(name, (m,))
            if value.ndim == 0:
                value = np.full(shape, float(value))
            else:  # a copy the caller cannot change
                value = np.array(np.broadcast_to(value, shape) if value.shape != shape else value)
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @classmethod
    def _validated(cls, **values: Any) -> PlanningProblem:
        """Return a problem from already validated, converted arrays (no checks, no copies)."""
        out = object.__new__(cls)
        for name, value in values.items():
            object.__setattr__(out, name, value)
        return out

    @classmethod
    def stack(cls, problems: Sequence[PlanningProblem]) -> PlanningProblem:
        """Return the batch (B,) of single problems with the same M and objective."""
        if not problems:
            raise ValueError("problems must hold at least one problem")
        objective = problems[0].objective
        if any(p.objective is not objective for p in problems):
            raise ValueError("problems must all have the same objective")
        arrays = {
            f.name: np.stack([getattr(p, f.name) for p in problems])
            for f in fields(cls)
            if f.name != "objective"
        }
        return cls(**arrays, objective=objective)

    def __getitem__(self, index: Any) -> PlanningProblem:
        """Return the problem(s) at ``index`` of the batch axes (``problem[i]``: copy ``i``)."""
        if not self.batch_shape:
            raise TypeError("a single planning problem (batch_shape ()) cannot be indexed")
        np.empty(self.batch_shape, dtype=bool)[index]  # IndexError for indices past the batch
        values = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name != "objective":
                value = np.array(value[index])
                value.setflags(write=False)
            values[f.name] = value
        return self._validated(**values)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Return the batch axes, ``()`` for a single problem."""
        return self.target.shape[:-1]

    @property
    def n_sensors(self) -> int:
        """Return M."""
        return int(self.sensors.shape[-2])

    @cached_property
    def prior_info(self) -> FloatArray:
        """Return the prior position information ``P(k+1|k)_11^{-1}``, (..., 2, 2), read-only."""
        info = inv2(self.prior_cov)
        info.setflags(write=False)
        return info

    @property
    def rel_sensors(self) -> FloatArray:
        """Return the current sensor positions relative to the predicted target (the ``c_i``)."""
        return self.sensors - self.target[..., None, :]

    def score(self, next_positions: ArrayLike) -> FloatArray:
        """Return the objective of eq. (17) at absolute next positions (..., M, 2).

        The batch axes of ``next_positions`` (just before ``(M, 2)``) match the problem's;
        any further leading axes (candidates) broadcast. Shape: the leading axes.
        """
        rel = np.asarray(next_positions, dtype=np.float64) - self.target[..., None, :]
        info = total_information(self.prior_info, rel, self.sigma_d2, self.sigma_theta2)
        return self.objective.of_information(info)

    def trace(self, next_positions: ArrayLike) -> FloatArray:
        """Return :meth:`score` (the name from when the trace was the only objective)."""
        return self.score(next_positions)

    def violation(self, next_positions: ArrayLike) -> FloatArray:
        """Return each sensor's largest constraint violation (0 when feasible), shape (..., M)."""
        p = np.asarray(next_positions, dtype=np.float64)
        step = np.linalg.norm(p - self.sensors, axis=-1) - self.r
        dist = self.rho - np.linalg.norm(p - self.target[..., None, :], axis=-1)
        return np.maximum(np.maximum(step, dist), 0.0)


def _broadcast(batch_of: dict[str, tuple[int, ...]]) -> tuple[int, ...]:
    """Return the broadcast of the fields' batch shapes, or raise naming them all."""
    shapes = list(batch_of.values())
    if all(sh == shapes[0] for sh in shapes):  # the common case, without numpy's helper
        return shapes[0]
    try:
        return np.broadcast_shapes(*shapes)
    except ValueError:
        listed = ", ".join(f"{k} {v}" for k, v in batch_of.items())
        raise ValueError(f"the batch axes of the fields do not broadcast: {listed}") from None


@runtime_checkable
class Planner(Protocol):
    """Anything that maps a :class:`PlanningProblem` to next absolute positions.

    The result has shape ``problem.batch_shape + (M, 2)``.
    """

    def plan(self, problem: PlanningProblem, rng: np.random.Generator) -> FloatArray: ...
