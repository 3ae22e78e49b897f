"""The planning problem of a decentralized team: the central problem plus what each robot
knows (issue 37).

With a communication model (the scenario field ``communication``;
:mod:`activetrack.world.team_filters`) the world's planning problem is a
:class:`TeamProblem`: the central filter's problem (what a centralized planner plans
from, unchanged) carrying :class:`TeamViews`, every robot's own prediction of every
target and the last step's link matrix. :meth:`TeamViews.views` turns them into one
:class:`~activetrack.world.problem.PlanningProblem` per robot (the team's sensors, reaches
and rules, robot ``i``'s prediction): what a distributed planner
(:class:`activetrack.baselines.distributed_gsr.DistributedGSR`) gives each robot.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from activetrack.world.prediction import indexed
from activetrack.world.problem import PlanningProblem, Prediction

_FIELDS = tuple(f.name for f in dataclasses.fields(PlanningProblem))


@dataclass(frozen=True, eq=False)
class TeamViews:
    """Every robot's prediction of every target and the step's links.

    Attributes:
        predictions: one :class:`Prediction` per target whose mean (..., M, n) and
            covariance (..., M, n, n) carry a robot axis before the state: robot ``i``'s
            ``x_hat_i(k+1|k)``, ``P_i(k+1|k)``.
        links: the last step's link matrix, bool (..., M, M) (row: receiver).
    """

    predictions: tuple[Prediction, ...]
    links: np.ndarray

    def __getitem__(self, index: Any) -> TeamViews:
        """Return the views of the copies at ``index`` of the batch axes."""
        return TeamViews(tuple(indexed(q, index) for q in self.predictions), self.links[index])

    def views(self, problem: PlanningProblem) -> list[PlanningProblem]:
        """Return robot ``i``'s problem for every ``i``: ``problem`` (the team's sensors,
        reaches and rules) with robot ``i``'s prediction of every target."""
        base = PlanningProblem(**{k: getattr(problem, k) for k in _FIELDS})
        out = []
        for i in range(problem.n_sensors):
            own = tuple(
                q.with_state(q.mean[..., i, :], q.cov[..., i, :, :]) for q in self.predictions
            )
            pred: Any = own if problem.multi_target else own[0]
            out.append(dataclasses.replace(base, prior_cov=None, target=None, prediction=pred))
        return out

    def view_of(self, problem: PlanningProblem, robots: np.ndarray) -> PlanningProblem:
        """Return ``problem`` with, in every copy ``c``, robot ``robots[c]``'s prediction of
        every target (``robots``: int, the problem's batch shape)."""
        base = PlanningProblem(**{k: getattr(problem, k) for k in _FIELDS})
        idx = np.asarray(robots)[..., None, None]
        own = []
        for q in self.predictions:
            mean = np.take_along_axis(q.mean, idx, axis=-2)[..., 0, :]
            cov = np.take_along_axis(q.cov, idx[..., None], axis=-3)[..., 0, :, :]
            own.append(q.with_state(mean, cov))
        pred: Any = tuple(own) if problem.multi_target else own[0]
        return dataclasses.replace(base, prior_cov=None, target=None, prediction=pred)


@dataclass(frozen=True)
class TeamProblem(PlanningProblem):
    """A :class:`PlanningProblem` (the central filter's) with the team's :class:`TeamViews`."""

    team: TeamViews | None = None

    def __getitem__(self, index: Any) -> PlanningProblem:
        """Return the problem(s) at ``index`` of the batch axes, with their views."""
        base = PlanningProblem(**{k: getattr(self, k) for k in _FIELDS})[index]
        team = None if self.team is None else self.team[index]
        return TeamProblem(**{k: getattr(base, k) for k in _FIELDS}, team=team)


def with_team(world: Any, problem: PlanningProblem, index: int | None) -> PlanningProblem:
    """Return ``problem`` as a :class:`TeamProblem` carrying ``world``'s robots' predictions
    and links (copy ``index``, or every copy), or ``problem`` itself for a central team."""
    if not world.decentralized:
        return problem
    models = problem.prediction if problem.multi_target else (problem.prediction,)
    preds = tuple(
        q.with_state(world.team_get("x_pred", index, k), world.team_get("P_pred", index, k))
        for k, q in enumerate(models)
    )
    team = TeamViews(preds, np.asarray(world.links(index), bool))
    return TeamProblem(**{k: getattr(problem, k) for k in _FIELDS}, team=team)
