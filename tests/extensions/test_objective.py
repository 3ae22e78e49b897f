"""A new objective defined here, outside the library, by subclassing ``activetrack.Objective``,
and run through the World, the PettingZoo parallel env, GSR (its numerical steps), GBES and
the look-ahead planner with no change to the library.

``EOptimal`` is E-optimality: the largest eigenvalue of each target's posterior position
covariance ``P = Y^{-1}``, summed over the targets. For ``Y = [[a, b], [b, c]]`` the
eigenvalues are ``(a + c) / 2 +- sqrt(((a - c) / 2)^2 + b^2)``, and the largest eigenvalue
of ``Y^{-1}`` is ``1 / lambda_min(Y) = lambda_max(Y) / det Y`` (the product of the two is
``det Y``; this form has no cancellation). It is convex in ``Y``: ``lambda_min`` is
concave, and ``1 / x`` convex and decreasing on ``x > 0``.

Every check is against a longhand computation: ``np.linalg.eigvalsh`` of explicitly
inverted matrices, the Jacobian of eq. (9) written out row by row, dense grids.
"""

from __future__ import annotations

import numpy as np
import pytest

import activetrack
from activetrack import Objective
from tests.core.helpers import textbook_h


class EOptimal(Objective):
    """The largest eigenvalue of each target's posterior position covariance, summed."""

    name = "e_optimal"
    convex = True
    nonnegative = True

    def of_entries(self, a, b, c):
        return (0.5 * (a + c) + np.hypot(0.5 * (a - c), b)) / (a * c - b * b)


# Longhand ------------------------------------------------------------------------------
def largest_eig(P):
    """Return the largest eigenvalue of each position block P[..., :2, :2] (eigvalsh)."""
    return np.linalg.eigvalsh(np.asarray(P)[..., :2, :2])[..., -1]


def info_longhand(target, sensors, sd2, st2):
    """Return ``sum_i H_i^T R_i^{-1} H_i`` with H from eq. (9), row by row."""
    H = textbook_h(target, sensors)
    w = np.ravel(np.column_stack([1.0 / np.asarray(sd2), 1.0 / np.asarray(st2)]))
    return H.T @ (w[:, None] * H)


def score_longhand(problem, positions):
    """Return the E-optimal value of a single one-target range-bearing problem at absolute
    ``positions`` (M, 2): the largest eigenvalue of ``(P11^{-1} + sum info)^{-1}``."""
    M = problem.n_sensors
    sd2 = np.broadcast_to(problem.sigma_d2, (M,))
    st2 = np.broadcast_to(problem.sigma_theta2, (M,))
    Y = np.linalg.inv(problem.prior_cov) + info_longhand(problem.target, positions, sd2, st2)
    return float(largest_eig(np.linalg.inv(Y)))


def world_score_longhand(world, index=0):
    """Return the sum over targets of the largest eigenvalue of the world's posterior P."""
    return sum(float(largest_eig(world.get("P", index, target=k))) for k in range(world.n_targets))


# The base's defaults -----------------------------------------------------------------
def test_e_optimal_derived_methods_against_eigenvalues():
    rng = np.random.default_rng(0)
    A = rng.normal(size=(50, 2, 2))
    Y = A @ A.transpose(0, 2, 1) + 0.1 * np.eye(2)
    obj = EOptimal()
    want = largest_eig(np.linalg.inv(Y))
    np.testing.assert_allclose(obj.of_information(Y), want, rtol=1e-12)
    # of_covariance's default (of_entries of P11^{-1}), on whole 4x4 state covariances.
    B = rng.normal(size=(50, 4, 4))
    P = B @ B.transpose(0, 2, 1) + 0.1 * np.eye(4)
    np.testing.assert_allclose(obj.of_covariance(P), largest_eig(P), rtol=1e-10)
    np.testing.assert_allclose(
        obj.of_covariances(P.reshape(25, 2, 4, 4)), largest_eig(P).reshape(25, 2).sum(-1),
        rtol=1e-10,
    )  # fmt: skip
    # The default tangent (central differences) against the closed-form derivative of
    # lambda_max(Y^{-1}) = 1 / lambda_min(Y): d lambda_min = u^T dY u (u its unit
    # eigenvector), so d phi / dY = -u u^T / lambda_min^2.
    lam, vec = np.linalg.eigh(Y)
    u = vec[..., :, 0]
    G = -u[..., :, None] * u[..., None, :] / lam[..., 0, None, None] ** 2
    np.testing.assert_allclose(obj.gradient(Y), G, rtol=1e-7, atol=1e-9 * np.abs(G).max())
    assert obj.name == "e_optimal" and repr(obj) == "EOptimal()"


