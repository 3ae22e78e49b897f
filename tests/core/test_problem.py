"""The planning problem, single and batched, against explicit per-copy computations."""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.objective import TRACE
from activetrack.problem import PlanningProblem
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
