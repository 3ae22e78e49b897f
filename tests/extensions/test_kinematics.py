"""A new kinematics defined here, outside the library, by subclassing ``activetrack.Kinematics``,
and run through the World, the PettingZoo parallel env, GSR (its numerical steps) and the
look-ahead planner with no change to the library; and the built-in ``Disk``'s methods.

``Square`` reaches the axis-aligned square of half-width ``h`` about the sensor (a robot
that moves each axis at most ``h`` per step); its action is the displacement in metres,
``Box(-h, h, (2,))``. It implements only what the base asks (``radius``, ``reaches``,
``clip``, ``reach_boundary``) and its own ``apply``/``command``: the projection out of the
``rho`` disks, the boundary and the samples of its feasible set are the base's defaults.

Every check is against an independent computation: a brute-force search of dense grids of
the feasible set, closed-form centroids, the formulas of eq. (13)-(16) written out.
"""

from __future__ import annotations

import numpy as np
import pytest

import activetrack
from activetrack import Disk, Kinematics


class Square(Kinematics):
    """The axis-aligned square of half-width ``h`` about the sensor."""

    name = "square"

    def __init__(self, h: float) -> None:
        self.h = float(h)
        self.action_low, self.action_high = (-self.h, -self.h), (self.h, self.h)

    @property
    def radius(self):
        return self.h * np.sqrt(2.0)

    def reaches(self, points, position):
        d = np.asarray(points, float) - np.asarray(position, float)
        return np.all(np.abs(d) <= self.h * (1.0 + 1e-12), axis=-1)

    def clip(self, wanted, position):
        p = np.asarray(position, float)
        return p + np.clip(np.asarray(wanted, float) - p, -self.h, self.h)

    def reach_boundary(self, position, spacing):
        n = max(1, int(np.ceil(2.0 * self.h / spacing)))
        t = np.linspace(-self.h, self.h, n + 1)
        o = np.full_like(t, self.h)
        sides = [np.stack(s, -1) for s in ((t, -o), (o, t), (-t, o), (-o, -t))]
        return np.asarray(position, float) + np.concatenate(sides)

    def apply(self, actions, position):
        return np.asarray(position, float) + np.clip(np.asarray(actions, float), -self.h, self.h)

    def command(self, points, position):
        return np.asarray(points, float) - np.asarray(position, float)


# Longhand --------------------------------------------------------------------------------
def square_grid(c, h, n=801):
    """Return a dense grid of the square ``|p - c|_inf <= h``, edges included, (n^2, 2)."""
    g = np.linspace(-h, h, n)
    return c + np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)


def disk_grid(c, r, n=801):
    """Return a dense grid of the disk ``|p - c| <= r`` with its circle, (P, 2)."""
    pts = square_grid(c, r, n)
    ang = np.linspace(-np.pi, np.pi, 20_001)
    pts = np.concatenate([pts, c + r * np.stack([np.cos(ang), np.sin(ang)], -1)])
    return pts[np.hypot(*(pts - c).T) <= r]


def outside(pts, targets, rho):
    """Return whether ``pts`` keep ``rho`` from every target (the longhand of eq. 16)."""
    d = np.hypot(*(pts[:, None, :] - np.asarray(targets)[None]).transpose(2, 0, 1))
    return np.all(d >= rho, axis=1)


def rho_rings(targets, rho, n=20_001):
    """Return dense points of every ``rho`` circle (the boundary a projection may end on)."""
    ang = np.linspace(-np.pi, np.pi, n)
    ring = np.stack([np.cos(ang), np.sin(ang)], -1)
    return np.concatenate([t + rho * ring for t in np.asarray(targets)])


def brute_nearest(q, feasible_pts):
    """Return the distance from ``q`` to the nearest of ``feasible_pts``."""
    return float(np.min(np.hypot(*(feasible_pts - q).T)))


