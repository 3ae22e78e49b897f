"""The world, the planners and the environments with robots whose state goes beyond the
position (``Unicycle``: a heading; ``DoubleIntegrator``: a velocity).

- The world keeps each sensor's state: at a reset the heading points at the targets' prior
  mean and the velocity is zero; after every step the new state is the longhand
  integration of one command within the limits that ends at the new position (the
  unicycle's arc: its chord leaves at the mean of the two headings; the double
  integrator's constant acceleration: ``p' = p + (v + v') dt / 2``), an unprojected action's
  state is the action's own integration, and no sensor ends inside a ``rho`` disk.
- Observations end with each agent's heading ``(cos, sin)`` or velocity over the top speed;
  the global state holds every agent's.
- GSR, GBES, RM and the look-ahead plan moves that the sensor's state can make (its
  feasible set), which the world executes as planned, then advances the state.
- PettingZoo's ``parallel_api_test`` and Gymnasium's ``check_env`` pass, with the normalized
  ``Box`` action space.
"""

from __future__ import annotations

import numpy as np
import pytest

import activetrack
from activetrack import DoubleIntegrator, Unicycle
from activetrack.world import World

ROBOTS = {
    "unicycle": Unicycle(0.0, 10.0, 4.0),
    "fixed_wing": Unicycle(5.0, 10.0, 6.0),
    "double_integrator": DoubleIntegrator(300.0, 10.0),
}


_G = np.linspace(-1, 1, 41)
#: A grid of normalized commands (every kinematics' action box).
GRID = np.stack(np.meshgrid(_G, _G), -1).reshape(-1, 2)


def wrap(a):
    return np.angle(np.exp(1j * np.asarray(a)))


def check_step(kin, before, after, dt):
    """Assert that ``after`` (M, S) follows from ``before`` by one command within the
    limits, integrated longhand."""
    for b, a in zip(before, after, strict=True):
        if isinstance(kin, Unicycle):
            turn = wrap(a[2] - b[2])  # w dt
            assert abs(turn) <= kin.w_max * dt * (1 + 1e-9)
            d = a[:2] - b[:2]
            chord = np.hypot(*d)
            half = 0.5 * turn
            sinc = np.sinc(half / np.pi)
            v = chord / (dt * sinc)
            assert kin.v_min * (1 - 1e-9) - 1e-9 <= v <= kin.v_max * (1 + 1e-9)
            if chord > 1e-9:  # the chord leaves at the mean heading
                assert abs(wrap(np.arctan2(d[1], d[0]) - (b[2] + half))) < 1e-7
            # and its length is the arc's: (2 v / w) sin(w dt / 2)
            w = turn / dt
            want = v * dt if w == 0 else 2 * v / abs(w) * abs(np.sin(w * dt / 2))
            assert chord == pytest.approx(want, rel=1e-9, abs=1e-12)
        else:
            acc = (a[2:] - b[2:]) / dt
            assert np.hypot(*acc) <= kin.a_max * (1 + 1e-9)
            assert np.hypot(*a[2:]) <= kin.v_max * (1 + 1e-12)
            np.testing.assert_allclose(a[:2], b[:2] + 0.5 * (b[2:] + a[2:]) * dt, rtol=0,
                                       atol=1e-9)  # fmt: skip


