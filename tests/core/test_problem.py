"""The planning problem, single and batched, against explicit per-copy computations."""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.models.objective import TRACE
from activetrack.world.problem import PlanningProblem, Prediction
from tests.core.helpers import random_spd

FIELDS = ("prior_cov", "target", "sensors", "r", "rho", "sigma_d2", "sigma_theta2")


def _random_batch(rng, shape, m):
    prior = np.stack([random_spd(rng, 2) for _ in range(int(np.prod(shape)))]).reshape(
        shape + (2, 2)
    )
    return dict(
        prior_cov=prior,
        target=rng.normal(0, 3, shape + (2,)),
        sensors=rng.normal(0, 5, shape + (m, 2)),
        r=rng.uniform(0.5, 2, m),  # shared by all copies: (M,)
        rho=rng.uniform(0.5, 2, shape + (m,)),
        sigma_d2=rng.uniform(0.5, 5, shape + (m,)),
        sigma_theta2=0.3,  # a scalar
    )


def _explicit_trace(prior_cov, target, pos, sd2, st2):
    """tr((P^-1 + sum_i H_i^T R_i^-1 H_i)^-1) with textbook Jacobians and np.linalg.inv."""
    info = np.linalg.inv(prior_cov)
    for p, a, b in zip(pos, sd2, st2, strict=True):
        d = p - target
        q = d @ d
        h = np.array([[d[0] / np.sqrt(q), d[1] / np.sqrt(q)], [-d[1] / q, d[0] / q]])
        info = info + h.T @ np.diag([1 / a, 1 / b]) @ h
    return np.trace(np.linalg.inv(info))


def test_batched_score_matches_a_loop_of_explicit_inverses():
    rng = np.random.default_rng(0)
    kw = _random_batch(rng, (4, 3), 3)
    prob = PlanningProblem(**kw)
    assert prob.batch_shape == (4, 3) and prob.n_sensors == 3
    assert prob.r.shape == (4, 3, 3) and prob.sigma_theta2.shape == (4, 3, 3)
    cand = rng.normal(0, 5, (5, 4, 3, 3, 2))  # 5 candidate configurations per copy
    got = prob.score(cand)
    assert got.shape == (5, 4, 3)
    for k in range(5):
        for i in range(4):
            for j in range(3):
                ref = _explicit_trace(
                    kw["prior_cov"][i, j],
                    kw["target"][i, j],
                    cand[k, i, j],
                    kw["sigma_d2"][i, j],
                    np.full(3, 0.3),
                )
                assert got[k, i, j] == pytest.approx(ref, rel=1e-10)
    np.testing.assert_array_equal(prob.trace(cand), got)


def test_single_problem_scores_candidate_batches_and_indexing_gives_the_single_problem():
    rng = np.random.default_rng(1)
    kw = _random_batch(rng, (6,), 2)
    batch = PlanningProblem(**kw)
    for i in (0, 3, 5):
        single = PlanningProblem(
            kw["prior_cov"][i],
            kw["target"][i],
            kw["sensors"][i],
            kw["r"],
            kw["rho"][i],
            kw["sigma_d2"][i],
            0.3,
        )
        sub = batch[i]
        assert sub.batch_shape == () and single.batch_shape == ()
        for f in FIELDS:
            np.testing.assert_array_equal(getattr(sub, f), getattr(single, f))
        cand = rng.normal(0, 4, (7, 2, 2))
        np.testing.assert_array_equal(sub.score(cand), single.score(cand))
        ref = [
            _explicit_trace(single.prior_cov, single.target, c, single.sigma_d2, [0.3, 0.3])
            for c in cand
        ]
        np.testing.assert_allclose(single.score(cand), ref, rtol=1e-10)
    assert batch[1:4].batch_shape == (3,)
    with pytest.raises(IndexError):
        batch[0, 1]
    with pytest.raises(TypeError, match="single"):
        batch[0][0]


