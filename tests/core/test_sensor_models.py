"""Sensor models (range-bearing, range-only, bearing-only, uncertain poses) against
independent computations: finite differences, Monte Carlo, textbook matrix forms and
today's range-bearing code (eq. 4, 9, 11, 12, 17)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from activetrack.estimation import ekf
from activetrack.models import measurement, objective
from activetrack.models import sensor_models as sm
from activetrack.models.sensor_models import SensorModel
from tests.core.helpers import jacobian, range_bearing

MODELS = [SensorModel.RANGE_BEARING, SensorModel.RANGE, SensorModel.BEARING]
ALL = np.array([0, 1, 2, 0, 1, 2])


def _team(rng, m=6, dist=(2.0, 20.0)):
    target = rng.uniform(-10, 10, 2)
    ang = rng.uniform(-np.pi, np.pi, m)
    r = rng.uniform(*dist, m)
    sensors = target + np.column_stack([r * np.cos(ang), r * np.sin(ang)])
    sd2 = rng.uniform(0.5, 4.0, m)
    st2 = rng.uniform(0.01, 0.5, m)
    return target, sensors, sd2, st2


def _random_psd(rng, m, scale, rank=2):
    A = rng.standard_normal((m, 2, rank)) * scale
    return A @ A.mT


def _textbook_stack(target, sensors, models, sd2, st2, pose_cov=None):
    """Return (H, R_eff) of the used components only: longhand rows of eq. (9), numpy matmul."""
    rows, var, blocks = [], [], []
    for i, s in enumerate(sensors):
        dx, dy = target[0] - s[0], target[1] - s[1]
        d2 = dx * dx + dy * dy
        Hi, Ri = [], []
        if models[i] in (0, 1):
            Hi.append([dx / np.sqrt(d2), dy / np.sqrt(d2)])
            Ri.append(sd2[i])
        if models[i] in (0, 2):
            Hi.append([-dy / d2, dx / d2])
            Ri.append(st2[i])
        Hi = np.array(Hi)
        Rs = np.diag(Ri)
        if pose_cov is not None:
            Hs = -Hi  # d/dp_S of a function of p_T - p_S
            Rs = Rs + Hs @ pose_cov[i] @ Hs.T
        rows.append(Hi)
        blocks.append(Rs)
        var.append(len(Ri))
    H = np.vstack(rows)
    R = np.zeros((H.shape[0], H.shape[0]))
    k = 0
    for Rs, n in zip(blocks, var, strict=True):
        R[k : k + n, k : k + n] = Rs
        k += n
    return H, R


# --- measurement function, Jacobians, innovation -------------------------------------


def test_measure_layout_matches_range_bearing_and_zeroes_unused():
    rng = np.random.default_rng(1)
    target, sensors, _, _ = _team(rng)
    phi = rng.uniform(-3, 3, 6)
    z = sm.measure(target, sensors, ALL, phi)
    ref = range_bearing(target, sensors, phi)
    use_d, use_t = ALL != 2, ALL != 1
    # To rounding: measure's distance is the modulus of a complex number, the reference's
    # np.hypot (they differ in the last bit).
    np.testing.assert_allclose(z[use_d, 0], ref[use_d, 0], rtol=1e-15, atol=0)
    np.testing.assert_allclose(z[use_t, 1], ref[use_t, 1], rtol=1e-15, atol=1e-15)
    assert np.all(z[~use_d, 0] == 0.0) and np.all(z[~use_t, 1] == 0.0)
    # known geometry: sensor 5 m south of the target, facing east: bearing pi/2
    z = sm.measure(np.array([3.0, 9.0]), np.array([[3.0, 4.0]] * 3), np.array([0, 1, 2]))
    np.testing.assert_allclose(z, [[5.0, np.pi / 2], [5.0, 0.0], [0.0, np.pi / 2]])


coord = st.floats(-50, 50, allow_nan=False)


@settings(max_examples=150, deadline=None)
@given(tx=coord, ty=coord, sx=coord, sy=coord, phi=st.floats(-3, 3), model=st.sampled_from(MODELS))
def test_jacobians_match_central_differences(tx, ty, sx, sy, phi, model):
    target, sensor = np.array([tx, ty]), np.array([[sx, sy]])
    if np.hypot(tx - sx, ty - sy) < 0.5:
        return
    codes = np.array([int(model)])
    h = 1e-6
    fd_t, fd_s = np.empty((2, 2)), np.empty((2, 2))
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        for fd, dt, ds in ((fd_t, e, 0 * e), (fd_s, 0 * e, e)):
            zp = sm.measure(target + dt, sensor + ds, codes, phi)[0]
            zm = sm.measure(target - dt, sensor - ds, codes, phi)[0]
            diff = zp - zm
            diff[1] = measurement.wrap_angle(diff[1])
            fd[:, j] = diff / (2 * h)
    np.testing.assert_allclose(sm.jacobian_target(target, sensor, codes)[0], fd_t, 1e-6, 1e-8)
    np.testing.assert_allclose(sm.jacobian_sensor(target, sensor, codes)[0], fd_s, 1e-6, 1e-8)


def test_range_bearing_jacobian_equals_todays():
    rng = np.random.default_rng(2)
    target, sensors, _, _ = _team(rng, m=50)
    # same formula (eq. 9), evaluated through the unit vector: equal to rounding
    np.testing.assert_allclose(
        sm.jacobian_target(target, sensors, np.zeros(50, int)),
        jacobian(target, sensors),
        rtol=1e-14,
        atol=1e-17,
    )


def test_innovation_wraps_bearing_and_ignores_unused():
    target = np.array([0.0, 0.0])
    sensors = np.array([[1.0, 1e-9], [1.0, 1e-9], [1.0, 1e-9]])  # bearing ~ -pi (wrapped)
    h = sm.measure(target, sensors, np.array([0, 1, 2]))
    z = np.array([[1.5, np.pi - 0.01], [1.5, np.nan], [np.nan, np.pi - 0.01]])
    nu = sm.innovation(z, target, sensors, np.array([0, 1, 2]))
    assert np.all(np.isfinite(nu))
    np.testing.assert_allclose(nu[:, 0], [1.5 - h[0, 0], 1.5 - h[1, 0], 0.0])
    # pi - 0.01 minus (atan2(-1e-9, -1) ~ -pi) is 2 pi - 0.01 - 1e-9, wrapped to -0.01 - 1e-9
    np.testing.assert_allclose(nu[:, 1], [-0.01 - 1e-9, 0.0, -0.01 - 1e-9], atol=1e-12)


def test_sample_noise_moments_per_model():
    rng = np.random.default_rng(3)
    target, sensors = np.array([1.0, 2.0]), np.array([[11.0, 2.0], [1.0, -8.0], [-9.0, 2.5]])
    codes = np.array([0, 1, 2])
    sd2, st2 = np.array([2.0, 3.0, 1.0]), np.array([0.04, 0.5, 0.09])
    n = 40_000
    z = sm.sample(np.broadcast_to(target, (n, 2)), sensors, codes, sd2, st2, rng)
    nu = sm.innovation(z, target, sensors, codes)
    var = nu.var(axis=0)
    want = np.array([[2.0, 0.04], [3.0, 0.0], [0.0, 0.09]])
    # sample variance of n normals: relative standard error sqrt(2 / n) ~ 0.7 %; 5 sigma
    np.testing.assert_allclose(var, want, rtol=5 * np.sqrt(2 / n))
    assert np.all(z[:, 1, 1] == 0.0) and np.all(z[:, 2, 0] == 0.0)


# --- Fisher information ---------------------------------------------------------------


def test_weights_zero_unused_components():
    w_d, w_t = sm.weights(ALL, np.arange(1.0, 7.0), np.full(6, 0.25))
    np.testing.assert_array_equal(w_d, [1.0, 1 / 2, 0.0, 1 / 4, 1 / 5, 0.0])
    np.testing.assert_array_equal(w_t, [4.0, 0.0, 4.0, 4.0, 0.0, 4.0])


def test_range_bearing_information_equals_todays_jacobian_form_and_eq17():
    rng = np.random.default_rng(4)
    target, sensors, sd2, st2 = _team(rng, m=40)
    codes = np.zeros(40, int)
    w_d, w_t = sm.weights(codes, sd2, st2)
    info = sm.fisher_information(sensors - target, w_d, w_t)
    H = jacobian(target, sensors)
    Rinv = np.zeros((40, 2, 2))
    Rinv[:, 0, 0], Rinv[:, 1, 1] = 1 / sd2, 1 / st2
    np.testing.assert_allclose(info, H.mT @ Rinv @ H, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(
        info, objective.sensor_information(sensors - target, sd2, st2), rtol=1e-12, atol=1e-15
    )


def test_single_component_models_equal_todays_formula_with_infinite_variance():
    # range only == range-bearing with w_theta = 0, bearing only == with w_d = 0
    rng = np.random.default_rng(5)
    target, sensors, sd2, st2 = _team(rng)
    w_d, w_t = sm.weights(ALL, sd2, st2)
    info = sm.fisher_information(sensors - target, w_d, w_t)
    sd2_inf = np.where(ALL == 2, np.inf, sd2)
    st2_inf = np.where(ALL == 1, np.inf, st2)
    today = objective.sensor_information(sensors - target, sd2_inf, st2_inf)
    np.testing.assert_allclose(info, today, rtol=1e-12, atol=1e-15)
    H = sm.jacobian_target(target, sensors, ALL)
    W = np.zeros((6, 2, 2))
    W[:, 0, 0], W[:, 1, 1] = w_d, w_t
    np.testing.assert_allclose(info, H.mT @ W @ H, rtol=1e-12, atol=1e-15)
    # rank one for the single-component models
    assert np.all(
        np.abs(np.linalg.det(info[ALL != 0]))
        < 1e-12 * np.trace(info[ALL != 0], axis1=1, axis2=2) ** 2
    )


def _log_likelihood(pt, z, sensor, code, sd2, st2):
    """Gaussian log-likelihood of one sensor's measurement, longhand per model."""
    dx, dy = pt[0] - sensor[0], pt[1] - sensor[1]
    out = 0.0
    if code in (0, 1):
        out -= 0.5 * (z[..., 0] - np.hypot(dx, dy)) ** 2 / sd2
    if code in (0, 2):
        e = z[..., 1] - np.arctan2(dy, dx)
        e = (e + np.pi) % (2 * np.pi) - np.pi
        out = out - 0.5 * e**2 / st2
    return out


