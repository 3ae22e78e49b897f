"""apply_actions / actions_to_reach against independent geometry (eq. 13-16)."""

import numpy as np
import pytest

from activetrack.sensor_motion import actions_to_reach, apply_actions, move_to

# The moves are compiled (activetrack.motion_kernels): make test also runs these as plain Python.
pytestmark = pytest.mark.kernels


def _brute_nearest_feasible(q, c, r, rho, n=400):
    """Return the feasible point nearest to q from a dense polar grid of the speed disk."""
    rad = np.sqrt(np.linspace(0.0, 1.0, n))[:, None] * r
    ang = np.linspace(0.0, 2 * np.pi, 4 * n, endpoint=False)[None, :]
    pts = np.stack([c[0] + rad * np.cos(ang), c[1] + rad * np.sin(ang)], -1).reshape(-1, 2)
    # add the exact boundary arcs of both circles, where the optimum lies
    t = np.linspace(0.0, 2 * np.pi, 20 * n)
    pts = np.concatenate([pts, c + r * np.stack([np.cos(t), np.sin(t)], -1),
                          rho * np.stack([np.cos(t), np.sin(t)], -1)])  # fmt: skip
    ok = (np.hypot(*(pts - c).T) <= r * (1 + 1e-9)) & (np.hypot(*pts.T) >= rho * (1 - 1e-9))
    pts = pts[ok]
    return pts[np.argmin(np.hypot(*(pts - q).T))]


def test_free_move_is_position_plus_reach_times_action():
    sensors = np.array([[10.0, 0.0], [0.0, -7.0]])
    target = np.array([1.0, 1.0])
    a = np.array([[0.5, -0.25], [-0.1, 0.3]])
    r = np.array([2.0, 0.5])
    new, proj = apply_actions(a, sensors, target, r, np.array([1.0, 1.0]))
    np.testing.assert_array_equal(new, sensors + a * r[:, None])
    assert not proj.any()


def test_long_actions_are_scaled_onto_the_unit_disk():
    sensors = np.array([[10.0, 0.0], [20.0, 0.0]])
    a = np.array([[3.0, 4.0], [1.0, 1.0]])  # norms 5 and sqrt 2
    new, _ = apply_actions(a, sensors, np.zeros(2), np.array([1.0, 2.0]), np.array([1.0, 1.0]))
    np.testing.assert_allclose(new[0], [10.6, 0.8], rtol=0, atol=1e-14)
    np.testing.assert_allclose(new[1], [20.0 + np.sqrt(2), np.sqrt(2)], rtol=0, atol=1e-14)


def test_norm_within_tolerance_of_one_is_not_rescaled():
    a = np.array([[np.cos(0.3), np.sin(0.3)]]) * (1 + 5e-13)
    sensors = np.array([[10.0, 0.0]])
    new, _ = apply_actions(a, sensors, np.zeros(2), np.array([1.0]), np.array([1.0]))
    np.testing.assert_array_equal(new, sensors + a)


@pytest.mark.parametrize("seed", range(6))
def test_projection_is_feasible_and_nearest(seed):
    rng = np.random.default_rng(seed)
    rho, r = 2.0, 1.0
    c = rng.uniform(-3.0, 3.0, 2)  # sensor relative to the predicted target
    target = rng.uniform(-5, 5, 2)
    sensors = (target + c)[None]
    ang = rng.uniform(0, 2 * np.pi)
    a = rng.uniform(0.0, 1.0) * np.array([[np.cos(ang), np.sin(ang)]])
    new, proj = apply_actions(a, sensors, target, np.array([r]), np.array([rho]))
    q = c + r * a[0]
    if np.hypot(*q) >= rho:
        assert not proj[0]
        np.testing.assert_array_equal(new, sensors + r * a)
        return
    assert proj[0]
    s = new[0] - target
    if np.hypot(*c) + r >= rho:  # a feasible point exists: feasible and nearest
        assert np.hypot(*(s - c)) <= r * (1 + 1e-12)
        assert np.hypot(*s) >= rho * (1 - 1e-12)
        best = _brute_nearest_feasible(q, c, r, rho)
        assert np.hypot(*(s - q)) <= np.hypot(*(best - q)) + 1e-3
    else:  # none: as far from the target as the reach allows
        np.testing.assert_allclose(s, c + r * c / np.hypot(*c), atol=1e-12)


def test_boundary_point_passes_unprojected():
    target = np.array([3.0, -1.0])
    rho = 2.0
    goal = target + rho * np.array([np.cos(1.0), np.sin(1.0)])  # on the rho circle
    sensors = (goal + np.array([0.6, 0.0]))[None]
    a = actions_to_reach(goal[None], sensors, np.array([1.0]))
    new, proj = apply_actions(a, sensors, target, np.array([1.0]), np.array([rho]))
    assert not proj[0]
    np.testing.assert_array_equal(new[0], goal)


def test_sensor_that_cannot_move_stays_even_inside_rho():
    sensors = np.array([[0.5, 0.0]])
    new, proj = apply_actions(
        np.array([[1.0, 0.0]]), sensors, np.zeros(2), np.array([0.0]), np.array([2.0])
    )
    np.testing.assert_array_equal(new, sensors)
    assert not proj[0]