def test_stack_and_violation_per_copy():
    rng = np.random.default_rng(2)
    singles = [PlanningProblem(**{**_random_batch(rng, (), 3)}) for _ in range(5)]
    batch = PlanningProblem.stack(singles)
    nxt = rng.normal(0, 5, (5, 3, 2))
    v = batch.violation(nxt)
    for b, p in enumerate(singles):
        step = np.linalg.norm(nxt[b] - p.sensors, axis=1) - p.r
        dist = p.rho - np.linalg.norm(nxt[b] - p.target, axis=1)
        np.testing.assert_allclose(v[b], np.maximum(np.maximum(step, dist), 0.0))
    np.testing.assert_allclose(batch.rel_sensors, [p.sensors - p.target for p in singles])
    np.testing.assert_allclose(batch.prior_info, np.linalg.inv(batch.prior_cov), rtol=1e-12)


def test_arrays_are_stored_read_only_and_the_default_objective_is_the_trace():
    p = PlanningProblem(np.eye(2), np.zeros(2), [[1.0, 0.0]], 1.0, 0.5, 1.0, 1.0)
    assert p.objective is TRACE
    for f in FIELDS + ("prior_info",):
        with pytest.raises(ValueError):
            getattr(p, f)[...] = 0.0


def _base():
    return dict(
        prior_cov=np.broadcast_to(np.eye(2), (3, 2, 2)).copy(),
        target=np.zeros((3, 2)),
        sensors=np.ones((3, 2, 2)),
        r=1.0,
        rho=0.5,
        sigma_d2=1.0,
        sigma_theta2=1.0,
    )


@pytest.mark.parametrize(
    "change, field",
    [
        ({"prior_cov": np.array([np.eye(2), np.eye(2), np.diag([1.0, -1.0])])}, "prior_cov"),
        ({"prior_cov": np.array([np.eye(2), [[1.0, 0.5], [0.0, 1.0]], np.eye(2)])}, "prior_cov"),
        ({"prior_cov": np.ones((3, 3, 3))}, "prior_cov"),
        ({"target": np.zeros((3, 3))}, "target"),
        ({"target": np.array([[0.0, 0.0], [np.nan, 0.0], [0.0, 0.0]])}, "target"),
        ({"sensors": np.ones((3, 2, 3))}, "sensors"),
        ({"r": np.array([[1.0, -1.0]] * 3)}, "r"),
        ({"rho": np.ones((3, 4))}, "rho"),
        ({"sigma_d2": np.zeros(2)}, "sigma_d2"),
        ({"sigma_theta2": np.ones((2, 2))}, "sigma_theta2"),
        ({"objective": "trace"}, "objective"),
    ],
)
def test_bad_fields_raise_value_errors_naming_them(change, field):
    with pytest.raises(ValueError, match=field):
        PlanningProblem(**{**_base(), **change})


# The prediction a problem may carry -------------------------------------------------
def _prediction_kw(rng, shape, n=4):
    """Return a random prediction's arrays: mean, SPD cov, Phi, a rank-deficient PSD Q."""
    cov = np.stack([random_spd(rng, n) for _ in range(int(np.prod(shape)))]).reshape(shape + (n, n))
    G = rng.normal(size=(n, 2))
    return dict(
        mean=rng.normal(0, 3, shape + (n,)), cov=cov, Phi=rng.normal(size=(n, n)), Q=G @ G.T
    )


