"""apply_actions / actions_to_reach against independent geometry (eq. 13-16)."""

import numpy as np
import pytest

from activetrack.kinematics.geometry import project_feasible
from activetrack.kinematics.sensor_motion import actions_to_reach, apply_actions, move_to

# The moves are compiled (activetrack.kinematics._kernels): make test also runs these as plain
# Python.
pytestmark = pytest.mark.kernels


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


def _circle(center, radius, n):
    """Return ``n`` points evenly spaced on a circle, the first at angle 0."""
    t = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    return center + radius * np.stack([np.cos(t), np.sin(t)], -1)


#: Points on each boundary circle of the brute-force grid: an optimum on a boundary arc
#: is within one spacing, 2 pi max(r, rho) / N_BOUNDARY, of a feasible grid point.
N_BOUNDARY = 20000
_ON_CIRCLE = _circle(0.0, 1.0, N_BOUNDARY)
_RADII = np.sqrt(np.linspace(0.0, 1.0, 120))[:, None, None]  # uniform in area
_IN_DISK = (_RADII * _circle(0.0, 1.0, 480)).reshape(-1, 2)  # the unit disk, polar


def _brute_force(s, t, r, rho, wanted):
    """Return ``(kind, value, h)`` from a dense grid of the speed disk around ``s``
    (polar, plus both boundary circles): if some grid point is feasible (within reach,
    at least ``rho`` from ``t``), ``("nearest", smallest distance to wanted)``; else
    ``("farthest", largest distance from t)``. ``h`` bounds how far the grid's value can
    be from the exact one (the grid spacing on the circles, where the optimum lies)."""
    pts = np.concatenate([s + r * _IN_DISK, s + r * _ON_CIRCLE, t + rho * _ON_CIRCLE])
    # The same relative slack as the code's tests (rounding of the circle points).
    in_reach = np.hypot(*(pts - s).T) <= r * (1 + 1e-12)
    far = np.hypot(*(pts - t).T) >= rho * (1 - 1e-12)
    h = 2 * np.pi * max(r, rho) / N_BOUNDARY
    ok = in_reach & far
    if ok.any():
        return "nearest", np.min(np.hypot(*(pts[ok] - wanted).T)), h
    return "farthest", np.max(np.hypot(*(pts[in_reach] - t).T)), h


def _wanted(entry, s, r, x):
    """Return where the move would end without the ``rho`` rule, from the rules of
    eq. (13)/(15) as the module docstring states them: ``s + r a`` with ``a`` scaled onto
    the unit disk (apply_actions), the proposal scaled onto the speed circle (move_to),
    ``q`` itself (project_feasible: already within reach)."""
    if entry == "project_feasible":
        return x
    if entry == "apply_actions":
        big = np.max(np.abs(x))
        a = x if big == 0 else x / big  # no overflow in the norm below
        norm = np.hypot(*a)  # |x| = big * norm
        return s + r * (x if big == 0 or norm <= 1 / big else a / norm)
    d = x - s
    return x if np.hypot(*d) <= r else s + r * d / np.hypot(*d)


def _classify(entry, s, t, r, rho, x):
    """Return the geometric classes of a case: where the wanted point lies (outside the
    ``rho`` disk; inside with the radial point within reach; inside with the nearest
    point at an intersection of the two circles, left or right of the line target-sensor;
    no feasible point; a sensor that cannot move), the degenerate cases, and how the move
    was capped."""
    n, c = _wanted(entry, s, r, x), s - t
    q = n - t
    nq, nc = np.hypot(*q), np.hypot(*c)
    tags = set()
    if entry == "apply_actions":
        with np.errstate(over="ignore"):
            norm = np.hypot(*x)
        tags.add("overflowing action" if np.isinf(norm) else "long" if norm > 1 else "short")
    elif entry == "move_to":
        tags.add("beyond reach" if np.hypot(*(x - s)) > r else "within reach")
    if nq == 0:
        tags.add("wanted point at the target")
    if nc == 0:
        tags.add("sensor at the target")
    if nc + r == rho:
        tags.add("tangent circles")
    if nq >= rho:
        kind = "outside"
    elif r == 0:
        kind = "cannot move"
    elif nc + r < rho:
        kind = "no feasible point"
    else:
        d = q / nq if nq > 0 else c / nc if nc > 0 else np.array([1.0, 0.0])
        if np.hypot(*(rho * d - c)) <= r:
            kind = "radial"
        else:
            kind = "intersection " + ("left" if c[0] * q[1] - c[1] * q[0] > 0 else "right")
    return kind, frozenset(tags)


