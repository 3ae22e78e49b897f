"""Random motion: feasible, and uniform by arc length on the curve ADB (closed forms)."""

from __future__ import annotations

import numpy as np
from scipy import stats

from activetrack.baselines import RandomMotion
from activetrack.problem import PlanningProblem


def _problem(c, r=1.0, rho=2.0):
    c = np.atleast_2d(np.asarray(c, float))
    return PlanningProblem(np.eye(2), np.array([1.0, -2.0]), c + [1.0, -2.0], r, rho, 1.0, 0.5)


def test_case1_angles_are_uniform_on_the_facing_arc():
    # Case I: ADB is the speed-circle arc centred on -c with half-angle arccos(r / ||c||).
    c = np.array([6.0, 2.0])
    p = _problem(c)
    rng = np.random.default_rng(0)
    pts = np.array([RandomMotion().plan(p, rng)[0] for _ in range(3000)]) - p.target
    d = pts - c
    assert np.allclose(np.hypot(*d.T), 1.0)
    rel = np.angle((d[:, 0] + 1j * d[:, 1]) / -(c[0] + 1j * c[1]))
    alpha = np.arccos(1.0 / np.hypot(*c))
    assert stats.kstest(rel, stats.uniform(-alpha, 2 * alpha).cdf).pvalue > 1e-3


def test_case3_pieces_are_hit_in_proportion_to_their_length():
    # Case III: two speed-circle pieces and the rho arc between them (lengths in closed form).
    r, rho = 1.0, 2.0
    c = np.array([2.5, 0.0])
    nc = 2.5
    alpha = np.arccos(r / nc)
    beta = np.arccos((nc**2 + r**2 - rho**2) / (2 * r * nc))
    gamma = np.arccos((rho**2 + nc**2 - r**2) / (2 * rho * nc))
    lengths = np.array([r * (alpha - beta), r * (alpha - beta), 2 * rho * gamma])
    p = _problem(c, r, rho)
    rng = np.random.default_rng(1)
    pts = np.array([RandomMotion().plan(p, rng)[0] for _ in range(4000)]) - p.target
    on_rho = np.isclose(np.hypot(*pts.T), rho, atol=1e-9)
    upper = ~on_rho & (pts[:, 1] > 0)
    counts = np.array([upper.sum(), (~on_rho & ~upper).sum(), on_rho.sum()])
    expected = lengths / lengths.sum() * len(pts)
    assert stats.chisquare(counts, expected).pvalue > 1e-3
    # Within the rho arc the angle is uniform on [-gamma, gamma].
    ang = np.arctan2(pts[on_rho, 1], pts[on_rho, 0])
    assert stats.kstest(ang, stats.uniform(-gamma, 2 * gamma).cdf).pvalue > 1e-3


def test_rm_is_feasible_and_handles_fixed_sensors():
    rng = np.random.default_rng(2)
    for _ in range(200):
        c = rng.uniform(-6, 6, (4, 2))
        p = _problem(c, r=np.array([1.0, 1.0, 0.0, 1.0]), rho=2.0)
        out = RandomMotion().plan(p, rng)
        nc = np.hypot(*c.T)
        ok = (nc + p.r >= p.rho) & (p.r > 0)
        assert np.all(p.violation(out)[ok] <= 1e-9)
        assert np.allclose(out[2], p.sensors[2])  # r = 0 stays


def test_rm_draws_only_from_the_given_generator():
    p = _problem([[5.0, 0.0], [0.0, 4.0]])
    a = RandomMotion().plan(p, np.random.default_rng(3))
    b = RandomMotion().plan(p, np.random.default_rng(3))
    assert np.array_equal(a, b)


def test_rm_on_a_batch_draws_copy_by_copy_then_sensor_by_sensor():
    # One uniform per free sensor, copies in order: the same as planning them one by one.
    rng = np.random.default_rng(4)
    singles = [_problem(rng.uniform(-6, 6, (3, 2)), r=np.array([1.0, 0.0, 1.0])) for _ in range(5)]
    batch = PlanningProblem.stack(singles)
    out = RandomMotion().plan(batch, np.random.default_rng(9))
    assert out.shape == (5, 3, 2)
    g = np.random.default_rng(9)
    for b, p in enumerate(singles):
        np.testing.assert_array_equal(out[b], RandomMotion().plan(p, g))