@pytest.mark.parametrize("code", [0, 1, 2])
def test_fisher_information_matches_monte_carlo_score_covariance(code):
    # Fisher information = covariance of the score d log p(z | p_T) / d p_T (at the truth);
    # the score is taken by central differences of the log-likelihood, not from H.
    rng = np.random.default_rng(10 + code)
    target, sensor = np.array([0.5, -1.0]), np.array([[4.0, 2.0]])
    sd2, st2 = 0.5, 0.02
    codes = np.array([code])
    n = 40_000
    z = sm.sample(np.broadcast_to(target, (n, 2)), sensor, codes, sd2, st2, rng)[:, 0]
    h = 1e-5
    score = np.empty((n, 2))
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        score[:, j] = (
            _log_likelihood(target + e, z, sensor[0], code, sd2, st2)
            - _log_likelihood(target - e, z, sensor[0], code, sd2, st2)
        ) / (2 * h)
    prods = score[:, :, None] * score[:, None, :]
    mc = prods.mean(axis=0)
    se = prods.std(axis=0) / np.sqrt(n)
    w_d, w_t = sm.weights(codes, sd2, st2)
    info = sm.fisher_information(sensor - target, w_d, w_t)[0]
    # 5 standard errors of the Monte Carlo mean, plus the finite-difference error
    assert np.all(np.abs(mc - info) <= 5 * se + 1e-6 * np.abs(info).max())