# (a) the base's defaults, on the square, against brute force -------------------------------
CASES = [  # (sensor, targets, rho): one target inside the square, one at its edge, two
    ((0.0, 0.0), [(0.3, 0.2)], 0.5),
    ((0.0, 0.0), [(1.1, -0.4)], 0.6),
    ((1.0, 2.0), [(1.4, 2.3), (0.5, 1.6)], 0.45),
]


@pytest.mark.parametrize("case", CASES)
def test_square_projection_is_the_nearest_point_of_a_brute_force_grid(case):
    c, targets, rho = np.array(case[0]), np.array(case[1]), case[2]
    kin, h = Square(1.0), 1.0
    n = 801
    res = 2 * h / (n - 1)  # the grid's spacing: its nearest point is within res of the true one
    pts = np.concatenate([square_grid(c, h, n), rho_rings(targets, rho)])
    pts = pts[kin.reaches(pts, c) & outside(pts, targets, rho * (1 - 1e-12))]
    rng = np.random.default_rng(0)
    wanted = np.concatenate([
        c + rng.uniform(-2.5, 2.5, (60, 2)),  # inside and outside the square
        targets[0] + rng.uniform(-rho, rho, (40, 2)),  # inside a rho disk
        targets[-1] + rng.uniform(-rho, rho, (40, 2)),  # inside the last one
    ])  # fmt: skip
    for q in wanted:
        got = kin.project(q, c, targets, rho)
        assert kin.reaches(got, c) and outside(got[None], targets, rho * (1 - 1e-9))[0]
        d_got, d_best = float(np.hypot(*(got - q))), brute_nearest(q, pts)
        # No grid point is nearer than the projection (up to its boundary spacing) and the
        # projection is no farther than the grid's resolution from the grid's best.
        assert d_got <= d_best + 1e-3 * h
        assert d_got >= d_best - res
    # A feasible point is its own projection, exactly.
    inside = pts[rng.integers(len(pts), size=20)]
    for q in inside:
        np.testing.assert_array_equal(kin.project(q, c, targets, rho), q)


def test_square_projection_of_an_empty_set_violates_least():
    c, kin = np.zeros(2), Square(1.0)
    targets, rho = np.array([[0.2, -0.1]]), 3.0  # the rho disk covers the whole square
    grid = square_grid(c, 1.0, 401)
    assert not np.any(outside(grid, targets, rho))
    got = kin.project(np.array([0.5, 0.5]), c, targets, rho)
    margin = np.hypot(*(grid - targets[0]).T)
    assert kin.reaches(got, c)
    assert float(np.hypot(*(got - targets[0]))) >= margin.max() - 2.0 / 400


@pytest.mark.parametrize("case", CASES)
def test_square_boundary_and_samples(case):
    c, targets, rho = np.array(case[0]), np.array(case[1]), case[2]
    kin = Square(1.0)
    edge = kin.boundary(c, targets, rho, 0.01)
    assert len(edge) > 100
    on_square = np.isclose(np.max(np.abs(edge - c), axis=1), 1.0, atol=1e-12)
    on_ring = np.isclose(np.min(np.hypot(*(edge[:, None] - targets).transpose(2, 0, 1)), 1), rho)
    assert np.all(on_square | on_ring)
    assert np.all(kin.reaches(edge, c) & outside(edge, targets, rho * (1 - 1e-12)))
    # Consecutive along each piece: no gap wider than the spacing along the square's sides.
    rng = np.random.default_rng(1)
    n = 40_000
    s = kin.sample(c, targets, rho, rng, n)
    assert s.shape == (n, 2)
    assert np.all(kin.reaches(s, c) & outside(s, targets, rho * (1 - 1e-12)))
    # Uniform in F: its mean against F's centroid from a fine grid (independent of the
    # sampler), within 4 standard errors of the mean.
    grid = square_grid(c, 1.0, 1201)
    grid = grid[outside(grid, targets, rho)]
    centroid, spread = grid.mean(0), grid.std(0)
    assert np.all(np.abs(s.mean(0) - centroid) <= 4 * spread / np.sqrt(n) + 2e-3)


