"""The analytic single-sensor optimum (Section IV-A) against independent computations.

The reference objective builds the 2x2 information matrix of eq. (22) entry by entry and
inverts it: by its adjugate on dense grids, with ``np.linalg.inv`` as a cross-check, and in
40-digit arithmetic (mpmath) wherever a value is compared (near the target the matrix is
so ill-conditioned that a float64 inverse is only good to ~cond * eps). The reference
optimum is a dense search of the whole feasible boundary (both circles' feasible arcs,
found here with their own geometry, >= 20,000 points) with bounded local refinement.
Nothing here calls the solver's own objective, candidates or geometry.
"""

import math
import os
import subprocess
import sys
from pathlib import Path

import mpmath as mp
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from activetrack.solvers.analytic import (
    BatchSolution,
    SingleSensorSolution,
    case1_critical_points,
    solve_single_sensor,
    solve_single_sensor_batch,
)

ROOT = Path(__file__).resolve().parents[2]
J = np.array([[0.0, 1.0], [-1.0, 0.0]])  # C(-pi/2), eq. (9)


# ----------------------------------------------------------------------------- references


def ref_f0(prior_info, pts, sd2, st2):
    """Return tr((L' + info(s))^-1) of eq. (22) for points (K, 2).

    The information matrix is built entry by entry from eq. (9) and inverted by its
    adjugate (``tr(M^-1) = tr(M) / det(M)`` for 2x2), vectorized over the points.
    """
    pts = np.atleast_2d(np.asarray(pts, dtype=float))
    n2 = np.einsum("ki,ki->k", pts, pts)
    js = pts @ J.T
    info = (
        prior_info
        + np.einsum("ki,kj->kij", pts, pts) / (sd2 * n2)[:, None, None]
        + np.einsum("ki,kj->kij", js, js) / (st2 * n2 * n2)[:, None, None]
    )
    det = info[:, 0, 0] * info[:, 1, 1] - info[:, 0, 1] * info[:, 1, 0]
    return (info[:, 0, 0] + info[:, 1, 1]) / det


def inv_f0(prior_info, s, sd2, st2):
    """Return f0 at one point through ``np.linalg.inv`` of the explicit information matrix."""
    s = np.asarray(s, dtype=float)
    n2 = float(s @ s)
    info = prior_info + np.outer(s, s) / (sd2 * n2) + np.outer(J @ s, J @ s) / (st2 * n2 * n2)
    return float(np.trace(np.linalg.inv(info)))


def feasible_arcs(c, r, rho):
    """Return the feasible boundary as arcs (center, radius, t0, t1), t1 - t0 <= 2 pi.

    Speed circle: the part with ||s|| >= rho. rho circle: the part with ||s - c|| <= r.
    Each is the complement (or the whole) of one arc centred on the line through c.
    """
    c = np.asarray(c, dtype=float)
    nc = float(np.linalg.norm(c))
    phi = math.atan2(c[1], c[0]) if nc > 0 else 0.0
    arcs = []
    if r > 0:
        # Points c + r u(t) with ||.|| < rho: |t - (phi + pi)| < beta (law of cosines).
        cosb = (nc * nc + r * r - rho * rho) / (2 * r * nc) if nc > 0 else np.inf
        if cosb >= 1:  # entire speed circle outside the rho disk
            arcs.append((c, r, 0.0, 2 * math.pi))
        elif cosb > -1:
            beta = math.acos(cosb)
            arcs.append((c, r, phi + math.pi + beta, phi + 3 * math.pi - beta))
    if rho > 0:
        # Points rho u(t) with ||. - c|| <= r: |t - phi| <= g.
        cosg = (rho * rho + nc * nc - r * r) / (2 * rho * nc) if nc > 0 else -np.inf
        if nc == 0 and rho > r:
            cosg = np.inf
        if cosg <= -1:
            arcs.append((np.zeros(2), rho, 0.0, 2 * math.pi))
        elif cosg < 1:
            g = math.acos(cosg)
            arcs.append((np.zeros(2), rho, phi - g, phi + g))
    return arcs