# --- uncertain sensor poses -----------------------------------------------------------


@pytest.mark.parametrize("code", [0, 1, 2])
def test_effective_noise_matches_monte_carlo_of_random_sensor_position(code):
    # z = h(p_T, p_S + e) + n, e ~ N(0, Sigma_s): its covariance is R + H_s Sigma_s H_s^T to
    # first order; at distance 8 with Sigma_s ~ 0.3^2 the second-order term is ~1e-4
    # relative, below the Monte Carlo band (5 standard errors of a sample variance, ~3.5%).
    rng = np.random.default_rng(20 + code)
    target, sensor = np.array([0.0, 0.0]), np.array([[6.0, 5.3]])
    codes = np.array([code])
    sd2, st2 = 0.05, 0.002
    cov = np.array([[[0.09, 0.03], [0.03, 0.05]]])
    n = 40_000
    e = rng.multivariate_normal(np.zeros(2), cov[0], size=n)
    z = sm.sample(np.broadcast_to(target, (n, 2)), sensor + e[:, None, :], codes, sd2, st2, rng)
    nu = sm.innovation(z, target, sensor, codes)[:, 0]
    mc = np.cov(nu.T)
    R_eff = sm.effective_noise(target, sensor, codes, sd2, st2, cov)[0]
    used = sm.USES[code]
    for i in range(2):
        for j in range(2):
            if not (used[i] and used[j]):
                assert R_eff[i, j] == 0.0 and mc[i, j] == 0.0
                continue
            # standard error of a sample covariance entry: sqrt((s_ii s_jj + s_ij^2) / n)
            se = np.sqrt((R_eff[i, i] * R_eff[j, j] + R_eff[i, j] ** 2) / n)
            assert abs(mc[i, j] - R_eff[i, j]) <= 5 * se, (i, j, mc, R_eff)


