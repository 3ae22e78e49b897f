"""A new sensor model defined here, outside the library, by subclassing
``activetrack.SensorModel``, and run through the World, the PettingZoo parallel env, GSR
(its numerical steps) and the look-ahead planner with no change to the library.

``FadingRange`` measures the distance only, with a noise variance that grows with it:
``z = d + e``, ``e ~ N(0, s(d))``, ``s(d) = sigma_d2 (1 + d^2 / L^2)``. Its Fisher
information about the target position (a Gaussian whose mean and variance both depend on
it) is ``J = g g^T / s + q q^T / (2 s^2)`` with ``g = grad d = (p_T - p_S) / d`` and
``q = grad s = 2 sigma_d2 (p_T - p_S) / L^2``; the EKF uses the first term
(``H^T R^{-1} H``, the default), the planners the whole (the override below).

Every check is against an independent computation: the covariance of the score of the
log-likelihood over many noisy draws (Monte Carlo, with a band computed for it), the
textbook Kalman-gain update with the stacked Jacobian written out by hand, dense grids.
"""

from __future__ import annotations

import numpy as np
import pytest

import activetrack
from activetrack import SensorModel
from tests.core.helpers import textbook_h


class FadingRange(SensorModel):
    """Distance only, its noise variance ``sigma_d2 (1 + d^2 / length^2)``."""

    name = "fading_range"
    slots = (True, False)
    angular = (False, False)
    marker = "D"

    def __init__(self, length: float = 20.0) -> None:
        self.length = float(length)

    def function(self, target, sensor, orientation=0.0):
        delta = np.asarray(target, float) - np.asarray(sensor, float)
        out = np.zeros(delta.shape)
        out[..., 0] = np.hypot(delta[..., 0], delta[..., 1])
        return out

    def variance(self, rel, sigma_d2):
        return sigma_d2 * (1.0 + (rel[..., 0] ** 2 + rel[..., 1] ** 2) / self.length**2)

    def noise_covar(self, target, sensor, sigma_d2, sigma_theta2):
        rel = np.asarray(target, float) - np.asarray(sensor, float)
        s = self.variance(rel, np.asarray(sigma_d2, float))
        R = np.zeros(s.shape + (2, 2))
        R[..., 0, 0] = s
        return R

    def information(self, rel, sigma_d2, sigma_theta2, pose_cov=None, detect=None,
                    orientation=0.0):  # fmt: skip
        J = super().information(rel, sigma_d2, sigma_theta2, pose_cov, None, orientation)
        if pose_cov is None:  # the variance's own information (exact Fisher information)
            rel = np.asarray(rel, float)
            s = self.variance(rel, np.asarray(sigma_d2, float))
            q = -2.0 * np.asarray(sigma_d2, float)[..., None] * rel / self.length**2
            J = J + q[..., :, None] * q[..., None, :] / (2.0 * s**2)[..., None, None]
        if detect is not None:
            inside = rel[..., 0] ** 2 + rel[..., 1] ** 2 <= detect[1]
            f = np.where(inside, detect[0], 0.0)
            if len(detect) > 2:
                f = np.where(detect[2], f, 0.0)
            J = J * f[..., None, None]
        return J


# Longhand ------------------------------------------------------------------------------
def score_draws(target, sensor, sd2, length, n, rng):
    """Return ``n`` draws of the score ``d/dp_T log p(z | p_T)`` (n, 2) of one measurement,
    written out: ``(z - d)/s g + ((z - d)^2 / (2 s^2) - 1 / (2 s)) q``."""
    delta = target - sensor
    d = np.hypot(*delta)
    s = sd2 * (1.0 + d * d / length**2)
    g = delta / d
    q = 2.0 * sd2 * delta / length**2
    e = rng.normal(0.0, np.sqrt(s), n)  # z - d
    return (e / s)[:, None] * g + (e * e / (2 * s * s) - 1 / (2 * s))[:, None] * q


def info_longhand(model, target, sensors, sd2, st2):
    """Return the team's ``sum_i H_i^T R_i^{-1} H_i`` plus the fading sensors' variance
    terms: range-bearing rows from eq. (9) (``textbook_h``), the fading sensors' row and
    variance by hand. ``model`` per sensor: "rb" or a FadingRange."""
    Y = np.zeros((2, 2))
    for i, kind in enumerate(model):
        if kind == "rb":
            H = textbook_h(target, sensors[i : i + 1])
            Y += H.T @ np.diag([1 / sd2[i], 1 / st2[i]]) @ H
        else:
            delta = target - sensors[i]
            d = np.hypot(*delta)
            s = sd2[i] * (1 + d * d / kind.length**2)
            g, q = delta / d, 2 * sd2[i] * delta / kind.length**2
            Y += np.outer(g, g) / s + np.outer(q, q) / (2 * s * s)
    return Y


