"""The compiled closed-loop arithmetic (:mod:`activetrack.world._loop_kernels`) against NumPy
longhand, and the world's one-call step against its stage-by-stage step.

The stage-by-stage step (target motion, measurement, EKF, prediction, each its own call)
is checked against the paper's longhand loop in ``test_world.py``; here the one-call step
(:func:`activetrack.world._loop_kernels.advance_rows`, ``advance_observe_row``) must give the same
states, rewards and observations on every task it serves.
"""

import numpy as np
import pytest

from activetrack.models.motion import predict
from activetrack.world import World, tracking
from activetrack.world.scenarios import make_scenario
from tests.core.helpers import random_spd

pytestmark = pytest.mark.kernels

#: Tasks whose step is one compiled call (one target, known positions, no occluders).
FUSED = ["paper", "homogeneous", "range_only", "bearing_only", "mixed"]


@pytest.mark.parametrize("batch", [(), (3,), (2, 3)])
def test_predict_matches_numpy_and_is_exactly_symmetric(batch):
    rng = np.random.default_rng(0)
    n = 6
    Phi = rng.standard_normal((n, n))
    Q = random_spd(rng, n)
    P = np.stack([random_spd(rng, n) for _ in range(int(np.prod(batch)))]).reshape(batch + (n, n))
    x = rng.standard_normal(batch + (n,))
    x_next, P_next = predict(x, P, Phi, Q)
    want = Phi @ P @ Phi.T + Q  # NumPy's own products, in its own order
    np.testing.assert_allclose(P_next, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())
    np.testing.assert_allclose(x_next, x @ Phi.T, rtol=1e-13, atol=1e-13)
    assert np.array_equal(P_next, np.swapaxes(P_next, -1, -2))  # exactly, not to rounding
    assert P_next.shape == batch + (n, n) and x_next.shape == batch + (n,)


def test_predict_keeps_each_batch_shape_and_checks_sizes():
    rng = np.random.default_rng(1)
    Phi = np.eye(4) + np.diag([0.1, 0.1], 2)  # constant velocity, dt = 0.1
    Q = random_spd(rng, 4)
    P = np.stack([random_spd(rng, 4) for _ in range(3)])
    x = rng.standard_normal(4)
    x_next, P_next = predict(x, P, Phi, Q)  # one mean, three covariances
    assert x_next.shape == (4,) and P_next.shape == (3, 4, 4)
    np.testing.assert_allclose(x_next, Phi @ x, rtol=1e-14)
    np.testing.assert_allclose(P_next, Phi @ P @ Phi.T + Q, rtol=1e-13)
    xs = rng.standard_normal((2, 4))
    x_next, P_next = predict(xs, P[0], Phi, Q)  # two means, one covariance
    assert x_next.shape == (2, 4) and P_next.shape == (4, 4)
    np.testing.assert_allclose(x_next, xs @ Phi.T, rtol=1e-14)
    for bad in ((x[:2], P), (x, P[:, :2, :2]), (np.zeros((5, 2)), np.zeros((5, 2, 2)))):
        with pytest.raises(ValueError, match="predict needs"):  # the kernel would overrun
            predict(*bad, Phi, Q)


def test_measure_and_move_target_broadcast_and_check_sizes():
    p = tracking.LoopParams.from_scenario(make_scenario("paper"))
    rng = np.random.default_rng(5)
    sensors = rng.normal(size=(4, 3, 2)) * 5
    target = rng.normal(size=2)
    noise = rng.standard_normal((4, 6))
    z = tracking.measure(p, target, sensors, noise)  # one target for every copy
    d = target - sensors  # eq. (4) longhand, orientation 0, bearings wrapped after the noise
    want_d = np.hypot(d[..., 0], d[..., 1]) + np.sqrt(p.sigma_d2) * noise[:, 0::2]
    want_t = np.arctan2(d[..., 1], d[..., 0]) + np.sqrt(p.sigma_theta2) * noise[:, 1::2]
    want_t = (want_t + np.pi) % (2 * np.pi) - np.pi
    np.testing.assert_allclose(z, np.stack([want_d, want_t], -1), rtol=1e-14, atol=1e-14)
    np.testing.assert_array_equal(z, tracking.measure(p, target, sensors, noise.reshape(4, 3, 2)))
    with pytest.raises(ValueError, match="measure needs"):  # more sensors than the params'
        tracking.measure(p, target, np.zeros((6, 2)), np.zeros(12))
    with pytest.raises(ValueError):  # too few normals
        tracking.measure(p, target, sensors, noise[:1])
    t0 = p.targets[0]
    x, w = rng.normal(size=4), rng.standard_normal((3, 4))
    got = tracking.move_target(t0, x, w)
    np.testing.assert_allclose(got, x @ t0.Phi.T + w @ t0.noise_factor.T, rtol=1e-13, atol=1e-13)
    with pytest.raises(ValueError, match="move_target needs"):
        tracking.move_target(t0, x[:2], w)