def arc_points(arc, t):
    center, rad, _, _ = arc
    t = np.atleast_1d(t)
    return center + rad * np.stack([np.cos(t), np.sin(t)], axis=-1)


def mp_trace(prior_info, x, y, sd2, st2):
    """Return f0 at (x, y) (mpmath numbers) in 40-digit arithmetic, as an mpf.

    The entries of M = L' + info(s) one by one, then tr(M^-1) = tr(M) / det(M) (2x2):
    mpmath's general matrix inverse gives the same 40 digits at ten times the cost.
    """
    mp.mp.dps = 40
    n2 = x * x + y * y
    p = [x, y]
    q = [y, -x]  # J s
    sd2, st2 = mp.mpf(float(sd2)), mp.mpf(float(st2))
    M = [
        [
            mp.mpf(float(prior_info[i, j]))
            + p[i] * p[j] / (sd2 * n2)
            + q[i] * q[j] / (st2 * n2 * n2)
            for j in range(2)
        ]
        for i in range(2)
    ]
    return (M[0][0] + M[1][1]) / (M[0][0] * M[1][1] - M[0][1] * M[1][0])


def mp_f0(prior_info, s, sd2, st2):
    """Return f0 at one point with 40-digit arithmetic (the float64 inverse of the
    information matrix loses ~cond(M) eps when the sensor is very close to the target)."""
    mp.mp.dps = 40
    return float(mp_trace(prior_info, mp.mpf(float(s[0])), mp.mpf(float(s[1])), sd2, st2))


def focus_angles(arc, c):
    """Return extra angles near the speed-circle point closest to the target, where f0
    changes on the length scale ||c|| - r (empty for the rho circle)."""
    center, rad, t0, t1 = arc
    nc = float(np.linalg.norm(c))
    if not np.any(center) or nc <= rad:
        return np.empty(0)
    tn = t0 + (math.atan2(-c[1], -c[0]) - t0) % (2 * math.pi)
    d = (nc - rad) / rad
    t = np.concatenate(
        [tn + np.linspace(-1, 1, 501) * min(math.pi, 10.0**k * d) for k in range(-1, 4)]
    )
    return t[(t >= t0) & (t <= t1)]


def brute_force(prior_info, c, r, rho, sd2, st2, n_total=20_000):
    """Return the minimum of f0 over the feasible boundary: dense grid + local refinement.

    At least ``n_total`` points on the feasible arcs (arc ends included), plus a few
    thousand near the point closest to the target; the best points of every arc are then
    refined by bounded zooming grids (each level 41 points on +-w around the incumbent,
    w shrinking 20x per level, clipped to the arc). The incumbents are finally evaluated
    in 40-digit arithmetic, so the value returned is the true objective of a feasible point.
    """
    arcs = [a for a in feasible_arcs(c, r, rho) if a[3] > a[2]]
    lengths = np.array([a[1] * (a[3] - a[2]) for a in arcs])
    incumbents = []
    for arc, length in zip(arcs, lengths, strict=True):
        n = max(2_000, int(n_total * length / lengths.sum()) + 1)
        t = np.linspace(arc[2], arc[3], n)
        t = np.sort(np.concatenate([t, focus_angles(arc, c)]))
        vals = ref_f0(prior_info, arc_points(arc, t), sd2, st2)
        top = np.argsort(vals)[:4]
        gap = np.diff(t)
        w = np.maximum(gap[np.minimum(top, gap.size - 1)], gap[np.maximum(top - 1, 0)])
        tc = t[top]
        for _ in range(6):
            grid = np.clip(tc[:, None] + w[:, None] * np.linspace(-1, 1, 41), arc[2], arc[3])
            v = ref_f0(prior_info, arc_points(arc, grid.ravel()), sd2, st2).reshape(grid.shape)
            tc = grid[np.arange(top.size), np.argmin(v, axis=1)]
            w = w / 20
        incumbents += [arc_points(arc, tt)[0] for tt in tc]
    return min(mp_f0(prior_info, p, sd2, st2) for p in incumbents)