def test_batched_equals_one_by_one():
    rng = np.random.default_rng(3)
    B, M = 7, 4
    a = rng.uniform(-1.5, 1.5, (B, M, 2))
    sensors = rng.uniform(-3, 3, (B, M, 2))
    target = rng.uniform(-1, 1, (B, 2))
    r = rng.uniform(0.5, 2.0, M)
    rho = rng.uniform(0.5, 2.5, M)
    new, proj = apply_actions(a, sensors, target, r, rho)
    assert proj.any() and not proj.all()
    for b in range(B):
        nb, pb = apply_actions(a[b], sensors[b], target[b], r, rho)
        np.testing.assert_array_equal(new[b], nb)
        np.testing.assert_array_equal(proj[b], pb)


@pytest.mark.parametrize("r", [1.0, 0.37, 2.5])
def test_actions_to_reach_round_trip(r):
    rng = np.random.default_rng(11)
    n = 4000
    sensors = rng.uniform(-30.0, 30.0, (n, 1, 2))
    ang = rng.uniform(0, 2 * np.pi, n)
    rad = r * np.sqrt(rng.uniform(0, 1, n))
    goal = sensors + (rad[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1))[:, None]
    a = actions_to_reach(goal, sensors, np.array([r]))
    assert np.all(np.hypot(a[..., 0], a[..., 1]) <= 1 + 1e-12)
    new, proj = apply_actions(a, sensors, np.full((n, 2), 1e3), np.array([r]), np.array([0.5]))
    assert not proj.any()
    diff = np.abs(new - goal)
    # Where a coordinate shrinks by cancellation (crossing zero) p + r a cannot always hit
    # it exactly: at most one unit in the last place of the largest operand; exact
    # almost everywhere.
    largest = np.maximum(np.maximum(np.abs(sensors), np.abs(goal)), np.abs(goal - sensors))
    assert np.all(diff <= np.spacing(largest))
    assert np.mean(diff == 0) > 0.99
    if r == 1.0:  # r a = a exactly; Sterbenz: goal within a factor 2 of the start is exact
        safe = (goal / sensors >= 0.5) & (goal / sensors <= 2.0)
        assert np.all(diff[safe] == 0)


def test_actions_to_reach_caps_and_handles_zero_reach():
    sensors = np.array([[0.0, 0.0], [5.0, 5.0]])
    goal = np.array([[3.0, 4.0], [7.0, 5.0]])
    a = actions_to_reach(goal, sensors, np.array([1.0, 0.0]))
    np.testing.assert_allclose(a, [[0.6, 0.8], [0.0, 0.0]], atol=1e-15)


def test_huge_finite_actions_keep_their_direction():
    # |a| overflows to inf for a = [1.7e308, 1.7e308]; the move must still be a full step
    # along the diagonal (independent: the unit vector (1, 1) / sqrt 2).
    sensors = np.array([[10.0, 0.0], [0.0, 10.0]])
    a = np.array([[1.7e308, 1.7e308], [-1e300, 0.0]])
    new, _ = apply_actions(a, sensors, np.zeros(2), np.array([1.0, 2.0]), np.zeros(2))
    np.testing.assert_allclose(new[0], [10.0 + 2**-0.5, 2**-0.5], rtol=0, atol=1e-14)
    np.testing.assert_allclose(new[1], [-2.0, 10.0], rtol=0, atol=1e-14)


def test_move_to_caps_the_step_and_keeps_feasible_positions():
    rng = np.random.default_rng(5)
    sensors = rng.uniform(-10, 10, (200, 2))
    target = np.array([0.5, -0.5])
    r, rho = np.full(200, 1.5), np.full(200, 1.0)
    proposals = sensors + rng.uniform(-4, 4, (200, 2))
    new, projected = move_to(proposals, sensors, target, r, rho)
    step = np.hypot(*(new - sensors).T)
    assert np.all(step <= r * (1 + 1e-12))
    dist = np.hypot(*(new - target).T)
    reachable = np.hypot(*(sensors - target).T) + r >= rho
    assert np.all(dist[reachable] >= rho[reachable] * (1 - 1e-12))
    # Within reach and outside rho: unchanged, bit for bit.
    ok = (np.hypot(*(proposals - sensors).T) <= r) & (np.hypot(*(proposals - target).T) > rho)
    np.testing.assert_array_equal(new[ok], proposals[ok])
    # Beyond reach, outside rho after capping: on the speed circle along the proposal.
    far = ~ok & ~projected
    direction = (proposals - sensors)[far] / np.hypot(*(proposals - sensors)[far].T)[:, None]
    np.testing.assert_allclose(new[far], sensors[far] + r[far, None] * direction, atol=1e-12)
    # A sensor with r = 0 stays where it is.
    stay, _ = move_to(proposals[:3], sensors[:3], target, np.zeros(3), np.zeros(3))
    np.testing.assert_array_equal(stay, sensors[:3])