def test_pose_uncertain_information_equals_textbook_inverse():
    rng = np.random.default_rng(6)
    for _ in range(20):
        target, sensors, sd2, st2 = _team(rng)
        cov = _random_psd(rng, 6, rng.uniform(0.05, 2.0), rank=rng.integers(1, 3))
        w_d, w_t = sm.weights(ALL, sd2, st2)
        info = sm.fisher_information(sensors - target, w_d, w_t, cov)
        for i in range(6):
            H, R = _textbook_stack(
                target, sensors[i : i + 1], ALL[i : i + 1], sd2[i:], st2[i:], cov[i:]
            )
            ref = H.T @ np.linalg.inv(R) @ H
            np.testing.assert_allclose(info[i], ref, rtol=1e-10, atol=1e-14 * np.abs(ref).max())
        # sensor pose uncertainty never adds information: J0 - J_eff is PSD
        info0 = sm.fisher_information(sensors - target, w_d, w_t)
        gap = np.linalg.eigvalsh(info0 - info)
        assert np.all(gap >= -1e-12 * np.abs(info0).max())


def test_zero_pose_covariance_is_exactly_todays_information():
    rng = np.random.default_rng(7)
    target, sensors, sd2, st2 = _team(rng)
    w_d, w_t = sm.weights(ALL, sd2, st2)
    a = sm.fisher_information(sensors - target, w_d, w_t, np.zeros((6, 2, 2)))
    b = sm.fisher_information(sensors - target, w_d, w_t)
    np.testing.assert_array_equal(a, b)


def test_isotropic_pose_covariance_adds_variance_in_position_units():
    # Sigma_s = s I: range variance sigma_d^2 + s, bearing variance (position units)
    # d^2 sigma_theta^2 + s along u and v (independent closed form of the 2x2 inverse)
    rel, s = np.array([[3.0, 4.0]]), 0.7
    sd2, st2 = 2.0, 0.1
    u = rel[0] / 5.0
    v = np.array([u[1], -u[0]])
    want = np.outer(u, u) / (sd2 + s) + np.outer(v, v) / (25.0 * st2 + s)
    got = sm.fisher_information(
        rel, np.array([1 / sd2]), np.array([1 / st2]), np.array([s * np.eye(2)])
    )
    np.testing.assert_allclose(got[0], want, rtol=1e-13)


