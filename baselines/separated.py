"""Planners under the team rule of a minimum separation ``d_sep`` (issue 36).

:class:`Separated` wraps any planner (GSR, GBES, RM, the look-ahead) so that its plans
keep the separation the world enforces
(:class:`activetrack.kinematics.separation.Separation`): the plan is taken sensor by
sensor in agent order, a Gauss-Seidel pass whose exclusion disks are the sensors already
placed (their planned positions, sensors 0..i-1) and the others where they stand
(i+1..M-1), the world's own order, and the sensors already placed moving along their
planned segments at the same instants. A sensor whose planned move keeps the separation
keeps it; one whose move would come within ``d_ij`` of an exclusion disk on the way, or of
a sensor already placed at the same instant, takes,
among the rule's candidates that are feasible (within reach, outside every ``rho`` disk,
a path clear of the exclusion disks), the one of least objective with the other sensors
at their planned points (sensors 0..i-1 already moved) — the sensor's subproblem solved
numerically on its feasible set minus the exclusion disks. Boxed in (no feasible
candidate), it takes the world's own choice. The plan first goes through the world's
own mending of a move (:func:`activetrack.kinematics.sensor_motion.move_to`: reach and
``rho``), so the world then executes the plan as given.

The wrapped planner keeps its own objective and arithmetic; the pass only moves the
sensors it must, so a plan that already keeps the separation is returned unchanged.

GSR, GBES and RM keep the rule in their own search when the problem carries ``d_sep``
(:mod:`activetrack.baselines.gsr_separation`), so they need no wrapper; the experts
(:class:`activetrack.baselines.policies.PlannerPolicy`) pass the plans of every other
planner (the look-ahead) through :func:`separate`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.kinematics import sensor_motion
from activetrack.kinematics.separation import (
    Separation,
    pair_distances,
    segment_distance,
    together,
)
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem


class Separated:
    """A planner whose plans keep the separation ``d_sep`` (module docstring).

    Args:
        planner: any planner with ``plan(problem, rng)``.
        d_sep: the scenario's field (a distance for every pair, or M radii).
    """

    def __init__(self, planner: Any, d_sep: Any) -> None:
        self.planner = planner
        self.d_sep = d_sep

    def plan(self, problem: PlanningProblem, rng: np.random.Generator | None = None) -> FloatArray:
        """Return the wrapped planner's plan made to keep the separation, ``batch + (M, 2)``."""
        plan = np.asarray(self.planner.plan(problem, rng), np.float64)
        return separate(problem, plan, self.d_sep)


def separate(problem: PlanningProblem, plan: FloatArray, d_sep: Any) -> FloatArray:
    """Return ``plan`` (``batch + (M, 2)``) passed through the Gauss-Seidel pass of the
    module docstring for the problem (or each problem of a batch)."""
    m = plan.shape[-2]
    rule = Separation(pair_distances(d_sep, m))
    out = np.array(plan)
    if plan.ndim == 2:
        return _one(problem, out, rule)
    for idx in np.ndindex(plan.shape[:-2]):
        out[idx] = _one(problem[idx], out[idx], rule)
    return out


def _one(problem: PlanningProblem, plan: FloatArray, rule: Separation) -> FloatArray:
    """Return one problem's ``plan`` (M, 2) passed through the pass."""
    old = np.asarray(problem.sensors, np.float64)
    targets = np.asarray(problem.targets, np.float64).reshape(-1, 2)
    r = np.broadcast_to(problem.r, (len(old),))
    rho = np.broadcast_to(problem.rho, (len(old),))
    d = rule.d
    # The world's own mending first (a point beyond reach or in a rho disk), so that the
    # world executes the pass's plan as given.
    pos, _ = sensor_motion.move_to(plan, old, np.asarray(problem.target, np.float64), r, rho)
    for i in range(len(old)):
        js = np.array([j for j in range(len(old)) if j != i])
        obst = np.where((js < i)[:, None], pos[js], old[js])
        if np.all(segment_distance(old[i], pos[i], obst) >= d[i, js]) and np.all(
            together(old[i], pos[i], old[js], obst) >= d[i, js]
        ):
            continue
        c, ok, clear = rule.candidates(
            old[i], pos[i], obst, d[i, js], targets, float(r[i]), float(rho[i]), old[js]
        )
        ok &= clear >= 0.0
        if not np.any(ok):  # boxed in: what the world would do
            pos[i] = rule._fallback(old[i], pos[i], obst, d[i, js], targets, float(r[i]),
                                    float(rho[i]), old[js])[0]  # fmt: skip
            continue
        trial = np.broadcast_to(pos, (int(ok.sum()), *pos.shape)).copy()
        trial[:, i] = c[ok]
        pos[i] = c[ok][int(np.argmin(problem.score(trial)))]
    return pos