@pytest.mark.parametrize("copies", [1, 2])
@pytest.mark.parametrize("name", list(ROBOTS))
def test_world_keeps_each_sensors_state_consistent_and_outside_rho(name, copies):
    kin = ROBOTS[name]
    sc = activetrack.make_scenario("paper", kinematics=kin)
    near = sc.target_states("x0_hat")[0][:2]
    world = World(sc, copies, sensor_center=tuple(near), sensor_radius=3.0)
    world.reset(seeds=list(range(10, 10 + copies)))
    bound = world.scenario.kinematics
    dt = world.scenario.dt
    states = world.sensor_states().reshape(copies, -1, bound.state_dim)
    assert world.get("motion").reshape(copies, 3, -1).shape[-1] == bound.state_dim - 2
    if isinstance(kin, Unicycle):  # facing the prior mean
        d = near - states[..., :2]
        np.testing.assert_allclose(wrap(states[..., 2] - np.arctan2(d[..., 1], d[..., 0])), 0,
                                   atol=1e-12)  # fmt: skip
    else:
        assert np.all(states[..., 2:] == 0.0)
    rho = world.scenario.per_sensor("rho")
    rng = np.random.default_rng(0)
    n_proj = n_free = 0
    for step in range(25):
        before = world.sensor_states().reshape(copies, -1, bound.state_dim)
        targets = world.planning_problem().targets.reshape(copies, -1, 2)
        act = rng.uniform(-1.2, 1.2, before.shape[:-1] + (2,))
        if step % 2 == 0:  # absolute positions at the target (clipped, projected)
            asked = targets[:, :1] + rng.normal(0.0, 0.3, act.shape)
            world.step(asked if copies > 1 else asked[0])
        else:
            world.step_actions(act if copies > 1 else act[0])
        after = world.sensor_states().reshape(copies, -1, bound.state_dim)
        proj = world.get("projected").reshape(copies, -1)
        np.testing.assert_array_equal(after[..., :2], world.get("sensors").reshape(copies, -1, 2))
        for c in range(copies):
            check_step(bound, before[c], after[c], dt)
            for i in range(3):
                gap = np.hypot(*(after[c, i, :2] - targets[c]).T).min()
                # Outside rho unless no command leads out (a start deep inside the disk).
                reach = bound.apply(GRID, before[c, i])
                can = np.hypot(*(reach[:, None] - targets[c]).transpose(2, 0, 1)).min(1)
                assert gap >= rho[i] * (1 - 1e-9) or can.max() < rho[i]
                if step % 2 == 1 and not proj[c, i]:  # the action's own integration
                    want = bound.advance(act[c, i], before[c, i])
                    np.testing.assert_allclose(after[c, i], want, rtol=0, atol=1e-12)
                    n_free += 1
        n_proj += int(proj.sum())
        # The observation ends with each agent's own features, the state with everyone's.
        obs = world.observe().reshape(copies, 3, -1)
        feats = (np.stack([np.cos(after[..., 2]), np.sin(after[..., 2])], -1)
                 if isinstance(bound, Unicycle) else after[..., 2:] / bound.v_max)  # fmt: skip
        np.testing.assert_allclose(obs[..., -2:], feats, rtol=0, atol=1e-6)
        glob = world.state().reshape(copies, -1)
        np.testing.assert_allclose(glob[:, -7:-1], feats.reshape(copies, 6), rtol=0, atol=1e-6)
        if world.get("terminated").any() or world.get("truncated").any():
            world.reset(seeds=list(range(copies)))
    assert n_proj > 0 and n_free > 0  # both rules exercised
    low, high = world.layout.bounds(world.length_scale)
    assert np.all(low[-2:] == -1) and np.all(high[-2:] == 1)
    assert len(low) == world.observe().shape[-1]


def _planners():
    from activetrack.baselines.gbes import GBES
    from activetrack.baselines.gsr import GSR
    from activetrack.baselines.lookahead import LookaheadPlanner
    from activetrack.baselines.random_motion import RandomMotion

    return {
        "GSR": GSR(),
        "GBES": GBES(spacing=0.1),
        "RM": RandomMotion(),
        "lookahead": LookaheadPlanner(horizon=2, headings=4, bearings=2, tail=0),
    }