pos = st.floats(-30, 30, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(
    x=pos,
    y=pos,
    wd=st.sampled_from([0.0, 1e-3, 0.5, 1.0, 1e4]),
    wt=st.sampled_from([0.0, 1e-3, 2.0, 1e6]),
    l1=st.floats(0, 100),
    l2=st.floats(0, 100),
    ang=st.floats(-3.2, 3.2),
)
def test_pose_uncertain_information_is_psd_and_finite(x, y, wd, wt, l1, l2, ang):
    c, s = np.cos(ang), np.sin(ang)
    Q = np.array([[c, -s], [s, c]])
    cov = (Q @ np.diag([l1, l2]) @ Q.T)[None]
    info = sm.fisher_information(np.array([[x, y]]), np.array([wd]), np.array([wt]), cov)[0]
    assert np.all(np.isfinite(info))
    assert info[0, 1] == info[1, 0]
    scale = max(np.abs(info).max(), 1e-300)
    assert info[0, 0] >= 0 and info[1, 1] >= 0
    assert np.linalg.eigvalsh(info).min() >= -1e-12 * scale


# --- team sums and objective entries --------------------------------------------------


def test_mixed_team_sum_equals_per_sensor_sum_and_objective_entries():
    rng = np.random.default_rng(8)
    B = 5
    target = rng.uniform(-5, 5, (B, 2))
    sensors = target[:, None, :] + rng.uniform(3, 10, (B, 6, 1)) * np.stack(
        [np.cos(a := rng.uniform(-3, 3, (B, 6))), np.sin(a)], -1
    )
    sd2, st2 = rng.uniform(0.5, 3, 6), rng.uniform(0.01, 0.3, 6)
    cov = _random_psd(rng, 6, 0.3)
    prior = np.stack([np.linalg.inv(np.eye(2) * (1 + i)) for i in range(B)])
    w_d, w_t = sm.weights(ALL, sd2, st2)
    rel = sensors - target[:, None, :]
    for pc in (None, cov):
        per = sm.fisher_information(rel, w_d, w_t, pc)
        Y = sm.team_information(rel, w_d, w_t, pc, prior_info=prior)
        ref = prior.copy()
        for i in range(6):
            ref = (
                ref
                + sm.fisher_information(
                    rel[:, i : i + 1],
                    w_d[i : i + 1],
                    w_t[i : i + 1],
                    pc if pc is None else pc[i : i + 1],
                )[:, 0]
            )
        np.testing.assert_allclose(Y, ref, rtol=1e-13)
        np.testing.assert_allclose(per.sum(axis=1) + prior, ref, rtol=1e-13)
        a, b, c = sm.team_entries(prior, rel, w_d, w_t, pc)
        np.testing.assert_allclose(
            objective.TRACE.of_entries(a, b, c),
            np.trace(np.linalg.inv(ref), axis1=1, axis2=2),
            rtol=1e-12,
        )
    # all range-bearing without pose covariance: today's objective
    zero = np.zeros(6, int)
    w_d, w_t = sm.weights(zero, sd2, st2)
    a, b, c = sm.team_entries(prior, rel, w_d, w_t)
    today = objective.TRACE.of_information(objective.total_information(prior, rel, sd2, st2))
    np.testing.assert_allclose(objective.TRACE.of_entries(a, b, c), today, rtol=1e-13)


def test_sensor_at_target_contributes_nothing_and_no_nan():
    target = np.array([1.0, 2.0])
    sensors = np.array([[1.0, 2.0], [1.0 + 1e-120, 2.0], [5.0, 2.0]])
    codes = np.array([0, 2, 1])
    w_d, w_t = sm.weights(codes, 1.0, 0.1)
    cov = np.broadcast_to(np.eye(2) * 0.2, (3, 2, 2))
    with np.errstate(all="raise"):
        for pc in (None, cov):
            info = sm.fisher_information(sensors - target, w_d, w_t, pc)
            assert np.all(info[:2] == 0.0) and np.all(np.isfinite(info))
            assert np.any(info[2] != 0.0)
        H = sm.jacobian_target(target, sensors, codes)
        assert np.all(H[:2] == 0.0) and np.all(np.isfinite(H))
        Y, b = sm.update_terms(np.zeros((3, 2)), target, sensors, codes, w_d, w_t, 0.0, cov)
        assert np.all(Y[:2] == 0.0) and np.all(b[:2] == 0.0) and np.all(np.isfinite(b))
        z = sm.measure(target, sensors, codes)
        assert np.all(np.isfinite(z))
    # a very close (but not zero-distance) sensor with strong weights and pose uncertainty:
    # huge but finite information, and a finite EKF gradient term
    origin, close = np.zeros(2), np.array([[1e-99, 1e-99]] * 3)
    w_d, w_t = sm.weights(codes, 1e-4, 1e-6)
    aniso = np.broadcast_to(np.array([[0.2, 0.05], [0.05, 0.3]]), (3, 2, 2))
    with np.errstate(all="raise"):
        Y, b = sm.update_terms(np.ones((3, 2)), origin, close, codes, w_d, w_t, 0.0, aniso)
        assert np.all(np.isfinite(Y)) and np.all(np.isfinite(b))
        assert np.all(np.abs(b).max(axis=-1) > 0.0)  # informative, not zeroed


# --- EKF terms --------------------------------------------------------------------------


@pytest.mark.parametrize("with_pose", [False, True])
def test_update_terms_give_the_textbook_ekf_update(with_pose):
    # information form (P^-1 + E^T Y E)^-1, x + P+ E^T b  vs  K = P H^T S^-1 with stacked
    # used rows and the full R_eff (block diagonal) of the pose-uncertain model
    rng = np.random.default_rng(30 + with_pose)
    for _ in range(10):
        target, sensors, sd2, st2 = _team(rng)
        x = np.concatenate([target + rng.normal(0, 0.5, 2), rng.normal(0, 1, 2)])
        A = rng.standard_normal((4, 4))
        P = A @ A.T + np.eye(4)
        phi = rng.uniform(-3, 3, 6)
        cov = _random_psd(rng, 6, 0.4) if with_pose else None
        z = sm.sample(target, sensors, ALL, sd2, st2, rng, phi)
        w_d, w_t = sm.weights(ALL, sd2, st2)
        Yi, bi = sm.update_terms(z, x[:2], sensors, ALL, w_d, w_t, phi, cov)
        E = np.zeros((2, 4))
        E[0, 0] = E[1, 1] = 1
        P_post = np.linalg.inv(np.linalg.inv(P) + E.T @ Yi.sum(0) @ E)
        x_post = x + P_post @ E.T @ bi.sum(0)
        He, R = _textbook_stack(x[:2], sensors, ALL, sd2, st2, cov)
        H = np.hstack([He, np.zeros((He.shape[0], 2))])
        nu_full = sm.innovation(z, x[:2], sensors, ALL, phi)
        nu = np.concatenate([nu_full[i][sm.USES[c]] for i, c in enumerate(ALL)])
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        np.testing.assert_allclose(x_post, x + K @ nu, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(P_post, P - K @ S @ K.T, rtol=1e-8, atol=1e-12)


def test_update_terms_reduce_to_todays_ekf_with_infinite_variances():
    # today's ekf.update handles range-only / bearing-only through 1/inf = 0 weights
    rng = np.random.default_rng(40)
    target, sensors, sd2, st2 = _team(rng)
    x = np.concatenate([target + 0.3, [1.0, -1.0]])
    A = rng.standard_normal((4, 4))
    P = A @ A.T + np.eye(4)
    z = sm.sample(target, sensors, ALL, sd2, st2, rng)
    w_d, w_t = sm.weights(ALL, sd2, st2)
    Yi, bi = sm.update_terms(z, x[:2], sensors, ALL, w_d, w_t)
    E = np.eye(4)[:2]
    P_post = np.linalg.inv(np.linalg.inv(P) + E.T @ Yi.sum(0) @ E)
    x_post = x + P_post @ E.T @ bi.sum(0)
    x_t, P_t = ekf.update(
        x, P, z, sensors, np.where(ALL == 2, np.inf, sd2), np.where(ALL == 1, np.inf, st2)
    )
    np.testing.assert_allclose(x_t, x_post, rtol=1e-10)
    np.testing.assert_allclose(P_t, P_post, rtol=1e-9, atol=1e-12)


# --- validation -------------------------------------------------------------------------


def test_team_validation_and_storage():
    team = sm.SensorTeam(["range_bearing", "RANGE", SensorModel.BEARING, 1], 2.0, [0.1] * 4)
    np.testing.assert_array_equal(team.models, [0, 1, 2, 1])
    assert team.models.dtype == np.int8 and team.n_sensors == 4 and team.pose_cov is None
    assert team.sigma_d2.shape == (4,) and not team.sigma_d2.flags.writeable
    w_d, w_t = team.weights()
    np.testing.assert_array_equal(w_d, [0.5, 0.5, 0.0, 0.5])
    team = sm.SensorTeam([0, 1], 1.0, 1.0, pose_cov=np.eye(2) * 0.1)
    assert team.pose_cov.shape == (2, 2, 2)
    with pytest.raises(ValueError, match="models must hold sensor models"):
        sm.SensorTeam([0, 3], 1.0, 1.0)
    with pytest.raises(ValueError, match="models must hold sensor models"):
        sm.SensorTeam(["sonar"], 1.0, 1.0)
    with pytest.raises(ValueError, match="sigma_d2 must be > 0"):
        sm.SensorTeam([0], 0.0, 1.0)
    with pytest.raises(ValueError, match="must broadcast"):
        sm.SensorTeam([0, 1], [1.0, 2.0, 3.0], 1.0)
    with pytest.raises(ValueError, match="pose_cov must be positive semidefinite"):
        sm.SensorTeam([0], 1.0, 1.0, pose_cov=[[[1.0, 2.0], [2.0, 1.0]]])
    with pytest.raises(ValueError, match="pose_cov must be symmetric"):
        sm.SensorTeam([0], 1.0, 1.0, pose_cov=[[[1.0, 0.2], [0.0, 1.0]]])
    with pytest.raises(ValueError, match="pose_cov must be finite"):
        sm.SensorTeam([0], 1.0, 1.0, pose_cov=[[[np.nan, 0.0], [0.0, 1.0]]])


def test_k_target_axis_broadcasts():
    # rel (K, M, 2) against per-sensor weights (M,) and pose covariances (M, 2, 2)
    rng = np.random.default_rng(50)
    targets = rng.uniform(-5, 5, (3, 2))
    _, sensors, sd2, st2 = _team(rng)
    cov = _random_psd(rng, 6, 0.3)
    prior = np.stack([np.eye(2) * (1 + k) for k in range(3)])
    w_d, w_t = sm.weights(ALL, sd2, st2)
    rel = sensors[None] - targets[:, None, :]
    a, b, c = sm.team_entries(prior, rel, w_d, w_t, cov)
    for k in range(3):
        ref = sm.team_information(rel[k], w_d, w_t, cov, prior_info=prior[k])
        np.testing.assert_allclose([a[k], b[k], c[k]], [ref[0, 0], ref[0, 1], ref[1, 1]], 1e-13)


@pytest.mark.slow
def test_pose_accounting_update_is_consistent_and_ignoring_is_not():
    # One EKF update on N independent trials (position-only state): truth drawn from the
    # prior, measurements from the true sensor positions, the filter at the believed ones
    # (true + N(0, Sigma_s)). Mean NEES of the posterior: chi^2_2 has mean 2 and variance
    # 4, so over N trials the mean has standard deviation 2 / sqrt(N) (0.032 for N = 4000).
    rng = np.random.default_rng(60)
    n, m = 4000, 6
    x_hat = np.array([1.0, -2.0])
    P = np.array([[0.3, 0.1], [0.1, 0.2]])
    x_true = rng.multivariate_normal(x_hat, P, size=n)
    ang = np.linspace(0, 2 * np.pi, m, endpoint=False)
    sensors = x_hat + 40.0 * np.column_stack([np.cos(ang), np.sin(ang)])
    sd2, st2 = np.full(m, 0.01), np.full(m, 2e-5)
    cov = np.broadcast_to(np.array([[0.2, 0.08], [0.08, 0.1]]), (m, 2, 2))
    believed = sensors + rng.multivariate_normal(np.zeros(2), cov[0], size=(n, m))
    z = sm.sample(x_true, sensors, ALL, sd2, st2, rng)
    w_d, w_t = sm.weights(ALL, sd2, st2)
    x_b = np.broadcast_to(x_hat, (n, 2))
    nees = {}
    for name, pc in (("accounting", cov), ("ignoring", None)):
        Yi, bi = sm.update_terms(z, x_b, believed, ALL, w_d, w_t, 0.0, pc)
        P_post = np.linalg.inv(np.linalg.inv(P) + Yi.sum(axis=1))
        x_post = x_b + np.einsum("nij,nj->ni", P_post, bi.sum(axis=1))
        e = x_true - x_post
        nees[name] = np.einsum("ni,nij,nj->n", e, np.linalg.inv(P_post), e).mean()
    band = 4 * 2 / np.sqrt(n)  # 4 standard deviations of the mean, plus linearization slack
    assert abs(nees["accounting"] - 2.0) < band + 0.05, nees
    assert nees["ignoring"] > 2.0 + 10 * band, nees
