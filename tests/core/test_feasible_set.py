"""The K-target feasible set: membership, projection, boundary arcs, sampling, fallback.

References: dense sampling of the plane (brute-force nearest feasible point), the
single-target geometry of :mod:`activetrack.kinematics.geometry`, bisection walks to the boundary,
and distances written out longhand here.
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from activetrack.kinematics import feasible_set as fs
from activetrack.kinematics import geometry


def feasible_longhand(s, center, r, targets, rho, tol=1e-9):
    """Return membership in F with an absolute tolerance, written out."""
    ok = np.linalg.norm(s - center, axis=-1) <= r + tol
    for t in targets:
        ok &= np.linalg.norm(s - t, axis=-1) >= rho - tol
    return ok


def random_layout(rng, k):
    center = rng.normal(size=2)
    r = rng.uniform(0.3, 2.0)
    targets = center + rng.normal(size=(k, 2)) * rng.uniform(0.3, 2.0)
    rho = r * rng.uniform(0.05, 1.0)
    return center, r, targets, rho


def test_contains_matches_longhand_distances():
    rng = np.random.default_rng(0)
    for k in (1, 2, 4):
        center, r, targets, rho = random_layout(rng, k)
        s = center + rng.uniform(-1.5 * r, 1.5 * r, size=(5000, 2))
        got = fs.contains(s, center, r, targets, rho)
        want = feasible_longhand(s, center, r, targets, rho, tol=0.0)
        # Away from the circles (where the tolerance matters) both agree exactly.
        margin = np.abs(np.linalg.norm(s - center, axis=-1) - r) > 1e-9
        for t in targets:
            margin &= np.abs(np.linalg.norm(s - t, axis=-1) - rho) > 1e-9
        np.testing.assert_array_equal(got[margin], want[margin])


def test_contains_accepts_boundary_points_to_rounding():
    rng = np.random.default_rng(1)
    center, r, targets, rho = random_layout(rng, 3)
    ang = rng.uniform(0, 2 * np.pi, 1000)
    on_reach = center + r * np.stack([np.cos(ang), np.sin(ang)], -1)
    outside = np.ones(len(ang), bool)
    for t in targets:
        outside &= np.linalg.norm(on_reach - t, axis=-1) > rho * (1 + 1e-9)
    assert np.all(fs.contains(on_reach, center, r, targets, rho)[outside])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), k=st.integers(1, 4), far=st.booleans())
def test_project_is_the_nearest_feasible_point_by_brute_force(seed, k, far):
    rng = np.random.default_rng(seed)
    center, r, targets, rho = random_layout(rng, k)
    q = center + rng.normal(size=2) * (2.0 * r if far else 0.5 * r)
    p = fs.project(q, center, r, targets, rho)
    n = 400
    u = np.linspace(-r, r, n)
    grid = center + np.stack(np.meshgrid(u, u), -1).reshape(-1, 2)
    ok = feasible_longhand(grid, center, r, targets, rho, tol=0.0)
    if not ok.any():  # F (nearly) empty on this grid: nothing to compare with
        return
    assert feasible_longhand(p, center, r, targets, rho, tol=1e-9 * (1 + r))
    d = np.linalg.norm(p - q)
    d_grid = np.linalg.norm(grid[ok] - q, axis=-1).min()
    assert d_grid >= d - 1e-9  # no feasible sample is closer (exactly: F is closed)
    if feasible_longhand(q, center, r, targets, rho, tol=0.0):
        np.testing.assert_array_equal(p, q)
    else:  # on the boundary: on one of the circles
        gaps = [abs(np.linalg.norm(p - center) - r)]
        gaps += [abs(np.linalg.norm(p - t) - rho) for t in targets]
        assert min(gaps) <= 1e-9 * (1 + r)


def test_project_agrees_with_single_target_geometry():
    rng = np.random.default_rng(2)
    b = 20_000
    c = rng.normal(size=(b, 2)) * 2
    r = rng.uniform(0, 3, b)
    t = rng.normal(size=(b, 1, 2)) * 2
    rho = rng.uniform(0, 3, b)
    ang = rng.uniform(0, 2 * np.pi, b)
    q = c + (r * np.sqrt(rng.random(b)))[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    got = fs.project(q, c, r, t, rho)
    want = geometry.project_feasible(q - t[:, 0], c - t[:, 0], r, rho) + t[:, 0]
    scale = 1.0 + np.abs(c).max(-1) + r + rho
    assert np.all(np.abs(got - want).max(-1) <= 1e-12 * scale)


def test_project_is_batched_over_leading_axes():
    rng = np.random.default_rng(3)
    c = rng.normal(size=(3, 4, 2))
    t = rng.normal(size=(3, 4, 2, 2))
    q = rng.normal(size=(3, 4, 2))
    r, rho = rng.uniform(0.5, 1, (3, 4)), rng.uniform(0.1, 0.5, (3, 4))
    out = fs.project(q, c, r, t, rho)
    assert out.shape == (3, 4, 2)
    for i in range(3):
        for j in range(4):
            np.testing.assert_array_equal(
                out[i, j], fs.project(q[i, j], c[i, j], r[i, j], t[i, j], rho[i, j])
            )


def test_empty_set_fallback():
    rng = np.random.default_rng(4)
    # K = 1: the reachable point farthest from the target (geometry's fallback).
    c, t = np.array([0.3, -0.2]), np.array([[0.0, 0.1]])
    out = fs.project(c, c, 0.5, t, 2.0)
    want = geometry.unreachable_fallback(c - t[0], 0.5) + t[0]
    np.testing.assert_allclose(out, want, rtol=0, atol=1e-15)
    assert fs.is_empty(c, 0.5, t, 2.0)
    # K targets surrounding the sensor: finite, in the reach disk, and at least as far from
    # the nearest target (minus rho) as the centre and the far points it chooses among.
    for _ in range(50):
        k = int(rng.integers(2, 5))
        c = rng.normal(size=2)
        ang = np.sort(rng.uniform(0, 2 * np.pi, k))
        targets = c + 0.5 * np.stack([np.cos(ang), np.sin(ang)], -1)
        r, rho = 0.3, 1.5
        assert fs.is_empty(c, r, targets, rho)
        out = fs.project(c + 0.1, c, r, targets, rho)
        assert np.all(np.isfinite(out))
        assert np.linalg.norm(out - c) <= r * (1 + 1e-12)

        units = (c - targets) / np.linalg.norm(c - targets, axis=-1)[:, None]
        margin = [
            np.min(np.linalg.norm(s - targets, axis=-1)) - rho for s in [out, c, *(c + r * units)]
        ]
        assert margin[0] >= max(margin[1:]) - 1e-12


def walk_to_boundary(s, direction, center, r, targets, rho):
    """Bisection along a ray from feasible s to the first exit from F."""
    lo, hi = 0.0, 1e-3
    while feasible_longhand(s + hi * direction, center, r, targets, rho, tol=0.0):
        lo, hi = hi, 2 * hi
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if feasible_longhand(s + mid * direction, center, r, targets, rho, tol=0.0):
            lo = mid
        else:
            hi = mid
    return s + lo * direction


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), k=st.integers(1, 4))
def test_boundary_arcs_are_the_boundary(seed, k):
    rng = np.random.default_rng(seed)
    center, r, targets, rho = random_layout(rng, k)
    arcs = fs.boundary_arcs(center, r, targets, rho)
    pts = geometry.discretize(arcs, spacing=2e-3 * r) if arcs else np.empty((0, 2))
    circles = [(center, r)] + [(t, rho) for t in targets]
    # Every arc point is feasible and on one of the circles (so next to an infeasible point).
    assert np.all(feasible_longhand(pts, center, r, targets, rho, tol=1e-9))
    on = np.zeros(len(pts), bool)
    for o, rad in circles:
        on |= np.abs(np.linalg.norm(pts - o, axis=-1) - rad) <= 1e-9 * (1 + rad)
    assert on.all()
    # Arc ends (of arcs that are not whole circles) lie on a second circle.
    for arc in arcs:
        if np.isclose(arc.t1 - arc.t0, 2 * np.pi):
            continue
        for end in arc.points(np.array([arc.t0, arc.t1])):
            hits = sum(abs(np.linalg.norm(end - o) - rad) <= 1e-9 * (1 + rad) for o, rad in circles)
            assert hits >= 2
    # Every boundary point found by walking out of F lies on an arc.
    u = rng.random((300, 2))
    cand = center + r * np.sqrt(u[:, :1]) * np.column_stack(
        [np.cos(2 * np.pi * u[:, 1]), np.sin(2 * np.pi * u[:, 1])]
    )
    cand = cand[feasible_longhand(cand, center, r, targets, rho, tol=0.0)][:15]
    if len(cand) and not arcs:
        pytest.fail("F has interior points but no boundary arcs")
    for s in cand:
        ang = rng.uniform(0, 2 * np.pi)
        sb = walk_to_boundary(s, np.array([np.cos(ang), np.sin(ang)]), center, r, targets, rho)
        assert np.min(np.linalg.norm(pts - sb, axis=1)) < 2e-3 * r


def test_boundary_arcs_special_cases():
    assert fs.boundary_arcs([0.0, 0.0], 0.0, [[1.0, 0.0]], 0.5) == []
    assert fs.boundary_arcs([0.0, 0.0], 1.0, [[0.1, 0.0]], 3.0) == []  # F empty
    arcs = fs.boundary_arcs([0.0, 0.0], 1.0, [[5.0, 0.0]], 0.5)  # disks apart: reach circle
    assert len(arcs) == 1 and arcs[0].radius == 1.0
    assert np.isclose(arcs[0].t1 - arcs[0].t0, 2 * np.pi)
    # Two targets at the same position count once.
    arcs = fs.boundary_arcs([0.0, 0.0], 1.0, [[0.2, 0.0], [0.2, 0.0]], 0.3)
    assert sum(a.radius == 0.3 for a in arcs) == 1


def test_sample_interior_is_feasible_deterministic_and_uniform():
    rng = np.random.default_rng(5)
    center, r, targets, rho = np.zeros(2), 1.0, np.array([[0.5, 0.0], [-0.3, 0.4]]), 0.3
    a = fs.sample_interior(center, r, targets, rho, np.random.default_rng(7), 4000)
    b = fs.sample_interior(center, r, targets, rho, np.random.default_rng(7), 4000)
    np.testing.assert_array_equal(a, b)
    assert a.shape == (4000, 2)
    assert np.all(feasible_longhand(a, center, r, targets, rho, tol=1e-12))
    # The sample mean matches the centroid of F from a fine grid (Monte Carlo, 5 sigma).
    u = np.linspace(-1, 1, 801)
    grid = np.stack(np.meshgrid(u, u), -1).reshape(-1, 2)
    grid = grid[feasible_longhand(grid, center, r, targets, rho, tol=0.0)]
    se = grid.std(0) / np.sqrt(len(a))
    assert np.all(np.abs(a.mean(0) - grid.mean(0)) < 5 * se + 1e-3)
    del rng
    # Fallbacks: r = 0 feasible -> the centre; F empty -> the fallback point.
    out = fs.sample_interior([2.0, 0.0], 0.0, [[0.0, 0.0]], 1.0, np.random.default_rng(0), 3)
    np.testing.assert_array_equal(out, np.tile([2.0, 0.0], (3, 1)))
    out = fs.sample_interior([0.0, 0.0], 0.5, [[0.1, 0.0]], 2.0, np.random.default_rng(0), 2)
    want = fs.fallback(np.zeros(2), 0.5, np.array([[0.1, 0.0]]), 2.0)
    np.testing.assert_array_equal(out, np.tile(want, (2, 1)))