def test_square_command_round_trips():
    kin, rng = Square(0.7), np.random.default_rng(2)
    c = rng.uniform(-5, 5, (50, 2))
    p = c + rng.uniform(-0.7, 0.7, (50, 2))
    np.testing.assert_allclose(kin.apply(kin.command(p, c), c), p, rtol=0, atol=1e-14)


# (b) the built-in Disk against independent computations ----------------------------------
@pytest.mark.parametrize("case", CASES)
def test_disk_projection_is_the_nearest_point_of_a_brute_force_grid(case):
    c, targets, rho = np.array(case[0]), np.array(case[1]), case[2]
    r, n = 1.0, 801
    kin = Disk(r)
    pts = np.concatenate([disk_grid(c, r, n), rho_rings(targets, rho)])
    pts = pts[
        (np.hypot(*(pts - c).T) <= r * (1 + 1e-12)) & outside(pts, targets, rho * (1 - 1e-12))
    ]
    rng = np.random.default_rng(3)
    for q in np.concatenate([c + rng.uniform(-0.7, 0.7, (60, 2)),
                             targets[0] + rng.uniform(-rho, rho, (30, 2))]):  # fmt: skip
        q = c + (q - c) * min(1.0, r / max(np.hypot(*(q - c)), 1e-300))  # in reach (the rule)
        got = kin.project(q, c, targets, rho)
        assert np.hypot(*(got - c)) <= r * (1 + 1e-12)
        assert outside(got[None], targets, rho * (1 - 1e-12))[0]
        d_got, d_best = float(np.hypot(*(got - q))), brute_nearest(q, pts)
        assert d_best - 2 * r / (n - 1) <= d_got <= d_best + 1e-12


def test_disk_clip_apply_command_and_membership_against_the_formulas():
    rng = np.random.default_rng(4)
    c = rng.uniform(-10, 10, (200, 2))
    q = c + rng.uniform(-3, 3, (200, 2))
    kin = Disk(1.5)
    d = np.hypot(*(q - c).T)
    want = c + (q - c) * np.minimum(1.0, 1.5 / d)[:, None]  # eq. (13): onto the circle
    np.testing.assert_allclose(kin.clip(q, c), want, rtol=1e-14, atol=1e-13)
    a = rng.uniform(-2, 2, (200, 2))
    na = np.hypot(*a.T)
    np.testing.assert_allclose(
        kin.apply(a, c), c + 1.5 * a / np.maximum(na, 1.0)[:, None], rtol=1e-14, atol=1e-13
    )
    np.testing.assert_array_equal(kin.reaches(q, c), d <= 1.5 * (1 + 1e-12))
    # command: apply gives the reachable points back bit for bit (actions_to_reach's rule).
    p = kin.clip(q, c)
    np.testing.assert_array_equal(kin.apply(kin.command(p, c), c), p)
    assert kin.radius == 1.5 and Disk(1.5) == kin and Disk(0.5) != kin
    with pytest.raises(ValueError, match="radius"):
        Disk(-1.0)


@pytest.mark.parametrize("case", CASES)
def test_disk_boundary_and_samples(case):
    c, targets, rho = np.array(case[0]), np.array(case[1]), case[2]
    kin = Disk(1.0)
    edge = kin.boundary(c, targets, rho, 0.01)
    on_reach = np.isclose(np.hypot(*(edge - c).T), 1.0)
    on_ring = np.isclose(np.min(np.hypot(*(edge[:, None] - targets).transpose(2, 0, 1)), 1), rho)
    assert len(edge) > 100 and np.all(on_reach | on_ring)
    rng, n = np.random.default_rng(5), 40_000
    s = kin.sample(c, targets, rho, rng, n)
    assert np.all((np.hypot(*(s - c).T) <= 1 + 1e-12) & outside(s, targets, rho * (1 - 1e-12)))
    grid = disk_grid(c, 1.0, 1201)
    grid = grid[outside(grid, targets, rho)]
    assert np.all(np.abs(s.mean(0) - grid.mean(0)) <= 4 * grid.std(0) / np.sqrt(n) + 2e-3)