# (a) the World -------------------------------------------------------------------------
@pytest.mark.parametrize("preset", ["paper", "two_targets"])
def test_world_scores_and_rewards_with_the_new_objective(preset):
    world = activetrack.world.World(preset, 2, objective=EOptimal())
    plain = activetrack.world.World(preset, 2)  # the same episodes under the trace
    assert isinstance(world.scenario.objective, EOptimal)
    world.reset(seeds=[1, 2])
    plain.reset(seeds=[1, 2])
    rng = np.random.default_rng(3)
    scale = world.scenario.reward_scale
    for _ in range(8):
        for b in range(2):
            assert world.score[b] == pytest.approx(world_score_longhand(world, b), rel=1e-10)
        moves = rng.uniform(-1, 1, plain.get("sensors").shape) * world.scenario.r[None, :, None]
        target = plain.get("sensors") + moves
        res = world.step(target)
        plain.step(target)
        want = np.array([world_score_longhand(world, b) for b in range(2)])
        np.testing.assert_allclose(res.reward, -scale * want, rtol=1e-10)
        # The objective scores the filter; it does not change it.
        for k in range(world.n_targets):
            np.testing.assert_array_equal(world.get("P", target=k), plain.get("P", target=k))


def test_scenario_records_and_validates_the_new_objective():
    sc = activetrack.make_scenario("paper", objective=EOptimal())
    assert sc.to_dict()["objective"] == {
        "name": "e_optimal",
        "class": f"{__name__}.EOptimal",
    }
    # A built-in's instance is its name: the scenario and its record as before.
    assert activetrack.make_scenario("paper", objective=activetrack.LOGDET).objective == "logdet"
    assert activetrack.make_scenario("paper", objective=activetrack.TRACE) == (
        activetrack.make_scenario("paper")
    )

    class Shadow(EOptimal):
        name = "trace"

    class NaNs(EOptimal):
        name = "nans"

        def of_entries(self, a, b, c):
            return np.sqrt(a - c)  # NaN where c > a

    class Scalar(EOptimal):
        name = "scalar"

        def combine(self, values, axis=-1):
            return np.sum(values)  # over every axis: not one value per configuration

    class Raises(EOptimal):
        name = "raises"

        def of_entries(self, a, b, c):
            raise ZeroDivisionError("bug")

    for bad in (EOptimal, Shadow(), "e_optimal", NaNs(), Scalar(), Raises()):
        with pytest.raises(ValueError, match="objective"):
            activetrack.make_scenario("paper", objective=bad)


# (b) the PettingZoo parallel env --------------------------------------------------------
def test_parallel_env_passes_the_api_test_and_rewards_the_new_objective():
    from pettingzoo.test import parallel_api_test

    from activetrack.envs.tracking_env import parallel_env

    parallel_api_test(parallel_env("paper", objective=EOptimal()), num_cycles=60)
    env = parallel_env("two_targets", objective=EOptimal())
    env.reset(seed=4)
    rng = np.random.default_rng(5)
    scale = env.scenario.reward_scale
    for _ in range(10):
        actions = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.agents}
        _, rewards, *_ = env.step(actions)
        want = -scale * world_score_longhand(env.world)
        for a in actions:
            assert rewards[a] == pytest.approx(want, rel=1e-10)


# (c) GSR through the numerical solver, and GBES ----------------------------------------
def _problem(seed, steps=5):
    """Return a paper world's single planning problem with the new objective, after a few
    GSR-planned steps (a prior that is no longer round)."""
    from activetrack.baselines.gsr import GSR

    world = activetrack.world.World("paper", 1, objective=EOptimal())
    world.reset(seeds=[seed])
    for _ in range(steps):
        world.step(GSR().plan(world.planning_problem(0)))
    return world.planning_problem(0)


