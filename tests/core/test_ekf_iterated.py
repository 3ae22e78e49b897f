"""The iterated EKF (``ekf.update(..., iterations=n)``, ``Scenario.filter_iterations``).

References: the maximum a posteriori estimate found by scipy's BFGS on the negative log
posterior (Gaussian prior, range/bearing measurements with wrapped bearing residuals),
and the posterior covariance ``(P^-1 + H^T R^-1 H)^-1`` inverted with numpy at that
estimate (the iterated EKF's fixed point, Gauss-Newton on that density).
"""

import numpy as np
import pytest
from scipy import optimize

from activetrack.estimation import ekf
from activetrack.world import World
from activetrack.world.scenarios import make_scenario

# The EKF is compiled (activetrack.estimation._kernels): make test also runs these as plain Python.
pytestmark = pytest.mark.kernels

USES = {0: (1.0, 1.0), 1: (1.0, 0.0), 2: (0.0, 1.0)}  # range-and-bearing, range, bearing


def _h(pos, sensors, orient):
    rel = pos - sensors
    return np.hypot(rel[:, 0], rel[:, 1]), np.arctan2(rel[:, 1], rel[:, 0]) - orient


def _neg_log_post(x, x0, Pinv, z, sensors, wd, wt, orient):
    r, th = _h(x[:2], sensors, orient)
    e = x - x0
    dth = (z[:, 1] - th + np.pi) % (2 * np.pi) - np.pi
    return 0.5 * (e @ Pinv @ e + np.sum(wd * (z[:, 0] - r) ** 2) + np.sum(wt * dth**2))


def _jac_info(pos, sensors, wd, wt):
    rel = pos - sensors
    n2 = np.sum(rel * rel, 1)
    u = rel / np.sqrt(n2)[:, None]
    v = np.stack([-rel[:, 1], rel[:, 0]], 1) / n2[:, None]
    return np.einsum("i,ij,ik->jk", wd, u, u) + np.einsum("i,ij,ik->jk", wt, v, v)


@pytest.mark.parametrize("seed", range(20))
def test_iterated_update_reaches_the_map_estimate_and_its_covariance(seed):
    rng = np.random.default_rng(seed)
    m = 4
    models = rng.integers(0, 3, m)
    models[0] = 0  # one full fix, so that the posterior mode is well determined
    sd2, st2 = rng.uniform(0.5, 2.0, m), rng.uniform(0.005, 0.05, m)
    orient = rng.uniform(-0.3, 0.3, m)
    wd = np.array([USES[k][0] for k in models]) / sd2
    wt = np.array([USES[k][1] for k in models]) / st2
    truth = np.array([0.0, 0.0, -4.0, 3.0])
    A = rng.normal(size=(4, 4))
    P = A @ A.T + np.diag([20.0, 20.0, 10.0, 10.0])  # a long gap's prediction
    x0 = truth + np.linalg.cholesky(P) @ rng.normal(size=4)
    # Sensors 4 to 15 m away (Gauss-Newton's convergence slows where a sensor's
    # measurement curves strongly across the posterior, within a meter or two).
    ang, dist = rng.uniform(0, 2 * np.pi, m), rng.uniform(4.0, 15.0, m)
    sensors = truth[:2] + dist[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1)
    r, th = _h(truth[:2], sensors, orient)
    z = np.stack([r + rng.normal(size=m) * np.sqrt(sd2), th + rng.normal(size=m) * np.sqrt(st2)], 1)
    mask = np.ones(m, bool)
    mask[rng.integers(1, m)] = rng.random() < 0.5  # a missed detection now and then
    wd, wt = wd * mask, wt * mask
    weights = (np.array([USES[k][0] for k in models]) / sd2,
               np.array([USES[k][1] for k in models]) / st2)  # fmt: skip
    x, Pp = ekf.update(x0, P, z, sensors, sd2, st2, orient, mask, models=models.astype(np.int8),
                       weights=weights, iterations=50)  # fmt: skip
    Pinv = np.linalg.inv(P)
    best = optimize.minimize(
        _neg_log_post, x, args=(x0, Pinv, z, sensors, wd, wt, orient), method="BFGS",
        options={"gtol": 1e-12},
    )  # fmt: skip
    np.testing.assert_allclose(x, best.x, atol=1e-5)
    info = np.zeros((4, 4))
    info[:2, :2] = _jac_info(x[:2], sensors, wd, wt)
    np.testing.assert_allclose(Pp, np.linalg.inv(Pinv + info), rtol=1e-8, atol=1e-10)
    # The plain EKF (one linearization, at the prediction) is farther from the mode.
    x1, _ = ekf.update(x0, P, z, sensors, sd2, st2, orient, mask, models=models.astype(np.int8),
                       weights=weights)  # fmt: skip
    assert np.linalg.norm(x - best.x) <= np.linalg.norm(x1 - best.x) + 1e-9


@pytest.mark.parametrize(("B", "m", "pose"), [(5, 3, False), (3, 3, True), (4, 3, True)])
def test_one_iteration_is_the_ekf_and_a_batch_equals_its_rows(B, m, pose):
    # (B = M with a shared (M, 2, 2) pose covariance: the batch axis is not guessed from shapes.)
    rng = np.random.default_rng(3)
    P = np.stack([np.diag([9.0, 9.0, 4.0, 4.0])] * B)
    x0 = rng.normal(size=(B, 4)) * 3
    sensors = rng.uniform(-10, 10, (B, m, 2))
    z = np.stack([rng.uniform(3, 12, (B, m)), rng.uniform(-3, 3, (B, m))], -1)
    sd2, st2 = np.full(m, 1.0), np.full(m, 0.05)
    cov = np.diag([0.5, 0.2])[None] * np.arange(1, m + 1)[:, None, None] if pose else None
    plain = ekf.update(x0, P, z, sensors, sd2, st2, pose_cov=cov)
    one = ekf.update(x0, P, z, sensors, sd2, st2, pose_cov=cov, iterations=1)
    for a, b in zip(plain, one, strict=True):
        np.testing.assert_array_equal(a, b)
    xb, Pb = ekf.update(x0, P, z, sensors, sd2, st2, pose_cov=cov, iterations=20)
    for i in range(B):
        xi, Pi = ekf.update(x0[i], P[i], z[i], sensors[i], sd2, st2, pose_cov=cov, iterations=20)
        np.testing.assert_allclose(xb[i], xi, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(Pb[i], Pi, rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(Pb[i], Pb[i].T)
        assert np.all(np.linalg.eigvalsh(Pb[i]) > 0)


def test_filter_iterations_field():
    assert make_scenario("paper").filter_iterations == 1
    assert "filter_iterations" not in make_scenario("paper").to_dict()
    sc = make_scenario("paper", filter_iterations=5)
    assert sc.to_dict()["filter_iterations"] == 5 and not sc.is_paper_model
    for bad in (0, 101, 2.0, True, "5"):
        with pytest.raises(ValueError, match=r"filter_iterations must be an integer in \[1, 100\]"):
            make_scenario("paper", filter_iterations=bad)
    # The world's filter is the iterated one (the same draws, another estimate).
    w, plain = World("paper", filter_iterations=8), World("paper")
    for world in (w, plain):
        world.reset(seeds=[0])
        world.step_actions(np.zeros((3, 2)))
    assert not np.array_equal(w.get("x_hat"), plain.get("x_hat"))
    np.testing.assert_array_equal(w.get("x_true"), plain.get("x_true"))
