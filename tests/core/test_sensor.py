"""The public sensor models (:mod:`activetrack.models.sensor`): the three built-ins' methods
and the base class's defaults against independent computations (eq. 4 and 9 written out
in ``tests.core.helpers``, central finite differences, textbook inverses, Monte Carlo)."""

from __future__ import annotations

import numpy as np
import pytest

import activetrack
from activetrack import BearingOnly, RangeBearing, RangeOnly, SensorModel
from activetrack.models import sensor_models
from tests.core import helpers

BUILT_INS = [RangeBearing(), RangeOnly(), BearingOnly()]
USED = {"range_bearing": (1.0, 1.0), "range": (1.0, 0.0), "bearing": (0.0, 1.0)}


class PlainRangeBearing(SensorModel):
    """Range and bearing with only ``function`` defined: every other method is the base's
    default (finite-difference Jacobian, diagonal noise, ``H^T R_eff^+ H``)."""

    name = "plain_range_bearing"
    slots = (True, True)

    def function(self, target, sensor, orientation=0.0):
        d = np.asarray(target, float) - np.asarray(sensor, float)
        return np.stack([np.hypot(d[..., 0], d[..., 1]),
                         np.arctan2(d[..., 1], d[..., 0]) - orientation], -1)  # fmt: skip


def _geometry(rng, n=40):
    target = rng.normal(0, 5, (n, 2))
    ang = rng.uniform(-np.pi, np.pi, n)
    sensor = target + rng.uniform(1.0, 20.0, n)[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    return target, sensor


def _textbook_info(target, sensor, sd2, st2, used, cov=None):
    """Return ``H^T (R + H cov H^T)^{-1} H`` on the used rows, H of eq. (9) (helpers)."""
    H = helpers.jacobian(target, sensor[None])[0]
    rows = [k for k in range(2) if used[k]]
    H = H[rows]
    R = np.diag([sd2, st2])[np.ix_(rows, rows)]
    if cov is not None:
        R = R + H @ cov @ H.T
    return H.T @ np.linalg.inv(R) @ H


def test_old_enum_names_still_hold_the_codes():
    assert SensorModel.RANGE_BEARING == 0 and SensorModel.RANGE == 1 and SensorModel.BEARING == 2
    assert sensor_models.SensorModel is activetrack.SensorModel
    assert [m.code for m in BUILT_INS] == [0, 1, 2]
    assert [m.name for m in BUILT_INS] == ["range_bearing", "range", "bearing"]
    assert RangeOnly() == RangeOnly() and RangeOnly() != BearingOnly()
    assert all(m.builtin for m in BUILT_INS) and not PlainRangeBearing().builtin


@pytest.mark.parametrize("model", BUILT_INS + [PlainRangeBearing()], ids=lambda m: m.name)
def test_function_and_jacobian_against_eq4_and_finite_differences(model):
    rng = np.random.default_rng(1)
    target, sensor = _geometry(rng)
    phi = rng.uniform(-2, 2, len(target))
    used = np.array(USED.get(model.name, (1.0, 1.0)))
    want = helpers.range_bearing(target, sensor[:, None, :], phi[:, None])[:, 0] * used
    got = model.function(target, sensor, phi)
    got[:, 1] = np.where(used[1] > 0, (got[:, 1] - want[:, 1] + np.pi) % (2 * np.pi) - np.pi
                         + want[:, 1], 0.0)  # fmt: skip
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    # Central differences of the helpers' eq. (4), bearing differences wrapped.
    h = 1e-6
    fd = np.empty((len(target), 2, 2))
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        plus = helpers.range_bearing(target + e, sensor[:, None], wrap=False)[:, 0]
        minus = helpers.range_bearing(target - e, sensor[:, None], wrap=False)[:, 0]
        fd[:, :, k] = (plus - minus) / (2 * h)
    fd *= used[None, :, None]
    np.testing.assert_allclose(model.jacobian(target, sensor, phi), fd, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("model", BUILT_INS + [PlainRangeBearing()], ids=lambda m: m.name)
@pytest.mark.parametrize("with_pose", [False, True])
def test_information_against_the_textbook_inverse(model, with_pose):
    rng = np.random.default_rng(2 + with_pose)
    target, sensor = _geometry(rng, 20)
    used = USED.get(model.name, (1.0, 1.0))
    for t, s in zip(target, sensor, strict=True):
        sd2, st2 = rng.uniform(0.1, 3), rng.uniform(0.001, 0.3)
        cov = helpers.random_spd(rng, 2, 0.3) if with_pose else None
        want = _textbook_info(t, s, sd2, st2, used, cov)
        got = model.information(s - t, sd2, st2, cov)
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-9 * np.abs(want).max())
    # Detection: p_detect inside the range, 0 outside (and where the line of sight is cut).
    rel = sensor - target
    d2 = (rel**2).sum(-1)
    r2 = np.median(d2)
    J = model.information(rel, 1.0, 0.1)
    Jd = model.information(rel, 1.0, 0.1, None, (0.7, r2))
    np.testing.assert_allclose(Jd, np.where((d2 <= r2)[:, None, None], 0.7 * J, 0.0), rtol=1e-12)
    seen = rng.random(len(rel)) < 0.5
    Js = model.information(rel, 1.0, 0.1, None, (1.0, np.inf, seen))
    np.testing.assert_allclose(Js, np.where(seen[:, None, None], J, 0.0), rtol=1e-12)


@pytest.mark.parametrize("model", BUILT_INS + [PlainRangeBearing()], ids=lambda m: m.name)
def test_measure_moments_by_monte_carlo(model):
    rng = np.random.default_rng(3)
    n = 200_000
    t, s, phi, sd2, st2 = np.array([1.0, -2.0]), np.array([-4.0, 3.0]), 0.3, 0.8, 0.02
    z = model.measure(t, s, sd2, st2, rng.standard_normal((n, 2)), phi)
    used = USED.get(model.name, (1.0, 1.0))
    mean = helpers.range_bearing(t, s[None], phi)[0]
    for k, var in ((0, sd2), (1, st2)):
        if not used[k]:
            np.testing.assert_array_equal(z[:, k], 0.0)
            continue
        assert abs(z[:, k].mean() - mean[k]) < 5 * np.sqrt(var / n)
        assert abs(z[:, k].var() - var) < 5 * var * np.sqrt(2 / n)


@pytest.mark.parametrize("model", BUILT_INS + [PlainRangeBearing()], ids=lambda m: m.name)
@pytest.mark.parametrize("with_pose", [False, True])
def test_update_terms_give_the_textbook_kalman_update(model, with_pose):
    rng = np.random.default_rng(4 + with_pose)
    used = USED.get(model.name, (1.0, 1.0))
    rows = [k for k in range(2) if used[k]]
    for _ in range(10):
        t = rng.normal(0, 3, 2)
        s = t + rng.uniform(3, 12) * np.array([np.cos(a := rng.uniform(-3, 3)), np.sin(a)])
        sd2, st2, phi = rng.uniform(0.2, 2), rng.uniform(0.005, 0.1), rng.uniform(-1, 1)
        cov = helpers.random_spd(rng, 2, 0.2) if with_pose else None
        x = np.concatenate([t + rng.normal(0, 0.4, 2), rng.normal(0, 1, 2)])
        P = helpers.random_spd(rng, 4)
        z = model.measure(t, s, sd2, st2, rng.standard_normal(2), phi)
        Y, b = model.update_terms(z, x[:2], s, sd2, st2, phi, cov)
        E = np.eye(4)[:2]
        P_post = np.linalg.inv(np.linalg.inv(P) + E.T @ Y @ E)
        x_post = x + P_post @ E.T @ b
        # Textbook: K = P H^T S^-1 on the used rows, R_eff = R + H cov H^T.
        He = helpers.jacobian(x[:2], s[None])[0][rows]
        H = np.hstack([He, np.zeros((len(rows), 2))])
        R = np.diag([sd2, st2])[np.ix_(rows, rows)]
        if cov is not None:
            R = R + He @ cov @ He.T
        zhat = helpers.range_bearing(x[:2], s[None], phi)[0]
        nu = (z - zhat)[rows]
        if used[1]:
            nu[-1] = (nu[-1] + np.pi) % (2 * np.pi) - np.pi
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        np.testing.assert_allclose(x_post, x + K @ nu, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(P_post, P - K @ S @ K.T, rtol=1e-6, atol=1e-10)


def test_zero_distance_gives_no_information_and_no_nan():
    for model in BUILT_INS + [PlainRangeBearing()]:
        J = model.information(np.zeros(2), 1.0, 0.1)
        assert np.all(J == 0.0), model.name
        assert np.all(model.jacobian(np.ones(2), np.ones(2)) == 0.0), model.name