def _feasible_grid(problem, i, n=401):
    """Return a dense sampling (points, 2) of sensor i's feasible set: the reach disk
    ``|p - c_i| <= r_i`` minus the ``rho_i`` disk about the predicted target, boundaries
    included."""
    c, r, rho, t = problem.sensors[i], problem.r[i], problem.rho[i], problem.target
    g = np.linspace(-1.0, 1.0, n)
    disk = c + r * np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    ang = np.linspace(-np.pi, np.pi, 20_001)
    ring = np.stack([np.cos(ang), np.sin(ang)], -1)
    pts = np.concatenate([disk, c + r * ring, t + rho * ring])
    keep = (np.linalg.norm(pts - c, axis=1) <= r * (1 + 1e-12)) & (
        np.linalg.norm(pts - t, axis=1) >= rho * (1 - 1e-12)
    )
    return pts[keep]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gsr_plans_the_new_objective_coordinatewise_optimally(seed):
    from activetrack.baselines.gsr import GSR

    problem = _problem(seed)
    assert not problem.is_paper  # not the trace: GSR's numerical single-sensor steps
    res = GSR(tol=1e-12).plan_with_info(problem)
    assert np.max(problem.violation(res.positions)) <= 1e-9
    assert res.value == pytest.approx(score_longhand(problem, res.positions), rel=1e-10)
    assert res.value <= score_longhand(problem, problem.sensors) * (1 + 1e-12)
    # Gauss-Seidel's fixed point: no sensor alone has a better feasible point.
    for i in range(problem.n_sensors):
        pts = _feasible_grid(problem, i)
        values = []
        for p in pts[:: max(1, len(pts) // 4000)]:
            trial = res.positions.copy()
            trial[i] = p
            values.append(score_longhand(problem, trial))
        assert min(values) >= res.value * (1 - 1e-7), i


def test_gsr_plans_a_batch_with_the_new_objective_like_each_copy():
    from activetrack.baselines.gsr import GSR

    world = activetrack.world.World("paper", 3, objective=EOptimal())
    world.reset(seeds=[7, 8, 9])
    problem = world.planning_problem()
    out = GSR().plan(problem)
    for b in range(3):
        single = problem[b]
        assert np.max(single.violation(out[b])) <= 1e-9
        assert float(single.score(out[b])) == pytest.approx(
            score_longhand(single, out[b]), rel=1e-10
        )


def test_gbes_plans_the_new_objective_as_its_exhaustive_grid_search():
    from activetrack.baselines.gbes import GBES

    problem = _problem(3, steps=3)
    best = GBES(spacing=0.25).search(problem)
    every = GBES(spacing=0.25, prune=False).search(problem)
    assert best.value == pytest.approx(every.value, rel=1e-12)
    assert best.value == pytest.approx(score_longhand(problem, best.positions), rel=1e-10)

    class NotConvex(EOptimal):
        name = "not_convex"
        convex = False

    q = activetrack.PlanningProblem(
        problem.prior_cov, problem.target, problem.sensors, problem.r, problem.rho,
        problem.sigma_d2, problem.sigma_theta2, objective=NotConvex(),
    )  # fmt: skip
    with pytest.raises(ValueError, match="not_convex.*convex"):
        GBES(spacing=0.25).search(q)


# (d) the look-ahead planner --------------------------------------------------------------
def test_lookahead_scores_its_plan_with_the_new_objective():
    from activetrack.baselines.lookahead import Lookahead

    problem = _problem(4, steps=3)
    la = Lookahead(horizon=3, headings=8, tail=2, tail_weight=1.5, discount=0.9)
    res = la.plan_prediction(problem)
    assert np.max(problem.violation(res.positions)) <= 1e-9
    assert res.score <= res.gsr_score
    # The plan's score in the deterministic model, longhand: the information of each step's
    # positions about that step's predicted mean, the last step's held for the tail.
    pred = problem.prediction
    F, Q = pred.Phi, pred.Q
    M, H = problem.n_sensors, la.horizon
    sd2 = np.broadcast_to(problem.sigma_d2, (M,))
    st2 = np.broadcast_to(problem.sigma_theta2, (M,))
    P, x = np.array(pred.cov), np.array(pred.mean)
    means = []
    for _ in range(H):
        means.append(x[:2].copy())
        x = F @ x
    E = np.zeros((2, len(x)))
    E[0, 0] = E[1, 1] = 1.0
    w = [0.9**h for h in range(H)] + [1.5 * 0.9 ** (H - 1)] * 2
    total = 0.0
    for h, wh in enumerate(w):
        j = min(h, H - 1)
        Y = info_longhand(means[j], res.plan[:, j], sd2, st2)
        post = np.linalg.inv(np.linalg.inv(P) + E.T @ Y @ E)
        total += wh * float(largest_eig(post))
        P = F @ post @ F.T + Q
    assert float(res.score) == pytest.approx(total, rel=1e-9)
