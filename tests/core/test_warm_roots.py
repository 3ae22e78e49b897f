"""Roots of f3 from a nearby f3's roots (Aberth steps, inclusion test) and the solves and
GSR plans built on them, against mpmath, a fresh solve and textbook Gauss-Seidel sweeps.

The warm path may decline (then the companion QR decides), but what it certifies must be
right: every root of the new polynomial within its inclusion disk of an approximation. The
references are independent: mpmath's roots at 40 digits, a dense search of the feasible
boundary (``test_solver.brute_force``), the solver with no kept roots (itself checked
against that search in ``test_solver.py``), and GSR's eq. (38) loop written here with
fresh ``solve_single_sensor`` calls.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.baselines import GSR, random_problem
from activetrack.models.objective import sensor_information
from activetrack.solvers._scalar import (
    NO_ROOTS,
    ROOTS_SIZE,
    ROOTS_TAG,
    solve_point,
)
from activetrack.solvers.analytic import solve_single_sensor
from activetrack.solvers.companion import IM_TOL, RE_TOL, _aberth_into, accepted_roots_from
from tests.core.test_hessenberg_qr import matched_error, mp_roots, poly_from_roots
from tests.core.test_solver import brute_force

pytestmark = pytest.mark.kernels


def _random_roots(rng: np.random.Generator) -> np.ndarray:
    """Return 10 roots: a few real ones in and near [-1, 1], complex pairs, one far out."""
    n_real = 2 * int(rng.integers(1, 4))  # 2, 4 or 6 real roots
    real = rng.uniform(-1.3, 1.3, n_real)
    pairs = (10 - n_real - 2) // 2
    z = rng.uniform(-1.5, 1.5, pairs) + 1j * rng.uniform(0.05, 1.5, pairs)
    far = rng.choice([-1, 1]) * 10.0 ** rng.uniform(0.5, 3, 2)
    return np.concatenate([real, z, z.conj(), far])


def _accepted(z: np.ndarray) -> list[float]:
    """Return the acceptance rule of :mod:`activetrack.solvers.companion` applied to roots ``z``."""
    keep = (np.abs(z.imag) <= IM_TOL) & (np.abs(z.real) <= 1 + RE_TOL)
    return sorted(np.clip(z.real[keep], -1.0, 1.0))


def _near_edge(z: np.ndarray) -> bool:
    """Return whether a root sits within 1e-6 of the acceptance box's edges."""
    return bool(
        np.any(np.abs(np.abs(z.imag) - IM_TOL) < 1e-6)
        or np.any(np.abs(np.abs(z.real) - 1 - RE_TOL) < 1e-6)
    )


@pytest.mark.parametrize("step", [1e-9, 1e-6, 1e-3])
def test_warm_roots_of_a_nearby_polynomial_match_mpmath(step: float) -> None:
    """From the roots of ``q0``, the roots of ``q0`` with coefficients moved by ``step``
    (relative): whenever the Aberth steps certify, every root is right to rounding, and
    they certify on most of these well-separated polynomials."""
    rng = np.random.default_rng(int(step * 1e9) + 7)
    certified = 0
    for _ in range(25):
        q0 = poly_from_roots(_random_roots(rng))
        q1 = q0 * (1.0 + step * rng.normal(size=10))
        start = mp_roots(q0)
        ref = mp_roots(q1)  # the reference of both checks below
        zr, zi = start.real.copy(), start.imag.copy()
        if _aberth_into(q1, zr, zi):
            certified += 1
            assert matched_error(zr + 1j * zi, ref) <= 1e-10
        # The solver's entry: the same accepted roots as mpmath's, warm or not.
        if _near_edge(ref):
            continue
        out, zr, zi = np.empty(10), start.real.copy(), start.imag.copy()
        n, found = accepted_roots_from(np.append(q1, 1.0), out, zr, zi, True)
        assert found
        np.testing.assert_allclose(sorted(out[:n]), _accepted(ref), rtol=0, atol=1e-9)
    assert certified >= 20


