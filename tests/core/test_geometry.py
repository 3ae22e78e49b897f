"""Feasible-set geometry: Lemma 3's curve ADB and the projection, against brute force."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from activetrack.kinematics import geometry

# The moves are compiled (activetrack.kinematics._kernels): make test also runs these as plain
# Python.
pytestmark = pytest.mark.kernels


def feasible(s, c, r, rho, tol=1e-9):
    return (np.linalg.norm(s - c, axis=-1) <= r + tol) & (np.linalg.norm(s, axis=-1) >= rho - tol)


def first_boundary_towards_origin(s, c, r, rho):
    """Walk from feasible s towards the origin; return the last feasible point (bisection)."""
    lo, hi = 0.0, 1.0  # fraction of s: hi is feasible
    # find an infeasible fraction first (exists: the origin is infeasible when rho > 0)
    ts = np.linspace(1.0, 0.0, 4001)
    pts = ts[:, None] * s
    ok = feasible(pts, c, r, rho, tol=0.0)
    k = np.argmin(ok)  # first infeasible along the walk
    hi, lo = ts[k - 1], ts[k]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if feasible(mid * s, c, r, rho, tol=0.0):
            hi = mid
        else:
            lo = mid
    return hi * s


@settings(max_examples=150, deadline=None)
@given(
    cn=st.floats(0.1, 20),
    ca=st.floats(-np.pi, np.pi),
    r=st.floats(0.1, 5),
    rho=st.floats(0.05, 5),
    seed=st.integers(0, 1000),
)
def test_curve_adb_contains_every_first_boundary_point(cn, ca, r, rho, seed):
    c = cn * np.array([np.cos(ca), np.sin(ca)])
    arcs = geometry.facing_boundary(c, r, rho)
    if cn + r < rho:
        assert arcs == []
        return
    pts = geometry.discretize(arcs, spacing=1e-3 * r)
    assert np.all(feasible(pts, c, r, rho))
    rng = np.random.default_rng(seed)
    # random feasible points of the disk
    u = rng.random((400, 2))
    cand = c + r * np.sqrt(u[:, :1]) * np.column_stack(
        [np.cos(2 * np.pi * u[:, 1]), np.sin(2 * np.pi * u[:, 1])]
    )
    cand = cand[feasible(cand, c, r, rho, tol=0.0)][:20]
    for s in cand:
        sb = first_boundary_towards_origin(s, c, r, rho)
        assert np.min(np.linalg.norm(pts - sb, axis=1)) < 2e-3 * r + 1e-6


def test_cases_match_paper_definitions():
    c = np.array([10.0, 0.0])
    assert geometry.case_of(c, 1.0, 2.0) == 1  # rho <= |c| - r
    assert geometry.case_of(c, 1.0, 9.99) == 2  # rho >= sqrt(|c|^2 - r^2)
    assert geometry.case_of(c, 1.0, 9.5) == 3
    assert geometry.case_of(c, 12.0, 2.0) == 4
    assert len(geometry.facing_boundary(c, 1.0, 2.0)) == 1
    assert len(geometry.facing_boundary(c, 1.0, 9.995)) == 1
    assert len(geometry.facing_boundary(c, 1.0, 9.5)) == 3


@settings(max_examples=100, deadline=None)
@given(
    cn=st.floats(0.5, 10),
    r=st.floats(0.2, 5),
    rho=st.floats(0.1, 5),
    qa=st.floats(-np.pi, np.pi),
    qr=st.floats(0, 1),
)
def test_projection_is_nearest_feasible_point(cn, r, rho, qa, qr):
    c = np.array([cn, 0.0])
    q = c + r * qr * np.array([np.cos(qa), np.sin(qa)])
    p = geometry.project_feasible(q, c, r, rho)
    if cn + r < rho:
        np.testing.assert_allclose(p, geometry.unreachable_fallback(c, r))
        return
    assert feasible(p, c, r, rho, tol=1e-9)
    # brute force: dense polar grid of the feasible set; no point of it is closer to q
    # (the feasibility test only on the grid points closer than p, the same comparison)
    t = np.linspace(0, 2 * np.pi, 2000)
    rad = np.linspace(0, r, 400)
    grid = c + (rad[:, None, None] * np.stack([np.cos(t), np.sin(t)], -1)).reshape(-1, 2)
    dist = np.linalg.norm(grid - q, axis=1)
    closer = dist + 1e-9 < np.linalg.norm(p - q)
    better = feasible(grid[closer], c, r, rho, tol=0.0)
    assert not better.any(), (p, grid[closer][better][:3], dist[closer][better].min())


def test_uniform_sampling_covers_arcs_by_length():
    c = np.array([3.0, 0.0])
    arcs = geometry.facing_boundary(c, 1.0, 2.5)  # case III: three arcs
    rng = np.random.default_rng(0)
    pts = np.array([geometry.sample_uniform(arcs, rng) for _ in range(6000)])
    on_rho = np.isclose(np.linalg.norm(pts, axis=1), 2.5, atol=1e-9)
    lengths = np.array([a.length for a in arcs])
    expected = lengths[-1] / lengths.sum()  # the rho arc is appended last
    assert on_rho.mean() == pytest.approx(
        expected, abs=4 * np.sqrt(expected * (1 - expected) / 6000)
    )