def rotation(phi):
    return np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])


# ----------------------------------------------------------------------------- strategies

logu = st.floats(0.0, 1.0)


@st.composite
def problems(draw, case):
    """Draw a problem of the given geometric case (1-4) within the ranges of the issue."""
    lam = [10.0 ** (-2 + 4 * draw(logu)) for _ in range(2)]
    phi = draw(st.floats(0, math.pi))
    prior = rotation(phi) @ np.diag(lam) @ rotation(phi).T
    prior = 0.5 * (prior + prior.T)

    def span(lo, hi):
        return lo * (hi / lo) ** draw(logu)

    r = span(0.05, 5.0)
    rho = span(0.05, 5.0)
    if case == 1:
        lo, hi = max(0.5, r + rho), 50.0
    elif case == 2:
        lo, hi = max(0.5, r, rho - r), min(50.0, math.sqrt(rho * rho + r * r))
    elif case == 3:
        lo, hi = max(0.5, r, math.sqrt(rho * rho + r * r)), min(50.0, rho + r)
    else:
        lo, hi = max(0.5, rho - r), r
    lo, hi = lo * (1 + 1e-9), hi * (1 - 1e-9)  # strictly inside: the case is well defined
    assume(hi > lo)
    nc = span(lo, hi) if case != 4 else lo + (hi - lo) * draw(logu)
    ang = draw(st.floats(-math.pi, math.pi))
    c = nc * np.array([math.cos(ang), math.sin(ang)])
    sd2 = 10.0 ** (-3 + 4 * draw(logu))
    st2 = 10.0 ** (-3 + 4 * draw(logu))
    return prior, c, r, rho, sd2, st2


def check_against_brute_force(prior, c, r, rho, sd2, st2):
    sol = solve_single_sensor(prior, c, r, rho, sd2, st2)
    assert isinstance(sol, SingleSensorSolution)
    assert sol.feasible
    s = sol.s
    # The returned point is feasible to 1e-9 (eq. 23-24).
    assert np.linalg.norm(s - c) <= r * (1 + 1e-9)
    assert np.linalg.norm(s) >= rho * (1 - 1e-9)
    # The reported value is the objective at s (40 digits; float64 inverse to cond * eps).
    v_at_s = mp_f0(prior, s, sd2, st2)
    assert sol.value == pytest.approx(v_at_s, rel=1e-12)
    assert sol.value == pytest.approx(inv_f0(prior, s, sd2, st2), rel=1e-4)
    ref = brute_force(prior, c, r, rho, sd2, st2)
    assert (v_at_s - ref) / ref <= 1e-9, (v_at_s, ref)  # never worse than the dense search
    assert abs(v_at_s - ref) / ref <= 1e-6  # and agrees with it
    return sol


PROPERTY_SETTINGS = settings(
    # As plain Python (NUMBA_DISABLE_JIT=1, the kernels' source check) a fifth of them.
    max_examples=100 if os.environ.get("NUMBA_DISABLE_JIT") == "1" else 500,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.filter_too_much, HealthCheck.too_slow],
)


@pytest.mark.kernels
@PROPERTY_SETTINGS
@given(problems(1))
def test_case1_matches_dense_search(p):
    assert check_against_brute_force(*p).case == 1


@pytest.mark.kernels
@PROPERTY_SETTINGS
@given(problems(2))
def test_case2_matches_dense_search(p):
    assert check_against_brute_force(*p).case == 2


@pytest.mark.kernels
@PROPERTY_SETTINGS
@given(problems(3))
def test_case3_matches_dense_search(p):
    assert check_against_brute_force(*p).case == 3