def test_a_cluster_is_left_to_the_qr() -> None:
    """A double root (disks that must overlap) is never certified; the QR finds it."""
    rng = np.random.default_rng(3)
    roots = np.array([0.3, 0.3, -0.6, 0.9, 0.1 + 0.5j, 0.1 - 0.5j, -1.2, 2.0, 3.0, -5.0])
    q = poly_from_roots(roots)
    start = roots + 1e-3 * (rng.normal(size=10) + 1j * rng.normal(size=10))
    zr, zi = start.real.copy(), start.imag.copy()
    assert not _aberth_into(q, zr, zi)
    out = np.empty(10)
    n, found = accepted_roots_from(np.append(q, 1.0), out, zr, zi, True)
    assert found and matched_error(zr + 1j * zi, roots) <= 1e-7  # a double root: ~sqrt(eps)
    assert np.allclose(sorted(out[:n]), [-0.6, 0.3, 0.3, 0.9], atol=1e-7)


@pytest.mark.parametrize("gap", [1e-4, 1e-15])
def test_a_start_that_misses_a_root_is_never_certified_wrongly(gap: float) -> None:
    """Two approximations on one root and none near another: Aberth's repulsion finds
    every root from ``gap`` 1e-4 apart; from 1e-15 apart both already satisfy the stopping
    test at the same root, and only the inclusion test sees that a root is missing. What
    is certified is right (checked against mpmath)."""
    rng = np.random.default_rng(4)
    refused = 0
    for _ in range(30):
        roots = _random_roots(rng)
        q = poly_from_roots(roots)
        start = roots.copy()
        k, j = rng.choice(10, 2, replace=False)
        start[k] = start[j] + gap * max(1.0, abs(start[j])) * (1 + 1j)  # k lost, j twice
        zr, zi = start.real.copy(), start.imag.copy()
        if _aberth_into(q, zr, zi):
            assert matched_error(zr + 1j * zi, mp_roots(q)) <= 1e-10
        else:
            refused += 1
    assert refused >= 20 if gap < 1e-12 else refused == 0


def test_degenerate_starts_and_polynomials_decline_without_raising() -> None:
    """Coincident approximations, NaN coefficients: the warm path declines (no division by
    zero, also as plain Python) and the QR's answer stands (none for NaN)."""
    q = poly_from_roots(np.linspace(-0.9, 0.9, 10))
    zr, zi = np.zeros(10), np.zeros(10)
    assert not _aberth_into(q, zr, zi)
    bad = q.copy()
    bad[3] = np.nan
    zr, zi = np.linspace(-1, 1, 10), np.zeros(10)
    assert not _aberth_into(bad, zr, zi)
    out = np.empty(10)
    assert accepted_roots_from(np.append(bad, 1.0), out, zr, zi, True) == (0, False)


def _bench_problem(rng: np.random.Generator) -> tuple:
    """Return one speed-circle problem ``(L, c, r, rho, sd2, st2)`` (prior information L)."""
    lam = 10.0 ** rng.uniform(-2, 2, 2)
    phi = rng.uniform(0, np.pi)
    rot = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    L = rot @ np.diag(lam) @ rot.T
    r = 10 ** rng.uniform(-1, 0.5)
    nc = r * rng.uniform(1.5, 20)
    ang = rng.uniform(-np.pi, np.pi)
    c = nc * np.array([np.cos(ang), np.sin(ang)])
    rho = rng.uniform(0.05, 0.9) * (nc - r)
    return L, c, r, rho, 10 ** rng.uniform(-3, 0), 10 ** rng.uniform(-3, 0)