def test_from_prediction_derives_the_position_blocks_and_indexing_stacking_keep_it():
    rng = np.random.default_rng(3)
    kw = _prediction_kw(rng, (5,))
    pred = Prediction(**kw)
    m = 3
    rest = dict(sensors=rng.normal(0, 5, (5, m, 2)), r=1.0, rho=0.5, sigma_d2=1.0, sigma_theta2=0.3)
    prob = PlanningProblem.from_prediction(pred, **rest)
    # The position blocks, read from the caller's arrays (not the stored ones).
    np.testing.assert_array_equal(prob.prior_cov, kw["cov"][:, :2, :2])
    np.testing.assert_array_equal(prob.target, kw["mean"][:, :2])
    # Given explicitly (equal to the blocks) they are accepted and give the same problem.
    same = PlanningProblem(kw["cov"][:, :2, :2], kw["mean"][:, :2], **rest, prediction=pred)
    for p in (prob, same):
        np.testing.assert_array_equal(p.prediction.mean, kw["mean"])
        np.testing.assert_array_equal(p.prediction.cov, kw["cov"])
        np.testing.assert_array_equal(p.prediction.Phi, kw["Phi"])
        np.testing.assert_array_equal(p.prediction.Q, kw["Q"])
    for i in (0, 3):
        sub = prob[i]
        np.testing.assert_array_equal(sub.prediction.mean, kw["mean"][i])
        np.testing.assert_array_equal(sub.prediction.cov, kw["cov"][i])
        np.testing.assert_array_equal(sub.prediction.Phi, kw["Phi"])
        assert sub.prediction.batch_shape == ()
    np.testing.assert_array_equal(prob[1:4].prediction.cov, kw["cov"][1:4])
    back = PlanningProblem.stack([prob[i] for i in range(5)])
    for name in ("mean", "cov", "Phi", "Q"):
        np.testing.assert_array_equal(getattr(back.prediction, name), kw[name])
    np.testing.assert_array_equal(back.prior_cov, kw["cov"][:, :2, :2])
    # Stored read-only.
    for name in ("mean", "cov", "Phi", "Q"):
        with pytest.raises(ValueError):
            getattr(prob.prediction, name)[...] = 0.0
    # A problem without a prediction has None, and keeps it through indexing and stacking.
    plain = PlanningProblem(**_random_batch(rng, (4,), 2))
    assert plain.prediction is None and plain[2].prediction is None
    assert PlanningProblem.stack([plain[0], plain[1]]).prediction is None


def test_a_single_prediction_broadcasts_over_the_batch():
    rng = np.random.default_rng(4)
    kw = _prediction_kw(rng, ())
    prob = PlanningProblem.from_prediction(
        Prediction(**kw), rng.normal(0, 5, (6, 2, 2)), 1.0, 0.5, 1.0, 0.3
    )
    assert prob.batch_shape == (6,) and prob.prediction.batch_shape == (6,)
    np.testing.assert_array_equal(prob.prediction.cov[4], kw["cov"])
    np.testing.assert_array_equal(prob.prior_cov[2], kw["cov"][:2, :2])


def test_with_state_checks_the_state_and_shares_the_model():
    rng = np.random.default_rng(5)
    kw = _prediction_kw(rng, ())
    pred = Prediction(**kw)
    other = _prediction_kw(rng, (3,))
    nxt = pred.with_state(other["mean"], other["cov"])
    assert nxt.Phi is pred.Phi and nxt.Q is pred.Q
    np.testing.assert_array_equal(nxt.cov, other["cov"])
    with pytest.raises(ValueError, match="prediction.cov"):
        pred.with_state(other["mean"], -other["cov"])
    with pytest.raises(ValueError, match="prediction.mean"):
        pred.with_state(np.zeros((3, 6)), np.broadcast_to(np.eye(6), (3, 6, 6)))


def test_mixed_or_different_predictions_do_not_stack():
    rng = np.random.default_rng(6)
    rest = dict(sensors=np.ones((1, 2)), r=1.0, rho=0.5, sigma_d2=1.0, sigma_theta2=0.3)
    a = PlanningProblem.from_prediction(Prediction(**_prediction_kw(rng, ())), **rest)
    b = PlanningProblem.from_prediction(Prediction(**_prediction_kw(rng, ())), **rest)
    plain = PlanningProblem(a.prior_cov, a.target, **rest)
    with pytest.raises(ValueError, match="prediction"):
        PlanningProblem.stack([a, plain])
    with pytest.raises(ValueError, match="prediction.Phi"):
        PlanningProblem.stack([a, b])


def _pred_base():
    n = 4
    cov = np.broadcast_to(np.eye(n) + 0.1, (3, n, n)).copy()
    return dict(mean=np.zeros((3, n)), cov=cov, Phi=np.eye(n), Q=np.diag([0.0, 0.0, 1.0, 1.0]))


