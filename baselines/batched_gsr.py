"""Compatibility front end of GSR for a batch given as arrays.

:class:`BatchedGSR` is :class:`activetrack.baselines.GSR` (without restarts) on a batched
:class:`activetrack.world.problem.PlanningProblem`: :meth:`BatchedGSR.plan_batch` builds the
problem from arrays and runs GSR's compiled sweeps over the copies
(:func:`activetrack.baselines.gsr.relax_batch`, what ``GSR().plan`` runs on a batched
problem). New code can call ``GSR().plan`` on a batched problem directly.

The batched expert is :class:`activetrack.baselines.GSRPolicy` on the batched
environment's planning problem: ``env.step_positions(expert.plan(env.planning_problem()))``.
"""

from __future__ import annotations

from dataclasses import dataclass

from activetrack.baselines.gsr import (
    GSRBatchResult,
    check_parameters,
    relax_batch,
    warn_warm_roots,
)
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem

#: The result of :meth:`BatchedGSR.plan_batch`: ``positions`` (B, M, 2) absolute,
#: ``value`` (B,), ``sweeps`` (B,).
BatchedGSRResult = GSRBatchResult


@dataclass
class BatchedGSR:
    """Plain GSR (no restarts) for B problems with the same number of sensors M.

    Attributes:
        tol: relative improvement per sweep below which a copy stops (>= 0).
        max_sweeps: at most this many sweeps per copy (>= 1).
        warm_roots: deprecated, no effect (as :class:`activetrack.baselines.GSR`'s).
    """

    tol: float = 1e-9
    max_sweeps: int = 100
    warm_roots: bool | None = None

    def __post_init__(self) -> None:
        check_parameters(self.tol, self.max_sweeps)
        warn_warm_roots(self.warm_roots)

    def plan_batch(
        self,
        prior_cov: FloatArray,
        target: FloatArray,
        sensors: FloatArray,
        r: FloatArray,
        rho: FloatArray,
        sigma_d2: FloatArray,
        sigma_theta2: FloatArray,
    ) -> BatchedGSRResult:
        """Return GSR's next positions for B problems.

        Shapes: ``prior_cov`` (B, 2, 2) predicted position covariances, ``target`` (B, 2),
        ``sensors`` (B, M, 2); the per-sensor parameters are scalars, (M,) or (B, M).
        """
        problem = PlanningProblem(prior_cov, target, sensors, r, rho, sigma_d2, sigma_theta2)
        if len(problem.batch_shape) != 1:
            raise ValueError(
                f"plan_batch takes one batch axis: sensors (B, M, 2), got {problem.sensors.shape}"
            )
        return relax_batch(problem, self.tol, self.max_sweeps)
