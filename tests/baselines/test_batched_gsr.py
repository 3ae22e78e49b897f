"""Batched GSR against the scalar GSR, problem by problem."""

import numpy as np
import pytest

from activetrack.baselines import GSR, GSRPolicy
from activetrack.baselines._common import random_problem
from activetrack.baselines.batched_gsr import BatchedGSR
from activetrack.envs.batched import BatchedActiveTracking


def stack(problems):
    return [
        np.stack([getattr(p, f) for p in problems])
        for f in ("prior_cov", "target", "sensors", "r", "rho", "sigma_d2", "sigma_theta2")
    ]


@pytest.mark.parametrize("m", [1, 3, 5])
def test_batched_gsr_equals_scalar_gsr(m):
    rng = np.random.default_rng(m)
    # distances 0.5..6 m: some sensors cannot keep rho (fallback), most can
    problems = [random_problem(rng, m, distance=(0.5, 6.0)) for _ in range(150)]
    res = BatchedGSR().plan_batch(*stack(problems))
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
        BatchedGSR(tol=-1.0)
    with pytest.raises(ValueError, match="max_sweeps"):
        BatchedGSR(max_sweeps=0)


def count_certified(monkeypatch):
    """Count the solver rows the batched GSR takes from certified warm starts."""
    import activetrack.baselines.batched_gsr as bg

    seen = {"certified": 0, "rows": 0}
    solve = bg._solve_batch_unchecked

    def counting(*args):
        sol, roots = solve(*args)
        seen["certified"] += int(roots.certified.sum())
        seen["rows"] += roots.certified.size
        return sol, roots

    monkeypatch.setattr(bg, "_solve_batch_unchecked", counting)
    return seen


def env_problems(n, steps, seed):
    """Return batched GSR inputs along random-action episodes (as benchmarks/throughput.py)."""
    env = BatchedActiveTracking(n, scenario="paper")
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    p = env.params
    out = []
    for _ in range(steps):
        out.append(
            (env.P_pred[:, :2, :2].copy(), env.x_pred[:, :2].copy(), env.sensors.copy())
            + (p.r, p.rho, p.sigma_d2, p.sigma_theta2)
        )
        env.step(rng.uniform(-1, 1, (n, 6)))
    return out


def assert_same_plans(warm, cold):
    """Warm-started and plain batched GSR agree: values to rounding, sweeps nearly always.

    A copy stops when no sensor is left to re-solve, i.e. when a re-solve returns its
    position bit for bit; a last-bit difference in where Newton polishing stops can then
    cost or save one confirming sweep (the plain batched GSR and the scalar GSR differ
    in the same way on a few copies).
    """
    np.testing.assert_allclose(warm.value, cold.value, rtol=1e-10)
    np.testing.assert_allclose(warm.positions, cold.positions, atol=1e-6)
    assert np.all(np.abs(warm.sweeps - cold.sweeps) <= 1)
    assert np.mean(warm.sweeps != cold.sweeps) <= 0.02


@pytest.mark.parametrize("distance", [(3.5, 12.0), (0.5, 6.0)])
def test_warm_started_roots_give_the_plain_companion_path(monkeypatch, distance):
    # Mostly case I (the speed circle, where the roots of f3 are used), then mixed cases.
    rng = np.random.default_rng(17)
    args = stack([random_problem(rng, 3, distance=distance) for _ in range(600)])
    seen = count_certified(monkeypatch)
    warm = BatchedGSR().plan_batch(*args)
    if distance[0] > 3.0:
        assert seen["certified"] >= 0.4 * seen["rows"]  # the shortcut is exercised
    assert_same_plans(warm, BatchedGSR(warm_roots=False).plan_batch(*args))


def test_warm_started_roots_on_environment_problems(monkeypatch):
    for args in env_problems(256, 3, seed=4):
        seen = count_certified(monkeypatch)
        warm = BatchedGSR().plan_batch(*args)
        assert seen["certified"] >= 0.5 * seen["rows"]
        monkeypatch.undo()
        assert_same_plans(warm, BatchedGSR(warm_roots=False).plan_batch(*args))


def test_warm_roots_must_be_a_bool():
    with pytest.raises(ValueError, match="warm_roots"):
        BatchedGSR(warm_roots="yes")


def test_batched_gsr_rejects_a_fixed_sensor_on_the_target_and_names_the_copy():
    # The check the scalar planners always had: r = 0 and exactly on the predicted target.
    sensors = np.array([[[3.0, 0.0], [0.0, 4.0]], [[1.0, -2.0], [5.0, 5.0]]])
    target = np.array([[0.0, 0.0], [1.0, -2.0]])  # copy 1, sensor 0 sits on the target
    r = np.array([[1.0, 1.0], [0.0, 1.0]])
    args = (np.broadcast_to(np.eye(2), (2, 2, 2)), target, sensors, r, 2.0, 1.0, 0.5)
    with pytest.raises(ValueError, match="cannot move") as err:
        BatchedGSR().plan_batch(*args)
    assert "(1, 0)" in str(err.value)


def test_batched_gsr_rejects_rho_zero_with_a_reachable_target():
    sensors = np.array([[[3.0, 0.0]], [[0.5, 0.0]]])
    args = (np.broadcast_to(np.eye(2), (2, 2, 2)), np.zeros((2, 2)), sensors, 1.0, 0.0, 1.0, 1.0)
    with pytest.raises(ValueError, match=r"rho must be > 0.*\(1, 0\)"):
        BatchedGSR().plan_batch(*args)