@pytest.mark.kernels
@PROPERTY_SETTINGS
@given(problems(4))
def test_case4_target_within_reach_matches_dense_search(p):
    assert check_against_brute_force(*p).case == 4


@pytest.mark.kernels
@pytest.mark.parametrize("seed", range(100))
def test_hard_instances_close_to_the_target(seed):
    """Speed circle passing very near the target: f0 varies fast and roots crowd."""
    rng = np.random.default_rng(1000 + seed)
    lam = 10.0 ** rng.uniform(-2, 2, 2)
    phi = rng.uniform(0, math.pi)
    prior = rotation(phi) @ np.diag(lam) @ rotation(phi).T
    r = 10 ** rng.uniform(-1.3, 0.7)
    nc = r * (1 + 10 ** rng.uniform(-4, -1))
    ang = rng.uniform(-math.pi, math.pi)
    c = nc * np.array([math.cos(ang), math.sin(ang)])
    rho = (nc - r) * rng.uniform(0.1, 1.0)
    sd2, st2 = 10 ** rng.uniform(-3, 1), 10 ** rng.uniform(-3, 1)
    assert check_against_brute_force(prior, c, r, rho, sd2, st2).case == 1


# ------------------------------------------------------------------ Case-I critical points


def tangential_derivative(prior, s, c, r, sd2, st2):
    """Return (s - c)^T C(pi/2) grad f0(s) (eq. 31), grad f0 by central differences in
    40-digit arithmetic (step 1e-8 r: no cancellation noise, truncation ~1e-16)."""
    mp.mp.dps = 40
    x, y = mp.mpf(float(s[0])), mp.mpf(float(s[1]))
    h = mp.mpf(1e-8 * r)
    gx = (mp_trace(prior, x + h, y, sd2, st2) - mp_trace(prior, x - h, y, sd2, st2)) / (2 * h)
    gy = (mp_trace(prior, x, y + h, sd2, st2) - mp_trace(prior, x, y - h, sd2, st2)) / (2 * h)
    # C(pi/2) g = (-gy, gx).
    return float(-(x - mp.mpf(float(c[0]))) * gy + (y - mp.mpf(float(c[1]))) * gx)


@pytest.mark.parametrize("seed", range(200))
def test_companion_roots_are_kkt_points_on_the_speed_circle(seed):
    rng = np.random.default_rng(seed)
    lam = 10.0 ** rng.uniform(-2, 2, 2)
    phi = rng.uniform(0, math.pi)
    prior = rotation(phi) @ np.diag(lam) @ rotation(phi).T
    r = 10 ** rng.uniform(-1.3, 0.7)
    nc = r + 10 ** rng.uniform(-0.5, 1.5)
    ang = rng.uniform(-math.pi, math.pi)
    c = nc * np.array([math.cos(ang), math.sin(ang)])
    sd2, st2 = 10 ** rng.uniform(-3, 1), 10 ** rng.uniform(-3, 1)
    pts, roots = case1_critical_points(prior, c, r, sd2, st2, return_roots=True)
    assert len(pts) >= 2  # at least the minimum and the maximum over the circle
    t = np.linspace(-math.pi, math.pi, 4097)
    vals = ref_f0(prior, c + r * np.stack([np.cos(t), np.sin(t)], -1), sd2, st2)
    d = np.diff(vals)
    scale = np.max(np.abs(d)) / (t[1] - t[0])  # max |df0/dt| over the circle
    distinct = np.unique(roots)
    for s, v in zip(pts, roots, strict=True):
        # f2 = 0 (eq. 30): on the speed circle.
        assert abs(np.linalg.norm(s - c) - r) <= 1e-9 * r
        # f1 = 0 (eq. 31-32): the gradient is normal to the circle; (s - c)^T C(pi/2) grad
        # f0 is df0/dt, compared with its largest value on the circle. A root of f3 that
        # nearly coincides with another one (two critical points sharing a coordinate, or
        # a minimum and a maximum about to merge) is only accurate to ~ eps / separation.
        sep = np.min(np.abs(distinct[distinct != v] - v), initial=1.0)
        tang = tangential_derivative(prior, s, c, r, sd2, st2)
        assert abs(tang) <= 1e-6 * max(1.0, 1e-2 / sep) * scale
    # Completeness: every sign change of df0/dt on a dense grid is bracketed by a root.
    found = np.arctan2(pts[:, 1] - c[1], pts[:, 0] - c[0])
    for i in np.flatnonzero(np.sign(d[:-1]) * np.sign(d[1:]) < 0):
        lo, hi = t[i], t[i + 2]
        dist = np.abs((found - 0.5 * (lo + hi) + math.pi) % (2 * math.pi) - math.pi)
        assert np.min(dist) <= (hi - lo), f"no root near t={t[i + 1]}"