def test_scenario_maps_vmax_to_disks_and_disks_keep_the_compiled_world_bit_for_bit():
    sc = activetrack.make_scenario("paper")
    team = sc.kinematics_models
    assert all(type(k) is Disk for k in team)
    np.testing.assert_array_equal([k.radius for k in team], sc.per_sensor("vmax") * sc.dt)
    assert sc.capabilities.disk_kinematics and sc.capabilities.fused_step
    given = activetrack.make_scenario("paper", kinematics=team)
    assert given.capabilities.fused_step and np.array_equal(given.r, sc.r)
    a = activetrack.world.World(sc, 2)
    b = activetrack.world.World(given, 2)
    a.reset(seeds=[5, 6])
    b.reset(seeds=[5, 6])
    rng = np.random.default_rng(6)
    for _ in range(20):
        act = rng.uniform(-1.5, 1.5, (2, 3, 2))
        a.step_actions(act)
        b.step_actions(act)
    for key in ("sensors", "x_hat", "P"):
        np.testing.assert_array_equal(a.get(key), b.get(key))


def test_scenario_validates_and_records_a_new_kinematics():
    sc = activetrack.make_scenario("paper", kinematics=Square(0.4))
    assert not sc.capabilities.disk_kinematics and not sc.capabilities.paper_problem
    np.testing.assert_allclose(sc.r, 0.4 * np.sqrt(2.0))
    rec = sc.to_dict()["kinematics"]
    assert rec[0] == {"name": "square", "class": f"{__name__}.Square", "radius": sc.r[0]}
    assert "kinematics" not in activetrack.make_scenario("paper").to_dict()

    class Nameless(Square):
        name = ""

    class Broken(Square):
        def clip(self, wanted, position):
            raise ZeroDivisionError("bug")

    class Huge(Square):
        radius = 1e12

    for bad in (Square, "square", Nameless(1.0), Broken(1.0), Huge(1.0), (Square(1.0),) * 2):
        with pytest.raises(ValueError, match="kinematics"):
            activetrack.make_scenario("paper", kinematics=bad)


# (c) the World ---------------------------------------------------------------------------
@pytest.mark.parametrize("preset", ["paper", "two_targets"])
@pytest.mark.parametrize("copies", [1, 3])
def test_world_moves_every_sensor_inside_its_square_and_outside_rho(preset, copies):
    kin = Square(0.5)
    near = activetrack.make_scenario(preset).target_states("x0_hat")[0][:2]  # start close by
    world = activetrack.world.World(preset, copies, kinematics=kin, sensor_center=tuple(near),
                                    sensor_radius=3.0)  # fmt: skip
    world.reset(seeds=list(range(copies)))
    rho = world.scenario.per_sensor("rho")
    rng = np.random.default_rng(7)
    n_proj = 0
    for step in range(12):
        before = world.get("sensors").reshape(copies, -1, 2)
        targets = world.planning_problem().targets.reshape(copies, -1, 2)
        if step % 2:  # actions (metres, clipped to the box), then absolute positions
            act = rng.uniform(-0.8, 0.8, before.shape)
            world.step_actions(act if copies > 1 else act[0])
            asked = before + np.clip(act, -0.5, 0.5)
        else:  # towards the nearest target: some moves end inside its rho disk
            asked = targets[:, :1] + rng.normal(0.0, 1.0, before.shape)
            world.step(asked if copies > 1 else asked[0])
            asked = before + np.clip(asked - before, -0.5, 0.5)
        after = world.get("sensors").reshape(copies, -1, 2)
        proj = world.get("projected").reshape(copies, -1)
        for b in range(copies):
            for i in range(world.n_sensors):
                assert kin.reaches(after[b, i], before[b, i])
                pts = square_grid(before[b, i], 0.5, 201)
                ok = outside(pts, targets[b], rho[i])
                if not ok.any():  # F is empty (a start deep in a disk): the least violation
                    gap = np.min(np.hypot(*(pts[:, None] - targets[b]).transpose(2, 0, 1)), 1)
                    got = np.min(np.hypot(*(after[b, i] - targets[b]).T))
                    assert got >= gap.max() - 0.5 / 100
                    continue
                assert outside(after[b, i][None], targets[b], rho[i] * (1 - 1e-9))[0]
                if not proj[b, i]:  # an unprojected move is the asked one, exactly
                    np.testing.assert_array_equal(after[b, i], asked[b, i])
                else:  # the nearest feasible point: no grid point of F is nearer
                    pts = pts[ok]
                    d = np.hypot(*(after[b, i] - asked[b, i]))
                    assert d <= brute_nearest(asked[b, i], pts) + 1e-3
                    n_proj += 1
    assert n_proj > 0  # the rho rule was exercised


