"""Long runs at the extremes of the accepted scenario ranges: P stays symmetric positive
definite, every state and trace finite.

The loop uses the core kernels only (the initial conditions of :class:`activetrack.world.World`,
:func:`~activetrack.world.tracking.advance`, :func:`activetrack.models.motion.predict`); the sensors
move by random feasible displacements (within their reach ``r``, pushed out to ``rho``
from the predicted target), standing in for a planner. Positive definiteness is checked
independently with LAPACK's Cholesky factorization of every posterior and prediction.
"""

import itertools
import warnings

import numpy as np
import pytest

import activetrack as at
from activetrack.models import motion
from activetrack.world import World, scenarios, tracking


def random_feasible_move(sensors, x_pred, r, rho, rng):
    """Return sensors moved uniformly within their reach disk, then pushed out to rho."""
    u = rng.standard_normal(sensors.shape)
    u /= np.maximum(np.linalg.norm(u, axis=1, keepdims=True), 1e-300)
    moved = sensors + (r * np.sqrt(rng.random(len(r))))[:, None] * u
    off = moved - x_pred[:2]
    dist = np.linalg.norm(off, axis=1)
    inside = dist < rho
    if np.any(inside):
        unit = np.where(dist[:, None] > 0, off / np.where(dist > 0, dist, 1.0)[:, None], [1, 0])
        moved[inside] = x_pred[:2] + rho[inside, None] * unit[inside]
    return moved


def check_spd(name, P, k):
    """Assert ``P`` is finite, exactly symmetric and positive definite (Cholesky)."""
    assert np.all(np.isfinite(P)), f"{name} not finite at step {k}"
    if not np.array_equal(P, P.T):  # the same test, numpy's report only on a failure
        np.testing.assert_array_equal(P, P.T, err_msg=f"{name} not symmetric at step {k}")
    try:
        np.linalg.cholesky(P)
    except np.linalg.LinAlgError:
        pytest.fail(f"{name} not positive definite at step {k}: eig {np.linalg.eigvalsh(P)}")


def run_closed_loop(sc, steps, seed=0):
    """Run ``steps`` steps of the core loop on ``sc``; assert finite values and SPD P."""
    params = tracking.LoopParams.from_scenario(sc)
    rng = np.random.default_rng(seed)
    world = World(sc)
    world.reset(seeds=[rng])  # the initial conditions, drawn from rng (which continues below)
    x_true, x_hat, P, sensors = (
        world.x_true[0].copy(),
        world.x_hat[0].copy(),
        world.P[0].copy(),
        world.sensors[0].copy(),
    )
    check_spd("P0", P, 0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow or invalid-value warning either
        for k in range(steps):
            x_pred, P_pred = motion.predict(x_hat, P, params.Phi, params.Q)
            check_spd("P_pred", P_pred, k)
            sensors = random_feasible_move(sensors, x_pred, params.r, params.rho, rng)
            noise = rng.standard_normal(params.n_noise)
            x_true, z, x_hat, P = tracking.advance(params, x_true, x_pred, P_pred, sensors, noise)
            for name, v in [("x_true", x_true), ("z", z), ("x_hat", x_hat), ("sensors", sensors)]:
                assert np.all(np.isfinite(v)), f"{name} not finite at step {k}"
            check_spd("P", P, k)
            assert P[0, 0] + P[1, 1] > 0.0


def _corners():
    """Accepted scenarios at the corners of the ranges of q, dt, variances, vmax and rho."""
    out = []
    for q, dt, sd2, st2, fast, rho in itertools.product(
        [0.0, scenarios.Q_MAX],
        [scenarios.DT_RANGE[0], 0.1, scenarios.DT_RANGE[1]],
        scenarios.SIGMA_D2_RANGE,
        scenarios.SIGMA_THETA2_RANGE,
        [False, True],
        [0.0, 2.0],
    ):
        vmax = min(scenarios.SPEED_MAX, scenarios.LENGTH_MAX / dt) if fast else 0.0
        kw = dict(q=q, dt=dt, sigma_d2=sd2, sigma_theta2=st2, vmax=vmax, rho=rho)
        try:
            at.make_scenario("paper", **kw)
        except ValueError:
            continue  # beyond the coupled limit: rejected at construction (tested below)
        out.append(kw)
    return out


CORNERS = _corners()


def test_corner_grid_is_mostly_accepted():
    assert len(CORNERS) >= 48  # of 96: the rest exceed the documented coupled limit


@pytest.mark.slow
@pytest.mark.parametrize(
    "kw", CORNERS, ids=lambda kw: ",".join(f"{k}={v:g}" for k, v in kw.items())
)
def test_long_run_at_range_corners_keeps_p_spd(kw):
    run_closed_loop(at.make_scenario("paper", **kw), steps=1000)


@pytest.mark.slow
@pytest.mark.parametrize(
    "kw",
    [
        # largest q with the paper's team, sensors that cannot follow (the case)
        dict(q=scenarios.Q_MAX, vmax=0.0),
        dict(q=scenarios.Q_MAX, vmax=scenarios.SPEED_MAX / 1e3, rho=0.0),
        # constant acceleration model at the largest q
        dict(
            motion="ca",
            q=scenarios.Q_MAX,
            x0=(0, 0, -8, 6, 0, 0),
            x0_hat=(2, -2, 0, 0, 0, 0),
            P0=(4.0, 4.0, 100.0, 100.0, 10.0, 10.0),
        ),
        # extreme initial covariances (within the coupled limit) and far-away positions
        dict(P0=(1e8, 1e8, 1e16, 1e16), sigma_d2=1e8, q=scenarios.Q_MAX, dt=1e-3),
        dict(P0=(1e-8, 1e-8, 1e-8, 1e-8), sigma_d2=1e-8, q=0.0),
        dict(
            x0=(1e9, -1e9, 0, 0),
            x0_hat=(1e9, -1e9, 0, 0),
            sensor_center=(-1e9, 1e9),
            sensor_radius=1e9,
            vmax=1e9,
            dt=1.0,
            q=1e6,
        ),
        # a large team with identical sensors, and sensors starting on the estimate
        dict(n_sensors=200, sigma_d2=1.0, sigma_theta2=0.1),
        dict(sensor_center=(2.0, -2.0), sensor_radius=0.0, vmax=0.0, rho=0.0, q=0.0),
    ],
)
def test_long_run_at_other_extremes_keeps_p_spd(kw):
    run_closed_loop(at.make_scenario("paper", **kw), steps=1000)


def test_sensor_starting_on_the_target_gives_finite_values():
    """The issue's case (vmax = 0, start on the target): no information, never NaN."""
    sc = at.make_scenario(
        "paper", sensor_center=(2.0, -2.0), sensor_radius=0.0, vmax=0.0, rho=0.0, q=0.0
    )
    run_closed_loop(sc, steps=20)


@pytest.mark.parametrize(
    "kw, field",
    [
        (dict(q=1e12), "q"),
        (dict(q=scenarios.Q_MAX, sigma_d2=1e-8), "sigma_d2"),
        (dict(dt=1e4), "sigma_d2"),  # P0's velocity variance over one step of 1e4 s
        (dict(P0=(1e16, 1e16, 1.0, 1.0), sigma_d2=1e-8), "sigma_d2"),
    ],
)
def test_unrepresentable_scales_are_rejected_at_construction(kw, field):
    with pytest.raises(ValueError, match=field):
        at.make_scenario("paper", **kw)