# -------------------------------------------------------------------- degenerate inputs


@pytest.mark.kernels
def test_infeasible_returns_farthest_reachable_point():
    prior = np.diag([2.0, 0.5])
    c = np.array([0.3, 0.4])  # ||c|| = 0.5
    sol = solve_single_sensor(prior, c, 1.0, 2.0, 0.1, 0.01)
    assert not sol.feasible
    np.testing.assert_allclose(sol.s, c + 1.0 * c / 0.5)
    assert sol.value == pytest.approx(ref_f0(prior, sol.s, 0.1, 0.01)[0], rel=1e-12)


def test_infeasible_at_the_target_picks_the_x_axis():
    sol = solve_single_sensor(np.eye(2), np.zeros(2), 0.5, 1.0, 0.1, 0.01)
    assert not sol.feasible
    np.testing.assert_allclose(sol.s, [0.5, 0.0])


@pytest.mark.kernels
@pytest.mark.parametrize(
    ("c", "rho", "feasible"),
    [([3.0, -4.0], 1.0, True), ([3.0, -4.0], 5.0, True), ([0.3, 0.4], 1.0, False)],
)
def test_zero_reach_stays_put(c, rho, feasible):
    prior = np.array([[2.0, 0.3], [0.3, 1.0]])
    sol = solve_single_sensor(prior, c, 0.0, rho, 0.2, 0.05)
    np.testing.assert_array_equal(sol.s, c)
    assert sol.feasible is feasible
    assert sol.value == pytest.approx(ref_f0(prior, c, 0.2, 0.05)[0], rel=1e-12)


@pytest.mark.kernels
def test_target_reachable_with_zero_rho_approaches_the_infimum():
    """rho = 0, ||c|| <= r: f0 -> 1 / (l1 + 1/sigma_d^2) along the major eigen-axis."""
    phi = 0.7
    prior = rotation(phi) @ np.diag([3.0, 0.2]) @ rotation(phi).T
    sol = solve_single_sensor(prior, np.array([0.5, -0.2]), 2.0, 0.0, 0.5, 0.1)
    assert sol.case == 4 and sol.feasible
    assert 0 < np.linalg.norm(sol.s) <= 1e-6
    assert sol.value == pytest.approx(1 / (3.0 + 1 / 0.5), rel=1e-9)
    direction = sol.s / np.linalg.norm(sol.s)
    assert abs(direction @ np.array([math.cos(phi), math.sin(phi)])) == pytest.approx(1.0)


def test_sensor_on_the_target_is_case4():
    prior = np.array([[1.0, 0.2], [0.2, 0.5]])
    sol = solve_single_sensor(prior, np.zeros(2), 2.0, 1.0, 0.1, 0.3)
    assert sol.case == 4 and sol.feasible
    assert np.linalg.norm(sol.s) == pytest.approx(1.0)
    assert sol.value == pytest.approx(brute_force(prior, np.zeros(2), 2.0, 1.0, 0.1, 0.3), rel=1e-9)


