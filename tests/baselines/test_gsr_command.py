"""GSR's command-space step (``baselines.gsr_command``) against independent computations.

- Every sensor of a GSR plan on robots (unicycle, fixed-wing, double integrator; compiled
  and NumPy paths) is feasible (reachable from its state, outside every ``rho`` disk) and
  optimal for its own subproblem (the others where the plan puts them) against a brute
  force over a dense grid of commands (201 x 201, each mapped by ``Kinematics.apply``).
- One sensor (GSR is then the single-sensor solve): never worse than the previous
  candidate/compass-search path (``baselines.gsr_kinematic``).
- A batch plans each copy as it would plan it alone.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack import DoubleIntegrator, Unicycle
from activetrack.baselines import gsr_command, gsr_numeric
from activetrack.baselines.gsr import GSR
from activetrack.world import World

ROBOTS = {
    "unicycle": Unicycle(0.0, 10.0, np.pi),
    "fixed_wing": Unicycle(5.0, 10.0, 6.0),
    "double_integrator": DoubleIntegrator(300.0, 10.0),
}
_G = np.linspace(-1.0, 1.0, 201)
DENSE = np.stack(np.meshgrid(_G, _G), -1).reshape(-1, 2)


def problems(kin, seeds, steps=3, **world_kwargs):
    """Yield planning problems of worlds driven a few steps by random commands (headings
    and velocities away from their reset values), sensors near the target."""
    world = World("paper", len(seeds), kinematics=kin, **world_kwargs)
    world.reset(seeds=list(seeds))
    rng = np.random.default_rng(0)
    bound = world.scenario.kinematics
    for _ in range(steps):
        problem = world.planning_problem()
        yield problem, bound
        states = problem.sensor_states
        plan = np.asarray(bound.apply(rng.uniform(-1, 1, states.shape[:-1] + (2,)), states))
        plan = np.stack([[bound.project(plan[b, i], states[b, i], problem.targets[b],
                                        problem.rho[b, i]) for i in range(plan.shape[1])]
                         for b in range(len(plan))])  # fmt: skip
        world.step(plan)


def brute_force(problem, kin, plan, i):
    """Return the least objective (float) of sensor ``i`` over the dense command grid with
    the others at ``plan`` (M, 2)."""
    state = problem.sensor_states[i]
    pts = np.asarray(kin.apply(DENSE, state))
    e = pts[:, None, :] - problem.targets.reshape(-1, 2)
    ok = np.all(np.hypot(e[..., 0], e[..., 1]) >= problem.rho[i], axis=-1)
    trial = np.broadcast_to(plan, (int(ok.sum()),) + plan.shape).copy()
    trial[:, i] = pts[ok]
    return float(np.min(problem.score(trial)))


def check_plan(problem, kin, plan):
    """Assert that ``plan`` (M, 2) is feasible and each sensor optimal against the brute
    force (relative 1e-9; the brute force's own grid is much coarser than that)."""
    value = float(problem.score(plan))
    for i in range(len(plan)):
        state = problem.sensor_states[i]
        assert kin.feasible(plan[i], state, problem.targets, problem.rho[i]), i
        t = problem.targets.reshape(-1, 2)
        assert np.min(np.hypot(*(plan[i] - t).T)) >= problem.rho[i]  # exactly, no tolerance
        assert value <= brute_force(problem, kin, plan, i) * (1 + 1e-9), i


@pytest.mark.kernels
@pytest.mark.parametrize("compiled", [True, False])
@pytest.mark.parametrize("name", list(ROBOTS))
def test_each_sensor_optimal_against_a_dense_command_grid(name, compiled, monkeypatch):
    if not compiled:
        monkeypatch.setattr(gsr_numeric, "_built_in", lambda *a: False)
    # Sensors start near the target: the rho disk cuts their reach sets.
    for problem, kin in problems(ROBOTS[name], [3, 4], sensor_center=(8.0, 0.0),
                                 sensor_radius=4.0):  # fmt: skip
        plan = GSR().plan(problem)
        for b in range(2):
            check_plan(problem[b], kin, plan[b])


@pytest.mark.parametrize("name", list(ROBOTS))
def test_one_sensor_never_worse_than_the_candidate_path(name, monkeypatch):
    got, old = [], []
    for problem, _ in problems(ROBOTS[name], [5, 6, 7], n_sensors=1, sensor_center=(9.0, 0.0)):
        got.append(GSR().plan_with_info(problem).value)
        with monkeypatch.context() as m:
            m.setattr(gsr_command, "supports", lambda kin: False)
            old.append(GSR().plan_with_info(problem).value)
    got, old = np.concatenate(got), np.concatenate(old)
    assert np.all(got <= old * (1 + 1e-9)), got / old - 1


@pytest.mark.parametrize("name", ["unicycle", "double_integrator"])
def test_a_batch_plans_each_copy_as_alone(name):
    for problem, _ in problems(ROBOTS[name], [8, 9, 10], steps=2):
        plan = GSR().plan(problem)
        for b in range(3):
            np.testing.assert_array_equal(plan[b], GSR().plan(problem[b]))


@pytest.mark.kernels
@pytest.mark.parametrize("name", list(ROBOTS) + ["disk"])
def test_compiled_points_are_the_kinematics_apply(name):
    from activetrack import Disk
    from activetrack.baselines import gsr_command_kernel as ck

    kin = Disk(1.5) if name == "disk" else ROBOTS[name].bind(0.1)
    code, prm = gsr_command.compiled_kinematics(kin)
    rng = np.random.default_rng(2)
    states = rng.normal(0, 5, (50, kin.state_dim))
    if name == "double_integrator":  # velocities within the speed bound
        v = states[:, 2:]
        states[:, 2:] = v / np.maximum(1, np.hypot(*v.T) / kin.v_max)[:, None]
    if name != "disk" and kin.state_dim == 3:
        states[:, 2] = rng.uniform(-np.pi, np.pi, 50)
    u = rng.uniform(-1.0, 1.0, (50, 40, 2))  # the action box the solver searches
    want = np.asarray(kin.apply(u, states[:, None, :]))
    got = np.array([[ck.point(code, prm, states[s], *u[s, q]) for q in range(40)]
                    for s in range(50)])  # fmt: skip
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * (1 + np.abs(want).max()))
    # and the compiled membership test agrees with the kinematics' on those points
    for s in range(50):
        for q in range(0, 40, 7):
            assert ck.reaches(code, prm, states[s], *want[s, q]) <= bool(
                kin.reaches(want[s, q], states[s])
            )
