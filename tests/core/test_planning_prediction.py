"""Which prediction a planner plans from (:mod:`activetrack.world.planning_prediction`) and
the IMM's mode predictions the planning problem carries (``Prediction.modes``), against
independent computations:

- at a reset every mode starts at the prior ``N(x0_hat, P0)``, so mode j's prediction is
  ``Phi_j x0_hat, Phi_j P0 Phi_j^T + Q_j`` and the mixture's moments those of
  ``sum_j c_j N(...)`` with ``c = initial Pi``: computed here by hand;
- with the identity as transition matrix the IMM's modes do not mix, so mode 0's filter is
  the EKF of mode 0's model on the same measurements: the single-model problem of the IMM
  world is the EKF world's problem (the default estimator, the compiled fused step) at
  every step of an episode;
- the modes survive indexing and stacking problems; bad values name the field.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack import IMMSpec
from activetrack.models.behaviour import coordinated_turn
from activetrack.world import World
from activetrack.world.planning_prediction import checked, chosen
from activetrack.world.prediction import ModePredictions, Prediction
from activetrack.world.presets import MANEUVERING
from activetrack.world.problem import PlanningProblem
from activetrack.world.scenarios import make_scenario


def _mixture_by_hand(weights, means, covs):
    """Return the mean and covariance of ``sum_j w_j N(m_j, C_j)`` by the definitions."""
    mean = sum(w * m for w, m in zip(weights, means, strict=True))
    cov = sum(
        w * (C + np.outer(m - mean, m - mean)) for w, m, C in zip(weights, means, covs, strict=True)
    )
    return mean, cov


def test_at_a_reset_each_mode_predicts_the_prior_with_its_own_model():
    sc = make_scenario("maneuvering")
    spec = IMMSpec.from_behaviour(MANEUVERING)
    w = World(sc, 1, estimator=spec)
    w.reset(seeds=[3])
    problem = w.planning_problem(0)
    x0, P0 = np.asarray(sc.x0_hat, float), np.asarray(sc.initial_cov, float)
    means = [m.Phi @ x0 for m in spec.models]
    covs = [m.Phi @ P0 @ m.Phi.T + m.Q for m in spec.models]
    c = np.array([sum(spec.initial[i] * spec.transition[i, j] for i in range(3)) for j in range(3)])
    modes = problem.prediction.modes
    np.testing.assert_allclose(modes.weights, c, rtol=1e-14)
    np.testing.assert_allclose(modes.means, means, rtol=1e-12, atol=1e-12)
    tol = 1e-12 * np.max(np.abs(covs))  # the zero entries: rounding of the scale's
    np.testing.assert_allclose(modes.covs, covs, rtol=1e-12, atol=tol)
    mean, cov = _mixture_by_hand(c, means, covs)
    np.testing.assert_allclose(problem.prediction.mean, mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(problem.prediction.cov, cov, rtol=1e-12, atol=tol)
    # The single-model problem: mode 0 (constant velocity) alone, the rest unchanged.
    single = chosen(problem, 0)
    np.testing.assert_allclose(single.target, means[0][:2], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(single.prior_cov, covs[0][:2, :2], rtol=1e-12, atol=tol)
    np.testing.assert_allclose(single.prediction.cov, covs[0], rtol=1e-12, atol=tol)
    assert single.prediction.modes is None
    for field in ("sensors", "r", "rho", "sigma_d2", "sigma_theta2"):
        np.testing.assert_array_equal(getattr(single, field), getattr(problem, field))
    # Not vacuous: the turning modes make the mixture's covariance the larger.
    assert np.trace(cov[:2, :2]) > np.trace(covs[0][:2, :2]) + 1e-6
    assert chosen(problem, "mixture") is problem


def test_without_mixing_the_single_model_problem_is_the_ekf_worlds_at_every_step():
    sc = make_scenario("maneuvering")
    cv = sc.target_models[0]  # the filter's own model: mode 0 is the EKF's model exactly
    turns = [coordinated_turn(w, 10.0, sc.dt) for w in (1.0, -1.0)]
    spec = IMMSpec([cv, *turns], np.eye(3))  # the identity: the modes never mix
    n, seeds = 3, [11, 12, 13]
    imm, ekf = World(sc, n, estimator=spec), World(sc, n)
    for w in (imm, ekf):
        w.reset(seeds=seeds)
    rng = np.random.default_rng(4)
    apart = 0.0
    for _ in range(40):
        mine, theirs = chosen(imm.planning_problem(), 0), ekf.planning_problem()
        np.testing.assert_allclose(
            mine.prediction.mean, theirs.prediction.mean, rtol=1e-12, atol=1e-12
        )
        np.testing.assert_allclose(mine.prediction.cov, theirs.prediction.cov, rtol=1e-12)
        np.testing.assert_allclose(mine.target, theirs.target, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(mine.prior_cov, theirs.prior_cov, rtol=1e-12)
        apart = max(apart, float(np.max(np.abs(imm.x_pred - ekf.x_pred))))
        # Small moves well away from the targets: no projection about either prediction.
        actions = rng.uniform(-0.3, 0.3, (n, sc.n_sensors, 2))
        for w in (imm, ekf):
            w.step_actions(actions)
            assert not np.any(w.get("projected"))
    assert apart > 1e-3  # the mixture is not mode 0's prediction


def test_the_modes_survive_indexing_and_stacking():
    w = World("maneuvering", 3, estimator=IMMSpec.from_behaviour(MANEUVERING))
    w.reset(seeds=[0, 1, 2])
    w.step_actions(np.full((3, w.n_sensors, 2), 0.5))
    batch = w.planning_problem()
    singles = [w.planning_problem(i) for i in range(3)]
    for i, single in enumerate(singles):
        for f in ("weights", "means", "covs"):
            np.testing.assert_array_equal(
                getattr(batch[i].prediction.modes, f), getattr(single.prediction.modes, f)
            )
            np.testing.assert_array_equal(
                getattr(single.prediction.modes, f), getattr(batch.prediction.modes, f)[i]
            )
    stacked = PlanningProblem.stack(singles)
    for f in ("weights", "means", "covs"):
        np.testing.assert_array_equal(
            getattr(stacked.prediction.modes, f), getattr(batch.prediction.modes, f)
        )
    np.testing.assert_array_equal(chosen(stacked, 2).target, chosen(batch, 2).target)
    with pytest.raises(ValueError, match=r"prediction\.modes"):
        PlanningProblem.stack([singles[0], World("maneuvering", 1).planning_problem(0)])


def _prediction(**changes):
    mean0, mean1 = np.array([0.0, 0.0, 1.0, 0.0]), np.array([0.1, 0.0, 1.0, 0.5])
    weights = np.array([0.7, 0.3])
    covs = np.stack([np.eye(4), 2.0 * np.eye(4)])
    mean, cov = _mixture_by_hand(weights, [mean0, mean1], covs)
    fields = {
        "weights": weights,
        "means": np.stack([mean0, mean1]),
        "covs": covs,
        "mean": mean,
        "cov": cov,
    }
    fields.update(changes)
    modes = ModePredictions(fields["weights"], fields["means"], fields["covs"])
    return Prediction(fields["mean"], fields["cov"], np.eye(4), np.eye(4), modes)


def test_a_prediction_with_modes_is_their_mixture():
    q = _prediction()
    assert q.modes.n_modes == 2 and q.modes.dim == 4
    with pytest.raises(ValueError, match=r"prediction\.mean must be the moments"):
        _prediction(mean=np.zeros(4))
    with pytest.raises(ValueError, match=r"prediction\.cov must be the moments"):
        _prediction(cov=np.eye(4))
    with pytest.raises(ValueError, match=r"prediction\.modes\.weights"):
        _prediction(weights=np.array([0.7, 0.4]))
    with pytest.raises(ValueError, match=r"prediction\.modes\.covs"):
        _prediction(covs=np.stack([np.eye(4), -np.eye(4)]))
    with pytest.raises(ValueError, match=r"prediction\.modes\.means"):
        _prediction(means=np.zeros((3, 4)))
    with pytest.raises(ValueError, match=r"prediction\.modes must be"):
        Prediction(q.mean, q.cov, np.eye(4), np.eye(4), (q.modes.weights,))
    with pytest.raises(ValueError, match=r"prediction\.modes .* must broadcast"):
        Prediction(
            q.mean,
            q.cov,
            np.eye(4),
            np.eye(4),
            ModePredictions(np.stack([q.modes.weights] * 2), q.modes.means, q.modes.covs),
        )


@pytest.mark.parametrize("bad", ["single", "Mixture", -1, 1.0, True, None, (0,)])
def test_bad_choices_name_the_field(bad):
    with pytest.raises(ValueError, match=r"prediction must be 'mixture' or a mode index"):
        checked(bad)


def test_a_mode_the_filter_does_not_have_names_the_field():
    imm = World("maneuvering", 1, estimator=IMMSpec.from_behaviour(MANEUVERING))
    imm.reset(seeds=[0])
    with pytest.raises(ValueError, match=r"prediction must be .* in \[0, 2\] .* got 3"):
        chosen(imm.planning_problem(0), 3)
    ekf = World("maneuvering", 1)
    ekf.reset(seeds=[0])
    problem = ekf.planning_problem(0)
    assert chosen(problem, 0).prediction is problem.prediction  # the EKF: its one mode
    with pytest.raises(ValueError, match=r"in \[0, 0\] \(the filter has 1 mode\), got 1"):
        chosen(problem, 1)
    by_hand = PlanningProblem(
        problem.prior_cov, problem.target, problem.sensors, 1.0, 2.0, 0.1, 0.01
    )
    with pytest.raises(ValueError, match=r"prediction=0 needs a problem that carries"):
        chosen(by_hand, 0)
    assert chosen(by_hand, "mixture") is by_hand


def test_two_targets_choose_each_targets_mode():
    sc = make_scenario("two_targets")
    spec = IMMSpec(
        [sc.target_models[0], coordinated_turn(1.0, 1.0, sc.dt)], [[0.9, 0.1], [0.1, 0.9]]
    )
    w = World(sc, 1, estimator=spec)
    w.reset(seeds=[0])
    w.step_actions(np.zeros((1, sc.n_sensors, 2)))
    problem = w.planning_problem(0)
    for j in (0, 1):
        single = chosen(problem, j)
        assert single.multi_target and len(single.prediction) == 2
        for k in range(2):
            modes = problem.prediction[k].modes
            np.testing.assert_array_equal(single.target[k], modes.means[j, :2])
            np.testing.assert_array_equal(single.prior_cov[k], modes.covs[j, :2, :2])
