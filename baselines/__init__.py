"""The planners of the paper and the closed-loop simulation that compares them (Section V).

- :class:`GSR`: Gauss-Seidel relaxation over the analytic single-sensor optimum
  (Section IV-B, eq. 38), on one problem or a batch (one vectorized sweep over the
  copies), optionally with restarts that escape its local optima.
- :class:`GBES`: grid-based exhaustive search over the curves ADB (exact grid optimum).
- :class:`RandomMotion`: each sensor to a uniformly random point of its curve ADB.
- :class:`Lookahead` / :class:`LookaheadPlanner`: a receding-horizon planner that scores
  H steps of team motion in the deterministic covariance model (eq. 3, 11, 17).
- :class:`GSRPolicy`, :class:`GBESPolicy`, :class:`RMPolicy`, :class:`LookaheadPolicy`:
  the planners as expert policies for the environments (planning problems to next
  positions);
- :func:`simulate` / :func:`run_monte_carlo`: a planner driving the closed tracking loop
  (:class:`activetrack.world.World`) with per-step metrics, over seeds;
- :func:`evaluate` / :func:`summaries`: policies (planners or policy files) on the same
  held-out seeds, paired with GSR; :func:`map_seeds`: a function of seeds on Ray workers,
  equal to the serial loop (both imported on first use: they bring the plotting and Ray
  helpers).

A planner is anything with ``plan(problem, rng) -> next_positions`` of shape
``problem.batch_shape + (M, 2)``, see :class:`activetrack.Planner`.
"""

from activetrack.baselines._common import random_problem
from activetrack.baselines.gbes import GBES, GBESResult
from activetrack.baselines.gsr import GSR, GSRBatchResult, GSRResult
from activetrack.baselines.lookahead import Lookahead, LookaheadPlanner, LookaheadResult
from activetrack.baselines.policies import (
    GBESPolicy,
    GSRPolicy,
    LookaheadPolicy,
    PlannerPolicy,
    RMPolicy,
)
from activetrack.baselines.random_motion import RandomMotion
from activetrack.baselines.simulation import (
    MonteCarloResult,
    RunRecord,
    mean_ci,
    run_monte_carlo,
    simulate,
)

__all__ = [
    "GBES",
    "GBESPolicy",
    "GBESResult",
    "GSR",
    "GSRBatchResult",
    "GSRPolicy",
    "GSRResult",
    "Lookahead",
    "LookaheadPlanner",
    "LookaheadPolicy",
    "LookaheadResult",
    "MonteCarloResult",
    "PlannerPolicy",
    "RMPolicy",
    "RandomMotion",
    "RunRecord",
    "mean_ci",
    "random_problem",
    "run_monte_carlo",
    "evaluate",
    "map_seeds",
    "simulate",
    "summaries",
]

#: Public names imported on first use (module attribute -> the module that holds it).
_LAZY = {
    "evaluate": "activetrack.baselines.evaluation",
    "summaries": "activetrack.baselines.evaluation",
    "map_seeds": "activetrack.baselines.distributed",
}


def __getattr__(name: str):
    """Return the lazily imported public names of :data:`_LAZY`."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