def test_rotating_the_problem_rotates_the_solution():
    """Lemma 2 handled correctly: rotating prior and c together leaves the value unchanged."""
    rng = np.random.default_rng(5)
    for _ in range(50):
        lam = 10 ** rng.uniform(-2, 2, 2)
        phi, psi = rng.uniform(0, math.pi, 2)
        prior = rotation(phi) @ np.diag(lam) @ rotation(phi).T
        c = rng.uniform(-10, 10, 2)
        r, rho, sd2, st2 = rng.uniform(0.1, 3), rng.uniform(0.1, 3), 0.3, 0.05
        a = solve_single_sensor(prior, c, r, rho, sd2, st2)
        R = rotation(psi)
        b = solve_single_sensor(R @ prior @ R.T, R @ c, r, rho, sd2, st2)
        assert b.value == pytest.approx(a.value, rel=1e-9)
        assert b.case == a.case


# ------------------------------------------------------------------------------- batched


def random_batch(rng, n):
    lam = 10.0 ** rng.uniform(-2, 2, (n, 2))
    phi = rng.uniform(0, math.pi, n)
    R = np.stack([rotation(p) for p in phi])
    prior = np.einsum("bij,bj,bkj->bik", R, lam, R)
    nc = 10 ** rng.uniform(-1, 1.7, n)
    ang = rng.uniform(-math.pi, math.pi, n)
    c = nc[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    r = 10 ** rng.uniform(-1.3, 0.7, n)
    rho = 10 ** rng.uniform(-1.3, 0.7, n)
    r[::17] = 0.0  # r = 0
    rho[::13] = nc[::13] + r[::13] + 1.0  # infeasible
    c[::29] = 0.0  # on the target
    rho[5::31] = 0.0
    return prior, c, r, rho, 10 ** rng.uniform(-3, 1, n), 10 ** rng.uniform(-3, 1, n)


@pytest.mark.kernels
def test_batch_matches_scalar():
    rng = np.random.default_rng(11)
    prior, c, r, rho, sd2, st2 = random_batch(rng, 400)
    out = solve_single_sensor_batch(prior, c, r, rho, sd2, st2)
    assert isinstance(out, BatchSolution)
    assert out.s.shape == (400, 2) and out.value.shape == (400,)
    assert set(np.unique(out.case)) == {1, 2, 3, 4}
    assert not out.feasible.all() and out.feasible.any()
    for i in range(400):
        one = solve_single_sensor(prior[i], c[i], r[i], rho[i], sd2[i], st2[i])
        assert out.case[i] == one.case
        assert out.feasible[i] == one.feasible
        assert out.value[i] == pytest.approx(one.value, rel=1e-10)
        # The same point, or its mirror -s (same information).
        d = min(np.linalg.norm(out.s[i] - one.s), np.linalg.norm(out.s[i] + one.s))
        assert d <= 1e-7 * max(1.0, np.linalg.norm(one.s))


def test_batch_broadcasts_scalars_and_matches_unchecked_path():
    rng = np.random.default_rng(12)
    prior, c, *_ = random_batch(rng, 50)
    a = solve_single_sensor_batch(prior, c, 1.0, 0.5, 0.1, 0.02)
    b = solve_single_sensor_batch(prior, c, np.full(50, 1.0), 0.5, np.full(50, 0.1), 0.02)
    np.testing.assert_array_equal(a.value, b.value)
    for i in range(0, 50, 7):
        u = solve_single_sensor(prior[i], c[i], 1.0, 0.5, 0.1, 0.02, check=False)
        assert u.value == pytest.approx(a.value[i], rel=1e-10)


def test_argument_types_give_the_same_answer():
    """Float64 arrays with floats take the one-call path (checks inside the compiled
    solve); lists, ints, float32 and other layouts the general conversion; unchecked
    calls skip the checks. All solve the same problem bit for bit (the values below are
    exact in float32)."""
    P = np.array([[2.0, 0.25], [0.25, 1.0]])
    # The reference answer is checked against the dense search and the 40-digit objective.
    base = check_against_brute_force(P, np.array([3.0, 1.0]), 1.0, 0.5, 0.125, 0.25)
    for args in (
        (P.tolist(), [3, 1], 1, 0.5, 0.125, 0.25),
        (P.astype(np.float32), (3.0, 1.0), np.float32(1.0), 0.5, 0.125, np.float32(0.25)),
        (np.asfortranarray(P), np.array([3, 1]), 1.0, np.float64(0.5), 0.125, 0.25),
    ):
        for check in (True, False):
            out = solve_single_sensor(*args, check=check)
            assert np.array_equal(out.s, base.s) and out.value == base.value
            assert (out.case, out.feasible) == (base.case, base.feasible)


# ---------------------------------------------------------------------------- validation

GOOD = dict(
    prior_info=np.array([[2.0, 0.1], [0.1, 1.0]]),
    c=np.array([3.0, 1.0]),
    r=1.0,
    rho=0.5,
    sigma_d2=0.1,
    sigma_theta2=0.01,
)
BAD = [
    ("prior_info", np.array([[1.0, 0.5], [0.0, 1.0]]), "symmetric"),
    ("prior_info", np.array([[1.0, 2.0], [2.0, 1.0]]), "positive definite"),
    ("prior_info", np.array([[-1.0, 0.0], [0.0, -1.0]]), "positive definite"),
    ("prior_info", np.array([[np.nan, 0.0], [0.0, 1.0]]), "finite"),
    ("prior_info", np.eye(3), "shape"),
    ("c", np.array([np.inf, 0.0]), "finite"),
    ("c", np.array([1.0, 2.0, 3.0]), "shape"),
    ("r", -0.1, ">= 0"),
    ("r", np.nan, "finite"),
    ("rho", -1.0, ">= 0"),
    ("rho", np.inf, "finite"),
    ("sigma_d2", 0.0, "> 0"),
    ("sigma_theta2", -1.0, "> 0"),
    ("sigma_theta2", np.nan, "finite"),
]


@pytest.mark.parametrize(("name", "value", "why"), BAD)
def test_scalar_rejects_bad_input(name, value, why):
    kwargs = dict(GOOD, **{name: value})
    with pytest.raises(ValueError, match=name) as err:
        solve_single_sensor(**kwargs)
    assert why in str(err.value)


@pytest.mark.parametrize(
    ("bad", "why"),
    [
        (
            dict(prior_info=np.array([[np.nan, 0.0], [0.0, 1.0]]), r=-1.0),
            "prior_info must be finite",
        ),
        (dict(prior_info=np.array([[1.0, 0.5], [0.0, 1.0]]), c=np.ones(3)), "symmetric"),
        (dict(c=np.array([np.inf, 0.0]), sigma_d2=-0.1), "c must be finite"),
        (dict(r=-1.0, sigma_theta2=0.0), "r must be"),
    ],
)
def test_several_faults_name_the_first_in_argument_order(bad, why):
    """The prior, then ``c``, then the scalars: the first fault in the signature's order is
    the one named, whichever path (arrays or lists) the inputs take."""
    for kwargs in (
        dict(GOOD, **bad),
        {k: np.asarray(v).tolist() for k, v in {**GOOD, **bad}.items()},
    ):
        with pytest.raises(ValueError, match=why):
            solve_single_sensor(**kwargs)


@pytest.mark.parametrize("name", ["prior_info", "c", "r", "sigma_theta2"])
def test_ints_too_large_for_a_float_raise_naming_the_field(name):
    """``10**400`` cannot become a float64 (NumPy raises OverflowError): a ValueError
    naming the field, from the scalar and the batched solver."""
    huge = 10**400
    value = {"prior_info": [[huge, 0], [0, 1]], "c": [huge, 1]}.get(name, huge)
    with pytest.raises(ValueError, match=name):
        solve_single_sensor(**dict(GOOD, **{name: value}))
    batch = {
        k: [np.asarray(v).tolist()] if k in ("prior_info", "c") else v for k, v in GOOD.items()
    }
    batch[name] = [value]
    with pytest.raises(ValueError, match=name):
        solve_single_sensor_batch(**batch)


def test_unchecked_solve_of_wrong_shapes_raises():
    """``check=False`` skips the range checks, never the prior's and c's sizes: a (3, 3)
    prior or a (3,) ``c`` raises instead of solving some other problem."""
    for name, value in (("prior_info", np.eye(3)), ("c", np.array([3.0, 1.0, 2.0]))):
        with pytest.raises(ValueError):
            solve_single_sensor(**dict(GOOD, **{name: value}), check=False)


@pytest.mark.parametrize(("name", "value", "why"), BAD)
def test_batch_rejects_bad_input(name, value, why):
    kwargs = {k: np.stack([v, v]) if k in ("prior_info", "c") else v for k, v in GOOD.items()}
    if name not in ("prior_info", "c"):
        kwargs[name] = np.array([GOOD[name], value])  # the second problem is bad
    elif np.shape(value) == np.shape(GOOD[name]):
        kwargs[name] = np.stack([GOOD[name], value])
    else:
        kwargs[name] = np.stack([value, value])
    with pytest.raises(ValueError, match=name) as err:
        solve_single_sensor_batch(**kwargs)
    assert why in str(err.value)


def test_batch_rejects_mismatched_lengths():
    with pytest.raises(ValueError, match="rho"):
        solve_single_sensor_batch(
            np.stack([np.eye(2)] * 3), np.ones((3, 2)), 1.0, np.ones(2), 0.1, 0.1
        )


# ---------------------------------------------------------------------------- derivation


@pytest.mark.slow
def test_derivation_script_regenerates_the_coefficients():
    out = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "derive_polynomials.py")],
        capture_output=True,
        text=True,
        check=True,
        timeout=600,
    ).stdout
    committed = (ROOT / "src" / "activetrack" / "solvers" / "_coefficients.py").read_text()
    assert out == committed