def test_move_target_matches_numpy():
    rng = np.random.default_rng(2)
    n = 4
    target = tracking.TargetParams(rng.standard_normal((n, n)), random_spd(rng, n),
                                   rng.standard_normal((n, n)).T)  # fmt: skip
    x, w = rng.standard_normal((5, n)), rng.standard_normal((5, n))
    got = tracking.move_target(target, x, w)
    want = x @ target.Phi.T + w @ target.noise_factor.T
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13)
    # a transposed (Fortran-ordered) noise factor is stored C-contiguous for the kernels
    assert target.noise_factor.flags.c_contiguous


def _worlds(scenario, n, **kw):
    """Return two worlds from the same seeds: one-call steps, and stage-by-stage steps."""
    fused, staged = World(scenario, n, **kw), World(scenario, n, **kw)
    assert fused._fused
    staged._fused = False  # the general path (every stage its own call)
    seeds = [7 + 3 * i for i in range(n)]
    fused.reset(seeds=seeds)
    staged.reset(seeds=seeds)
    return fused, staged


def _assert_same_state(a, b):
    for key in ("sensors", "fixes", "projected", "n_projected", "k", "trace", "score"):
        np.testing.assert_allclose(
            np.asarray(a.get(key), float), np.asarray(b.get(key), float), rtol=1e-12, atol=1e-12
        )
    for key in ("x_true", "x_hat", "P", "x_pred", "P_pred"):
        np.testing.assert_allclose(a.get(key), b.get(key), rtol=1e-11, atol=1e-11)


@pytest.mark.parametrize("scenario", FUSED)
@pytest.mark.parametrize("n", [1, 4])
def test_one_call_step_equals_the_stage_by_stage_step(scenario, n):
    fused, staged = _worlds(scenario, n, n_steps=30, max_trace=40.0, rho=19.0)
    rng = np.random.default_rng(3)
    m = fused.n_sensors
    shape = (m, 2) if n == 1 else (n, m, 2)
    projected = 0
    for step in range(70):
        where = np.asarray(fused.get("x_pred"))[..., None, :2]
        toward = where - np.asarray(fused.get("sensors"))  # full speed at the target
        toward /= np.linalg.norm(toward, axis=-1, keepdims=True)
        if step % 3 == 2:  # absolute positions, some at the predicted target itself
            goal = np.asarray(fused.get("sensors")) + rng.uniform(-3, 3, shape)
            goal = np.where(rng.random(shape[:-1] + (1,)) < 0.5, where, goal)
            ra, rb = fused.step(goal), staged.step(goal)
        else:  # actions toward the target or random, some far outside the unit disk
            a = np.where(rng.random(shape[:-1] + (1,)) < 0.7, toward, rng.uniform(-1.5, 1.5, shape))
            ra, rb = fused.step_actions(a), staged.step_actions(a)
        for x, y in zip(ra, rb, strict=True):
            np.testing.assert_allclose(np.asarray(x, float), np.asarray(y, float), rtol=1e-12)
        _assert_same_state(fused, staged)
        obs_a, obs_b = fused.observe(), staged.observe()
        np.testing.assert_allclose(obs_a, obs_b, rtol=1e-6, atol=1e-6)
        projected += int(np.sum(fused.get("projected")))
        ended = np.atleast_1d(fused.get("terminated") | fused.get("truncated"))
        if ended.any():
            idx = None if n == 1 else ended
            fused.reset(idx)
            staged.reset(idx)
    assert projected > 0  # the rho rule was exercised


def test_one_call_step_of_a_subset_of_copies():
    fused, staged = _worlds("paper", 5)
    rng = np.random.default_rng(4)
    for live in ([0, 2], [4], np.array([True, False, True, True, False]), None):
        a = rng.uniform(-1, 1, (5, 3, 2))
        before = np.array(fused.get("x_hat"))
        ra, rb = fused.step_actions(a, live), staged.step_actions(a, live)
        np.testing.assert_allclose(ra.reward, rb.reward, rtol=1e-12)
        _assert_same_state(fused, staged)
        if live is not None:  # the others are untouched, bit for bit
            stepped = np.zeros(5, bool)
            stepped[live] = True
            rest = np.flatnonzero(~stepped)
            assert np.array_equal(fused.get("x_hat")[rest], before[rest])


def test_single_copy_observation_is_made_by_the_step_and_handed_out_once():
    fused, staged = _worlds("paper", 1)
    a = np.full((3, 2), 0.3)
    fused.step_actions(a)
    staged.step_actions(a)
    first, second = fused.observe(), fused.observe()
    assert first is not second  # a second call makes a new array
    np.testing.assert_array_equal(first, second)
    np.testing.assert_allclose(first, staged.observe(), rtol=1e-6, atol=1e-6)
    fused.reset(seeds=[1])  # the state changes: the step's observation is gone
    staged.reset(seeds=[1])
    np.testing.assert_array_equal(fused.observe(), staged.observe())