def test_team_commands_drive_the_world_to_planned_points():
    from activetrack.baselines.gsr import GSR
    from activetrack.kinematics.team import TeamMotion, actions_to_reach

    world = activetrack.world.World("paper", 2, kinematics=Square(0.5))
    world.reset(seeds=[3, 4])
    team = TeamMotion(world.scenario.kinematics_models)
    for _ in range(5):
        plan = GSR().plan(world.planning_problem())
        actions = team.commands(plan, world.get("sensors"))
        np.testing.assert_array_equal(
            actions,
            actions_to_reach(world.scenario.kinematics_models, plan, world.get("sensors"), 1.0),
        )
        world.step_actions(actions)
        np.testing.assert_allclose(world.get("sensors"), plan, rtol=0, atol=1e-12)


# (d) the PettingZoo parallel env -----------------------------------------------------------
def test_parallel_env_takes_its_action_space_from_the_kinematics():
    from gymnasium import spaces
    from pettingzoo.test import parallel_api_test

    from activetrack.envs.tracking_env import parallel_env

    parallel_api_test(parallel_env("paper", kinematics=Square(0.5)), num_cycles=60)
    env = parallel_env("paper", kinematics=Square(0.5))
    for a in env.possible_agents:
        assert env.action_space(a) == spaces.Box(-0.5, 0.5, (2,), dtype=np.float32)
    assert parallel_env("paper").action_space("sensor_0") == spaces.Box(-1, 1, (2,), np.float32)
    env.reset(seed=3)
    rng = np.random.default_rng(8)
    for _ in range(10):
        before = env.world.get("sensors", 0)
        actions = {a: env.action_space(a).sample() for a in env.agents}
        env.step(actions)
        after = env.world.get("sensors", 0)
        act = np.array([actions[a] for a in env.possible_agents], dtype=np.float64)
        free = ~env.world.get("projected", 0)
        np.testing.assert_array_equal(after[free], (before + act)[free])
        assert rng is not None


def test_gymnasium_views_take_the_joint_action_space_from_the_kinematics():
    from gymnasium import spaces
    from gymnasium.utils.env_checker import check_env

    from activetrack.envs.batched import BatchedActiveTracking
    from activetrack.envs.centralized import CentralizedTrackingEnv

    team = (Square(0.5), Square(0.25), Square(0.5))
    env = CentralizedTrackingEnv("paper", kinematics=team)
    lims = np.repeat([0.5, 0.25, 0.5], 2)
    assert env.action_space == spaces.Box(-lims.astype(np.float32), lims.astype(np.float32))
    check_env(env, skip_render_check=True)
    vec = BatchedActiveTracking(2, "paper", kinematics=team)
    assert vec.single_action_space == env.action_space
    vec.reset(seed=[1, 2])
    before = vec.world.get("sensors").copy()
    act = np.tile(np.array([0.4, -0.4, 0.3, 0.3, -0.9, 0.1]), (2, 1))
    vec.step(act)
    asked = before + np.clip(act.reshape(2, 3, 2), -lims.reshape(3, 2), lims.reshape(3, 2))
    free = ~vec.world.get("projected")
    np.testing.assert_array_equal(vec.world.get("sensors")[free], asked[free])


