"""Covariance intersection against brute-force weight grids, closed forms and the exact
error covariance of jointly Gaussian correlated estimates (never over-confident)."""

import itertools

import numpy as np
import pytest
from scipy import stats

import activetrack
from activetrack.estimation.fusion import covariance_intersection, information_fusion
from tests.core.helpers import random_spd


def criterion_value(covs, w, criterion):
    """Return tr or log det of (sum_i w_i P_i^{-1})^{-1}, written out directly."""
    Y = sum(wi * np.linalg.inv(P) for wi, P in zip(w, covs, strict=True))
    P = np.linalg.inv(Y)
    return np.trace(P) if criterion == "trace" else np.log(np.linalg.det(P))


def grid_values(covs, W, criterion):
    """Return :func:`criterion_value` at each weight row of ``W`` (G, n), batched."""
    infos = np.linalg.inv(covs)
    P = np.linalg.inv(np.einsum("gi,ijk->gjk", W, infos))
    if criterion == "trace":
        return np.trace(P, axis1=-2, axis2=-1)
    return np.linalg.slogdet(P)[1]


def simplex_grid(n, steps):
    """Return every weight vector of n entries that are multiples of 1 / steps."""
    heads = itertools.product(range(steps + 1), repeat=n - 1)
    return [np.array(c + (steps - sum(c),)) / steps for c in heads if sum(c) <= steps]


@pytest.mark.parametrize("criterion", ["trace", "logdet"])
@pytest.mark.parametrize("seed", range(6))
def test_two_estimates_weights_beat_a_fine_grid(criterion, seed):
    rng = np.random.default_rng(seed)
    d = 2 + seed % 3
    covs = np.stack([random_spd(rng, d), random_spd(rng, d, scale=rng.uniform(0.2, 5))])
    res = covariance_intersection(rng.standard_normal((2, d)), covs, criterion)
    a = np.linspace(0, 1, 20001)
    best = grid_values(covs, np.stack([a, 1 - a], axis=1), criterion).min()
    got = criterion_value(covs, res.weights, criterion)
    assert got <= best + 1e-9 * abs(best)
    np.testing.assert_allclose(res.weights.sum(), 1.0, rtol=0, atol=1e-15)
    assert (res.weights >= 0).all()
    np.linalg.cholesky(res.covariance)  # SPD
    np.testing.assert_array_equal(res.covariance, res.covariance.T)


@pytest.mark.parametrize("criterion", ["trace", "logdet"])
@pytest.mark.parametrize("n", [3, 4])
def test_several_estimates_weights_beat_a_simplex_grid(criterion, n):
    rng = np.random.default_rng(n)
    covs = np.stack([random_spd(rng, 2, scale=rng.uniform(0.3, 3)) for _ in range(n)])
    res = covariance_intersection(rng.standard_normal((n, 2)), covs, criterion)
    best = grid_values(covs, np.array(simplex_grid(n, 200 if n == 3 else 60)), criterion).min()
    got = criterion_value(covs, res.weights, criterion)
    assert got <= best + 1e-7 * abs(best)
    np.testing.assert_allclose(res.weights.sum(), 1.0, atol=1e-12)


def test_closed_forms():
    # Mirror-image covariances: by symmetry w = (1/2, 1/2), P = inv((I1 + I2) / 2).
    P1, P2 = np.diag([1.0, 4.0]), np.diag([4.0, 1.0])
    x = np.array([[1.0, 2.0], [3.0, -1.0]])
    res = covariance_intersection(x, np.stack([P1, P2]))
    np.testing.assert_allclose(res.weights, [0.5, 0.5], atol=1e-8)
    np.testing.assert_allclose(res.covariance, np.diag([1.6, 1.6]), rtol=1e-8)
    # mean = P (I1 x1 + I2 x2) / 2, entrywise: (1*1 + 0.25*3) / 2 * 1.6, (0.25*2 - 1) / 2 * 1.6
    # (to the weights' accuracy, ~1e-8: Brent's tolerance xatol + sqrt(eps) |w|).
    np.testing.assert_allclose(res.mean, [1.4, -0.4], rtol=1e-7)
    # One dimension: the information is linear in w, so the smaller variance wins alone.
    res1 = covariance_intersection([[5.0], [7.0], [1.0]], [[[2.0]], [[0.5]], [[3.0]]])
    np.testing.assert_allclose(res1.weights, [0, 1, 0], atol=1e-9)
    np.testing.assert_allclose(res1.mean, [7.0], rtol=1e-9)
    # Nested covariances (P1 <= P2): the better estimate alone.
    res2 = covariance_intersection(x, np.stack([P1, P1 + np.eye(2)]))
    np.testing.assert_allclose(res2.weights, [1, 0], atol=1e-9)
    np.testing.assert_allclose(res2.covariance, P1, rtol=1e-9)
    # Equal means are kept whatever the weights.
    res3 = covariance_intersection([[2.0, 3.0]] * 3, np.stack([P1, P2, np.eye(2)]))
    np.testing.assert_allclose(res3.mean, [2.0, 3.0], rtol=1e-12)