@pytest.mark.parametrize("n", [1, 3])
@pytest.mark.parametrize(
    "bad, match",
    [
        ("shape", "actions must have shape"),
        ("nan", "actions must be finite"),
        ("inf", "actions must be finite"),
        ("text", "actions must be real numbers"),
    ],
)
def test_a_bad_step_raises_and_changes_nothing(n, bad, match):
    """A step with bad moves raises a ValueError naming them, before any state or random
    draw changes: the episode then goes on exactly as if the call had not been made."""
    world, twin = World("paper", n), World("paper", n)
    for w in (world, twin):
        w.reset(seeds=range(n))
    m = world.n_sensors
    good = np.full((n, m, 2), 0.3) if n > 1 else np.full((m, 2), 0.3)
    wrong = {
        "shape": np.zeros((n, m + 1, 2)),
        "nan": np.where(np.arange(good.size).reshape(good.shape) == 1, np.nan, good),
        "inf": np.where(np.arange(good.size).reshape(good.shape) == 0, -np.inf, good),
        "text": np.full(good.shape, "a"),
    }[bad]
    with pytest.raises(ValueError, match=match):
        world.step_actions(wrong)
    with pytest.raises(ValueError, match=match.replace("actions", "positions")):
        world.step(wrong)
    for w in (world, twin):
        w.step_actions(good)
    for key in ("sensors", "k", "trace", "x_true", "x_hat", "P", "x_pred", "P_pred"):
        np.testing.assert_array_equal(world.get(key), twin.get(key))  # bit for bit
    np.testing.assert_array_equal(world.observe(), twin.observe())


def test_moves_of_copies_that_do_not_step_are_not_read():
    world = World("paper", 3)
    world.reset(seeds=[0, 1, 2])
    a = np.full((3, 3, 2), 0.2)
    a[1] = np.nan  # copy 1 does not step
    world.step_actions(a, live=[0, 2])
    assert world.get("k").tolist() == [1, 0, 1]
    assert np.isfinite(world.get("x_hat")).all()
    with pytest.raises(ValueError, match=r"copies \[1\]"):
        world.step_actions(a, live=[1, 2])


def test_one_call_step_of_mixed_sensors_matches_a_longhand_step():
    """One step of ``mixed`` (range-and-bearing, range-only and bearing-only sensors),
    written out from eq. (2), (4), (11) and (3): the draws taken from a copy of the
    episode's generator, the EKF with only the measured rows of H and R."""
    import copy

    world = World("mixed")
    world.reset(seeds=[3])
    sc, p = world.scenario, world.params
    m, n = world.n_sensors, 4
    sensors, x_true = np.array(world.get("sensors", 0)), np.array(world.get("x_true", 0))
    x_pred, P_pred = np.array(world.get("x_pred", 0)), np.array(world.get("P_pred", 0))
    normals = copy.deepcopy(world.rng(0)).standard_normal(n + 2 * m)
    a = np.random.default_rng(0).uniform(-0.6, 0.6, (m, 2))
    world.step_actions(a)
    assert not world.get("projected", 0).any()
    moved = sensors + sc.r[:, None] * a
    phi, noise_factor = p.targets[0].Phi, p.targets[0].noise_factor
    target = phi @ x_true + noise_factor @ normals[:n]
    sd2, st2 = sc.per_sensor("sigma_d2"), sc.per_sensor("sigma_theta2")
    rows, h_rows, r_diag, nu = [], [], [], []
    for i, (s, code) in enumerate(zip(moved, sc.sensor_models, strict=True)):
        dx, dy = target[0] - s[0], target[1] - s[1]
        ex, ey = x_pred[0] - s[0], x_pred[1] - s[1]
        e2 = ex * ex + ey * ey
        if code in (0, 1):  # range
            z = np.hypot(dx, dy) + np.sqrt(sd2[i]) * normals[n + 2 * i]
            rows.append(z)
            h_rows.append([ex / np.sqrt(e2), ey / np.sqrt(e2)])
            r_diag.append(sd2[i])
            nu.append(z - np.sqrt(e2))
        if code in (0, 2):  # bearing, wrapped after the noise
            z = np.arctan2(dy, dx) + np.sqrt(st2[i]) * normals[n + 2 * i + 1]
            z = (z + np.pi) % (2 * np.pi) - np.pi
            h_rows.append([-ey / e2, ex / e2])
            r_diag.append(st2[i])
            nu.append((z - np.arctan2(ey, ex) + np.pi) % (2 * np.pi) - np.pi)
    H = np.zeros((len(h_rows), n))
    H[:, :2] = h_rows
    S = H @ P_pred @ H.T + np.diag(r_diag)
    K = P_pred @ H.T @ np.linalg.inv(S)
    x_post, P_post = x_pred + K @ np.array(nu), P_pred - K @ S @ K.T
    np.testing.assert_allclose(world.get("sensors", 0), moved, rtol=0, atol=1e-12)
    np.testing.assert_allclose(world.get("x_true", 0), target, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(world.get("x_hat", 0), x_post, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(world.get("P", 0), P_post, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(world.get("x_pred", 0), phi @ x_post, rtol=1e-9, atol=1e-9)
    P_next = phi @ P_post @ phi.T + p.targets[0].Q
    np.testing.assert_allclose(world.get("P_pred", 0), P_next, rtol=1e-8, atol=1e-12)
    assert world.get("trace", 0) == pytest.approx(P_post[0, 0] + P_post[1, 1], rel=1e-9)
