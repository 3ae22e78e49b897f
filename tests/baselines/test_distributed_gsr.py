"""Distributed GSR (issue 37) against independent computations: with one group sharing one
estimate, robot-by-robot message passing ends where central GSR ends (its objective to
1e-9); disconnected groups each plan as the team of their own members alone (GSR on a
problem holding only them); a robot alone plans on its own estimate; rounds are bounded."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from activetrack.baselines.distributed_gsr import DistributedGSR
from activetrack.baselines.gsr import GSR
from activetrack.models.communication import RangeLimited
from activetrack.world import World
from activetrack.world.problem import PlanningProblem


def _problems(name: str, n: int, steps: int, seed: int = 0) -> list[PlanningProblem]:
    """Return GSR-driven planning problems of ``steps`` steps of a batch of ``n`` copies."""
    w = World(name, n)
    w.reset(seeds=list(range(seed, seed + n)))
    out = []
    for _ in range(steps):
        p = w.planning_problem()
        out.append(p)
        w.step(GSR().plan(p))
    return out


def _sub(p: PlanningProblem, members: list[int]) -> PlanningProblem:
    """Return ``p`` with only the sensors ``members`` (an independent, smaller problem)."""
    idx = np.asarray(members)
    cut = {k: np.asarray(getattr(p, k))[..., idx] for k in ("r", "rho", "sigma_d2", "sigma_theta2")}
    return dataclasses.replace(p, sensors=p.sensors[..., idx, :], **cut)


@pytest.mark.parametrize("name", ["paper", "homogeneous", "bearing_only", "range_only"])
def test_message_passing_with_full_links_ends_where_central_gsr_ends(name):
    d = DistributedGSR(shortcut=False)
    for p in _problems(name, 6, 12):
        m = p.n_sensors
        central = GSR().plan(p)
        ours = d.plan_views([p] * m, np.ones(p.batch_shape + (m, m), bool))
        np.testing.assert_allclose(p.score(ours), p.score(central), rtol=1e-9)
        np.testing.assert_allclose(ours, central, atol=1e-5)
        assert d.last_rounds.max() <= d.rounds


def test_shortcut_is_gsr_bit_for_bit_with_full_links_and_one_estimate():
    for name in ("paper", "two_targets", "urban"):
        for p in _problems(name, 4, 5):
            m = p.n_sensors
            ours = DistributedGSR().plan_views([p] * m, np.ones(p.batch_shape + (m, m), bool))
            assert np.array_equal(ours, GSR().plan(p))


def test_disconnected_groups_each_plan_as_a_team_of_their_own():
    # homogeneous: 4 sensors; links join {0, 2} and {1, 3} in copy 0, {0, 1, 2} and {3}
    # in copy 1.
    p = _problems("homogeneous", 2, 6, seed=3)[-1]
    links = np.eye(4, dtype=bool)[None].repeat(2, 0)
    for c, groups in enumerate(([[0, 2], [1, 3]], [[0, 1, 2], [3]])):
        for g in groups:
            for i in g:
                links[c, i, g] = True
    ours = DistributedGSR(shortcut=False).plan_views([p] * 4, links)
    for c, groups in enumerate(([[0, 2], [1, 3]], [[0, 1, 2], [3]])):
        keys = ("sensors", "r", "rho", "sigma_d2", "sigma_theta2")
        one = dataclasses.replace(
            p, **{k: np.asarray(getattr(p, k))[c] for k in keys},
            prior_cov=p.prior_cov[c], target=p.target[c], prediction=None,
        )  # fmt: skip
        for g in groups:
            alone = GSR().plan(_sub(one, g))
            np.testing.assert_allclose(ours[c, g], alone, atol=1e-5)


def test_a_robot_alone_plans_on_its_own_estimate():
    p = _problems("paper", 1, 4)[-1]
    m = p.n_sensors
    # Robot 1 believes the target is 3 m further east, with twice the covariance.
    own = dataclasses.replace(
        p, prediction=None, target=p.target + np.array([[3.0, 0.0]]), prior_cov=2 * p.prior_cov
    )
    views = [p] * m
    views[1] = own
    links = np.eye(m, dtype=bool)[None]
    ours = DistributedGSR().plan_views(views, links)
    np.testing.assert_allclose(ours[0, 1], GSR().plan(_sub(own, [1]))[0, 0], atol=1e-5)
    np.testing.assert_allclose(ours[0, 0], GSR().plan(_sub(p, [0]))[0, 0], atol=1e-5)


def test_rounds_are_bounded_and_bad_arguments_name_the_field():
    p = _problems("homogeneous", 3, 2)[-1]
    d = DistributedGSR(rounds=1, shortcut=False)
    d.plan_views([p] * 4, np.ones((3, 4, 4), bool))
    assert d.last_rounds.max() == 1
    with pytest.raises(ValueError, match="rounds"):
        DistributedGSR(rounds=0)
    with pytest.raises(ValueError, match="tol"):
        DistributedGSR(tol=1.5)
    with pytest.raises(ValueError, match="links"):
        DistributedGSR().plan_views([p] * 4, np.ones((3, 4, 3), bool))
    with pytest.raises(ValueError, match="views"):
        DistributedGSR().plan_views([p] * 3, np.ones((3, 4, 4), bool))


def test_on_a_decentralized_world_each_robot_plans_on_its_own_estimate():
    """radio with 5 m links that drop half their packets: the world's problem carries every
    robot's prediction (the world's filters per robot) and links; distributed GSR plans
    each group from them: a robot without links plans alone on its own prediction (GSR on
    a one-sensor problem of that prediction, built here from the world's arrays), which
    differs from its team mates'."""
    from activetrack.models.communication import RangeLimited
    from activetrack.world.problem import Prediction

    w = World("radio", 16, communication=RangeLimited(range=5.0, drop=0.5))
    w.reset(seeds=list(range(16)))
    w.step(GSR().plan(w.planning_problem()))  # at reset every robot holds the prior
    policy = DistributedGSR()
    alone_seen = 0
    for _ in range(20):
        p = w.planning_problem()
        plan = policy.plan(p)
        links = np.asarray(w.links())
        x, P = w.team_get("x_pred"), w.team_get("P_pred")
        np.testing.assert_array_equal(p.team.links, links)
        for c in range(16):
            for i in range(p.n_sensors):
                if links[c, i].sum() + links[c, :, i].sum() > 2:  # in contact with someone
                    continue
                assert not np.array_equal(x[c, i], x[c, i - 1])  # its own estimate
                alone_seen += 1
                q = p.prediction
                own = Prediction(x[c, i], P[c, i], q.Phi, q.Q)
                row = {
                    k: np.broadcast_to(getattr(p, k), (16, p.n_sensors))[c, [i]]
                    for k in ("r", "rho", "sigma_d2", "sigma_theta2")
                }
                one = PlanningProblem.from_prediction(own, sensors=p.sensors[c, [i]], **row)
                np.testing.assert_allclose(plan[c, i], GSR().plan(one)[0], atol=1e-6)
        w.step(plan)
    assert alone_seen > 0


def test_a_copy_of_a_decentralized_problem_keeps_its_views():
    w = World("radio", 3, communication=RangeLimited(range=5.0, drop=0.5))
    w.reset(seeds=[0, 1, 2])
    w.step(GSR().plan(w.planning_problem()))
    p = w.planning_problem()
    one = p[1]
    np.testing.assert_array_equal(one.team.links, p.team.links[1])
    np.testing.assert_array_equal(DistributedGSR().plan(one), DistributedGSR().plan(p)[1])