def test_one_estimate_is_returned_unchanged():
    P = np.array([[2.0, 0.3], [0.3, 1.0]])
    res = covariance_intersection([[1.0, -2.0]], [P])
    np.testing.assert_array_equal(res.mean, [1.0, -2.0])
    np.testing.assert_array_equal(res.covariance, P)
    np.testing.assert_array_equal(res.weights, [1.0])


def fused_error_covariance(covs, w, joint):
    """Return E[e e^T] of the fused error e = P sum_i w_i P_i^{-1} e_i for errors of joint
    covariance ``joint`` (n d, n d): the gain G = P [w_1 P_1^{-1}, ..., w_n P_n^{-1}]."""
    infos = [wi * np.linalg.inv(P) for wi, P in zip(w, covs, strict=True)]
    P = np.linalg.inv(sum(infos))
    G = P @ np.hstack(infos)
    return P, G @ joint @ G.T


def random_joint(rng, n, d, kind):
    """Return a random joint error covariance (n d, n d) of n estimates: ``independent``
    (block diagonal), ``correlated`` (a random SPD matrix, any cross-correlation) or
    ``common`` (largely the same error: e_i = e + small own noise)."""
    if kind == "independent":
        J = np.zeros((n * d, n * d))
        for i in range(n):
            J[i * d : (i + 1) * d, i * d : (i + 1) * d] = random_spd(rng, d)
        return J
    if kind == "correlated":
        return random_spd(rng, n * d)
    A = rng.standard_normal((d, d))
    common = np.kron(np.ones((n, n)), A @ A.T)
    return common + 0.01 * np.eye(n * d)


@pytest.mark.parametrize("kind", ["independent", "correlated", "common"])
@pytest.mark.parametrize("n", [2, 3])
def test_never_over_confident_for_any_correlation(kind, n):
    # P_ci - E[e e^T] is positive semidefinite, E computed exactly from the joint
    # covariance; the Kalman fusion, exact for independent errors, fails for correlated.
    rng = np.random.default_rng(10 * n + len(kind))
    d, kf_worst = 2, np.inf
    for _ in range(40):
        joint = random_joint(rng, n, d, kind)
        covs = np.stack([joint[i * d : (i + 1) * d, i * d : (i + 1) * d] for i in range(n)])
        for criterion in ("trace", "logdet"):
            res = covariance_intersection(rng.standard_normal((n, d)), covs, criterion)
            P, E = fused_error_covariance(covs, res.weights, joint)
            np.testing.assert_allclose(res.covariance, P, rtol=1e-9)
            gap = np.linalg.eigvalsh(res.covariance - E)
            assert gap.min() >= -1e-9 * np.abs(E).max()
        kf = information_fusion(np.zeros((n, d)), covs)
        _, E_kf = fused_error_covariance(covs, np.ones(n), joint)
        kf_worst = min(kf_worst, np.linalg.eigvalsh(kf.covariance - E_kf).min())
    if kind == "independent":
        assert kf_worst >= -1e-9  # exact: the Kalman fusion's P is its error covariance
    else:
        assert kf_worst < -1e-3  # over-confident: the test above has teeth


