"""The planners of Section V as expert policies for the tracking environments.

An expert reads the environment's planning problem (the prediction ``x_hat(k+1|k),
P(k+1|k)`` and the team, eq. 15-17; with a leading batch axis for the batched
environment) and returns the sensors' next absolute positions, which the environment
executes directly (``step_positions``): no actions, no round trip. The planner draws from
the policy's own generator, seeded like the simulation runner's
(``np.random.default_rng([seed, 1])``), so an episode run through the environment with
``reset(seed=s)`` and a policy made with ``seed=s`` reproduces
:func:`activetrack.baselines.simulation.simulate` with seed ``s`` exactly.

Example::

    from activetrack import envs
    from activetrack.baselines import GSRPolicy

    env = envs.parallel_env(scenario="paper")
    expert = GSRPolicy(seed=0)
    obs, infos = env.reset(seed=0)
    while env.agents:
        obs, rewards, terms, truncs, infos = env.step_positions(
            expert.plan(env.planning_problem())
        )

Users who need the actions behind an expert's positions (imitation labels) get them from
:func:`activetrack.kinematics.sensor_motion.actions_to_reach`.

The team rule ``d_sep`` (a problem's ``d_sep``): GSR, GBES and RM keep it in their own
search (:mod:`activetrack.baselines.gsr_separation`); the plan of any other planner (one
without ``keeps_d_sep = True``, e.g. the look-ahead) goes through
:func:`activetrack.baselines.separated.separate` first, so every expert's plan is one the
world executes as given.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.validation import FloatArray
from activetrack.world import planning_prediction
from activetrack.world.problem import Planner, PlanningProblem


class PlannerPolicy:
    """Any :class:`~activetrack.Planner` as an expert: planning problems to next positions.

    Args:
        planner: the planner; ``plan(problem, rng) -> (..., M, 2)`` absolute next positions.
        seed: seeds the planner generator as ``np.random.default_rng([seed, 1])``, the
            simulation runner's; ``None`` for fresh entropy.
        prediction: which prediction the planner plans from
            (:mod:`activetrack.world.planning_prediction`): ``"mixture"`` (the default)
            the filter's (with an IMM its predicted mixture's moments), an int ``j`` the
            IMM's mode j's prediction alone (0 with the EKF, its own).
    """

    def __init__(
        self, planner: Planner, seed: int | None = None, prediction: str | int = "mixture"
    ) -> None:
        self.planner = planner
        self.prediction = planning_prediction.checked(prediction)
        self.reset(seed)

    def reset(self, seed: int | None = None) -> None:
        """Re-seed the planner generator (as the runner does for world seed ``seed``)."""
        self.rng = np.random.default_rng() if seed is None else np.random.default_rng([seed, 1])

    def plan(self, problem: PlanningProblem) -> FloatArray:
        """Return the next absolute positions for ``problem``, shape (..., M, 2), float64
        (planned from :attr:`prediction`'s problem)."""
        problem = planning_prediction.chosen(problem, self.prediction)
        nxt = np.asarray(self.planner.plan(problem, self.rng), dtype=np.float64)
        if nxt.shape != problem.sensors.shape:
            raise ValueError(
                f"planner {self.planner!r} returned shape {nxt.shape}, "
                f"expected {problem.sensors.shape}"
            )
        if not getattr(self.planner, "keeps_d_sep", False):
            from activetrack.baselines import gsr_separation, separated  # noqa: PLC0415

            if gsr_separation.pair_matrix(problem) is not None:
                nxt = separated.separate(problem, nxt, problem.d_sep)
        return nxt

    __call__ = plan

    def check(self, problem: PlanningProblem) -> None:
        """Raise the planner's ValueError if its settings cannot plan ``problem`` (a
        planner without ``check`` can plan every problem), or the ValueError of a
        :attr:`prediction` the problem's filter does not have."""
        problem = planning_prediction.chosen(problem, self.prediction)
        check = getattr(self.planner, "check", None)
        if callable(check):
            check(problem)

    def __repr__(self) -> str:
        own = "" if self.prediction == "mixture" else f", prediction={self.prediction!r}"
        return f"{type(self).__name__}({self.planner!r}{own})"


class GSRPolicy(PlannerPolicy):
    """Gauss-Seidel relaxation (Section IV-B) as a policy; ``planner_kwargs`` go to ``GSR``
    (``prediction``: :class:`PlannerPolicy`'s)."""

    def __init__(
        self, seed: int | None = None, prediction: str | int = "mixture", **planner_kwargs: Any
    ) -> None:
        from activetrack.baselines.gsr import GSR

        super().__init__(GSR(**planner_kwargs), seed, prediction)


class DistributedGSRPolicy(PlannerPolicy):
    """GSR by message passing inside each connected group, each robot on its own estimate
    (:class:`~activetrack.baselines.distributed_gsr.DistributedGSR`, issue 37) as a policy;
    ``planner_kwargs`` go to ``DistributedGSR`` (``prediction``: :class:`PlannerPolicy`'s).
    On a central team it is GSR."""

    def __init__(
        self, seed: int | None = None, prediction: str | int = "mixture", **planner_kwargs: Any
    ) -> None:
        from activetrack.baselines.distributed_gsr import DistributedGSR

        super().__init__(DistributedGSR(**planner_kwargs), seed, prediction)


class DistributedLookaheadPolicy(PlannerPolicy):
    """The look-ahead run per connected group by the group's leader on its own estimate
    (:class:`~activetrack.baselines.group_planner.GroupPlanner`, issue 37); ``settings``
    as :class:`LookaheadPolicy`'s. On a central team it is the look-ahead."""

    def __init__(
        self, seed: int | None = None, prediction: str | int = "mixture", **settings: Any
    ) -> None:
        from activetrack.baselines.group_planner import GroupPlanner
        from activetrack.baselines.lookahead import LookaheadPlanner

        super().__init__(GroupPlanner(lambda: LookaheadPlanner(None, **settings)), seed, prediction)

    def reset(self, seed: int | None = None) -> None:
        """Re-seed and forget the episode (every group's planner)."""
        super().reset(seed)
        self.planner.reset()


class GBESPolicy(PlannerPolicy):
    """Grid-based exhaustive search (Section V) as a policy; kwargs go to ``GBES``
    (``prediction``: :class:`PlannerPolicy`'s)."""

    def __init__(
        self, seed: int | None = None, prediction: str | int = "mixture", **planner_kwargs: Any
    ) -> None:
        from activetrack.baselines.gbes import GBES

        super().__init__(GBES(**planner_kwargs), seed, prediction)


class RMPolicy(PlannerPolicy):
    """Random motion on the curves ADB (Section V) as a policy (``prediction``:
    :class:`PlannerPolicy`'s)."""

    def __init__(
        self, seed: int | None = None, prediction: str | int = "mixture", **planner_kwargs: Any
    ) -> None:
        from activetrack.baselines.random_motion import RandomMotion

        super().__init__(RandomMotion(**planner_kwargs), seed, prediction)


class LookaheadPolicy(PlannerPolicy):
    """The receding-horizon planner as a policy (:class:`~activetrack.baselines.lookahead.
    LookaheadPlanner`); ``settings`` go to :class:`~activetrack.baselines.lookahead.Lookahead`.

    It plans from the prediction the planning problem carries (``problem.prediction``, set
    by the world; ``prediction``: :class:`PlannerPolicy`'s), for any scenario and in any
    order of problems. ``scenario`` matters only for problems without a prediction (built
    by hand): the planner then recovers it from the episode's problems, seen in order, of
    that scenario (``None``: the matching preset). :meth:`reset` starts a new episode (no
    warm start from the last plan).

    Cost: on the occluded tasks its GSR rollout runs GSR's numerical steps H times per
    step; with the default settings (horizon 10) one episode took a median 354 ms of CPU
    per step on ``urban`` and 666 ms on ``urban_random`` (GSR alone: 24 and 22 ms), with
    ``OPENBLAS_NUM_THREADS=1 python benchmarks/time_lookahead.py --scenario urban
    --episodes 1``; ``evaluate --batched`` plans all episodes at once. The README's urban
    rows were measured with the previous default settings.
    """

    def __init__(
        self,
        seed: int | None = None,
        scenario: Any = "paper",
        prediction: str | int = "mixture",
        **settings: Any,
    ) -> None:
        from activetrack.baselines.lookahead import LookaheadPlanner

        super().__init__(LookaheadPlanner(scenario, **settings), seed, prediction)

    def reset(self, seed: int | None = None) -> None:
        """Re-seed and forget the episode (the next problem starts one)."""
        super().reset(seed)
        self.planner.reset()
