"""The compiled Hessenberg QR (eigenvalues of f3's companion matrix) against LAPACK and mpmath.

Reference roots come from mpmath's ``polyroots`` at 40 digits (an independent method:
Durand-Kerner in multiple precision) and from LAPACK's ``dgeev`` through NumPy. A
backward-stable method finds each root to about ``eps * cond``: simple, separated roots
to ~1e-12, double roots to ~sqrt(eps) ~1e-8, so the tolerances below follow the
polynomial, and the backward error (the residual relative to ``sum |q_k| max(1, |z|)^k``) is
checked on every polynomial against LAPACK's (coefficients of very different sizes make
both large: companion QR is stable for the matrix, not for the coefficients).
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest

from activetrack.solvers.companion import (
    IM_TOL,
    RE_TOL,
    _balanced_companion_into,
    monic,
    monic_roots,
    real_roots_scalar,
)
from activetrack.solvers.hessenberg_qr import balance, hessenberg_eigvals

pytestmark = pytest.mark.kernels


def poly_from_roots(roots: np.ndarray) -> np.ndarray:
    """Return ``q`` (10,) with ``prod (z - root) = z^10 + sum q_k z^k`` (real ``roots`` set)."""
    coeffs = np.real(np.poly(roots))  # highest power first, leading 1
    return coeffs[1:][::-1].copy()


def lapack_roots(q: np.ndarray) -> np.ndarray:
    """Return the companion-matrix eigenvalues by LAPACK (``dgeev`` through NumPy)."""
    return np.linalg.eigvals(np.vstack([-q[::-1], np.eye(10)[:9]]))


def mp_roots(q: np.ndarray) -> np.ndarray:
    """Return the roots of ``z^10 + sum q_k z^k`` by mpmath at 40 digits."""
    with mpmath.workdps(40):
        coeffs = [mpmath.mpf(1)] + [mpmath.mpf(float(v)) for v in q[::-1]]
        roots = mpmath.polyroots(coeffs, maxsteps=200, extraprec=200)
    return np.array([complex(z) for z in roots])


def matched_error(found: np.ndarray, ref: np.ndarray) -> float:
    """Return the largest distance from a reference root to its match (one-to-one, greedy
    by distance) among ``found``, relative to ``max(1, |root|)``."""
    left = list(found)
    worst = 0.0
    for z in sorted(ref, key=lambda z: -abs(z)):
        k = int(np.argmin([abs(z - w) for w in left]))
        worst = max(worst, abs(z - left.pop(k)) / max(1.0, abs(z)))
    return worst


def backward_error(q: np.ndarray, roots: np.ndarray) -> float:
    """Return ``max |p(z)| / sum |q_k| max(1, |z|)^k`` over ``roots`` (``p`` monic with
    ``q``): the normwise backward error, which a stable method keeps at a few eps."""
    full = np.concatenate([q, [1.0]])
    out = 0.0
    for z in roots:
        scale = np.dot(np.abs(full), max(1.0, abs(z)) ** np.arange(11))
        out = max(out, abs(np.dot(full, z ** np.arange(11))) / scale)
    return out


ADVERSARIAL = {
    # name: (q, tolerance on the roots)
    "unit_roots": (np.array([-1.0] + [0.0] * 9), 1e-12),  # z^10 = 1: on the circle
    "wilkinson_scaled": (poly_from_roots(np.arange(1, 11) / 10.0), 1e-6),  # ill-conditioned
    "double_roots": (poly_from_roots(np.repeat([-0.9, -0.3, 0.2, 0.5, 0.95], 2)), 3e-7),
    "near_double": (poly_from_roots([0.5, 0.5 + 1e-7, -0.5, 0.1, 0.7, -0.8, 2, -3, 5, 1e-3]), 1e-6),
    "wide_range": (poly_from_roots(10.0 ** np.arange(-4, 6)), 1e-9),
    "complex_pairs": (
        poly_from_roots(np.array([0.3 + 0.005j, 0.3 - 0.005j, 2j, -2j, 1 + 1j, 1 - 1j, 0.9, -0.7,
                                  -1.01, 1.009])),
        1e-10,
    ),  # fmt: skip
    "zero_roots": (poly_from_roots([0.0, 0.0, 0.0, 0.5, -0.5, 0.9, -0.9, 0.1, 3, -3]), 1e-12),
    # Coefficients ~1e15: a root at -3e14, the others conditioned to ~1e-7 (LAPACK's too).
    "tiny_lead": (
        monic(np.array([1.0, -2.0, 0.5, 3.0, -1.0, 0.2, 0.1, -0.3, 0.7, 1.0, 1e-16])), 3e-7
    ),
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(ADVERSARIAL))
def test_adversarial_polynomials_match_mpmath(name: str) -> None:
    q, tol = ADVERSARIAL[name]
    roots = monic_roots(q[None])[0]
    assert np.all(np.isfinite(roots))
    assert matched_error(roots, mp_roots(q)) <= tol
    assert backward_error(q, roots) <= max(1e-13, 10 * backward_error(q, lapack_roots(q)))


def test_random_polynomials_match_lapack_and_mpmath() -> None:
    rng = np.random.default_rng(0)
    qs = [rng.normal(size=10) * 10.0 ** rng.uniform(-3, 3, 10) for _ in range(60)]
    qs += [poly_from_roots(rng.uniform(-1.2, 1.2, 10)) for _ in range(20)]
    roots = monic_roots(np.array(qs))
    for q, found in zip(qs, roots, strict=True):
        lapack = lapack_roots(q)
        ref = mp_roots(q)
        # Both methods are backward stable: each within what the polynomial allows.
        assert backward_error(q, found) <= max(1e-13, 10 * backward_error(q, lapack))
        assert matched_error(found, ref) <= max(1e-9, 10 * matched_error(lapack, ref))


def test_general_hessenberg_matrices_match_lapack() -> None:
    """Not only companion matrices: random upper-Hessenberg ones of several sizes."""
    rng = np.random.default_rng(1)
    for n in (1, 2, 3, 5, 10, 16):
        for _ in range(20):
            a = np.triu(rng.normal(size=(n, n)), -1)
            wr, wi = np.empty(n), np.empty(n)
            assert hessenberg_eigvals(a.copy(), wr, wi)
            ev = np.linalg.eigvals(a)
            assert matched_error(wr + 1j * wi, ev) <= 1e-9 * max(1.0, np.abs(a).max())
            # Complex eigenvalues come in adjacent conjugate pairs.
            for k in np.flatnonzero(wi > 0):
                assert wi[k - 1] == -wi[k] and wr[k - 1] == wr[k]


def test_companion_balance_is_the_general_balance_bit_for_bit() -> None:
    """The O(n) balance of a companion matrix equals the general O(n^2) one on the dense
    matrix, entry for entry, on coefficients spanning 16 decades, exact zeros among them,
    the adversarial polynomials and every size (the solver deflates zero roots first)."""
    rng = np.random.default_rng(3)
    qs = [rng.normal(size=10) * 10.0 ** rng.uniform(-8, 8, 10) for _ in range(200)]
    qs += [np.where(rng.random(10) < 0.3, 0.0, rng.normal(size=10)) for _ in range(50)]
    qs += [q for q, _ in ADVERSARIAL.values()]
    for q in qs:
        for n in (10, 7, 3, 1):
            dense = np.zeros((n, n))
            dense[0] = -q[:n][::-1]
            dense[np.arange(1, n), np.arange(n - 1)] = 1.0
            balance(dense)
            fast = np.full((n, n), np.nan)
            _balanced_companion_into(q[:n].copy(), fast)
            assert np.array_equal(fast, dense)


def test_non_finite_polynomials_have_no_roots() -> None:
    q = np.ones((3, 10))
    q[0, 3] = np.nan
    q[1, 0] = np.inf
    roots = monic_roots(q)
    assert np.all(np.isnan(roots[:2]))
    assert np.all(np.isfinite(roots[2]))
    gam = np.ones(11)
    gam[4] = np.nan
    assert real_roots_scalar(tuple(gam)) == []


def test_scalar_accepted_roots_are_the_real_roots_in_the_interval() -> None:
    """The scalar path keeps exactly the roots in the acceptance box, clipped to [-1, 1]."""
    rng = np.random.default_rng(2)
    for _ in range(60):
        gam = rng.normal(size=11) * 10.0 ** rng.uniform(-2, 2, 11)
        got = sorted(real_roots_scalar(tuple(gam)))
        ref = mp_roots(monic(gam))
        near = [z for z in ref if abs(z.imag) <= IM_TOL and abs(z.real) <= 1.0 + RE_TOL]
        # Roots close to the box's edges may fall either way; skip those polynomials.
        edge = [
            z for z in ref
            if abs(abs(z.imag) - IM_TOL) < 1e-6 or abs(abs(z.real) - 1 - RE_TOL) < 1e-6
        ]  # fmt: skip
        if edge:
            continue
        want = sorted(min(1.0, max(-1.0, z.real)) for z in near)
        assert len(got) == len(want)
        assert all(math.isclose(g, w, abs_tol=1e-8) for g, w in zip(got, want, strict=True))