# (e) GSR through the numerical step ----------------------------------------------------------
def score_longhand(problem, positions):
    """Return the trace objective of a one-target range-bearing problem at ``positions``,
    from eq. (9)-(12) written out."""
    t = problem.target
    Y = np.linalg.inv(problem.prior_cov)
    for i, p in enumerate(positions):
        d = p - t
        q = float(d @ d)
        H = np.array([d / np.sqrt(q), np.array([-d[1], d[0]]) / q])
        R = np.diag([problem.sigma_d2[i], problem.sigma_theta2[i]])
        Y = Y + H.T @ np.linalg.inv(R) @ H
    return float(np.trace(np.linalg.inv(Y)))


def sensor_scores_longhand(problem, positions, i, pts):
    """Return the trace objective with sensor ``i`` moved to each of ``pts`` (P, 2), the
    others at ``positions``: eq. (9)-(12) written out, vectorized over the points."""
    t = problem.target
    Y = np.linalg.inv(problem.prior_cov)
    for j, p in enumerate(positions):
        if j != i:
            Y = Y + info_longhand(p[None] - t, problem, j)[0]
    Yp = Y + info_longhand(pts - t, problem, i)
    return (Yp[:, 0, 0] + Yp[:, 1, 1]) / (Yp[:, 0, 0] * Yp[:, 1, 1] - Yp[:, 0, 1] ** 2)


def info_longhand(d, problem, i):
    """Return ``H^T R^{-1} H`` (P, 2, 2) of sensor ``i`` at offsets ``d`` (P, 2) from the
    target: ``H`` rows ``d / |d|`` and ``(-d_y, d_x) / |d|^2`` (eq. 9)."""
    q = np.sum(d * d, axis=-1)
    h1 = d / np.sqrt(q)[:, None]
    h2 = np.stack([-d[:, 1], d[:, 0]], -1) / q[:, None]
    return (h1[:, :, None] * h1[:, None, :] / problem.sigma_d2[i]
            + h2[:, :, None] * h2[:, None, :] / problem.sigma_theta2[i])  # fmt: skip


def _problem(seed, steps=3, preset="paper", **overrides):
    from activetrack.baselines.gsr import GSR

    world = activetrack.world.World(preset, 1, kinematics=Square(0.5), **overrides)
    world.reset(seeds=[seed])
    for _ in range(steps):
        world.step(GSR().plan(world.planning_problem(0)))
    return world.planning_problem(0)


