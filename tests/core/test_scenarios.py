"""Scenario presets and the shared closed-loop functions."""

import numpy as np
import pytest

import activetrack as at


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