def test_never_over_confident_by_monte_carlo():
    # The same property by sampling jointly Gaussian errors: the mean NEES of the fused
    # estimate e^T P^{-1} e is <= d, inside the band of its sample mean (4 sigma, sigma
    # estimated from the samples); the Kalman fusion's is far above it.
    rng = np.random.default_rng(21)
    n, d, samples = 2, 2, 40000
    joint = np.kron(np.array([[1.0, 0.9], [0.9, 1.0]]), np.array([[2.0, 0.5], [0.5, 1.0]]))
    covs = np.stack([joint[:2, :2], joint[2:, 2:]])
    e = rng.multivariate_normal(np.zeros(n * d), joint, size=samples).reshape(samples, n, d)
    res = covariance_intersection(np.zeros((n, d)), covs)
    kf = information_fusion(np.zeros((n, d)), covs)

    def nees(fused_cov, w):
        infos = [wi * np.linalg.inv(P) for wi, P in zip(w, covs, strict=True)]
        err = np.einsum("ij,sj->si", fused_cov, sum(np.einsum("ij,sj->si", I, e[:, k])
                                                    for k, I in enumerate(infos)))  # fmt: skip
        q = np.einsum("si,ij,sj->s", err, np.linalg.inv(fused_cov), err)
        return q.mean(), q.std(ddof=1) / np.sqrt(samples)

    m_ci, s_ci = nees(res.covariance, res.weights)
    m_kf, s_kf = nees(kf.covariance, np.ones(n))
    assert m_ci <= d + 4 * s_ci
    assert m_kf > d + 4 * s_kf  # over-confident, ~d * 2 / 1.9

    # Where CI is tight: two copies of the same estimate (fully correlated errors). Its
    # covariance is then exactly P_1 and the NEES sum over the samples is chi-square with
    # d * samples degrees of freedom: the mean NEES lies in that distribution's two-sided
    # band, about d (1 +- 0.025), so a covariance 10% too small (NEES ~ 1.1 d) fails.
    covs = np.stack([joint[:2, :2]] * 2)
    e = np.repeat(rng.multivariate_normal(np.zeros(d), covs[0], size=samples)[:, None], 2, 1)
    res = covariance_intersection(np.zeros((n, d)), covs)
    lo, hi = np.array(stats.chi2.interval(1 - 1e-6, d * samples)) / samples
    m_tight, _ = nees(res.covariance, res.weights)
    assert lo <= m_tight <= hi
    assert not lo <= 1.1 * m_tight <= hi


def test_more_conservative_than_the_kalman_fusion_of_independent_estimates():
    rng = np.random.default_rng(30)
    for n in (2, 3, 5):
        covs = np.stack([random_spd(rng, 3) for _ in range(n)])
        x = rng.standard_normal((n, 3))
        ci, kf = covariance_intersection(x, covs), information_fusion(x, covs)
        # Closed form of the Kalman fusion, written out.
        np.testing.assert_allclose(
            kf.covariance, np.linalg.inv(sum(np.linalg.inv(P) for P in covs)), rtol=1e-10
        )
        assert np.linalg.eigvalsh(ci.covariance - kf.covariance).min() >= -1e-12
        assert np.trace(ci.covariance) > np.trace(kf.covariance)


def test_scale_free_weights_and_validation():
    rng = np.random.default_rng(40)
    covs = np.stack([random_spd(rng, 2) for _ in range(3)])
    x = rng.standard_normal((3, 2))
    a = covariance_intersection(x, covs)
    b = covariance_intersection(1e-3 * x, 1e-6 * covs)
    np.testing.assert_allclose(a.weights, b.weights, atol=1e-5)
    with pytest.raises(ValueError, match="criterion"):
        covariance_intersection(x, covs, "det")
    with pytest.raises(ValueError, match="covariances"):
        covariance_intersection(x, covs[:2])
    with pytest.raises(ValueError, match="covariances"):
        covariance_intersection(x, -covs)
    with pytest.raises(ValueError, match="means"):
        covariance_intersection(np.full((3, 2), np.nan), covs)
    with pytest.raises(ValueError, match="means"):
        covariance_intersection(np.zeros((0, 2)), covs[:0])
    assert "covariance_intersection" in activetrack.__all__