@pytest.mark.parametrize("near", [False, True])
@pytest.mark.parametrize("seed", [0, 1])
def test_gsr_plans_inside_the_squares_coordinatewise_optimally(seed, near):
    from activetrack.baselines.gsr import GSR

    # Far: the optimum at corners of the squares; near (sensors start about the target, one
    # sensor much more precise): on the rho circles and inside the squares.
    close = {"sensor_center": (2.5, 0.0), "sensor_radius": 1.0, "x0": (0.0, 0.0, 0.0, 0.0),
             "x0_hat": (0.0, 0.0, 0.0, 0.0), "q": 0.1}  # fmt: skip
    problem = _problem(seed, **(close if near else {}))
    kin = problem.kinematics[0]
    assert isinstance(kin, Square) and not problem.is_paper
    res = GSR(tol=1e-12).plan_with_info(problem)
    for i in range(problem.n_sensors):
        assert kin.feasible(res.positions[i], problem.sensors[i], problem.targets, problem.rho[i])
    assert res.value == pytest.approx(score_longhand(problem, res.positions), rel=1e-10)
    assert res.value <= score_longhand(problem, problem.sensors) * (1 + 1e-12)
    # The problem's violation measures the square (a point past a corner: its distance).
    far = res.positions + np.array([0.5, 0.5])
    gap = np.abs(far - problem.sensors) - 0.5
    want = np.hypot(*np.maximum(gap, 0.0).T)
    near = np.hypot(*(far - problem.target).T)
    want = np.maximum(want, np.maximum(problem.rho - near, 0.0))
    np.testing.assert_allclose(problem.violation(far), want, rtol=1e-12, atol=1e-15)
    for i in range(problem.n_sensors):  # no point of sensor i's F does better (dense grid)
        c = problem.sensors[i]
        edge = np.linspace(-0.5, 0.5, 20_001)
        sides = np.concatenate(
            [np.stack([edge, np.full_like(edge, s)], -1) for s in (-0.5, 0.5)]
            + [np.stack([np.full_like(edge, s), edge], -1) for s in (-0.5, 0.5)]
        )
        pts = np.concatenate([square_grid(c, 0.5, 401), c + sides,
                              rho_rings(problem.targets, problem.rho[i], 200_001)])  # fmt: skip
        pts = pts[Square(0.5).reaches(pts, c) & outside(pts, problem.targets, problem.rho[i])]
        best = float(np.min(sensor_scores_longhand(problem, res.positions, i, pts)))
        assert best >= res.value * (1 - 1e-9), i


def test_gsr_and_the_world_with_squares_and_two_targets():
    from activetrack.baselines.gsr import GSR

    world = activetrack.world.World("two_targets", 2, kinematics=Square(0.5))
    world.reset(seeds=[1, 2])
    for _ in range(4):
        problem = world.planning_problem()
        plan = GSR().plan(problem)
        for b in range(2):
            for i in range(world.n_sensors):
                assert Square(0.5).feasible(plan[b, i], problem.sensors[b, i],
                                            problem.targets[b], problem.rho[b, i])  # fmt: skip
        world.step(plan)
        np.testing.assert_array_equal(world.get("sensors"), plan)  # executed as planned


@pytest.mark.parametrize("preset", ["urban", "range_only", "uncertain_poses"])
def test_gsr_and_the_world_with_squares_beyond_the_paper(preset):
    from activetrack.baselines.gsr import GSR

    kin = Square(0.5)
    world = activetrack.world.World(preset, 2, kinematics=kin)
    world.reset(seeds=[0, 1])
    for _ in range(10):
        problem = world.planning_problem()
        plan = GSR().plan(problem)
        before = world.get("sensors").copy()
        world.step(plan)
        after = world.get("sensors")
        for b in range(2):
            for i in range(world.n_sensors):
                assert kin.feasible(plan[b, i], problem.sensors[b, i], problem.targets[b],
                                    problem.rho[b, i])  # fmt: skip
                assert kin.reaches(after[b, i], before[b, i])  # (occluders stop moves short)


# (f) the look-ahead planner ------------------------------------------------------------------
def test_lookahead_plans_paths_of_square_steps():
    from activetrack.baselines.lookahead import Lookahead, LookaheadPlanner

    problem = _problem(4)
    kin = problem.kinematics[0]
    la = Lookahead(horizon=3, headings=8, bearings=4, tail=1)
    res = la.plan_prediction(problem)
    assert res.score <= res.gsr_score
    start = problem.sensors
    for i in range(problem.n_sensors):
        prev = start[i]
        for h in range(la.horizon):
            assert kin.reaches(res.plan[i, h], prev)
            prev = res.plan[i, h]
        assert kin.feasible(res.positions[i], start[i], problem.targets, problem.rho[i])
    world = activetrack.world.World("paper", 1, kinematics=kin)
    world.reset(seeds=[4])
    planner = LookaheadPlanner(horizon=2, headings=4, bearings=0, tail=0)
    for _ in range(3):
        p = world.planning_problem(0)
        plan = planner.plan(p)
        world.step(plan)
        np.testing.assert_array_equal(world.get("sensors", 0), plan)
