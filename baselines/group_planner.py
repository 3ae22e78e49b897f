"""Any planner run per connected group of a decentralized team, by the group's leader
(issue 37: "the look-ahead likewise per group").

The step's link matrix splits the team into connected groups
(:func:`activetrack.models.communication.components`); in each group its lowest-indexed
robot, the leader, plans the whole group's moves with the wrapped planner (the
look-ahead, say) on **its own** estimate (its prediction of every target) and sends every
member its move. The robots outside the group are unknown to the leader: their noise
variances are set to :data:`~activetrack.baselines.distributed_gsr.SILENT` (no
information), so the plan of the group is the plan of a team of its members alone; their
planned moves are discarded. A robot alone is its own leader.

With one group (every link up) the leader is robot 0; when every robot's estimate is
the central one the plan is the wrapped planner's on the central problem, bit for bit (no
robot is silenced and the leader's view is the central prediction).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from activetrack.baselines.distributed_gsr import SILENT
from activetrack.models.communication import components
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem


class GroupPlanner:
    """A planner (any :class:`~activetrack.Planner`) run per connected group by its leader.

    Args:
        make: returns a new planner (``plan(problem, rng) -> (..., M, 2)``); group ``g``
            (in order of its lowest robot) has its own, so a planner that keeps state
            between steps (the look-ahead's warm start) keeps one per group.
        connection: ``"strong"`` or ``"weak"`` groups (:func:`components`).
    """

    def __init__(self, make: Callable[[], Any], connection: str = "strong") -> None:
        if not callable(make):
            raise TypeError(f"make must return a planner, got {type(make).__name__}")
        if connection not in ("weak", "strong"):
            raise ValueError(f"connection must be one of ['weak', 'strong'], got {connection!r}")
        self.make, self.connection = make, connection
        self.planners: list[Any] = [make()]
        if not callable(getattr(self.planners[0], "plan", None)):
            raise TypeError(f"make must return a planner, got {self.planners[0]!r}")

    @property
    def planner(self) -> Any:
        """The first group's planner (a central team's)."""
        return self.planners[0]

    @property
    def keeps_d_sep(self) -> bool:
        """Whether the wrapped planner keeps the team rule itself."""
        return bool(getattr(self.planner, "keeps_d_sep", False))

    def reset(self) -> None:
        """Reset every group's planner (a new episode), if it keeps state."""
        for p in self.planners:
            if callable(getattr(p, "reset", None)):
                p.reset()

    def _group(self, g: int) -> Any:
        while len(self.planners) <= g:
            self.planners.append(self.make())
        return self.planners[g]

    def plan(self, problem: PlanningProblem, rng: np.random.Generator | None = None) -> FloatArray:
        """Return the team's next absolute positions, batch + (M, 2): each group's leader's
        plan for its members (a central team: the wrapped planner's plan)."""
        team = getattr(problem, "team", None)
        if team is None:
            return self.planner.plan(problem, rng)
        n, labels = components(team.links, self.connection)
        m = problem.n_sensors
        out = np.array(problem.sensors, np.float64)
        for g in range(int(np.max(n))):
            member = labels == g  # (..., M); copies with fewer groups have no member
            leader = np.argmax(member, axis=-1)  # lowest member (0 where none)
            view = team.view_of(problem, leader)
            if not member.all():
                sd2 = np.broadcast_to(view.sigma_d2, member.shape)
                st2 = np.broadcast_to(view.sigma_theta2, member.shape)
                view = dataclasses.replace(
                    view,
                    sigma_d2=np.where(member, sd2, SILENT),
                    sigma_theta2=np.where(member, st2, SILENT),
                )
            plan = np.asarray(self._group(g).plan(view, rng), np.float64)
            out = np.where(member[..., None], plan, out)
        assert out.shape[-2] == m
        return out

    def __repr__(self) -> str:
        return f"GroupPlanner({self.planner!r})"
