"""K-target sensor modes and feasible-set boundary arcs against dense sampling."""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.baselines._common import sensor_modes, sensor_modes_multi
from activetrack.kinematics.feasible_set import boundary_arcs as feasible_arcs
from activetrack.kinematics.feasible_set import fallback
from activetrack.world.problem import PlanningProblem
from tests.baselines._multi import dense_boundary, multi_problem


def _random_config(rng):
    """Return (sensor, r, targets, rho); half the time the sensor sits among the targets."""
    k = int(rng.integers(2, 5))
    targets = rng.uniform(-2.0, 2.0, (k, 2))
    if rng.random() < 0.5:
        sensor = rng.uniform(-3.0, 3.0, 2)
    else:
        sensor = targets.mean(axis=0) + rng.uniform(-0.3, 0.3, 2)
    return sensor, float(rng.uniform(0.3, 2.0)), targets, float(rng.uniform(0.3, 1.8))


def test_arc_lengths_per_circle_match_dense_sampling():
    rng = np.random.default_rng(0)
    n = 40_000
    for _ in range(80):
        sensor, r, targets, rho = _random_config(rng)
        arcs = feasible_arcs(sensor, r, targets, rho)
        for centre, radius, _, ok in dense_boundary(sensor, r, targets, rho, n):
            mine = [a for a in arcs if np.allclose(a.center, centre) and a.radius == radius]
            got = sum(a.length for a in mine)
            # Each run of feasible samples misses less than one step at both ends.
            runs = int(np.count_nonzero(ok != np.roll(ok, 1))) + 1
            step = 2.0 * np.pi * radius / n
            assert got == pytest.approx(ok.mean() * 2.0 * np.pi * radius, abs=2 * runs * step)


def test_arc_points_are_feasible_boundary_points():
    rng = np.random.default_rng(1)
    for _ in range(200):
        sensor, r, targets, rho = _random_config(rng)
        for arc in feasible_arcs(sensor, r, targets, rho):
            assert arc.t1 > arc.t0 and arc.t1 - arc.t0 <= 2 * np.pi + 1e-12
            pts = arc.points(np.linspace(arc.t0, arc.t1, 33))
            reach = np.linalg.norm(pts - sensor, axis=-1)
            gaps = np.linalg.norm(pts[:, None] - targets[None], axis=-1)
            assert np.all(reach <= r * (1 + 1e-12))
            assert np.all(gaps >= rho * (1 - 1e-12))
            # on the reach circle or on one rho circle
            on = np.isclose(reach, r, rtol=1e-12) | np.any(np.isclose(gaps, rho, rtol=1e-12), 1)
            assert np.all(on)


def test_sensor_is_free_exactly_when_dense_sampling_finds_a_feasible_point():
    rng = np.random.default_rng(2)
    rad, ang = np.meshgrid(np.sqrt(np.linspace(0, 1, 80)), np.linspace(0, 2 * np.pi, 400))
    disk = np.stack([rad * np.cos(ang), rad * np.sin(ang)], -1).reshape(-1, 2)
    seen = {True: 0, False: 0}
    for _ in range(300):
        sensor, r, targets, rho = _random_config(rng)
        pts = sensor + r * disk
        margin = np.max(np.min(np.linalg.norm(pts[:, None] - targets[None], axis=-1), 1) - rho)
        free, fixed = sensor_modes_multi(sensor[None], targets, np.array([r]), np.array([rho]))
        if margin > 1e-2:
            assert free[0]
        elif margin < -1e-2:
            assert not free[0]
        seen[bool(free[0])] += 1
        if free[0]:
            np.testing.assert_array_equal(fixed[0], sensor)
    assert min(seen.values()) > 15  # both modes were exercised


def test_fallback_is_the_reach_point_of_least_violation():
    rng = np.random.default_rng(3)
    t = np.linspace(0, 2 * np.pi, 50_000, endpoint=False)
    done = 0
    while done < 40:
        sensor, r, targets, rho = _random_config(rng)
        if feasible_arcs(sensor, r, targets, rho):
            continue
        ring = sensor + r * np.stack([np.cos(t), np.sin(t)], -1)
        best = np.max(np.min(np.linalg.norm(ring[:, None] - targets[None], axis=-1), 1) - rho)
        x = fallback(sensor, np.float64(r), targets, np.float64(rho))
        val = np.min(np.linalg.norm(x - targets, axis=-1)) - rho
        assert np.linalg.norm(x - sensor) <= r * (1 + 1e-12)
        # Exact on the reach circle (farthest points and equidistant points are candidates):
        # never below the dense ring's best (up to rounding).
        assert val >= best - 1e-9
        done += 1


def test_modes_of_a_multi_target_problem():
    # Sensor 0 cannot move; sensor 1 is boxed in by three targets (from every point of its
    # reach disk the nearest target is at most ~1.235 m, checked by dense sampling, < 1.3);
    # sensor 2 is free.
    targets = np.array([[0.0, 1.2], [1.1, -0.6], [-1.1, -0.6]])
    p = PlanningProblem(
        np.stack([np.eye(2)] * 3),
        targets,
        np.array([[5.0, 0.0], [0.0, 0.0], [4.0, 4.0]]),
        np.array([0.0, 0.3, 1.0]),
        1.3,
        1.0,
        0.5,
        multi_target=True,
    )
    free, rel = sensor_modes(p)
    assert free.tolist() == [False, False, True]
    np.testing.assert_array_equal(rel[0] + targets[0], [5.0, 0.0])
    fb = fallback(np.zeros(2), np.float64(0.3), targets, np.float64(1.3))
    np.testing.assert_allclose(rel[1] + targets[0], fb, atol=1e-15)
    np.testing.assert_array_equal(rel[2] + targets[0], [4.0, 4.0])


def test_multi_target_modes_batch_equals_single_problems():
    rng = np.random.default_rng(4)
    singles = [multi_problem(rng, 3, 3, distance=(0.0, 3.0)) for _ in range(6)]
    free, rel = sensor_modes(PlanningProblem.stack(singles))
    for b, p in enumerate(singles):
        f, x = sensor_modes(p)
        np.testing.assert_array_equal(free[b], f)
        np.testing.assert_array_equal(rel[b], x)


def test_multi_target_modes_reject_degenerate_sensors():
    targets = np.array([[0.0, 0.0], [5.0, 0.0]])
    with pytest.raises(ValueError, match="rho must be > 0"):
        sensor_modes_multi(np.array([[0.5, 0.0]]), targets, np.array([1.0]), np.array([0.0]))
    with pytest.raises(ValueError, match="exactly on a predicted target"):
        sensor_modes_multi(np.array([[5.0, 0.0]]), targets, np.array([0.0]), np.array([1.0]))
