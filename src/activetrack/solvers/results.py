"""The results of the single-sensor solver (problem Pi_3, eq. 22-24): one and batched."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from activetrack.validation import FloatArray


@dataclass(frozen=True, init=False)
class SingleSensorSolution:
    """The solution of one single-sensor problem.

    Attributes:
        s: optimal next position relative to the predicted target, original frame, (2,).
        value: ``f0(s)``, the trace of the posterior position covariance at ``s`` (eq. 22).
        case: 1, 2, 3 (paper Fig. 3) or 4 (target within reach, ``||c|| <= r``).
        feasible: whether the constraints (23)-(24) can be met (and ``s`` meets them).
    """

    s: FloatArray
    value: float
    case: int
    feasible: bool

    def __init__(self, s: FloatArray, value: float, case: int, feasible: bool) -> None:
        # The generated __init__ of a frozen dataclass sets each field through
        # object.__setattr__, a noticeable share of a scalar solve; one dict update is
        # cheaper and leaves the instance the same.
        self.__dict__.update(s=s, value=value, case=case, feasible=feasible)


@dataclass(frozen=True)
class BatchSolution:
    """The solutions of ``B`` single-sensor problems (fields as in SingleSensorSolution).

    Attributes:
        s: (B, 2) optimal relative positions, original frame.
        value: (B,) objective values.
        case: (B,) int cases 1-4.
        feasible: (B,) bool.
    """

    s: FloatArray
    value: FloatArray
    case: np.ndarray
    feasible: np.ndarray