@pytest.mark.parametrize(
    "change, field",
    [
        ({"mean": np.zeros((3, 1))}, "prediction.mean"),
        ({"mean": np.array([[0.0, np.inf, 0.0, 0.0]] * 3)}, "prediction.mean"),
        ({"cov": np.broadcast_to(np.eye(3), (3, 3, 3))}, "prediction.cov"),
        ({"cov": np.broadcast_to(-np.eye(4), (3, 4, 4))}, "prediction.cov"),
        ({"cov": np.broadcast_to(np.eye(4), (2, 4, 4))}, "prediction.mean.*prediction.cov"),
        ({"Phi": np.eye(3)}, "prediction.Phi"),
        ({"Phi": np.full((4, 4), np.nan)}, "prediction.Phi"),
        ({"Q": -np.eye(4)}, "prediction.Q"),
        ({"Q": np.triu(np.ones((4, 4)))}, "prediction.Q"),
        ({"Q": np.eye(5)}, "prediction.Q"),
    ],
)
def test_bad_predictions_raise_value_errors_naming_the_field(change, field):
    with pytest.raises(ValueError, match=field):
        Prediction(**{**_pred_base(), **change})


def test_a_prediction_that_disagrees_with_the_problem_raises_naming_the_field():
    pred = Prediction(**_pred_base())
    base = _base()  # prior_cov eye(2), target 0: not the blocks (eye + 0.1) of the prediction
    with pytest.raises(ValueError, match="prior_cov must equal prediction.cov"):
        PlanningProblem(**base, prediction=pred)
    base["prior_cov"] = pred.cov[:, :2, :2]
    base["target"] = np.ones((3, 2))
    with pytest.raises(ValueError, match="target must equal prediction.mean"):
        PlanningProblem(**base, prediction=pred)
    base["target"] = np.zeros((3, 2))
    assert PlanningProblem(**base, prediction=pred).prediction.batch_shape == (3,)
    with pytest.raises(ValueError, match="batch axes.*prediction"):
        PlanningProblem.from_prediction(pred, np.ones((2, 2, 2)), 1.0, 0.5, 1.0, 1.0)
    with pytest.raises(ValueError, match="prediction must be"):
        PlanningProblem(**base, prediction=pred.mean)


@pytest.mark.parametrize("copies", [1, 3])
def test_the_world_problem_carries_exactly_the_world_prediction(copies):
    from activetrack.world import World

    world = World("homogeneous", copies, n_steps=4)
    world.reset(seeds=list(range(copies)))
    rng = np.random.default_rng(7)
    while not world.truncated.all():
        for index in [None, *range(copies)]:
            pred = world.planning_problem(index).prediction
            np.testing.assert_array_equal(pred.mean, world.get("x_pred", index))
            np.testing.assert_array_equal(pred.cov, world.get("P_pred", index))
            np.testing.assert_array_equal(pred.Phi, world.params.Phi)
            np.testing.assert_array_equal(pred.Q, world.params.Q)
        problem = world.planning_problem()
        np.testing.assert_array_equal(problem.prior_cov, world.P_pred[:, :2, :2])
        np.testing.assert_array_equal(problem.target, world.x_pred[:, :2])
        world.step_actions(rng.uniform(-1, 1, (copies, world.n_sensors, 2)))
    # The problem's arrays are copies: stepping the world leaves an earlier problem alone.
    kept = problem.prediction.cov.copy()
    world.reset(seeds=[9] * copies)
    np.testing.assert_array_equal(problem.prediction.cov, kept)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"models": [0, 1]}, "models"),  # 2 codes for 3 sensors
        ({"models": [0, 1, 7]}, "models"),
        ({"models": ["range", "sonar", 0]}, "models"),
        ({"pose_cov": np.eye(2)[None].repeat(2, 0)}, "pose_cov"),  # 2 matrices, 3 sensors
        ({"pose_cov": -np.eye(2)[None].repeat(3, 0)}, "pose_cov"),
        ({"pose_cov": np.full((3, 2, 2), np.nan)}, "pose_cov"),
        ({"multi_target": 1}, "multi_target"),
        ({"multi_target": True}, "multi_target"),  # target (2,) has no targets axis
    ],
)
def test_beyond_paper_fields_are_validated_naming_them(kwargs, field):
    with pytest.raises(ValueError, match=field):
        PlanningProblem(np.eye(2), np.zeros(2), np.ones((3, 2)), 1.0, 2.0, 1.0, 0.1, **kwargs)


