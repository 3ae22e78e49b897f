"""Scenario presets and the shared closed-loop functions."""

import numpy as np
import pytest
from scipy import stats

import activetrack as at
from activetrack import ekf, tracking
from tests.core.helpers import textbook_update


def test_paper_preset_is_section_v():
    sc = at.make_scenario("paper")
    assert sc.n_sensors == 3 and sc.n_steps == 50 and sc.dt == 0.1 and sc.q == 10.0
    np.testing.assert_allclose(sc.r, [1.0, 1.0, 1.0])  # vmax 10 m/s over 0.1 s
    np.testing.assert_allclose(sc.per_sensor("rho"), 2.0)
    np.testing.assert_allclose(sc.per_sensor("sigma_d2"), [2, 4, 4])
    np.testing.assert_allclose(sc.per_sensor("sigma_theta2"), [0.25, 0.5, 0.5])
    assert sc.x0 == (0.0, 0.0, -8.0, 6.0) and sc.x0_hat == (2.0, -2.0, 0.0, 0.0)


def test_overrides_and_errors_name_the_field():
    sc = at.make_scenario("homogeneous", n_sensors=8, rho=1.5)
    assert sc.n_sensors == 8 and np.all(sc.per_sensor("rho") == 1.5)
    assert at.make_scenario("paper", n_sensors=5).per_sensor("sigma_d2").shape == (5,)
    for kwargs, field in [
        ({"n_sensors": 0}, "n_sensors"),
        ({"dt": -0.1}, "dt"),
        ({"rho": -1.0}, "rho"),
        ({"sigma_d2": (1.0, 2.0)}, "sigma_d2"),
        ({"x0": (0.0, 0.0)}, "x0"),
        ({"P0": (1.0, -1.0, 1.0, 1.0)}, "P0"),
        ({"motion": "spiral"}, "motion"),
        ({"target_init": "random"}, "target_init"),
        ({"warp_drive": True}, "warp_drive"),
    ]:
        with pytest.raises(ValueError, match=field):
            at.make_scenario("paper", **kwargs)
    with pytest.raises(ValueError, match="scenario"):
        at.make_scenario("nope")


def test_initial_sensors_uniform_by_area():
    sc = at.make_scenario("paper", n_sensors=1, sigma_d2=1.0, sigma_theta2=1.0)
    rng = np.random.default_rng(0)
    pts = np.array([tracking.initial_conditions(sc, rng)[3][0] for _ in range(4000)])
    rad = np.linalg.norm(pts - np.array(sc.sensor_center), axis=1) / sc.sensor_radius
    # uniform by area: (rad)^2 ~ U(0, 1)
    assert stats.kstest(rad**2, "uniform").pvalue > 1e-3
    ang = np.arctan2(*(pts - sc.sensor_center).T[::-1])
    assert stats.kstest((ang + np.pi) / (2 * np.pi), "uniform").pvalue > 1e-3


def test_advance_is_one_step_of_the_textbook_loop():
    sc = at.make_scenario("paper")
    params = tracking.LoopParams.from_scenario(sc)
    rng = np.random.default_rng(3)
    x_true, x_hat, P, sensors = tracking.initial_conditions(sc, rng)
    x_pred, P_pred = ekf.predict(x_hat, P, params.Phi, params.Q)
    noise = rng.standard_normal(params.n_noise)
    x_next, z, x_post, P_post = tracking.advance(params, x_true, x_pred, P_pred, sensors, noise)
    # independent: target moved by Phi plus the process noise with covariance Q
    w = x_next - params.Phi @ x_true
    assert w @ np.linalg.solve(params.Q, w) == pytest.approx(noise[:4] @ noise[:4], rel=1e-9)
    x_ref, P_ref = textbook_update(x_pred, P_pred, z, sensors, params.sigma_d2, params.sigma_theta2)
    np.testing.assert_allclose(x_post, x_ref, rtol=1e-10)
    np.testing.assert_allclose(P_post, P_ref, rtol=1e-9)


def test_initial_cov_is_a_fresh_copy_of_p0():
    sc = at.make_scenario("paper", P0=(4.0, 9.0, 1.0, 1.0))
    P0 = sc.initial_cov
    np.testing.assert_array_equal(P0, np.diag([4.0, 9.0, 1.0, 1.0]))
    P0[0, 0] = -1.0  # a caller that mutates its copy does not change the scenario
    assert sc.initial_cov[0, 0] == 4.0
    _, _, P_episode, _ = tracking.initial_conditions(sc, np.random.default_rng(0))
    P_episode[1, 1] = 0.0
    assert sc.initial_cov[1, 1] == 9.0