def test_batch_answers_do_not_depend_on_the_batch_size():
    # A symmetric problem with two mirror-image optima (found in review): every batch
    # size must pick the same one, as the rows of a larger batch do.
    P = np.diag([139.4522929371407, 0.0015904259448963074])
    c = np.array([12.114480024579207, 0.0])
    args = (5.798948603381108, 1.6355187202997734, 0.0033688090712900255, 55.554388898101045)
    sols = [
        solve_single_sensor_batch(np.stack([P] * b), np.stack([c] * b), *args) for b in (1, 8, 9)
    ]
    for sol in sols[1:]:
        np.testing.assert_array_equal(sol.s[0], sols[0].s[0])
    # ... and it is the optimum: an independent dense search of the feasible boundary
    best = float(brute_force(P, c, *args))
    assert sols[0].value[0] <= best * (1 + 1e-9)
    assert abs(np.hypot(*(sols[0].s[0] - c)) - args[0]) <= 1e-9 * args[0]  # on the speed circle
    rng = np.random.default_rng(12)
    L = rng.standard_normal((40, 2, 2))
    priors = L @ L.transpose(0, 2, 1) + 0.1 * np.eye(2)
    cs = rng.uniform(-8, 8, (40, 2))
    whole = solve_single_sensor_batch(priors, cs, 1.0, 1.5, 0.5, 0.05)
    part = solve_single_sensor_batch(priors[:5], cs[:5], 1.0, 1.5, 0.5, 0.05)
    np.testing.assert_allclose(part.s, whole.s[:5], rtol=0, atol=1e-12)
    np.testing.assert_allclose(part.value, whole.value[:5], rtol=1e-14)