def test_multi_target_problem_takes_a_prediction_per_target_and_stacks():
    pred = Prediction(np.zeros(4), np.eye(4), np.eye(4), np.zeros((4, 4)))
    with pytest.raises(ValueError, match="prediction of a multi_target problem"):
        PlanningProblem(
            np.eye(2)[None], np.zeros((1, 2)), np.ones((3, 2)), 1.0, 2.0, 1.0, 0.1,
            prediction=pred, multi_target=True,
        )  # fmt: skip
    one = PlanningProblem(
        np.stack([np.eye(2), 2 * np.eye(2)]), np.array([[0.0, 0.0], [5.0, 0.0]]),
        np.ones((3, 2)), 1.0, 2.0, 1.0, 0.1, models=["range", 0, 2], multi_target=True,
    )  # fmt: skip
    both = PlanningProblem.stack([one, one])
    assert both.batch_shape == (2,) and both.n_targets == 2
    assert both.models.tolist() == [[1, 0, 2]] * 2
    np.testing.assert_array_equal(both[1].score(np.ones((3, 2))), one.score(np.ones((3, 2))))


def _two_predictions(rng, shape):
    """Return two targets' predictions of different state sizes (CV n=4, CA n=6)."""
    return Prediction(**_prediction_kw(rng, shape, 4)), Prediction(**_prediction_kw(rng, shape, 6))


def test_multi_target_predictions_give_the_blocks_and_survive_indexing_and_stacking():
    rng = np.random.default_rng(8)
    preds = _two_predictions(rng, (3,))
    rest = dict(sensors=rng.normal(0, 5, (3, 2, 2)), r=1.0, rho=0.5, sigma_d2=1.0,
                sigma_theta2=0.3, multi_target=True)  # fmt: skip
    prob = PlanningProblem(None, None, **rest, prediction=list(preds))
    assert isinstance(prob.prediction, tuple) and prob.predictions == prob.prediction
    for k, q in enumerate(preds):
        np.testing.assert_array_equal(prob.prior_cov[:, k], q.cov[:, :2, :2])
        np.testing.assert_array_equal(prob.target[:, k], q.mean[:, :2])
    # Given blocks equal to the predictions' are accepted; others name the field.
    same = PlanningProblem(prob.prior_cov, prob.target, **rest, prediction=preds)
    np.testing.assert_array_equal(same.predictions[1].cov, preds[1].cov)
    with pytest.raises(ValueError, match="target must equal prediction.mean"):
        PlanningProblem(prob.prior_cov, prob.target + 1.0, **rest, prediction=preds)
    with pytest.raises(ValueError, match=r"one Prediction per target \(2\), got 1"):
        PlanningProblem(prob.prior_cov, prob.target, **rest, prediction=preds[:1])
    with pytest.raises(ValueError, match="prediction of a multi_target problem"):
        PlanningProblem(None, None, **rest, prediction=(preds[0], "CV"))
    for i in range(3):
        sub = prob[i]
        for k, q in enumerate(preds):
            np.testing.assert_array_equal(sub.predictions[k].mean, q.mean[i])
            np.testing.assert_array_equal(sub.predictions[k].Phi, q.Phi)
    back = PlanningProblem.stack([prob[i] for i in range(3)])
    for k, q in enumerate(preds):
        np.testing.assert_array_equal(back.predictions[k].cov, q.cov)
    np.testing.assert_array_equal(back.target, prob.target)
    # A single-target problem's predictions are its one prediction.
    rest.pop("multi_target")
    one = PlanningProblem.from_prediction(preds[0], **rest)
    assert one.predictions == (one.prediction,)


def test_the_world_problem_carries_every_target_prediction():
    from activetrack.world import World

    world = World("two_targets", 2, n_steps=2)
    world.reset(seeds=[0, 1])
    for index in (None, 1):
        problem = world.planning_problem(index)
        assert len(problem.predictions) == world.n_targets == 2
        for k, q in enumerate(problem.predictions):
            np.testing.assert_array_equal(q.mean, world.get("x_pred", index, k))
            np.testing.assert_array_equal(q.cov, world.get("P_pred", index, k))
            np.testing.assert_array_equal(problem.target[..., k, :], q.mean[..., :2])
            np.testing.assert_array_equal(q.Phi, world.params.targets[k].Phi)
