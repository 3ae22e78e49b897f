"""EKF: Lemma 1, equality with the textbook update, consistency by Monte Carlo, wrapping."""

import warnings

import numpy as np
import pytest
from scipy import stats

import activetrack as at
from activetrack.estimation import ekf
from activetrack.models import measurement, motion
from tests.core.helpers import random_spd, sample, textbook_h, textbook_update
from tests.envs.reference import ekf_update as reference_ekf_update

# The EKF is compiled (activetrack.estimation._kernels): make test also runs these as plain Python.
pytestmark = pytest.mark.kernels


@pytest.mark.parametrize(
    "model", [at.constant_velocity(10.0, 0.1), at.constant_acceleration(2.0, 0.1)]
)
@pytest.mark.parametrize("seed", range(5))
def test_lemma1_full_update_position_block_equals_eq12(model, seed):
    rng = np.random.default_rng(seed)
    n, m = model.dim, 1 + seed % 4
    x = rng.standard_normal(n) * 3
    P = random_spd(rng, n, scale=2.0)
    sensors = x[:2] + rng.uniform(-15, 15, (m, 2))
    sd2, st2 = rng.uniform(0.1, 4, m), rng.uniform(0.01, 1, m)
    z = sample(x[:2], sensors, sd2, st2, rng)
    _, P_full = textbook_update(x, P, z, sensors, sd2, st2)
    eq12 = at.posterior_position_covariance(P[:2, :2], sensors - x[:2], sd2, st2)
    np.testing.assert_allclose(P_full[:2, :2], eq12, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("seed", range(10))
def test_update_equals_textbook_kalman_update(seed):
    rng = np.random.default_rng(100 + seed)
    n = 4 if seed % 2 else 6
    m = 1 + seed % 5
    x = rng.standard_normal(n)
    P = random_spd(rng, n)
    sensors = x[:2] + rng.uniform(-10, 10, (m, 2))
    sd2, st2 = rng.uniform(0.1, 4, m), rng.uniform(0.01, 1, m)
    z = sample(x[:2] + 0.3, sensors, sd2, st2, rng)
    x_ref, P_ref = textbook_update(x, P, z, sensors, sd2, st2)
    x_new, P_new = ekf.update(x, P, z, sensors, sd2, st2)
    np.testing.assert_allclose(x_new, x_ref, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(P_new, P_ref, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(P_new, P_new.T)
    assert np.all(np.linalg.eigvalsh(P_new) > 0)


def test_batched_update_matches_loop():
    rng = np.random.default_rng(7)
    B, m = 6, 3
    x = rng.standard_normal((B, 4))
    P = np.stack([random_spd(rng, 4) for _ in range(B)])
    sensors = x[:, None, :2] + rng.uniform(-10, 10, (B, m, 2))
    z = sample(x[:, :2], sensors, 1.0, 0.1, rng)
    xb, Pb = ekf.update(x, P, z, sensors, np.ones(m), np.full(m, 0.1))
    for b in range(B):
        xr, Pr = textbook_update(x[b], P[b], z[b], sensors[b], np.ones(m), np.full(m, 0.1))
        np.testing.assert_allclose(xb[b], xr, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(Pb[b], Pr, rtol=1e-9, atol=1e-12)


def test_subset_update_equals_update_with_those_sensors_only():
    rng = np.random.default_rng(3)
    x, P = rng.standard_normal(4), random_spd(rng, 4)
    sensors = x[:2] + rng.uniform(-10, 10, (4, 2))
    sd2, st2 = rng.uniform(0.5, 2, 4), rng.uniform(0.05, 0.5, 4)
    z = sample(x[:2], sensors, sd2, st2, rng)
    keep = np.array([True, False, True, False])
    x_ref, P_ref = textbook_update(x, P, z[keep], sensors[keep], sd2[keep], st2[keep])
    f = at.ExtendedKalmanFilter(at.constant_velocity(1.0, 0.1), x, P)
    f.update(z, sensors, sd2, st2, sensors=[0, 2])
    np.testing.assert_allclose(f.x, x_ref, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(f.P, P_ref, rtol=1e-9, atol=1e-12)
    g = at.ExtendedKalmanFilter(at.constant_velocity(1.0, 0.1), x, P)
    g.update(z, sensors, sd2, st2, sensors=keep)
    np.testing.assert_allclose(g.P, f.P)


def test_bearing_innovation_is_wrapped():
    # Target at the origin, sensor on the +x axis: true bearing from sensor is pi.
    x = np.array([0.0, 1e-3, 0.0, 0.0])
    P = np.diag([1.0, 1.0, 1.0, 1.0])
    sensor = np.array([[10.0, 0.0]])
    z = np.array([[10.0, -np.pi + 0.001]])  # the same direction as pi - 0.001
    x_new, _ = ekf.update(x, P, z, sensor, np.array([1.0]), np.array([0.01]))
    assert np.linalg.norm(x_new[:2] - x[:2]) < 0.1


def test_joseph_form_keeps_covariance_spd_under_tiny_noise():
    rng = np.random.default_rng(5)
    x, P = np.zeros(4), np.diag([1e4, 1e4, 1e4, 1e4])
    sensors = np.array([[30.0, 1.0], [-2.0, 40.0], [5.0, -25.0]])
    for _ in range(100):
        z = sample(x[:2], sensors, 1e-8, 1e-10, rng)
        x, P = ekf.update(x, P, z, sensors, np.full(3, 1e-8), np.full(3, 1e-10))
        x, P = motion.predict(x, P, np.eye(4), np.zeros((4, 4)))
        assert np.all(P == P.T)
        assert np.all(np.linalg.eigvalsh(P) > 0)


def test_nees_of_static_network_is_consistent():
    """200 Monte Carlo runs: the run-averaged position NEES lies in the 95% chi-square band."""
    runs, steps = 200, 40
    model = at.constant_velocity(1.0, 0.1)
    sensors = np.array([[15.0, 5.0], [-10.0, 12.0], [3.0, -18.0]])
    sd2, st2 = np.array([0.5, 0.5, 1.0]), np.array([0.01, 0.02, 0.01])
    P0 = np.diag([4.0, 4.0, 1.0, 1.0])
    rng = np.random.default_rng(2024)
    x_true = np.zeros((runs, 4))
    x_true[:, 2:] = [1.0, -0.5]
    x_hat = x_true + rng.standard_normal((runs, 4)) @ np.linalg.cholesky(P0).T
    P = np.broadcast_to(P0, (runs, 4, 4)).copy()
    nees = np.empty((steps, runs))
    for k in range(steps):
        x_hat, P = motion.predict(x_hat, P, model.Phi, model.Q)
        x_true = model.sample_next(x_true, rng)
        z = sample(x_true[:, :2], sensors, sd2, st2, rng)
        x_hat, P = ekf.update(x_hat, P, z, sensors, sd2, st2)
        nees[k] = ekf.position_nees(x_true, x_hat, P)
    lo, hi = stats.chi2.ppf([0.025, 0.975], 2 * runs) / runs
    per_step = nees.mean(axis=1)
    assert lo <= nees.mean() <= hi
    assert np.mean((per_step >= lo) & (per_step <= hi)) >= 0.85


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"sigma_d2": 0.0}, "sigma_d2"),
        ({"sigma_theta2": -1.0}, "sigma_theta2"),
        ({"z": np.full((2, 2), np.nan)}, "z"),
        ({"z": np.zeros((3, 2))}, "z"),
        ({"sensor_pos": np.zeros((2, 3))}, "sensor_pos"),
        ({"sensors": [5]}, "sensors"),
    ],
)
def test_filter_update_rejects_bad_input(kwargs, field):
    f = at.ExtendedKalmanFilter(at.constant_velocity(1.0, 0.1), np.zeros(4), np.eye(4))
    args = {
        "z": np.ones((2, 2)),
        "sensor_pos": np.array([[10.0, 0.0], [0.0, 10.0]]),
        "sigma_d2": 1.0,
        "sigma_theta2": 0.1,
    }
    args.update(kwargs)
    with pytest.raises(ValueError, match=field):
        f.update(**args)


@pytest.mark.parametrize(
    "x0, P0, field",
    [
        (np.zeros(3), np.eye(4), "x0"),
        (np.zeros(4), np.eye(3), "P0"),
        (np.zeros(4), np.diag([1.0, -1.0, 1.0, 1.0]), "P0"),
        (np.zeros(4), np.eye(4) + np.triu(np.ones((4, 4)), 1), "P0"),
        (np.array([0.0, np.inf, 0, 0]), np.eye(4), "x0"),
    ],
)
def test_filter_rejects_bad_initial_state(x0, P0, field):
    with pytest.raises(ValueError, match=field):
        at.ExtendedKalmanFilter(at.constant_velocity(1.0, 0.1), x0, P0)


def information_form_update(x, P, z, sensors, sd2, st2):
    """Return the EKF update written in information form (no gain, no innovation covariance).

    ``P+ = (P^{-1} + H^T R^{-1} H)^{-1}`` and ``x+ = x + P+ H^T R^{-1} nu`` (H = [H_e, 0]).
    """
    n = x.shape[0]
    He = textbook_h(x[:2], sensors)
    H = np.zeros((He.shape[0], n))
    H[:, :2] = He
    Rinv = np.diag(1.0 / np.ravel(np.column_stack([sd2, st2])))
    d = x[:2] - sensors
    zhat = np.column_stack([np.hypot(d[:, 0], d[:, 1]), np.arctan2(d[:, 1], d[:, 0])])
    nu = np.ravel(z - zhat)
    nu[1::2] = (nu[1::2] + np.pi) % (2 * np.pi) - np.pi
    P_post = np.linalg.inv(np.linalg.inv(P) + H.T @ Rinv @ H)
    return x + P_post @ H.T @ Rinv @ nu, P_post


@pytest.mark.parametrize("seed", range(8))
def test_update_equals_reference_and_information_form(seed):
    """Independent: the envs' longhand 2M x 2M update and the information form."""
    rng = np.random.default_rng(300 + seed)
    n = 4 if seed % 2 else 6
    m = 1 + seed % 4
    x = rng.standard_normal(n) * 5
    P = random_spd(rng, n, scale=10.0 ** rng.uniform(-2, 3))
    sensors = x[:2] + rng.uniform(-30, 30, (m, 2))
    sd2, st2 = 10.0 ** rng.uniform(-2, 1, m), 10.0 ** rng.uniform(-4, 0, m)
    z = sample(x[:2] + 0.2, sensors, sd2, st2, rng)
    x_new, P_new = ekf.update(x, P, z, sensors, sd2, st2)
    x_ref, P_ref = reference_ekf_update(x, P, z, sensors, sd2, st2)
    x_inf, P_inf = information_form_update(x, P, z, sensors, sd2, st2)
    for x_o, P_o in [(x_ref, P_ref), (x_inf, P_inf)]:
        np.testing.assert_allclose(x_new, x_o, rtol=1e-9, atol=1e-9 * np.abs(x).max())
        np.testing.assert_allclose(P_new, P_o, rtol=1e-8, atol=1e-10 * np.abs(P_o).max())
    np.testing.assert_array_equal(P_new, P_new.T)
    np.linalg.cholesky(P_new)


def test_batched_update_is_exactly_symmetric_and_matches_single():
    rng = np.random.default_rng(11)
    B, m = 64, 3
    x = rng.standard_normal((B, 6)) * 10
    P = np.stack([random_spd(rng, 6, scale=10.0 ** rng.uniform(-3, 3)) for _ in range(B)])
    sensors = x[:, None, :2] + rng.uniform(-10, 10, (B, m, 2))
    sd2, st2 = np.array([1.0, 2.0, 0.5]), np.array([0.1, 0.01, 0.2])
    z = sample(x[:, :2], sensors, sd2, st2, rng)
    xb, Pb = ekf.update(x, P, z, sensors, sd2, st2)
    np.testing.assert_array_equal(Pb, np.swapaxes(Pb, -1, -2))
    for b in range(B):
        xs, Ps = ekf.update(x[b], P[b], z[b], sensors[b], sd2, st2)
        np.testing.assert_allclose(xb[b], xs, rtol=1e-13, atol=1e-13 * np.abs(x[b]).max())
        np.testing.assert_allclose(Pb[b], Ps, rtol=1e-12, atol=1e-13 * np.abs(Ps).max())


@pytest.mark.parametrize("batched", [False, True])
def test_zero_distance_sensor_contributes_nothing(batched):
    """Rule: a sensor exactly on the estimate is ignored (= the update without it)."""
    rng = np.random.default_rng(21)
    x, P = rng.standard_normal(4) * 3, random_spd(rng, 4, scale=3.0)
    sensors = np.vstack([x[:2] + rng.uniform(-10, 10, (2, 2)), x[:2]])  # sensor 2 on it
    sd2, st2 = np.array([1.0, 2.0, 0.5]), np.array([0.1, 0.2, 0.05])
    z = sample(x[:2] + 0.3, sensors, sd2, st2, rng)
    z[2] = [0.7, 1.3]  # whatever it measured
    x_ref, P_ref = textbook_update(x, P, z[:2], sensors[:2], sd2[:2], st2[:2])
    args = (x, P, z, sensors, sd2, st2)
    if batched:  # with a second filter whose sensors are all away from its estimate
        far = sensors + np.array([0.0, 50.0])
        args = (
            np.stack([x, x]),
            np.stack([P, P]),
            np.stack([z, sample(x[:2], far, sd2, st2, rng)]),
            np.stack([sensors, far]),
            sd2,
            st2,
        )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy warning either
        x_new, P_new = ekf.update(*args)
    if batched:
        x_far, P_far = textbook_update(x, P, args[2][1], far, sd2, st2)
        np.testing.assert_allclose(x_new[1], x_far, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(P_new[1], P_far, rtol=1e-9, atol=1e-12)
        x_new, P_new = x_new[0], P_new[0]
    np.testing.assert_allclose(x_new, x_ref, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(P_new, P_ref, rtol=1e-9, atol=1e-12)


def test_update_with_every_sensor_at_zero_distance_returns_the_prior():
    rng = np.random.default_rng(4)
    x, P = rng.standard_normal(4), random_spd(rng, 4)
    tiny = x[:2] + np.array([1e-120, 0.0])  # below the rule's 1e-100 m: zero distance
    sensors = np.stack([x[:2], tiny])
    z = np.array([[3.0, 1.0], [0.5, -2.0]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        x_new, P_new = ekf.update(x, P, z, sensors, np.ones(2), np.full(2, 1e-10))
    np.testing.assert_array_equal(x_new, x)
    np.testing.assert_allclose(P_new, P, rtol=1e-13, atol=1e-15)
    f = at.ExtendedKalmanFilter(at.constant_velocity(1.0, 0.1), x, P)
    f.update(z, sensors, 1.0, 1e-10)  # the validated wrapper follows the same rule
    assert np.all(np.isfinite(f.P)) and np.all(np.isfinite(f.x))


def test_update_stays_spd_where_the_expanded_joseph_form_failed():
    """q = 1e10, sensors left behind: the expanded Joseph form went indefinite within ~50
    steps (trace < 0, then NaN). Here P and its prediction stay SPD for 1000 steps."""
    model = at.constant_velocity(1e10, 0.1)
    rng = np.random.default_rng(0)
    sensors = np.array([[20.0, 0.0], [21.0, 3.0], [18.0, -2.0]])
    sd2, st2 = np.array([2.0, 4.0, 4.0]), np.array([0.25, 0.5, 0.5])
    x_true, x = np.array([0.0, 0.0, -8.0, 6.0]), np.array([2.0, -2.0, 0.0, 0.0])
    P = np.diag([4.0, 4.0, 100.0, 100.0])
    for _ in range(1000):
        x, P = motion.predict(x, P, model.Phi, model.Q)
        np.linalg.cholesky(P)
        x_true = model.sample_next(x_true, rng)
        z = sample(x_true[:2], sensors, sd2, st2, rng)
        x, P = ekf.update(x, P, z, sensors, sd2, st2)
        np.testing.assert_array_equal(P, P.T)
        np.linalg.cholesky(P)
        assert np.all(np.isfinite(x))


def test_near_distance_rule_drops_a_sensor_only_beyond_the_information_bound():
    """A sensor whose bearing information ``w_theta / d^2`` would exceed ``tr(P11)``'s
    inverse INFORMATION_RATIO_MAX times gives nothing (= the textbook update without it);
    just outside that distance it counts in full (= the textbook update with it)."""
    rng = np.random.default_rng(31)
    x, P = rng.standard_normal(4), random_spd(rng, 4, scale=2.0)
    sd2, st2 = np.array([1.0, 0.5]), np.array([0.1, 0.04])
    d_edge = np.sqrt(np.trace(P[:2, :2]) / st2[1] / measurement.INFORMATION_RATIO_MAX)
    for factor, counted in ((1.01, True), (0.99, False)):
        sensors = np.stack([x[:2] + [6.0, -4.0], x[:2] + [0.0, factor * d_edge]])
        z = sample(x[:2] + 0.2, sensors, sd2, st2, rng)
        x_new, P_new = ekf.update(x, P, z, sensors, sd2, st2)
        keep = slice(None) if counted else slice(0, 1)
        x_ref, P_ref = textbook_update(x, P, z[keep], sensors[keep], sd2[keep], st2[keep])
        # Near the bound one update shrinks P11 ~1e10-fold: compare on P's own scale.
        np.testing.assert_allclose(P_new, P_ref, rtol=1e-6, atol=1e-12 * np.abs(P).max())
        np.testing.assert_allclose(x_new, x_ref, rtol=1e-6, atol=1e-9)


def test_sensors_on_the_rho_circle_of_a_tiny_rho_keep_p_spd():
    """rho = 1e-9 m and every sensor sent onto the predicted target (the world puts it on
    the rho circle): without the near-distance rule P lost definiteness (eigenvalue
    -1.1e-17 of 1.8 at step 15, independent review) and then went NaN."""
    from activetrack.envs import parallel_env

    for name, q, seed in (("homogeneous", 0.0, 3), ("paper", 10.0, 1)):
        env = parallel_env(name, n_steps=60, rho=1e-9, q=q)
        env.reset(seed=seed)
        w, m = env.world, env.world.n_sensors
        while env.agents:
            obs, rewards, *_ = env.step_positions(np.tile(w.get("x_pred", 0)[:2], (m, 1)))
            P = w.get("P", 0)
            np.linalg.cholesky(P)  # raises unless positive definite
            p = P[:2, :2]  # the position block's determinant, cancellation-free for 2x2
            assert p[0, 0] > 0 and p[0, 0] * p[1, 1] - p[0, 1] ** 2 > 0
            assert all(np.isfinite(o).all() for o in obs.values())
            assert all(np.isfinite(r) for r in rewards.values())