TEAM = ("range_bearing", FadingRange(), FadingRange())
KINDS = ("rb", FadingRange(), FadingRange())


def scenario(preset="paper", **kw):
    return activetrack.make_scenario(preset, sensor_model=TEAM, **kw)


# The model's methods -------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_information_matches_monte_carlo_score_covariance(seed):
    rng = np.random.default_rng(seed)
    model = FadingRange(length=rng.uniform(3.0, 8.0))
    target = rng.normal(0, 3, 2)
    sensor = target + rng.uniform(4, 10) * np.array([np.cos(a := rng.uniform(0, 6)), np.sin(a)])
    sd2 = rng.uniform(0.5, 3.0)
    J = model.information(sensor - target, sd2, 1.0)
    n = 400_000
    g = score_draws(target, sensor, sd2, model.length, n, rng)
    # Check u^T J u = E[(u^T g)^2] in several directions; the band is 5 standard errors of
    # that mean, from the draws' own spread (relative ~0.5%, far below a 10% error).
    for ang in np.linspace(0, np.pi, 7):
        u = np.array([np.cos(ang), np.sin(ang)])
        x = (g @ u) ** 2
        band = 5 * x.std() / np.sqrt(n)
        assert abs(u @ J @ u - x.mean()) <= band, ang
        assert band < 0.05 * (u @ J @ u) or u @ J @ u < 1e-3 * np.trace(J)
    # The variance term is not negligible here: omitting it fails the same test.
    H = model.jacobian(target, sensor)
    J0 = H.T @ H / model.variance(target - sensor, sd2)
    u = (target - sensor) / np.linalg.norm(target - sensor)
    x = (g @ u) ** 2
    assert abs(u @ J0 @ u - x.mean()) > 5 * x.std() / np.sqrt(n)


def test_default_jacobian_and_measure_against_closed_forms():
    rng = np.random.default_rng(4)
    model = FadingRange(6.0)
    t = rng.normal(0, 5, (50, 2))
    s = rng.normal(0, 5, (50, 2))
    H = model.jacobian(t, s)
    want = (t - s) / np.linalg.norm(t - s, axis=-1, keepdims=True)
    np.testing.assert_allclose(H[:, 0], want, rtol=1e-7, atol=1e-9)
    np.testing.assert_array_equal(H[:, 1], 0.0)
    # Measurements: mean d, variance s(d), slot 1 exactly 0 (Monte Carlo, 5 sigma band).
    n = 200_000
    t0, s0 = np.array([1.0, 2.0]), np.array([-3.0, 5.0])
    z = model.measure(t0, s0, 2.0, 0.1, rng.standard_normal((n, 2)))
    d, var = 5.0, 2.0 * (1 + 25 / 36)
    assert abs(z[:, 0].mean() - d) < 5 * np.sqrt(var / n)
    assert abs(z[:, 0].var() - var) < 5 * var * np.sqrt(2 / n)
    np.testing.assert_array_equal(z[:, 1], 0.0)


