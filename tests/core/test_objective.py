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