def test_a_solve_from_kept_roots_is_the_fresh_solve() -> None:
    """A sequence of nearby problems (the prior moving as in GSR's sweeps) solved from the
    previous solve's roots: the same value (to rounding), case and point (to the optimum's
    flatness) as a fresh solve; the kept roots are tagged; and the last solve of each
    sequence is feasible and never worse than a dense search of the feasible boundary."""
    rng = np.random.default_rng(5)
    for _ in range(60):
        L, c, r, rho, sd2, st2 = _bench_problem(rng)
        roots = np.empty(ROOTS_SIZE)
        roots[ROOTS_TAG] = NO_ROOTS
        for _ in range(4):
            L = L + 10 ** rng.uniform(-4, -1) * np.trace(L) * np.diag(rng.uniform(0, 1, 2))
            args = (L[0, 0], L[0, 1], L[1, 1], c[0], c[1], r, rho, sd2, st2)
            warm = solve_point(*args, roots)
            fresh = solve_point(*args, np.zeros(ROOTS_SIZE))
            assert roots[ROOTS_TAG] != NO_ROOTS
            assert warm[3:] == fresh[3:]
            assert abs(warm[2] - fresh[2]) <= 1e-12 * fresh[2]
            assert np.hypot(warm[0] - fresh[0], warm[1] - fresh[1]) <= 1e-6 * r
        s = np.array(warm[:2])
        assert np.hypot(*(s - c)) <= r * (1 + 1e-9) and np.hypot(*s) >= rho * (1 - 1e-9)
        ref = brute_force(L, c, r, rho, sd2, st2)
        assert (warm[2] - ref) / ref <= 1e-9


def _textbook_gsr(p, tol: float = 1e-9, max_sweeps: int = 100) -> float:
    """Return the value of Gauss-Seidel sweeps (eq. 38) from the current positions, every
    subproblem a fresh checked ``solve_single_sensor``, an update kept if it lowers the
    objective, stopping when a sweep improves by at most ``tol`` (relative)."""
    s = p.rel_sensors.copy()
    info = sensor_information(s, p.sigma_d2, p.sigma_theta2)

    def value(inf: np.ndarray) -> float:
        return float(np.trace(np.linalg.inv(p.prior_info + inf.sum(axis=0))))

    cur = value(info)
    for _ in range(max_sweeps):
        before = cur
        for i in range(s.shape[0]):
            others = p.prior_info + info.sum(axis=0) - info[i]
            sol = solve_single_sensor(  # c: where sensor i is now
                others, p.rel_sensors[i], p.r[i], p.rho[i], p.sigma_d2[i], p.sigma_theta2[i]
            )
            new = info.copy()
            new[i] = sensor_information(sol.s, p.sigma_d2[i], p.sigma_theta2[i])
            if value(new) < cur:
                s[i], info, cur = sol.s, new, value(new)
        if before - cur <= tol * before:
            break
    return cur


def test_gsr_with_kept_roots_matches_textbook_sweeps_with_fresh_solves() -> None:
    """GSR (its sweeps solve from each sensor's previous roots) reaches the value of the
    textbook sweeps whose every solve is fresh, to the sweeps' tolerance."""
    rng = np.random.default_rng(6)
    for _ in range(12):
        p = random_problem(rng, 3, distance=(2.0, 8.0))
        res = GSR().plan_with_info(p)
        if not res.warm_feasible:
            continue  # a sensor inside its rho disk: GSR starts elsewhere than the loop
        assert abs(res.value - _textbook_gsr(p)) <= 1e-8 * res.value


def test_tiny_roots_are_certified_only_when_right() -> None:
    """Roots near 1e-60 and 1e-18, where ``|f3|^2`` underflows: the stopping test must not
    take every point for a root (it did, comparing squares: 0 <= 0). What is certified is
    right relative to each root's own size (mpmath at 120 digits)."""
    rng = np.random.default_rng(8)
    families = [np.array([1e-60, 2e-60, -1.5e-60, 0.3, -0.5, 0.7, 0.2 + 0.6j, 0.2 - 0.6j, 2, -3])]
    families += [1e-18 * _random_roots(rng) for _ in range(5)]
    for roots in families:
        q = poly_from_roots(roots)
        start = roots * (1.0 + 1e-3 * rng.normal(size=10))
        zr, zi = start.real.copy(), start.imag.copy()
        if _aberth_into(q, zr, zi):
            import mpmath

            with mpmath.workdps(120):
                coeffs = [mpmath.mpf(1)] + [mpmath.mpf(float(v)) for v in q[::-1]]
                ref = [complex(z) for z in mpmath.polyroots(coeffs, maxsteps=400, extraprec=400)]
            found = list(zr + 1j * zi)
            for z in sorted(ref, key=abs, reverse=True):
                k = int(np.argmin([abs(z - w) for w in found]))
                assert abs(z - found.pop(k)) <= 1e-8 * abs(z)