def test_ekf_with_the_new_model_equals_the_longhand_kalman_update():
    from activetrack.estimation import generic

    rng = np.random.default_rng(5)
    models = (activetrack.RangeBearing(), FadingRange(7.0), activetrack.BearingOnly(),
              FadingRange(4.0))  # fmt: skip
    for _ in range(10):
        target = rng.normal(0, 2, 2)
        sensors = target + rng.normal(0, 8, (4, 2))
        sd2, st2 = rng.uniform(0.5, 2, 4), rng.uniform(0.01, 0.1, 4)
        phi = rng.uniform(-1, 1, 4)
        x = np.concatenate([target + rng.normal(0, 0.5, 2), rng.normal(0, 1, 2)])
        A = rng.standard_normal((4, 4))
        P = A @ A.T + np.eye(4)
        z = generic.measure(models, target[None], sensors, sd2, st2, phi,
                            rng.standard_normal(8))[0]  # fmt: skip
        x_post, P_post = generic.update(models, x, P, z, sensors, sd2, st2, phi)
        # Longhand: stacked used rows, R block diagonal, K = P H^T S^-1.
        rows, Rs, nus = [], [], []
        for i, m in enumerate(models):
            dx, dy = x[0] - sensors[i, 0], x[1] - sensors[i, 1]
            d2 = dx * dx + dy * dy
            bearing = np.arctan2(dy, dx) - phi[i]
            if isinstance(m, FadingRange):
                rows.append([dx / np.sqrt(d2), dy / np.sqrt(d2), 0, 0])
                Rs.append(sd2[i] * (1 + d2 / m.length**2))
                nus.append(z[i, 0] - np.sqrt(d2))
            if isinstance(m, activetrack.RangeBearing):
                rows.append([dx / np.sqrt(d2), dy / np.sqrt(d2), 0, 0])
                Rs.append(sd2[i])
                nus.append(z[i, 0] - np.sqrt(d2))
            if isinstance(m, (activetrack.RangeBearing, activetrack.BearingOnly)):
                rows.append([-dy / d2, dx / d2, 0, 0])
                Rs.append(st2[i])
                nus.append((z[i, 1] - bearing + np.pi) % (2 * np.pi) - np.pi)
        H, R, nu = np.array(rows), np.diag(Rs), np.array(nus)
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        np.testing.assert_allclose(x_post, x + K @ nu, rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(P_post, P - K @ S @ K.T, rtol=1e-7, atol=1e-10)


def test_scenario_maps_names_and_models_once_and_records_them():
    sc = scenario()
    assert sc.sensor_model[0] == "range_bearing" and isinstance(sc.sensor_model[1], FadingRange)
    assert not sc.capabilities.builtin_sensors and not sc.capabilities.fused_step
    assert sc.to_dict()["sensor_model"][1] == {
        "name": "fading_range", "class": f"{__name__}.FadingRange"
    }  # fmt: skip
    np.testing.assert_array_equal(sc.sensor_models, [0, 1, 1])  # the slots' codes
    # Built-in instances are their names: the same scenario, the compiled paths.
    plain = activetrack.make_scenario("paper", sensor_model=("range_bearing", "range", "bearing"))
    objs = activetrack.make_scenario(
        "paper", sensor_model=(activetrack.RangeBearing(), activetrack.RangeOnly(), "bearing")
    )
    assert objs == plain and objs.capabilities.builtin_sensors
    assert activetrack.make_scenario("paper", sensor_model=activetrack.RangeBearing()) == (
        activetrack.make_scenario("paper")
    )

    class Shadow(FadingRange):
        name = "range"

    class NaNs(FadingRange):
        name = "nans"

        def noise_covar(self, target, sensor, sigma_d2, sigma_theta2):
            return super().noise_covar(target, sensor, sigma_d2, sigma_theta2) * np.nan

    class Raises(FadingRange):
        name = "raises"

        def function(self, target, sensor, orientation=0.0):
            raise ZeroDivisionError("bug")

    class Shape(FadingRange):
        name = "shape"

        def function(self, target, sensor, orientation=0.0):
            return super().function(target, sensor)[..., :1]

    class Built(activetrack.RangeOnly):  # a built-in's code: its overrides would not run
        def noise_covar(self, target, sensor, sigma_d2, sigma_theta2):
            return 2 * super().noise_covar(target, sensor, sigma_d2, sigma_theta2)

    for bad in (FadingRange, Shadow(), "fading_range", 3, NaNs(), Raises(), Shape(), Built()):
        with pytest.raises(ValueError, match="sensor_model"):
            activetrack.make_scenario("paper", sensor_model=bad)


# (a) the World -------------------------------------------------------------------------
def test_world_runs_the_new_model_and_its_filter_is_consistent():
    """Mean position NEES over many copies within its band about 2 (2 dof), in a scenario
    where the EKF's linearization is good (small process noise and prior)."""
    N, T = 2000, 12
    sc = scenario(q=0.1, P0=(1.0, 1.0, 1.0, 1.0), target_init="gaussian")
    world = activetrack.world.World(sc, N)
    world.reset(seeds=list(range(N)))
    rng = np.random.default_rng(0)
    nees = []
    for _ in range(T):
        moves = rng.uniform(-1, 1, (N, 3, 2)) * world.scenario.r[None, :, None]
        world.step(world.get("sensors") + moves)
        x, xh, P = world.get("x_true"), world.get("x_hat"), world.get("P")
        e = x[:, :2] - xh[:, :2]
        nees.append(np.einsum("bi,bij,bj->b", e, np.linalg.inv(P[:, :2, :2]), e))
        assert np.all(np.isfinite(P)) and np.all(np.linalg.eigvalsh(P) > 0)
    # Copies are independent (steps are not): the band is 4 standard errors of the mean
    # over copies of each copy's mean NEES, from their own spread.
    per_copy = np.array(nees[2:]).mean(0)
    band = 4 * per_copy.std() / np.sqrt(N)
    assert abs(per_copy.mean() - 2.0) <= band, (per_copy.mean(), band)
    assert band < 0.2  # a 10% error in the NEES would show


@pytest.mark.parametrize("preset", ["paper", "two_targets", "uncertain_poses", "urban"])
def test_world_generic_path_equals_the_compiled_range_model_in_the_limit(preset):
    """With an unbounded length ``FadingRange`` is range-only: the generic NumPy path (the
    model's measure, noise and update; with K targets, uncertain poses, limited sensing,
    occluders, the iterated EKF) and the compiled kernels of the built-in give the same
    episodes up to rounding (the same normals)."""
    N = 20
    m = activetrack.make_scenario(preset).n_sensors
    far = activetrack.make_scenario(
        preset, sensor_model=("range_bearing",) + (FadingRange(1e9),) * (m - 1)
    )
    ref = activetrack.make_scenario(preset, sensor_model=("range_bearing",) + ("range",) * (m - 1))
    w1, w2 = activetrack.world.World(far, N), activetrack.world.World(ref, N)
    assert not far.capabilities.builtin_sensors and ref.capabilities.builtin_sensors
    w1.reset(seeds=list(range(N)))
    w2.reset(seeds=list(range(N)))
    rng = np.random.default_rng(2)
    for _ in range(10):
        target = w2.get("sensors") + rng.uniform(-1, 1, (N, m, 2)) * ref.r[None, :, None]
        r1, r2 = w1.step(target), w2.step(target)
        for k in range(ref.n_targets):
            np.testing.assert_allclose(w1.get("P", target=k), w2.get("P", target=k),
                                       rtol=1e-6, atol=1e-9)  # fmt: skip
            np.testing.assert_allclose(w1.get("x_hat", target=k), w2.get("x_hat", target=k),
                                       rtol=1e-6, atol=1e-8)  # fmt: skip
        np.testing.assert_allclose(r1.reward, r2.reward, rtol=1e-6)
        np.testing.assert_allclose(w1.observe(), w2.observe(), rtol=1e-4, atol=1e-5)
        # The planners' score of the same positions, the model's information against the
        # built-in's closed form.
        p1, p2 = w1.planning_problem(), w2.planning_problem()
        np.testing.assert_allclose(p1.score(target), p2.score(target), rtol=1e-6)


def test_world_single_copy_steps_like_the_batch():
    one = activetrack.world.World(scenario(), 1)
    two = activetrack.world.World(scenario(), 2)
    one.reset(seeds=[3])
    two.reset(seeds=[3, 4])
    rng = np.random.default_rng(1)
    for _ in range(5):
        target = two.get("sensors") + rng.uniform(-1, 1, (2, 3, 2))
        one.step(target[0])
        two.step(target)
        np.testing.assert_allclose(one.get("P", 0), two.get("P", 0), rtol=1e-12)
        np.testing.assert_allclose(one.get("x_hat", 0), two.get("x_hat", 0), rtol=1e-12)


# (b) the PettingZoo parallel env --------------------------------------------------------
def test_parallel_env_passes_the_api_test_with_the_new_model():
    from pettingzoo.test import parallel_api_test

    from activetrack.envs.tracking_env import parallel_env

    parallel_api_test(parallel_env(scenario()), num_cycles=40)


# (c) GSR through the numerical solver ----------------------------------------------------
def _problem(seed, steps=4):
    from activetrack.baselines.gsr import GSR

    world = activetrack.world.World(scenario(), 1)
    world.reset(seeds=[seed])
    for _ in range(steps):
        world.step(GSR().plan(world.planning_problem(0)))
    return world.planning_problem(0)


def score_longhand(problem, positions):
    sd2 = np.broadcast_to(problem.sigma_d2, (3,))
    st2 = np.broadcast_to(problem.sigma_theta2, (3,))
    Y = np.linalg.inv(problem.prior_cov) + info_longhand(KINDS, problem.target, positions, sd2,
                                                         st2)  # fmt: skip
    return float(np.trace(np.linalg.inv(Y)))


def _feasible_grid(problem, i, n=301):
    c, r, rho, t = problem.sensors[i], problem.r[i], problem.rho[i], problem.target
    g = np.linspace(-1.0, 1.0, n)
    disk = c + r * np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    ang = np.linspace(-np.pi, np.pi, 4001)
    ring = np.stack([np.cos(ang), np.sin(ang)], -1)
    pts = np.concatenate([disk, c + r * ring, t + rho * ring])
    keep = (np.linalg.norm(pts - c, axis=1) <= r * (1 + 1e-12)) & (
        np.linalg.norm(pts - t, axis=1) >= rho * (1 - 1e-12)
    )
    return pts[keep]


@pytest.mark.parametrize("seed", [0, 1])
def test_gsr_plans_the_new_model_coordinatewise_optimally(seed):
    from activetrack.baselines.gsr import GSR

    problem = _problem(seed)
    assert not problem.is_paper and problem.sensor_objects is not None
    res = GSR(tol=1e-12).plan_with_info(problem)
    assert np.max(problem.violation(res.positions)) <= 1e-9
    assert res.value == pytest.approx(score_longhand(problem, res.positions), rel=1e-6)
    assert res.value <= score_longhand(problem, problem.sensors) * (1 + 1e-9)
    for i in range(problem.n_sensors):
        pts = _feasible_grid(problem, i)
        values = []
        for p in pts[:: max(1, len(pts) // 3000)]:
            trial = res.positions.copy()
            trial[i] = p
            values.append(score_longhand(problem, trial))
        assert min(values) >= res.value * (1 - 1e-6), i


def test_gsr_plans_a_batch_with_the_new_model_like_each_copy():
    from activetrack.baselines.gsr import GSR

    world = activetrack.world.World(scenario(), 3)
    world.reset(seeds=[7, 8, 9])
    problem = world.planning_problem()
    out = GSR().plan(problem)
    for b in range(3):
        single = problem[b]
        assert single.sensor_objects == problem.sensor_objects
        assert np.max(single.violation(out[b])) <= 1e-9
        assert float(single.score(out[b])) == pytest.approx(
            score_longhand(single, out[b]), rel=1e-6
        )
        assert float(single.score(out[b])) <= score_longhand(single, single.sensors)


def test_gbes_plans_the_new_model_as_its_exhaustive_grid_search():
    from activetrack.baselines.gbes import GBES

    problem = _problem(3, steps=3)
    best = GBES(spacing=0.25).search(problem)
    every = GBES(spacing=0.25, prune=False).search(problem)
    assert best.value == pytest.approx(every.value, rel=1e-12)
    assert best.value == pytest.approx(score_longhand(problem, best.positions), rel=1e-6)


# (d) the look-ahead planner --------------------------------------------------------------
def test_lookahead_scores_its_plan_with_the_new_model():
    from activetrack.baselines.lookahead import Lookahead

    problem = _problem(4, steps=3)
    la = Lookahead(horizon=3, headings=8, tail=0, discount=0.9)
    res = la.plan_prediction(problem)
    assert np.max(problem.violation(res.positions)) <= 1e-9
    assert res.score <= res.gsr_score
    pred = problem.prediction
    F, Q = pred.Phi, pred.Q
    sd2 = np.broadcast_to(problem.sigma_d2, (3,))
    st2 = np.broadcast_to(problem.sigma_theta2, (3,))
    P, x = np.array(pred.cov), np.array(pred.mean)
    E = np.eye(len(x))[:2]
    total = 0.0
    for h in range(la.horizon):
        Y = info_longhand(KINDS, x[:2], res.plan[:, h], sd2, st2)
        post = np.linalg.inv(np.linalg.inv(P) + E.T @ Y @ E)
        total += 0.9**h * float(np.trace(post[:2, :2]))
        P = F @ post @ F.T + Q
        x = F @ x
    assert float(res.score) == pytest.approx(total, rel=1e-6)


# (e) the rendering -------------------------------------------------------------------------
def test_rendering_draws_each_sensor_with_its_models_marker():
    pytest.importorskip("matplotlib")
    from activetrack.envs.tracking_env import parallel_env

    env = parallel_env(scenario(), render_mode="rgb_array", n_steps=3)
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[-1] == 3
    r = env._recorder._renderer
    assert [h.get_marker() for h in r._art["heads"]] == ["o", "D", "D"]
    legend = r._ax.get_legend()
    entries = {
        t.get_text(): h.get_marker()
        for t, h in zip(legend.get_texts(), legend.legend_handles, strict=True)
        if hasattr(h, "get_marker")
    }
    assert entries["range & bearing"] == "o" and entries["fading_range"] == "D"
