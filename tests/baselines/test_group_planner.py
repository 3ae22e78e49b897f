"""A planner per connected group (issue 37): on a central team it is the planner; on a
decentralized one each group's members move as the planner moves a team of them alone,
planned on the group leader's own prediction (checked against GSR on a problem holding
only the group, built here from the world's arrays)."""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.baselines.group_planner import GroupPlanner
from activetrack.baselines.gsr import GSR
from activetrack.baselines.policy_specs import resolve_policy
from activetrack.models.communication import RangeLimited, components
from activetrack.world import World
from activetrack.world.problem import PlanningProblem, Prediction


def test_on_a_central_team_it_is_the_planner():
    w = World("paper", 4)
    w.reset(seeds=[0, 1, 2, 3])
    for _ in range(5):
        p = w.planning_problem()
        plan = GroupPlanner(GSR).plan(p)
        assert np.array_equal(plan, GSR().plan(p))
        w.step(plan)


def test_each_group_plans_as_a_team_of_its_members_on_its_leaders_estimate():
    w = World("homogeneous", 8, communication=RangeLimited(range=6.0, drop=0.4))
    w.reset(seeds=list(range(8)))
    w.step(GSR().plan(w.planning_problem()))
    planner, checked = GroupPlanner(GSR), 0
    for _ in range(10):
        p = w.planning_problem()
        plan = planner.plan(p)
        _, labels = components(np.asarray(w.links()), "strong")
        x, P = w.team_get("x_pred"), w.team_get("P_pred")
        for c in range(8):
            for g in np.unique(labels[c]):
                members = np.flatnonzero(labels[c] == g)
                lead = members[0]
                own = Prediction(x[c, lead], P[c, lead], p.prediction.Phi, p.prediction.Q)
                row = {
                    k: np.broadcast_to(getattr(p, k), (8, 4))[c, members]
                    for k in ("r", "rho", "sigma_d2", "sigma_theta2")
                }
                sub = PlanningProblem.from_prediction(own, sensors=p.sensors[c, members], **row)
                np.testing.assert_allclose(plan[c, members], GSR().plan(sub), atol=1e-6)
                checked += len(members) < 4
        w.step(plan)
    assert checked > 0  # some groups were not the whole team


@pytest.mark.parametrize("name", ["distributed-gsr", "distributed-lookahead"])
def test_the_distributed_policies_run_on_radio(name):
    w = World("radio", 3)
    w.reset(seeds=[0, 1, 2])
    policy = resolve_policy(name)
    for _ in range(3):
        plan = policy.plan(w.planning_problem())
        assert plan.shape == (3, 3, 2) and np.isfinite(plan).all()
        w.step(plan)


def test_bad_arguments_name_the_field():
    with pytest.raises(TypeError, match="make"):
        GroupPlanner(3)
    with pytest.raises(ValueError, match="connection"):
        GroupPlanner(GSR, connection="both")
