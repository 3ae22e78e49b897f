"""GBES and random motion (RM) with a kinematics of one's own: ``Square`` of
``tests/extensions/test_kinematics.py`` (the axis-aligned square of half-width ``h``), with no
change to the library.

- RM draws uniformly by arc length on the boundary of the feasible set ``F`` (the square
  minus the ``rho`` disks): its moments and the share of draws on the ``rho`` circles
  against a longhand tabulation of that boundary, with bands computed for each statistic.
- GBES is the exact optimum over its grid: against a brute-force joint search over every
  combination of the grid points (M = 2), with the objective of eq. (9)-(12) written out;
  the grid itself against a longhand boundary (every point on it, every longhand point
  within ``spacing`` of the grid).
- Both through the World and the runner (``simulate``): every planned move feasible and
  executed as planned.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import activetrack
from activetrack.baselines._common import boundary_grid
from activetrack.baselines.gbes import GBES
from activetrack.baselines.random_motion import RandomMotion, draw_on_boundary
from tests.extensions.test_kinematics import CASES, Square, info_longhand, outside, square_grid


# Longhand ---------------------------------------------------------------------------------
def boundary_longhand(c, h, targets, rho, step=2e-4):
    """Return points of the boundary of ``F`` (square ``|p - c|_inf <= h`` minus the open
    ``rho`` disks), evenly spaced ``about step`` by arc length on every piece, and whether
    each lies on a ``rho`` circle: ``(points (P, 2), on_ring (P,))``."""
    c, targets = np.asarray(c, float), np.asarray(targets, float)
    n = int(np.ceil(2 * h / step))
    t = -h + (np.arange(n) + 0.5) * (2 * h / n)  # midpoints: each stands for 2h / n
    o = np.full(n, h)
    edge = c + np.concatenate([np.stack(s, -1) for s in ((t, -o), (o, t), (-t, o), (-o, -t))])
    edge = edge[outside(edge, targets, rho)]
    rings = []
    for k, tk in enumerate(targets):
        m = int(np.ceil(2 * np.pi * rho / (2 * h / n)))  # the same arc length per point
        ang = (np.arange(m) + 0.5) * (2 * np.pi / m)
        ring = tk + rho * np.stack([np.cos(ang), np.sin(ang)], -1)
        others = np.delete(targets, k, axis=0)
        keep = np.all(np.abs(ring - c) <= h, axis=1)
        if len(others):
            keep &= outside(ring, others, rho)
        rings.append(ring[keep])
    ring = np.concatenate(rings)
    pts = np.concatenate([edge, ring])
    return pts, np.r_[np.zeros(len(edge), bool), np.ones(len(ring), bool)]


def statistics(pts, on_ring):
    """Return the tested statistics of points (P, 2): x, y, x^2, xy, y^2 and whether each
    is on a ``rho`` circle, one column each (P, 6)."""
    x, y = pts[:, 0], pts[:, 1]
    return np.stack([x, y, x * x, x * y, y * y, on_ring.astype(float)], -1)


# (a) RM: uniform by arc length on the boundary of F ----------------------------------------
@pytest.mark.parametrize("case", CASES)
def test_rm_draws_uniformly_by_arc_length_on_the_boundary_of_the_square_minus_rho(case):
    c, targets, rho = np.array(case[0]), np.array(case[1]), case[2]
    h = 1.0
    kin = Square(h)
    pts = boundary_grid(kin, c, targets, rho, None)  # what RM draws from (radius / 1024)
    n = 400_000
    got = draw_on_boundary(pts, np.random.default_rng(11).random(n))
    assert np.all(kin.reaches(got, c) & outside(got, targets, rho * (1 - 1e-12)))
    ring = np.min(np.abs(np.hypot(*(got[:, None] - targets).transpose(2, 0, 1)) - rho), 1) < 1e-9
    ring &= np.max(np.abs(got - c), axis=1) < h * (1 - 1e-12)  # (a corner on a ring: edge)
    ref_pts, ref_ring = boundary_longhand(c, h, targets, rho)
    ref = statistics(ref_pts, ref_ring)
    sample = statistics(got, ring).mean(0)
    # Each statistic's mean over n independent draws has standard error std / sqrt(n) (the
    # longhand distribution's std): 5 of them, plus the grid's discretization (radius / 1024
    # between points; a moment moves by at most about that times its gradient, <= 2 |c| + 2h).
    se = ref.std(0) / np.sqrt(n)
    disc = kin.radius / 1024 * np.r_[1, 1, [2 * (np.abs(c).max() + 2 * h)] * 3, 0]
    assert 0.05 < ref[:, 5].mean() < 0.95  # both kinds of piece are drawn
    np.testing.assert_array_less(np.abs(sample - ref.mean(0)), 5 * se + disc)
    # The band is tight enough for a 10% modelling error: 10% more weight on the rho arcs
    # moves the share on them by 0.1 p (1 - p) / (1 + 0.1 p), beyond the band.
    p = ref[:, 5].mean()
    assert 0.1 * p * (1 - p) / (1 + 0.1 * p) > 5 * se[5] + disc[5]


def test_rm_plan_draws_one_uniform_per_free_sensor_through_the_world():
    kin = Square(0.5)
    near = activetrack.make_scenario("two_targets").target_states("x0_hat")[0][:2]
    world = activetrack.world.World("two_targets", 2, kinematics=kin, sensor_center=tuple(near),
                                    sensor_radius=1.5)  # fmt: skip
    world.reset(seeds=[3, 4])
    rng = np.random.default_rng(12)
    on_ring = n_empty = 0
    for _ in range(8):
        problem = world.planning_problem()
        mirror = np.random.Generator(type(rng.bit_generator)())
        mirror.bit_generator.state = rng.bit_generator.state
        plan = RandomMotion().plan(problem, rng)
        for b in range(2):
            for i in range(world.n_sensors):
                t, p, rho = problem.targets[b], problem.sensors[b, i], problem.rho[b, i]
                if not np.any(outside(square_grid(p, 0.5, 201), t, rho)):
                    # F is empty (a start deep in a rho disk): the projection, no draw.
                    np.testing.assert_array_equal(plan[b, i], kin.project(p, p, t, rho))
                    n_empty += 1
                    continue
                assert kin.feasible(plan[b, i], p, t, rho)
                # On the boundary of F: on the square's edge or on a rho circle.
                edge = np.isclose(np.max(np.abs(plan[b, i] - p)), 0.5, rtol=0, atol=1e-12)
                ring = np.isclose(np.min(np.hypot(*(plan[b, i] - t).T)), rho, rtol=1e-12)
                assert edge or ring
                on_ring += bool(ring and not edge)
                # One uniform of the generator per sensor, in copy then sensor order.
                want = draw_on_boundary(boundary_grid(kin, p, t, rho, None), mirror.random())
                np.testing.assert_array_equal(plan[b, i], want)
        assert rng.bit_generator.state == mirror.bit_generator.state
        world.step(plan)
        moved = world.get("sensors")
        free = ~world.get("projected")
        np.testing.assert_array_equal(moved[free], plan[free])  # executed as planned
    assert on_ring > 0  # the rho circles were drawn from
    assert n_empty < 8 * 2 * world.n_sensors  # most moves were drawn


# (b) GBES: the exact optimum of its grid ---------------------------------------------------
def _two_sensor_problem():
    from activetrack.world.problem import PlanningProblem

    kin = Square(0.5)
    # Both squares cut by the rho circle about the target: the grid has edge and ring points.
    return PlanningProblem(
        np.diag([2.0, 1.0]), np.array([0.0, 0.0]), np.array([[0.9, 0.2], [-0.3, -0.8]]),
        kin.radius, 0.6, np.array([1.0, 2.0]), np.array([0.1, 0.3]), kinematics=(kin, kin),
    )  # fmt: skip


def trace_longhand(problem, pos0, pos1):
    """Return tr((P^-1 + J_0 + J_1)^-1) for every pair of positions (P0, 2) x (P1, 2):
    eq. (9)-(12) written out, (P0, P1)."""
    t = problem.target
    Y = (np.linalg.inv(problem.prior_cov)[None, None]
         + info_longhand(pos0 - t, problem, 0)[:, None]
         + info_longhand(pos1 - t, problem, 1)[None, :])  # fmt: skip
    det = Y[..., 0, 0] * Y[..., 1, 1] - Y[..., 0, 1] * Y[..., 1, 0]
    return (Y[..., 0, 0] + Y[..., 1, 1]) / det


@pytest.mark.parametrize("spacing", [0.1, 0.04])
def test_gbes_with_squares_is_the_brute_force_optimum_of_its_grid(spacing):
    problem = _two_sensor_problem()
    kin = problem.kinematics[0]
    gbes = GBES(spacing=spacing)
    res = gbes.search(problem)
    grid = [g + problem.target for g in gbes.candidates(problem)]
    assert res.n_combinations == len(grid[0]) * len(grid[1])
    # The grid is the boundary of F at the spacing: every point on it, and the points of a
    # longhand boundary within ``spacing / 2`` of a grid point (grid points at most
    # ``spacing`` apart along a piece), within ``spacing`` near the pieces' junctions (the
    # base's rho arcs end at their last feasible point, up to a spacing short).
    for i, g in enumerate(grid):
        c = problem.sensors[i]
        assert np.all(kin.reaches(g, c) & outside(g, problem.targets, 0.6 * (1 - 1e-12)))
        edge = np.isclose(np.max(np.abs(g - c), axis=1), 0.5, rtol=0, atol=1e-12)
        ring = np.isclose(np.hypot(*(g - problem.target).T), 0.6, rtol=1e-12)
        assert np.all(edge | ring) and np.any(ring) and np.any(edge)
        dense, _ = boundary_longhand(c, 0.5, problem.targets, 0.6, step=1e-3)
        gap = np.min(np.hypot(*(dense[:, None] - g[None]).transpose(2, 0, 1)), axis=1)
        assert gap.max() <= spacing and np.quantile(gap, 0.95) <= spacing / 2 * (1 + 1e-9)
    # Brute force over every combination, longhand objective.
    values = trace_longhand(problem, grid[0], grid[1])
    best = np.unravel_index(np.argmin(values), values.shape)
    assert res.value == pytest.approx(values[best], rel=1e-12)
    assert res.value <= values.min() * (1 + 1e-12)  # no combination of the grid is better
    np.testing.assert_allclose(res.positions, [grid[0][best[0]], grid[1][best[1]]],
                               rtol=0, atol=1e-12)  # fmt: skip
    unpruned = GBES(spacing=spacing, prune=False).search(problem)
    assert unpruned.n_evaluated >= res.n_combinations  # (blocks padded by repeats)
    np.testing.assert_array_equal(unpruned.positions, res.positions)


@pytest.mark.parametrize("preset", ["two_targets", "range_only", "uncertain_poses"])
def test_gbes_with_squares_beyond_the_paper_is_the_optimum_of_its_grid(preset):
    # Other sensor models, pose uncertainty and two targets: the problem's own objective
    # (its sensor models' information) over every combination, against GBES's search.
    kin = Square(0.5)
    world = activetrack.world.World(preset, 1, kinematics=kin, n_sensors=2)
    world.reset(seeds=[5])
    problem = world.planning_problem(0)
    # Both sensors 1.1 rho from the first target: the rho circle cuts their squares.
    unit = np.array([[1.0, 0.15], [-0.5, -1.0]])
    unit /= np.hypot(*unit.T)[:, None]
    sensors = problem.targets[0] + 1.1 * problem.rho[:, None] * unit
    problem = dataclasses.replace(problem, sensors=sensors)
    gbes = GBES(spacing=0.08)
    res = gbes.search(problem)
    g0, g1 = (g + problem.targets[0] for g in gbes.candidates(problem))
    pairs = np.stack(np.broadcast_arrays(g0[:, None], g1[None]), -2).reshape(-1, 2, 2)
    values = problem.score(pairs)
    assert res.value == pytest.approx(values.min(), rel=1e-12)
    for i, g in enumerate((g0, g1)):
        assert kin.feasible(res.positions[i], problem.sensors[i], problem.targets,
                            problem.rho[i])  # fmt: skip
        ring = np.isclose(np.min(np.hypot(*(g[:, None] - problem.targets).transpose(2, 0, 1)),
                                 axis=1), problem.rho[i], rtol=1e-12)  # fmt: skip
        assert np.any(ring) and not np.all(ring)  # both kinds of boundary in the grid
    assert np.any(np.all(np.isclose(pairs, res.positions, rtol=0, atol=1e-12), axis=(1, 2)))


def test_gbes_refuses_a_grid_beyond_the_memory_bound_before_building_it():
    problem = _two_sensor_problem()
    with pytest.raises(ValueError, match="spacing must be at least .* kinematics 'square'"):
        GBES(spacing=1e-9, adapt=False).search(problem)


def test_gbes_with_a_square_whose_feasible_set_is_empty_goes_to_its_projection():
    from activetrack.world.problem import PlanningProblem

    kin = Square(0.5)
    sensors = np.array([[0.1, 0.0], [2.0, 0.5]])  # sensor 0's square inside the rho disk
    problem = PlanningProblem(np.eye(2), np.zeros(2), sensors, kin.radius, np.array([3.0, 0.4]),
                              1.0, 0.2, kinematics=(kin, kin))  # fmt: skip
    grid = GBES(spacing=0.1).candidates(problem)
    assert len(grid[0]) == 1
    np.testing.assert_array_equal(grid[0][0], kin.project(sensors[0], sensors[0],
                                                          problem.targets, 3.0))  # fmt: skip
    # The projection of an empty F: the point of the square farthest from the target.
    assert np.hypot(*grid[0][0]) == pytest.approx(np.hypot(0.6, 0.5), rel=1e-3)
    res = GBES(spacing=0.1).search(problem)
    np.testing.assert_array_equal(res.positions[0], grid[0][0])


# (c) through the World and the runner --------------------------------------------------------
@pytest.mark.parametrize("planner", [GBES(spacing=0.1), RandomMotion()], ids=["GBES", "RM"])
@pytest.mark.parametrize("preset", ["paper", "two_targets"])
def test_planners_drive_the_world_with_squares(planner, preset):
    kin = Square(0.5)
    world = activetrack.world.World(preset, 2, kinematics=kin)
    world.reset(seeds=[1, 2])
    rng = np.random.default_rng(13)
    for _ in range(4):
        problem = world.planning_problem()
        plan = planner.plan(problem, rng)
        for b in range(2):
            for i in range(world.n_sensors):
                assert kin.feasible(plan[b, i], problem.sensors[b, i], problem.targets[b],
                                    problem.rho[b, i])  # fmt: skip
        world.step(plan)
        np.testing.assert_array_equal(world.get("sensors"), plan)


def test_simulate_runs_gbes_and_rm_with_squares():
    from activetrack.baselines.simulation import simulate

    kin = Square(0.5)
    sc = activetrack.make_scenario("paper", kinematics=kin, n_steps=6)
    for planner in (GBES(spacing=0.1), RandomMotion()):
        rec = simulate(sc, planner, 7)
        sensors = np.asarray(rec.sensors)
        assert sensors.shape[0] == 7  # step 0 and the 6 steps
        steps = np.diff(sensors, axis=0)
        assert np.all(np.abs(steps) <= 0.5 * (1 + 1e-12))  # every move inside the square
        assert np.all(np.isfinite(rec.trace))
