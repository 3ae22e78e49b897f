"""GSR on a batched planning problem (one compiled sweep over the copies) against the
scalar GSR, problem by problem."""

import numpy as np
import pytest

from activetrack.baselines import GSR, GSRPolicy
from activetrack.baselines._common import random_problem
from activetrack.envs.batched import BatchedActiveTracking
from activetrack.world.problem import PlanningProblem


def stack(problems):
    """Return the problems as one batched problem (B copies)."""
    return PlanningProblem(
        *(
            np.stack([getattr(p, f) for p in problems])
            for f in ("prior_cov", "target", "sensors", "r", "rho", "sigma_d2", "sigma_theta2")
        )
    )


@pytest.mark.parametrize("m", [1, 3, 5])
def test_batched_gsr_equals_scalar_gsr(m):
    rng = np.random.default_rng(m)
    # distances 0.5..6 m: some sensors cannot keep rho (fallback), most can
    problems = [random_problem(rng, m, distance=(0.5, 6.0)) for _ in range(150)]
    res = GSR().plan_with_info(stack(problems))
    gsr = GSR()
    for b, p in enumerate(problems):
        ref = gsr.plan_with_info(p)
        # The scalar and batched single-sensor solvers may place a flat optimum ~1e-7 apart;
        # the objective values agree to rounding.
        assert res.value[b] == pytest.approx(ref.value, rel=1e-10)
        np.testing.assert_allclose(res.positions[b], ref.positions, atol=1e-6)
        reachable = np.linalg.norm(p.rel_sensors, axis=1) + p.r >= p.rho
        assert np.all(p.violation(res.positions[b])[reachable] <= 1e-9)


def test_expert_plans_a_batched_env_and_its_positions_are_executed():
    # The batched expert is GSRPolicy on the batched problem; each copy's plan is the
    # scalar GSR optimum of that copy (value to rounding), executed as planned.
    N = 4
    env = BatchedActiveTracking(N, n_steps=6)
    env.reset(seed=11)
    expert, gsr = GSRPolicy(), GSR()
    for _ in range(6):
        problem = env.planning_problem()
        planned = expert.plan(problem)
        for i in range(N):
            assert problem.score(planned)[i] == pytest.approx(
                problem[i].score(gsr.plan(problem[i])), rel=1e-10
            )
        env.step_positions(planned)
        np.testing.assert_array_equal(env.sensors, planned)


def test_parameter_errors():
    with pytest.raises(ValueError, match="tol"):
        GSR(tol=-1.0)
    with pytest.raises(ValueError, match="max_sweeps"):
        GSR(max_sweeps=0)


def test_warm_roots_is_deprecated_and_changes_nothing():
    rng = np.random.default_rng(17)
    problem = stack([random_problem(rng, 3, distance=(3.5, 12.0)) for _ in range(50)])
    plain = GSR().plan(problem)
    with pytest.warns(DeprecationWarning, match="warm_roots"):
        GSR(warm_roots=False)
    with pytest.warns(DeprecationWarning):
        old = GSR(warm_roots=True).plan(problem)
    np.testing.assert_array_equal(old, plain)


def test_batched_gsr_rejects_a_fixed_sensor_on_the_target_and_names_the_copy():
    # The check the scalar planners always had: r = 0 and exactly on the predicted target.
    sensors = np.array([[[3.0, 0.0], [0.0, 4.0]], [[1.0, -2.0], [5.0, 5.0]]])
    target = np.array([[0.0, 0.0], [1.0, -2.0]])  # copy 1, sensor 0 sits on the target
    r = np.array([[1.0, 1.0], [0.0, 1.0]])
    args = (np.broadcast_to(np.eye(2), (2, 2, 2)), target, sensors, r, 2.0, 1.0, 0.5)
    with pytest.raises(ValueError, match="cannot move") as err:
        GSR().plan(PlanningProblem(*args))
    assert "(1, 0)" in str(err.value)


def test_batched_gsr_rejects_rho_zero_with_a_reachable_target():
    sensors = np.array([[[3.0, 0.0]], [[0.5, 0.0]]])
    args = (np.broadcast_to(np.eye(2), (2, 2, 2)), np.zeros((2, 2)), sensors, 1.0, 0.0, 1.0, 1.0)
    with pytest.raises(ValueError, match=r"rho must be > 0.*\(1, 0\)"):
        GSR().plan(PlanningProblem(*args))
