"""Range-bearing model: the tests' reference (eq. 4 against trigonometry, eq. 9 against finite
differences, the noise against its moments), the library's range-bearing measurement
(:func:`activetrack.models.sensor_models.measure`, model 0) against scalar trigonometry,
and the angle wrap."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from activetrack.models import measurement
from activetrack.models import sensor_models as sm
from tests.core import helpers

coord = st.floats(-50, 50, allow_nan=False)


@settings(max_examples=200, deadline=None)
@given(tx=coord, ty=coord, sx=coord, sy=coord, phi=st.floats(-3, 3))
def test_reference_jacobian_matches_central_differences(tx, ty, sx, sy, phi):
    target = np.array([tx, ty])
    sensor = np.array([[sx, sy]])
    if np.hypot(tx - sx, ty - sy) < 0.5:
        return
    H = helpers.jacobian(target, sensor)[0]
    h = 1e-6
    fd = np.empty((2, 2))
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        zp = helpers.range_bearing(target + e, sensor, phi)[0]
        zm = helpers.range_bearing(target - e, sensor, phi)[0]
        diff = zp - zm
        diff[1] = measurement.wrap_angle(diff[1])
        fd[:, j] = diff / (2 * h)
    np.testing.assert_allclose(H, fd, rtol=1e-6, atol=1e-8)


def test_reference_range_bearing_known_geometry():
    # target due north of the sensor, sensor facing east: bearing pi/2, distance 5
    z = helpers.range_bearing(np.array([3.0, 9.0]), np.array([[3.0, 4.0]]), 0.0)[0]
    np.testing.assert_allclose(z, [5.0, np.pi / 2])
    # facing north: bearing 0
    z = helpers.range_bearing(np.array([3.0, 9.0]), np.array([[3.0, 4.0]]), np.pi / 2)[0]
    np.testing.assert_allclose(z, [5.0, 0.0], atol=1e-15)


def test_wrap_angle_range():
    a = np.linspace(-20, 20, 10001)
    w = measurement.wrap_angle(a)
    assert np.all(w >= -np.pi) and np.all(w < np.pi)
    np.testing.assert_allclose(np.sin(w), np.sin(a), atol=1e-12)
    np.testing.assert_allclose(np.cos(w), np.cos(a), atol=1e-12)
    assert measurement.wrap_angle(np.pi) == -np.pi
    inside = np.array([-np.pi, -1.0, 0.0, 3.1])
    out = measurement.wrap_angle(inside)
    np.testing.assert_array_equal(out, inside)
    assert not np.shares_memory(out, inside)
    np.testing.assert_array_equal(measurement.wrap_angle(np.array([np.pi, 0.5])), [-np.pi, 0.5])
    assert np.isnan(measurement.wrap_angle(np.array([np.nan, 0.0]))[0])


def test_reference_sampled_noise_moments():
    # Bands for the statistics tested, from the sample itself: the mean error of n draws
    # has standard error s / sqrt(n) (s the sample's standard deviation: 1.4 m to 0.1 rad
    # here, so 4.5e-3 to 3e-4); a normal variance estimate has relative standard error
    # sqrt(2 / (n - 1)) = 4.5e-3. 4.5 standard errors each: a correct sampler is outside
    # with probability 7e-6 per component, while a bias of a tenth of a standard
    # deviation (22 standard errors) or a variance 10% off (22 as well) is far outside.
    rng = np.random.default_rng(0)
    target = np.array([0.0, 0.0])
    sensors = np.array([[10.0, 0.0], [0.0, -20.0]])
    sd2, st2 = np.array([2.0, 0.5]), np.array([0.01, 0.04])
    n = 100_000
    z = helpers.sample(np.broadcast_to(target, (n, 2)), sensors, sd2, st2, rng)
    truth = helpers.range_bearing(target, sensors)
    err = z - truth
    err[..., 1] = measurement.wrap_angle(err[..., 1])
    se_mean = err.std(0, ddof=1) / np.sqrt(n)
    assert np.all(np.abs(err.mean(0)) <= 4.5 * se_mean), (err.mean(0), se_mean)
    rtol = 4.5 * np.sqrt(2.0 / (n - 1))
    var = err.var(0, ddof=1)
    np.testing.assert_allclose(var[:, 0], sd2, rtol=rtol)
    np.testing.assert_allclose(var[:, 1], st2, rtol=rtol)


def test_measure_batched_against_scalar_trigonometry_and_unwrapped_option():
    rng = np.random.default_rng(7)
    targets = rng.uniform(-30, 30, (50, 2))
    sensors = rng.uniform(-30, 30, (50, 4, 2))
    phi = rng.uniform(-3, 3, (50, 4))
    z = sm.measure(targets, sensors, 0, phi)
    raw = sm.measure(targets, sensors, 0, phi, wrap=False)
    for b in range(50):
        for i in range(4):
            dx, dy = targets[b] - sensors[b, i]
            assert abs(z[b, i, 0] - math.hypot(dx, dy)) <= 1e-12 * math.hypot(dx, dy)
            assert abs(raw[b, i, 1] - (math.atan2(dy, dx) - phi[b, i])) <= 1e-14
    np.testing.assert_array_equal(raw[..., 0], z[..., 0])
    np.testing.assert_array_equal(measurement.wrap_angle(raw[..., 1]), z[..., 1])
    # a non-contiguous sensor array (every other column) gives the same answer
    wide = np.zeros((50, 4, 4))
    wide[..., ::2] = sensors
    np.testing.assert_array_equal(sm.measure(targets, wide[..., ::2], 0, phi), z)


def test_zero_distance_gives_finite_measurement_and_zero_jacobian_rows():
    """The zero-distance rule: no information (zero rows), never NaN; other sensors intact."""
    target = np.array([3.0, -1.0])
    sensors = np.array([[3.0, -1.0], [3.0 + 1e-120, -1.0], [6.0, 3.0]])
    z = sm.measure(target, sensors, 0, np.array([0.5, 0.0, 0.0]))
    assert np.all(np.isfinite(z))
    np.testing.assert_array_equal(z[:2, 0], 0.0)
    for H in (sm.jacobian_target(target, sensors, 0), helpers.jacobian(target, sensors)):
        np.testing.assert_array_equal(H[:2], 0.0)
        # the third sensor, 5 m away along (3, 4): h_d = -p/|p|, h_theta = J p / |p|^2 (eq. 9)
        np.testing.assert_allclose(H[2], [[-0.6, -0.8], [4.0 / 25.0, -3.0 / 25.0]], rtol=1e-14)
