"""Bounds and dimensions of the observation encoding (activetrack.world.observation)."""

import numpy as np
import pytest

from activetrack.world import observation as features


def test_bounds_and_dimensions():
    low, high = features.observation_bounds(3)
    assert low.shape == high.shape == (features.obs_dim(3),) == (23,)
    assert (low[2], high[2]) == (-1.0, 1.0)
    assert np.all(low[[9, 10, 15, 16, 21, 22]] == 0.0)
    slow, shigh = features.state_bounds(3)
    assert slow.shape == (features.state_dim(3),) == (24,) and (slow[-1], shigh[-1]) == (0, 1)


def _spd(rng, n, batch):
    a = rng.normal(size=batch + (n, n))
    return a @ np.swapaxes(a, -1, -2) + n * np.eye(n)


@pytest.mark.kernels
def test_extended_blocks_follow_the_docstring_entry_by_entry():
    """Two targets of different state sizes (a constant-velocity and a position-only one),
    three sensors with detection flags, a batch of 5: every entry by the module docstring's
    formulas; the one-pass observation equals the views of those blocks, and each copy
    alone gives its row."""
    rng = np.random.default_rng(4)
    B, M, dt, L = 5, 3, 0.1, 7.0
    x = [rng.normal(size=(B, 4)), rng.normal(size=(B, 2))]
    P = [_spd(rng, 4, (B,)), _spd(rng, 2, (B,))]
    fixes = rng.normal(size=(B, M, 2)) * 5
    const = rng.normal(size=(M, 10))
    det = rng.random((B, 2, M)) < 0.5
    target, sensor = features.features(x, P, fixes, const, dt, L, True, det)
    o = (x[0][:, :2] + x[1][:, :2]) / 2  # the centroid
    for k in range(2):
        t = target[:, 7 * k : 7 * k + 7]
        np.testing.assert_allclose(t[:, :2], (x[k][:, :2] - o) / L, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(t[:, 2], np.log(np.sqrt(P[k][:, 0, 0]) / L), rtol=1e-12)
        np.testing.assert_allclose(t[:, 3], np.log(np.sqrt(P[k][:, 1, 1]) / L), rtol=1e-12)
        corr = P[k][:, 0, 1] / np.sqrt(P[k][:, 0, 0] * P[k][:, 1, 1])
        np.testing.assert_allclose(t[:, 4], corr, rtol=1e-12)
        v = x[k][:, 2:4] * dt / L if k == 0 else np.zeros((B, 2))
        np.testing.assert_allclose(t[:, 5:], v, rtol=1e-12)
    np.testing.assert_allclose(sensor[..., :2], (fixes - o[:, None]) / L, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(sensor[..., 2:12], np.broadcast_to(const, (B, M, 10)))
    np.testing.assert_array_equal(sensor[..., 12:], np.swapaxes(det, -1, -2).astype(float))
    order = features.cyclic_order(M)
    obs = features.encode(x, P, fixes, const, dt, L, True, det, order, n_rays=3)
    assert obs.dtype == np.float32 and obs.shape == (B, M, 14 + 14 * M + 3)
    views = features.observations(target, sensor, order)
    np.testing.assert_array_equal(obs[..., :-3], views)
    for i in range(M):  # agent i: the targets, then sensors i, i+1, ... (mod M)
        np.testing.assert_array_equal(views[:, i, :14], target.astype(np.float32))
        ring = sensor[:, (i + np.arange(M)) % M].reshape(B, -1)
        np.testing.assert_array_equal(views[:, i, 14:], ring.astype(np.float32))
    for b in range(B):
        one = features.encode(
            [x[0][b], x[1][b]], [P[0][b], P[1][b]], fixes[b], const, dt, L, True, det[b], order
        )
        np.testing.assert_array_equal(one, obs[b, :, :-3])


@pytest.mark.kernels
def test_paper_blocks_follow_the_docstring_entry_by_entry():
    rng = np.random.default_rng(5)
    x, P = rng.normal(size=(2, 3, 4)), _spd(rng, 4, (2, 3))
    sensors, const = rng.normal(size=(2, 3, 4, 2)), rng.normal(size=(4, 4))
    t = features.target_features(x, P, 0.2, 3.0)
    want = np.stack([
        0.5 * np.log(P[..., 0, 0] / 9.0), 0.5 * np.log(P[..., 1, 1] / 9.0),
        P[..., 0, 1] / np.sqrt(P[..., 0, 0] * P[..., 1, 1]),
        x[..., 2] * 0.2 / 3.0, x[..., 3] * 0.2 / 3.0,
    ], -1)  # fmt: skip
    np.testing.assert_allclose(t, want, rtol=1e-12)
    s = features.sensor_features(sensors, x[..., :2], const, 3.0)
    np.testing.assert_allclose(s[..., :2], (sensors - x[..., None, :2]) / 3.0, rtol=1e-12)
    np.testing.assert_array_equal(s[..., 2:], np.broadcast_to(const, (2, 3, 4, 4)))


def test_bad_orders_and_masks_are_refused_before_the_kernels():
    """The kernels index with ``order`` unchecked: a table out of range, of the wrong shape
    or type is a ValueError naming it (and line_of_sight's ``where`` likewise)."""
    from activetrack.models import occluders as oc

    target, sensor = np.zeros((2, 5)), np.zeros((2, 3, 6))
    for bad in ([[0, 1, 3], [1, 2, 0], [2, 0, 1]], [[0, 1], [1, 0]], np.zeros((3, 3)),
                -features.cyclic_order(3)):  # fmt: skip
        with pytest.raises(ValueError, match="order must"):
            features.observations(target, sensor, bad)
    x, P = [np.zeros(4)], [np.eye(4)]
    with pytest.raises(ValueError, match="order must"):
        features.encode(x, P, np.ones((3, 2)), np.zeros((3, 4)), 0.1, 1.0, False, None,
                        np.full((3, 3), 7))  # fmt: skip
    occ = oc.Occluders.from_polygons([np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]])])
    s, t = np.zeros((4, 3, 2)) - 1.0, np.ones((4, 2, 2)) * 2.0
    for bad in (np.ones((4, 2, 3)), np.ones((5, 2, 3), bool), np.ones((2, 2), bool)):
        with pytest.raises(ValueError, match="where must be a bool array"):
            oc.line_of_sight(s, t, occ, bad)


def test_encode_takes_lists_like_arrays():
    """Nested lists are arrays here too (converted at the boundary, not inside numba)."""
    x, P = [np.array([0.5, -1.0, 2.0, 1.0])], [np.diag([2.0, 3.0, 1.0, 1.0])]
    fixes, const = [[3.0, 4.0], [-1.0, 2.0]], [[0.0, 0.1, 0.2, 0.3]] * 2
    order = features.cyclic_order(2)
    got = features.encode(x, P, fixes, const, 0.1, 5.0, False, None, order)
    want = features.encode(x, P, np.array(fixes), np.array(const), 0.1, 5.0, False, None, order)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_allclose(got[0, 5:7], (np.array([3.0, 4.0]) - [0.5, -1.0]) / 5.0, rtol=1e-6)