@pytest.mark.parametrize("planner", ["GSR", "GBES", "RM", "lookahead"])
@pytest.mark.parametrize("name", list(ROBOTS))
def test_planners_plan_moves_the_state_can_make(name, planner):
    kin = ROBOTS[name]
    plan_of = _planners()[planner]
    world = World("paper", 2, kinematics=kin)
    world.reset(seeds=[1, 2])
    bound = world.scenario.kinematics
    rng = np.random.default_rng(5)
    for _ in range(2):
        problem = world.planning_problem()
        states = problem.sensor_states
        assert states.shape == (2, 3, bound.state_dim)
        plan = plan_of.plan(problem, rng)
        for b in range(2):
            for i in range(3):
                assert bound.feasible(plan[b, i], states[b, i], problem.targets[b],
                                      problem.rho[b, i]), (b, i)  # fmt: skip
        before = world.sensor_states()
        world.step(plan)
        np.testing.assert_array_equal(world.get("sensors"), plan)  # executed as planned
        check_step(bound, before[0], world.sensor_states()[0], world.scenario.dt)


@pytest.mark.parametrize("name", ["unicycle", "double_integrator"])
def test_simulate_and_imitation_labels_with_robots(name):
    from activetrack.baselines.gsr import GSR
    from activetrack.baselines.simulation import simulate
    from activetrack.kinematics.team import actions_to_reach

    sc = activetrack.make_scenario("paper", kinematics=ROBOTS[name], n_steps=3)
    rec = simulate(sc, GSR(), 4)
    assert np.all(np.isfinite(rec.trace)) and np.asarray(rec.sensors).shape[0] == 4
    # The labels (the commands that reach the planned points) drive the world there.
    world = World(sc, 1)
    world.reset(seeds=[4])
    problem = world.planning_problem(0)
    plan = GSR().plan(problem)
    labels = actions_to_reach(problem.kinematics, plan, problem.sensor_states, problem.r)
    assert np.all(np.abs(labels) <= 1.0)
    world.step_actions(labels)
    np.testing.assert_allclose(world.get("sensors", 0), plan, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", list(ROBOTS))
def test_envs_pass_the_api_checks_with_robots(name):
    from gymnasium import spaces
    from gymnasium.utils.env_checker import check_env
    from pettingzoo.test import parallel_api_test

    from activetrack.envs.centralized import CentralizedTrackingEnv
    from activetrack.envs.tracking_env import parallel_env

    kin = ROBOTS[name]
    parallel_api_test(parallel_env("paper", kinematics=kin), num_cycles=30)
    env = parallel_env("paper", kinematics=kin)
    assert env.action_space("sensor_0") == spaces.Box(-1, 1, (2,), np.float32)
    obs, _ = env.reset(seed=3)
    feats = env.world.scenario.kinematics.features(env.world.sensor_states(0))
    for i, a in enumerate(env.possible_agents):
        assert env.observation_space(a).contains(obs[a])
        np.testing.assert_allclose(obs[a][-2:], feats[i], rtol=0, atol=1e-6)
    central = CentralizedTrackingEnv("paper", kinematics=kin)
    assert central.action_space == spaces.Box(-1, 1, (6,), np.float32)
    check_env(central, skip_render_check=True)
    # The batched view: its observations hold each copy's features too.
    from activetrack.envs.batched import BatchedActiveTracking

    vec = BatchedActiveTracking(2, "paper", kinematics=kin)
    assert vec.single_action_space == central.action_space
    obs, _ = vec.reset(seed=[1, 2])
    obs, *_ = vec.step(np.zeros((2, 6), np.float32))
    feats = vec.world.scenario.kinematics.features(vec.world.sensor_states())  # (2, 3, 2)
    obs = obs.reshape(2, 3, -1)  # each agent's observation ends with its own features
    assert vec.single_observation_space.contains(obs[0].reshape(-1))
    np.testing.assert_allclose(obs[..., -2:], feats, rtol=0, atol=1e-6)


@pytest.mark.parametrize("name", ["unicycle", "double_integrator"])
def test_rendering_draws_each_sensors_heading(name):
    from activetrack.envs.rendering import HEADING_LENGTH
    from activetrack.envs.tracking_env import parallel_env

    env = parallel_env("paper", kinematics=ROBOTS[name], render_mode="rgb_array")
    env.reset(seed=1)
    env.step({a: env.action_space(a).sample() for a in env.agents})
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[-1] == 3
    world = env.world
    states = world.sensor_states(0)
    kin = world.scenario.kinematics
    if isinstance(kin, Unicycle):  # the heading, longhand
        direction = np.stack([np.cos(states[:, 2]), np.sin(states[:, 2])], -1)
    else:  # the velocity over the top speed
        direction = states[:, 2:] / kin.v_max
    rho = world.scenario.per_sensor("rho")
    lines = env._recorder._renderer._art["headings"]
    for i, line in enumerate(lines):
        x, y = line.get_data()
        np.testing.assert_allclose(np.c_[x, y][0], states[i, :2], rtol=0, atol=1e-12)
        tip = states[i, :2] + HEADING_LENGTH * rho[i] * direction[i]
        np.testing.assert_allclose(np.c_[x, y][1], tip, rtol=0, atol=1e-12)
    env.close()
    # The paper's disks draw no heading.
    plain = parallel_env("paper", render_mode="rgb_array")
    plain.reset(seed=1)
    plain.render()
    assert all(len(line.get_data()[0]) == 0 for line in plain._recorder._renderer._art["headings"])
    plain.close()


def _driven(kin, dt, old, new, n=400):
    """Return n + 1 points of the path from state ``old`` to ``new`` (the unicycle's arc of
    the turn and chord between them, the double integrator's constant acceleration)."""
    s = np.linspace(0.0, 1.0, n + 1)[:, None]
    if isinstance(kin, Unicycle):
        turn = wrap(new[2] - old[2])
        d = new[:2] - old[:2]
        chord = np.hypot(*d)
        sinc = np.sinc(turn / 2 / np.pi)
        part = chord * s[:, 0] * np.sinc(s[:, 0] * turn / 2 / np.pi) / sinc
        ang = old[2] + s[:, 0] * turn / 2
        return old[:2] + part[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    acc = (new[2:] - old[2:]) / dt
    t = s * dt
    return old[:2] + old[2:] * t + 0.5 * acc * t * t


@pytest.mark.parametrize("name", ["unicycle", "double_integrator"])
def test_occluders_stop_robots_with_a_consistent_state(name):
    from activetrack.models.occluders import inside

    kin = ROBOTS[name]
    # A wall between the sensors (which start facing the target, to the west) and it.
    wall = (((16.0, -30.0), (16.4, -30.0), (16.4, 30.0), (16.0, 30.0)),)
    world = World("paper", 2, kinematics=kin, occluders=wall, sensor_center=(18.5, 0.0),
                  sensor_radius=1.5)  # fmt: skip
    world.reset(seeds=[3, 4])
    bound, dt = world.scenario.kinematics, world.scenario.dt
    occ = world.occluders()
    rng = np.random.default_rng(9)
    stopped = 0
    for _ in range(12):
        before = world.sensor_states()
        act = rng.uniform(-0.2, 0.2, (2, 3, 2)) + [0.8, 0.0]  # full speed ahead (or west)
        if isinstance(bound, DoubleIntegrator):
            act = act + [-0.8, 0.0]
            act[..., 0] -= 0.8
        world.step_actions(act)
        after = world.sensor_states()
        assert not np.any(inside(after[..., :2], occ))
        free = bound.advance(act, before)
        for c in range(2):
            for i in range(3):
                # The free move's own path (the arc, the parabola), densely sampled.
                arc = _driven(bound, dt, before[c, i], free[c, i])
                if not np.any(inside(arc, occ)):
                    np.testing.assert_array_equal(after[c, i, :2], free[c, i, :2])
                    continue  # the free move (its state: checked above)
                # Stopped short of a block: a move of its own (a command within the
                # limits), whose path stays out of the occluders.
                stopped += 1
                if np.array_equal(after[c, i, :2], before[c, i, :2]) and not np.any(
                    after[c, i, 2:] if isinstance(bound, DoubleIntegrator) else 0.0
                ):  # no command keeps it out (too fast to brake): held (path_rule)
                    continue
                check_step(bound, before[c, i][None], after[c, i][None], dt)
                assert not np.any(inside(_driven(bound, dt, before[c, i], after[c, i]), occ))
    assert stopped > 0
