"""Batched GSR against the scalar GSR, problem by problem."""

import numpy as np
import pytest

from activetrack.baselines import GSR
from activetrack.baselines._common import random_problem
from activetrack.baselines.batched_gsr import BatchedGSR, BatchedGSRPolicy
from activetrack.envs.batched import BatchedActiveTracking
from activetrack.envs.centralized import CentralizedTrackingEnv
from activetrack.envs.dynamics import actions_to_reach


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


def test_batched_expert_drives_batched_env_like_scalar_expert_drives_single_envs():
    N = 4
    env = BatchedActiveTracking(N, n_steps=6)
    singles = [CentralizedTrackingEnv("paper", n_steps=6) for _ in range(N)]
    env.reset(seed=11)
    for i, e in enumerate(singles):
        e.reset(seed=11 + i)
    policy, gsr = BatchedGSRPolicy(), GSR()
    for _ in range(6):
        a = policy.act(env)
        _, rew, *_ = env.step_agents(a)
        for i, e in enumerate(singles):
            prob = e.planning_problem()
            ai = actions_to_reach(gsr.plan(prob), prob.sensors, prob.r)
            _, r_i, *_ = e.step(ai.reshape(-1))
            assert rew[i] == pytest.approx(r_i, rel=1e-7)


def test_parameter_errors():
    with pytest.raises(ValueError, match="tol"):
        BatchedGSR(tol=-1.0)
    with pytest.raises(ValueError, match="max_sweeps"):
        BatchedGSR(max_sweeps=0)
