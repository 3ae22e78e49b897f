"""The objective of eq. (12)/(17): against explicit matrix inverses, Lemma 2, validation."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import activetrack as at
from activetrack.linalg2 import rotation
from activetrack.models.objective import TRACE
from tests.core.helpers import random_spd, textbook_h


def explicit_posterior(prior_cov, rel, sd2, st2):
    """eq. (12) written out: inverse of prior information plus H_e^T R^{-1} H_e."""
    He = textbook_h(np.zeros(2), rel)  # target at the origin, sensors at rel
    R = np.diag(np.ravel(np.column_stack([sd2, st2])))
    return np.linalg.inv(np.linalg.inv(prior_cov) + He.T @ np.linalg.inv(R) @ He)


@pytest.mark.parametrize("seed", range(20))
def test_posterior_matches_explicit_inverse(seed):
    rng = np.random.default_rng(seed)
    m = 1 + seed % 6
    prior = random_spd(rng, 2, scale=rng.uniform(0.1, 10))
    rel = rng.uniform(-20, 20, (m, 2))
    sd2, st2 = rng.uniform(1e-3, 10, m), rng.uniform(1e-3, 10, m)
    ref = explicit_posterior(prior, rel, sd2, st2)
    np.testing.assert_allclose(
        at.posterior_position_covariance(prior, rel, sd2, st2), ref, rtol=1e-10
    )
    np.testing.assert_allclose(at.posterior_trace(prior, rel, sd2, st2), np.trace(ref), rtol=1e-10)


def test_batched_over_candidates():
    rng = np.random.default_rng(1)
    prior = random_spd(rng, 2)
    rel = rng.uniform(-5, 5, (7, 4, 3, 2))
    sd2, st2 = np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.2, 0.3])
    out = at.posterior_trace(prior, rel, sd2, st2)
    assert out.shape == (7, 4)
    for idx in np.ndindex(7, 4):
        assert out[idx] == pytest.approx(
            np.trace(explicit_posterior(prior, rel[idx], sd2, st2)), rel=1e-10
        )


@settings(max_examples=100, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_lemma2_rotation_diagonalizes_and_preserves_trace(seed):
    rng = np.random.default_rng(seed)
    info = random_spd(rng, 2)
    phi0, lam = at.lemma2_rotation(info)
    assert lam[0] >= lam[1] > 0
    C = rotation(phi0)
    np.testing.assert_allclose(C @ np.diag(lam) @ C.T, info, rtol=1e-10, atol=1e-12)
    rel = rng.uniform(-5, 5, (3, 2))
    s = rel @ C  # s_i = C(-phi0) p_i as row vectors
    sd2, st2 = np.ones(3), np.full(3, 0.3)
    original = at.posterior_trace(np.linalg.inv(info), rel, sd2, st2)
    rotated = at.posterior_trace(np.diag(1 / lam), s, sd2, st2)  # eq. (18)
    assert rotated == pytest.approx(original, rel=1e-10)


def test_information_is_symmetric_in_sign():
    """A sensor at s gives the same information as at -s (eq. 17 is even in p)."""
    rng = np.random.default_rng(4)
    prior = random_spd(rng, 2)
    rel = rng.uniform(-5, 5, (2, 2))
    a = at.posterior_trace(prior, rel, [1, 2], [0.1, 0.2])
    b = at.posterior_trace(prior, rel * [[1], [-1]], [1, 2], [0.1, 0.2])
    assert a == pytest.approx(b, rel=1e-14)


@pytest.mark.parametrize(
    "args, field",
    [
        ((np.eye(2), np.zeros((1, 2)), 1.0, 1.0), "rel_positions"),
        ((np.eye(2), np.ones((1, 2)), 0.0, 1.0), "sigma_d2"),
        ((np.eye(2), np.ones((1, 2)), 1.0, -2.0), "sigma_theta2"),
        ((np.array([[1.0, 0.5], [0.0, 1.0]]), np.ones((1, 2)), 1.0, 1.0), "prior_cov"),
        ((np.array([[1.0, 2.0], [2.0, 1.0]]), np.ones((1, 2)), 1.0, 1.0), "prior_cov"),
        ((np.eye(3), np.ones((1, 2)), 1.0, 1.0), "prior_cov"),
        ((np.eye(2), np.ones((1, 3)), 1.0, 1.0), "rel_positions"),
        ((np.eye(2), np.ones(2), 1.0, 1.0), "rel_positions"),
        ((np.eye(2), np.ones((2, 2)), [1.0, 1.0, 1.0], 1.0), "sigma_d2"),
        ((np.eye(2), np.array([[np.nan, 1.0]]), 1.0, 1.0), "rel_positions"),
        ((np.eye(2), np.ones((1, 2)), np.inf, 1.0), "sigma_d2"),
        ((np.diag([np.inf, 1.0]), np.ones((1, 2)), 1.0, 1.0), "prior_cov"),
    ],
)
def test_bad_input_raises_value_error_naming_parameter(args, field):
    with pytest.raises(ValueError, match=field):
        at.posterior_trace(*args)
    with pytest.raises(ValueError, match=field):
        at.posterior_position_covariance(*args)


def test_trace_objective_against_explicit_inverse_and_covariance_trace():
    rng = np.random.default_rng(5)
    Y = np.stack([random_spd(rng, 2) for _ in range(20)])
    np.testing.assert_allclose(
        TRACE.of_information(Y), np.trace(np.linalg.inv(Y), axis1=-2, axis2=-1), rtol=1e-12
    )
    np.testing.assert_allclose(TRACE.of_covariance(Y), np.trace(Y, axis1=-2, axis2=-1))
    assert TRACE.name == "trace"


def test_trace_objective_gradient_matches_finite_differences():
    # Central differences along symmetric perturbations E_ab = e_a e_b^T + e_b e_a^T.
    rng = np.random.default_rng(6)
    h = 1e-6
    for _ in range(10):
        Y = random_spd(rng, 2)
        G = TRACE.gradient(Y)
        np.testing.assert_allclose(G, G.T)
        for a, b in ((0, 0), (0, 1), (1, 1)):
            E = np.zeros((2, 2))
            E[a, b] = E[b, a] = 1.0
            fd = (np.trace(np.linalg.inv(Y + h * E)) - np.trace(np.linalg.inv(Y - h * E))) / (2 * h)
            assert np.sum(G * E) == pytest.approx(fd, rel=1e-6, abs=1e-9)
        # The entry form: d phi / d(a, b, c) with b the off-diagonal entry counted twice.
        val, ga, gb, gc = TRACE.tangent(Y[0, 0], Y[0, 1], Y[1, 1])
        assert (ga, gb / 2, gc) == pytest.approx((G[0, 0], G[0, 1], G[1, 1]), rel=1e-14)
        assert val == pytest.approx(np.trace(np.linalg.inv(Y)), rel=1e-12)


def test_trace_objective_tangent_plane_is_a_lower_bound():
    # Convexity of tr(Y^-1) on SPD matrices, which GBES's pruning relies on.
    rng = np.random.default_rng(7)
    for _ in range(200):
        Y0, Y = random_spd(rng, 2, 0.1 + 5 * rng.random()), random_spd(rng, 2)
        v0, ga, gb, gc = TRACE.tangent(Y0[0, 0], Y0[0, 1], Y0[1, 1])
        d = Y - Y0
        lin = v0 + ga * d[0, 0] + gb * d[0, 1] + gc * d[1, 1]
        assert lin <= np.trace(np.linalg.inv(Y)) * (1 + 1e-12)


# The public base (activetrack.Objective): its derived defaults against longhand ----------
def _spd_batch(rng, n, count):
    A = rng.standard_normal((count, n, n))
    return A @ A.transpose(0, 2, 1) + 0.2 * np.eye(n)


def test_base_default_of_covariance_is_each_builtins_closed_form():
    # The default reads the value at the information P11^{-1}; the built-ins' overrides
    # read P directly. Both against numpy's trace and log-determinant of the 2x2 block.
    rng = np.random.default_rng(20)
    P = _spd_batch(rng, 4, 40)
    block = P[:, :2, :2]
    trace = np.trace(block, axis1=-2, axis2=-1)
    logdet = np.linalg.slogdet(block)[1]
    for obj, want in ((at.TRACE, trace), (at.WORST_TRACE, trace), (at.LOGDET, logdet)):
        np.testing.assert_allclose(at.Objective.of_covariance(obj, P), want, rtol=1e-11)
        np.testing.assert_allclose(obj.of_covariance(P), want, rtol=1e-12)


def test_base_combine_of_targets_and_of_covariances_against_longhand():
    rng = np.random.default_rng(21)
    P = _spd_batch(rng, 4, 30).reshape(10, 3, 4, 4)  # 10 configurations of K = 3 targets
    traces = np.trace(P[..., :2, :2], axis1=-2, axis2=-1)
    np.testing.assert_allclose(at.TRACE.of_covariances(P), traces.sum(-1), rtol=1e-12)
    np.testing.assert_allclose(at.WORST_TRACE.of_covariances(P), traces.max(-1), rtol=1e-12)
    Y = np.linalg.inv(P[..., :2, :2])
    a, b, c = Y[..., 0, 0], Y[..., 0, 1], Y[..., 1, 1]
    np.testing.assert_allclose(at.TRACE.of_targets(a, b, c), traces.sum(-1), rtol=1e-10)
    np.testing.assert_allclose(
        at.LOGDET.of_targets(a, b, c), np.linalg.slogdet(P[..., :2, :2])[1].sum(-1), rtol=1e-10
    )


def test_base_default_tangent_against_the_closed_form_gradients():
    # d tr(Y^-1) = -tr(Y^-2 dY), d(-log det Y) = -tr(Y^-1 dY); b counts twice (symmetric dY).
    rng = np.random.default_rng(22)
    Y = _spd_batch(rng, 2, 60)
    Y[:20] *= 1e-3  # other scales: the step follows the least eigenvalue
    Y[20:40] *= 1e3
    Yi = np.linalg.inv(Y)
    a, b, c = Y[:, 0, 0], Y[:, 0, 1], Y[:, 1, 1]
    for obj, G, val in (
        (at.TRACE, -Yi @ Yi, np.trace(Yi, axis1=-2, axis2=-1)),
        (at.LOGDET, -Yi, -np.linalg.slogdet(Y)[1]),
    ):
        v, ga, gb, gc = at.Objective.tangent(obj, a, b, c)
        np.testing.assert_allclose(v, val, rtol=1e-12)
        scale = np.abs(G).max(axis=(-2, -1))
        for got, want in ((ga, G[:, 0, 0]), (gb, 2 * G[:, 0, 1]), (gc, G[:, 1, 1])):
            assert np.all(np.abs(got - want) <= 1e-7 * scale)
        np.testing.assert_allclose(
            at.Objective.gradient(obj, Y), G, rtol=0, atol=1e-7 * scale.max()
        )


def test_logdet_tangent_plane_is_a_lower_bound():
    # LOGDET declares convex (GBES's bound relies on it).
    rng = np.random.default_rng(23)
    for _ in range(200):
        Y0, Y = random_spd(rng, 2, 0.1 + 5 * rng.random()), random_spd(rng, 2)
        v0, ga, gb, gc = at.LOGDET.tangent(Y0[0, 0], Y0[0, 1], Y0[1, 1])
        d = Y - Y0
        lin = v0 + ga * d[0, 0] + gb * d[0, 1] + gc * d[1, 1]
        assert lin <= -np.linalg.slogdet(Y)[1] + 1e-12 * (1 + abs(lin))


def test_the_base_is_abstract_and_built_ins_are_its_subclasses():
    from activetrack.models.objective import as_objective, is_trace

    with pytest.raises(TypeError):
        at.Objective()

    class NoValue(at.Objective):
        name = "no_value"

    with pytest.raises(TypeError, match="of_entries"):
        NoValue()
    for obj in (at.TRACE, at.WORST_TRACE, at.LOGDET):
        assert isinstance(obj, at.Objective) and obj.convex
        assert as_objective(obj.name) is obj and as_objective(obj) is obj
    assert at.TRACE.nonnegative and at.WORST_TRACE.nonnegative and not at.LOGDET.nonnegative
    assert is_trace(at.TRACE) and is_trace(at.TraceObjective())
    assert not is_trace(at.WORST_TRACE) and not is_trace(at.LOGDET)
    for bad in ("det", None, at.TraceObjective):
        with pytest.raises(ValueError, match="objective"):
            as_objective(bad)