def _draw(entry, rng):
    """Return one random case ``(s, t, r, rho, x)``; None near a class boundary."""
    t = rng.uniform(-5, 5, 2)
    rho, r = rng.uniform(0.5, 3.0), rng.uniform(0.2, 3.0)
    ang = rng.uniform(0, 2 * np.pi, 2)
    c = rng.uniform(0, rho + 2) * np.array([np.cos(ang[0]), np.sin(ang[0])])
    s, u = t + c, np.array([np.cos(ang[1]), np.sin(ang[1])])
    length = rng.uniform(0.0, 1.0) if rng.uniform() < 0.5 else rng.uniform(1.05, 3.0)
    if entry == "project_feasible":
        x = s + r * min(length, 1.0) * u
    else:
        x = u * length if entry == "apply_actions" else s + r * length * u
    q = _wanted(entry, s, r, x) - t
    nq, nc = np.hypot(*q), np.hypot(*c)
    d = q / nq
    margins = [abs(nq - rho), abs(np.hypot(*(rho * d - c)) - r), abs(c[0] * q[1] - c[1] * q[0])]
    # (A feasible set thinner than the grid spacing would leave the grid without a point.)
    if min(margins) < 1e-6 or abs(nc + r - rho) < 0.05:
        return None
    return s, t, r, rho, x


def _degenerate(entry):
    """Return hand-built cases ``(s, t, r, rho, x)``: the wanted point at the target, the
    sensor at the target (with and without a feasible point), both, tangent circles (one
    feasible point), a sensor that cannot move, a huge action."""
    t = np.array([1.0, -2.0])
    to_target = {"apply_actions": np.array([-1.0, 0.0]), "move_to": t, "project_feasible": t}
    cases = [
        (t + [1.5, 0.0], t, 1.5, 2.0, to_target[entry]),  # wanted at t: radial
        (t + [0.5, 0.0], t, 0.5, 2.0, to_target[entry]),  # wanted at t: none feasible
        (t.copy(), t, 2.5, 2.0, _step(entry, t, 0.7, [0.6, 0.8])),  # sensor at t
        (t.copy(), t, 1.0, 2.0, _step(entry, t, 1.0, [0.0, 1.0])),  # sensor at t, none
        (t.copy(), t, 2.5, 2.0, _step(entry, t, 0.0, [1.0, 0.0])),  # both at t
        (t + [1.5, 0.0], t, 0.5, 2.0, _step(entry, t + [1.5, 0.0], 0.5, [0.0, 1.0])),
    ]
    if entry != "project_feasible":
        moved = t + [1.0, 1.0]
        cases.append((moved, t, 0.0, 2.0, _step(entry, moved, 5.0, [1.0, 0.0])))
    if entry == "apply_actions":
        cases.append((t + [2.5, 0.0], t, 1.0, 2.0, np.array([-1.7e308, 1.0e308])))
    return cases


def _step(entry, s, length, u):
    """Return the action (apply_actions) or position that moves ``s`` by ``length`` (in
    units of the reach for an action, of distance otherwise) along ``u``."""
    u = np.asarray(u, np.float64)
    return length * u if entry == "apply_actions" else s + length * u


