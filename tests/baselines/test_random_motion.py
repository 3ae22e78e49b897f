"""Random motion: feasible, and uniform by arc length on the curve ADB (closed forms) or,
with K targets, on the feasible set's boundary (a dense tabulation)."""

from __future__ import annotations

import numpy as np
from scipy import stats

from activetrack.baselines import RandomMotion
from activetrack.baselines._common import sensor_modes
from activetrack.models.objective import LOGDET
from activetrack.world.problem import PlanningProblem
from tests.baselines._multi import dense_boundary, multi_problem


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


# K targets, mixed models, uncertain poses ---------------------------------------------------


def test_rm_on_random_multi_target_problems_is_feasible():

    rng = np.random.default_rng(10)
    n_free = 0
    for _ in range(300):
        p = multi_problem(rng, 3, int(rng.integers(1, 4)), distance=(0.0, 3.5))
        free, _ = sensor_modes(p)
        out = RandomMotion().plan(p, rng)
        assert np.all(p.violation(out)[free] <= 1e-9)
        n_free += int(free.sum())
    assert n_free > 700


def _arc_coordinate(points, sensor, r, targets, rho, n=400_000):
    """Return each point's arc-length coordinate along the feasible boundary, as a
    fraction of its length, from a dense tabulation of the circles (independent of RM)."""

    tables = dense_boundary(sensor, r, targets, rho, n)
    lengths = [ok.mean() * 2 * np.pi * rad for _, rad, _, ok in tables]
    offsets = np.concatenate([[0.0], np.cumsum(lengths)])
    out = np.full(len(points), np.nan)
    for j, (centre, rad, _, ok) in enumerate(tables):
        on = np.isclose(np.linalg.norm(points - centre, axis=-1), rad, atol=1e-9) & np.isnan(out)
        ang = np.mod(np.arctan2(*(points[on] - centre).T[::-1]), 2 * np.pi)
        before = np.concatenate([[0], np.cumsum(ok)])[np.ceil(ang / (2 * np.pi) * n).astype(int)]
        out[on] = offsets[j] + before * 2 * np.pi * rad / n
    return out / offsets[-1]


def test_rm_with_k_targets_is_uniform_by_arc_length_on_the_feasible_boundary():
    # A sensor among three targets: its boundary has reach-circle and rho-circle pieces.
    targets = np.array([[0.0, 1.6], [1.5, -0.9], [-1.4, -1.0]])
    sensor = np.array([[0.3, 0.1]])
    p = PlanningProblem(
        np.stack([np.eye(2)] * 3), targets, sensor, 1.0, 1.2, 1.0, 0.5, multi_target=True
    )
    batch = PlanningProblem.stack([p] * 4000)
    pts = RandomMotion().plan(batch, np.random.default_rng(11))[:, 0]
    assert np.max(batch.violation(pts[:, None])) <= 1e-9
    u = _arc_coordinate(pts, sensor[0], 1.0, targets, 1.2)
    assert not np.any(np.isnan(u))
    on_reach = np.isclose(np.linalg.norm(pts - sensor, axis=-1), 1.0, atol=1e-9)
    assert 0.1 < on_reach.mean() < 0.9  # both kinds of piece are drawn
    assert stats.kstest(u, stats.uniform(0, 1).cdf).pvalue > 1e-3


def test_rm_with_k_targets_draws_one_uniform_per_free_sensor_in_order():

    rng = np.random.default_rng(12)
    singles = [multi_problem(rng, 3, 2, distance=(0.0, 3.5)) for _ in range(6)]
    batch = PlanningProblem.stack(singles)
    g = np.random.default_rng(13)
    out = RandomMotion().plan(batch, g)
    n_free = int(sensor_modes(batch)[0].sum())
    ref = np.random.default_rng(13)
    ref.random(n_free)
    assert g.random() == ref.random()  # exactly n_free uniforms were drawn
    g = np.random.default_rng(13)
    for b, p in enumerate(singles):
        np.testing.assert_array_equal(out[b], RandomMotion().plan(p, g))


def test_rm_with_one_target_and_other_models_keeps_the_curve_adb_draws():
    # Models, poses and objectives do not change RM with one target: the same draws.

    p = multi_problem(np.random.default_rng(14), 3, 1, LOGDET, multi_target=False)
    plain = PlanningProblem(p.prior_cov, p.target, p.sensors, p.r, p.rho, p.sigma_d2,
                            p.sigma_theta2)  # fmt: skip
    a = RandomMotion().plan(p, np.random.default_rng(15))
    b = RandomMotion().plan(plain, np.random.default_rng(15))
    np.testing.assert_array_equal(a, b)