#: Every class each entry point must meet (a class missing from the cases fails the test):
#: the geometric ones, and the capping rules (each with every geometric class when drawn).
_GEOMETRY = {"outside", "radial", "intersection left", "intersection right", "no feasible point"}
_REQUIRED = {
    "apply_actions": (_GEOMETRY | {"cannot move"}, {"short", "long"}, {"overflowing action"}),
    "move_to": (_GEOMETRY | {"cannot move"}, {"within reach", "beyond reach"}, set()),
    "project_feasible": (_GEOMETRY, set(), set()),
}
_DEGENERATE = {"wanted point at the target", "sensor at the target", "tangent circles"}


def _call(entry, s, t, r, rho, x):
    """Return ``(positions, projected)`` of the cases (rows) through ``entry``: batched,
    one sensor per copy (projected is None for project_feasible)."""
    # (As plain Python, NUMBA_DISABLE_JIT=1, a zero divisor warns where the compiled
    # kernels' IEEE division is silent: the sensor at the target.)
    with np.errstate(divide="ignore", invalid="ignore"):
        if entry == "project_feasible":
            return project_feasible(x - t, s - t, r, rho) + t, None
        fn = apply_actions if entry == "apply_actions" else move_to
        new, proj = fn(x[:, None], s[:, None], t, r[:, None], rho[:, None])
    return new[:, 0], proj[:, 0]


@pytest.mark.parametrize("entry", list(_REQUIRED))
def test_moves_against_a_brute_force_search_of_the_feasible_set(entry):
    """Every move ends at the feasible point nearest to where it wanted to go, or (no
    feasible point) as far from the target as the reach allows, checked against a dense
    search of the feasible set {|p - s| <= r, |p - t| >= rho}, on cases drawn until every
    geometric class (and every capping rule) has several, plus the degenerate ones."""
    rng = np.random.default_rng(17)
    kinds, tags, rare = _REQUIRED[entry]
    wanted_classes = {(k, g) for k in _GEOMETRY for g in tags or {None}}
    cases, count = _degenerate(entry), {}
    for _ in range(20000):
        if all(count.get(key, 0) >= 4 for key in wanted_classes):
            break
        case = _draw(entry, rng)
        if case is None:
            continue
        kind, extra = _classify(entry, *case)
        key = (kind, next(iter(extra & tags), None))
        if count.get(key, 0) < 4:
            count[key] = count.get(key, 0) + 1
            cases.append(case)
    classes = [_classify(entry, *case) for case in cases]
    assert {k for k, _ in classes} >= kinds
    assert {(k, g) for k, extra in classes for g in (extra & tags or {None})} >= wanted_classes
    assert set().union(*(extra for _, extra in classes)) >= _DEGENERATE | rare

    s, t, r, rho, x = (np.array([case[i] for case in cases]) for i in range(5))
    new, projected = _call(entry, s, t, r, rho, x)
    for i, (kind, _) in enumerate(classes):
        wanted = _wanted(entry, s[i], r[i], x[i])
        scale = max(np.abs(s[i]).max(), rho[i] + np.abs(t[i]).max())
        if kind in ("outside", "cannot move"):
            expected = wanted if kind == "outside" else s[i]
            np.testing.assert_allclose(new[i], expected, rtol=0, atol=1e-12 * scale)
            assert projected is None or not projected[i]
            continue
        assert projected is None or projected[i]
        assert np.hypot(*(new[i] - s[i])) <= r[i] * (1 + 1e-12) + 1e-12 * scale
        goal, best, h = _brute_force(s[i], t[i], r[i], rho[i], wanted)
        if kind == "no feasible point":
            assert goal == "farthest"
            far = np.hypot(*(new[i] - t[i]))
            # The grid's points are within reach: the farthest is at least as far as
            # the grid's, and the grid's within h of it.
            assert best - 1e-9 <= far <= best + h, (i, kind, far, best)
            continue
        assert goal == "nearest", (i, kind)
        assert np.hypot(*(new[i] - t[i])) >= rho[i] * (1 - 1e-12)
        dist = np.hypot(*(new[i] - wanted))
        # Grid points are feasible, so the optimum is no farther than the grid's best,
        # and the grid's best is within h of the optimum.
        assert best - h <= dist <= best + 1e-9, (i, kind, dist, best)


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
