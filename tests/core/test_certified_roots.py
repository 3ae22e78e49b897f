"""Certified warm-started roots of f3 (the batched solver's shortcut) against independent roots.

The reference roots are computed by mpmath's ``polyroots`` in 30-digit arithmetic from the
exact float64 coefficients, so they are the roots of the very polynomial the solver holds;
which of them are accepted is decided on those reference roots with the solver's
acceptance rule (``|imag| <= 1e-2``, ``|real| <= 1 + 1e-2``), written out here. The
certificate may refuse a row (the solver then takes the companion eigenvalues) but must
never certify a wrong answer; where the roots crowd or sit on an acceptance boundary it
must refuse. At the solver level, a warm-started solve must give what the plain
companion-matrix path gives.
"""

import math

import mpmath as mp
import numpy as np
import pytest

from activetrack._coefficients import f3_coefficients
from activetrack.certified_roots import certified_roots as _certified_roots
from activetrack.certified_roots import nearest_seed as _nearest_seed
from activetrack.companion import monic as _monic
from activetrack.solver import CircleRoots, _solve_batch_unchecked

IM_TOL, RE_TOL = 1e-2, 1e-2  # the solver's acceptance rule for eigenvalues
PINNED = 1.1e-10  # the certificate's accuracy for accepted roots


def monic_from_roots(roots):
    """Return ``q`` (10,): ``prod (z - roots) = z^10 + sum q_k z^k`` (float64, real)."""
    c = np.poly(np.asarray(roots))  # highest degree first
    return np.real(c[1:][::-1]).astype(float)


def reference_roots(q):
    """Return the 10 roots of ``z^10 + sum q_k z^k`` in 30-digit arithmetic (complex)."""
    with mp.workdps(30):
        coeffs = [mp.mpf(1)] + [mp.mpf(float(x)) for x in q[::-1]]
        roots = mp.polyroots(coeffs, maxsteps=200, extraprec=60)
        return np.array([complex(r) for r in roots])


def accepted(z):
    """Return the accepted roots (the solver's rule), sorted."""
    z = np.asarray(z)
    keep = (np.abs(z.imag) <= IM_TOL) & (np.abs(z.real) <= 1.0 + RE_TOL)
    return np.sort_complex(z[keep])


def assert_certified_rows_are_right(q, z, ok):
    """Every certified row accepts exactly the reference's accepted roots, pinned."""
    for i in np.flatnonzero(ok):
        want = accepted(reference_roots(q[i]))
        got = accepted(z[i])
        assert len(got) == len(want), (i, got, want)
        for w in want:  # one certified root within PINNED of each accepted reference root
            assert np.min(np.abs(got - w)) <= PINNED, (i, got, want)


def random_roots(rng):
    """Return 10 conjugate-closed roots: some real in [-1, 1], pairs, far roots."""
    n_real = int(rng.integers(0, 5))
    real = list(rng.uniform(-1.0, 1.0, n_real))
    rest = 10 - n_real
    pairs = []
    for _ in range(rest // 2):
        scale = rng.choice([1.0, 5.0, 20.0])
        zc = complex(rng.uniform(-scale, scale), rng.uniform(0.05, scale))
        pairs += [zc, zc.conjugate()]
    if rest % 2:
        real.append(float(rng.choice([-1.0, 1.0]) * rng.uniform(2.0, 20.0)))
    return np.array(real + pairs, dtype=complex)


@pytest.mark.parametrize("rel", [1e-9, 1e-5, 1e-2])
def test_certified_roots_agree_with_30_digit_roots(rel):
    rng = np.random.default_rng(int(-math.log10(rel)))
    q = np.array([monic_from_roots(random_roots(rng)) for _ in range(40)])
    ref = [reference_roots(qi) for qi in q]
    # Warm start: the reference roots, perturbed and shuffled (a nearby polynomial's).
    guess = np.array([rng.permutation(r) for r in ref])
    guess *= 1.0 + rel * (rng.standard_normal(guess.shape) + 1j * rng.standard_normal(guess.shape))
    z, ok = _certified_roots(q, guess)
    assert z.shape == (40, 10)
    assert ok.mean() >= 0.75  # the shortcut does work (and so is tested)
    assert_certified_rows_are_right(q, z, ok)


def test_certified_roots_of_solver_polynomials():
    # f3 of random single-sensor problems (eq. 33), scaled and normalized as the solver does.
    rng = np.random.default_rng(3)
    rows = []
    for _ in range(40):
        l1, l2 = sorted(10.0 ** rng.uniform(-2, 2, 2), reverse=True)
        kappa = max(l1, 1.0)
        a, b = 10.0 ** rng.uniform(-2, 2), 10.0 ** rng.uniform(-2, 2)
        c1, c2 = rng.uniform(-20, 20, 2)
        rows.append(f3_coefficients(l1 / kappa, l2 / kappa, a, b, c1, c2))
    q = _monic(np.array(rows, dtype=float))
    ref = [reference_roots(qi) for qi in q]
    guess = np.array(ref) * (1.0 + 1e-4 * rng.standard_normal((40, 10)))
    z, ok = _certified_roots(q, guess)
    assert ok.mean() >= 0.8
    assert_certified_rows_are_right(q, z, ok)


def adversarial():
    """Return (name, roots) whose acceptance cannot be certified in float64."""
    far = [3.0 + 4.0j, 3.0 - 4.0j, -6.0 + 1.0j, -6.0 - 1.0j, 12.0, -15.0]
    return [
        # A double root inside the box: the float64 polynomial's two roots are ~1e-8
        # apart and cannot be pinned to 1e-10 by disjoint disks.
        ("double root", [0.3, 0.3, -0.5, 0.8] + far),
        ("close real roots", [0.3, 0.3 + 1e-9, -0.5, 0.8] + far),
        # A complex pair on the line |imag| = 1e-2 (accepted or not by a hair).
        ("pair on the imag limit", [0.5 + 0.01j, 0.5 - 0.01j, -0.5, 0.8] + far),
        # A real root on |real| = 1 + 1e-2.
        ("root on the real limit", [1.0 + RE_TOL, -0.5, 0.1, 0.8] + far),
        # A near-real complex pair straddling nothing but crowding: imag 1e-12.
        ("near-real pair", [0.2 + 1e-12j, 0.2 - 1e-12j, -0.5, 0.8] + far),
    ]


@pytest.mark.parametrize(("name", "roots"), adversarial())
def test_certificate_refuses_crowded_or_boundary_roots(name, roots):
    q = monic_from_roots(roots)[None]
    ref = reference_roots(q[0])
    # Even started at the 30-digit roots themselves.
    for guess in (ref, ref * (1.0 + 1e-7)):
        z, ok = _certified_roots(q, guess[None])
        assert not ok[0], name


def test_certificate_never_wrong_from_bad_starts():
    rng = np.random.default_rng(5)
    q = np.array([monic_from_roots(random_roots(rng)) for _ in range(40)])
    ref = np.array([reference_roots(qi) for qi in q])
    starts = [
        np.full((40, 10), 0.5 + 0.0j),  # coinciding: the corrections are infinite
        np.where(rng.random((40, 10)) < 0.1, np.nan, ref),  # NaN entries
        -ref,  # mirrored (the eigenframe flipped by pi)
        ref + 0.3,  # shifted
        rng.standard_normal((40, 10)) + 1j * rng.standard_normal((40, 10)),  # anything
    ]
    for guess in starts:
        z, ok = _certified_roots(q, guess)
        assert_certified_rows_are_right(q, z, ok)
    # Coinciding and NaN starts can never be certified.
    assert not _certified_roots(q, starts[0])[1].any()
    nan_rows = np.isnan(starts[1]).any(axis=1)
    assert not _certified_roots(q, starts[1])[1][nan_rows].any()


# ----------------------------------------------------------------- the batched solver


def rotation(phi):
    return np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])


def speed_circle_problems(rng, n):
    """Return ``(prior, c, r, rho, sd2, st2)`` for ``n`` problems on the speed circle (case I)."""
    lam = 10.0 ** rng.uniform(-2, 2, (n, 2))
    R = np.stack([rotation(p) for p in rng.uniform(0, math.pi, n)])
    prior = np.einsum("bij,bj,bkj->bik", R, lam, R)
    nc = 10 ** rng.uniform(0.3, 1.7, n)
    ang = rng.uniform(-math.pi, math.pi, n)
    c = nc[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    r = nc * rng.uniform(0.05, 0.6, n)
    rho = (nc - r) * rng.uniform(0.1, 0.9, n)
    return prior, c, r, rho, 10 ** rng.uniform(-3, 1, n), 10 ** rng.uniform(-3, 1, n)


def test_warm_started_batch_solve_equals_the_companion_path():
    rng = np.random.default_rng(8)
    n = 400
    prior, c, r, rho, sd2, st2 = speed_circle_problems(rng, n)
    _, roots = _solve_batch_unchecked(prior, c, r, rho, sd2, st2)
    assert np.isfinite(roots.roots).all() and not roots.certified.any()
    # The next sweep's problem: the prior moved a little (another sensor's move).
    bump = np.einsum("bi,bj->bij", *(2 * [rng.standard_normal((n, 2))]))
    prior2 = prior + 1e-3 * np.abs(prior).max(axis=(1, 2))[:, None, None] * bump
    cold, _ = _solve_batch_unchecked(prior2, c, r, rho, sd2, st2)
    warm, used = _solve_batch_unchecked(prior2, c, r, rho, sd2, st2, roots)
    assert used.certified.mean() >= 0.7  # the shortcut is exercised
    np.testing.assert_allclose(warm.value, cold.value, rtol=1e-10)
    # The same point, or its mirror -s (same information).
    d = np.minimum(np.linalg.norm(warm.s - cold.s, axis=1), np.linalg.norm(warm.s + cold.s, axis=1))
    assert np.all(d <= 1e-7 * np.maximum(1.0, np.linalg.norm(cold.s, axis=1)))
    # The returned roots are f3's roots either way (compared where both were computed).
    both = np.isfinite(used.roots).all(axis=1)
    for i in np.flatnonzero(both)[:30]:
        assert_certified_rows_are_right(
            _monic(np.array(f3_like(prior2[i], c[i], r[i], sd2[i], st2[i], used.swap[i])))[None],
            used.roots[i][None],
            np.array([used.certified[i]]),
        )


def f3_like(P, c, r, sd2, st2, swap):
    """Return f3's coefficients (eq. 33) of one problem in the solver's variable, longhand."""
    p11, p12, p22 = P[0, 0], 0.5 * (P[0, 1] + P[1, 0]), P[1, 1]
    phi0 = 0.5 * math.atan2(2.0 * p12, p11 - p22)
    l1 = 0.5 * (p11 + p22) + math.hypot(0.5 * (p11 - p22), p12)
    l2 = (p11 * p22 - p12 * p12) / l1
    a, b = 1.0 / sd2, 1.0 / st2
    kappa = max(l1, a, b / (r * r))
    C1 = (math.cos(phi0) * c[0] + math.sin(phi0) * c[1]) / r
    C2 = (-math.sin(phi0) * c[0] + math.cos(phi0) * c[1]) / r
    m1, m2, q1, q2 = (l2, l1, C2, C1) if swap else (l1, l2, C1, C2)
    return f3_coefficients(m1 / kappa, m2 / kappa, a / kappa, b / (r * r * kappa), q1, q2)


def test_guess_in_another_variable_or_missing_is_not_used():
    rng = np.random.default_rng(9)
    n = 64
    prior, c, r, rho, sd2, st2 = speed_circle_problems(rng, n)
    cold, roots = _solve_batch_unchecked(prior, c, r, rho, sd2, st2)
    flipped = CircleRoots(roots.roots, ~roots.swap, roots.certified)
    _, used = _solve_batch_unchecked(prior, c, r, rho, sd2, st2, flipped)
    assert not used.certified.any()
    missing = CircleRoots(np.full_like(roots.roots, np.nan), roots.swap, roots.certified)
    _, used = _solve_batch_unchecked(prior, c, r, rho, sd2, st2, missing)
    assert not used.certified.any()
    # Too few rows for the shortcut to pay: eigenvalues.
    few = slice(0, 8)
    sub = CircleRoots(roots.roots[few], roots.swap[few], roots.certified[few])
    args = (prior[few], c[few], r[few], rho[few], sd2[few], st2[few])
    _, used = _solve_batch_unchecked(*args, sub)
    assert not used.certified.any()
    # The same problems again from their own roots: certified (but where roots crowd,
    # near X = +-1 or in pairs, which the 1e-10 pin cannot reach), same answer.
    warm, used = _solve_batch_unchecked(prior, c, r, rho, sd2, st2, roots)
    assert used.certified.mean() >= 0.75
    np.testing.assert_allclose(warm.value, cold.value, rtol=1e-12)


def environment_problems(n):
    """Return sensor 0's problems of GSR's first sweep for ``n`` copies of the paper
    scenario after a few random steps: alike problems, as a batched environment's are."""
    from activetrack.envs.batched import BatchedActiveTracking

    env = BatchedActiveTracking(n, scenario="paper")
    env.reset(seed=2)
    rng = np.random.default_rng(2)
    for _ in range(3):
        env.step(rng.uniform(-1, 1, (n, 6)))
    p = env.params
    P, target, sensors = env.P_pred[:, :2, :2], env.x_pred[:, :2], env.sensors
    rel = sensors - target[:, None, :]
    info = np.linalg.inv(P)
    for j in (1, 2):  # the other sensors' information (eq. 17), written out
        x, y = rel[:, j, 0], rel[:, j, 1]
        n2 = x * x + y * y
        wd, wt = 1.0 / (p.sigma_d2[j] * n2), 1.0 / (p.sigma_theta2[j] * n2 * n2)
        a, b, c = wd * x * x + wt * y * y, (wd - wt) * x * y, wd * y * y + wt * x * x
        info = info + np.stack([a, b, b, c], -1).reshape(n, 2, 2)
    one = np.ones(n)
    params = (p.r[0], p.rho[0], p.sigma_d2[0], p.sigma_theta2[0])
    return (info, rel[:, 0]) + tuple(v * one for v in params)


@pytest.mark.parametrize("alike", [True, False])
def test_rows_without_a_guess_are_seeded_from_the_batch(alike):
    rng = np.random.default_rng(10)
    n = 600
    args = environment_problems(n) if alike else speed_circle_problems(rng, n)
    cold, _ = _solve_batch_unchecked(*args)
    none = CircleRoots(np.full((n, 10), np.nan, complex), np.zeros(n, bool), np.zeros(n, bool))
    seeded, used = _solve_batch_unchecked(*args, none)
    if alike:  # one row in 8 seeds (eigenvalues); most others certified from a seed's roots
        assert used.certified.mean() >= 0.6
    else:  # dissimilar problems make poor seeds: the probe stops it early
        assert used.certified.mean() <= 64 / n
    np.testing.assert_allclose(seeded.value, cold.value, rtol=1e-10)
    d = np.minimum(
        np.linalg.norm(seeded.s - cold.s, axis=1), np.linalg.norm(seeded.s + cold.s, axis=1)
    )
    assert np.all(d <= 1e-7 * np.maximum(1.0, np.linalg.norm(cold.s, axis=1)))


def test_nearest_seed_is_the_nearest_in_the_same_variable():
    rng = np.random.default_rng(12)
    q = rng.standard_normal((300, 10)) * 10.0 ** rng.uniform(-2, 6, (300, 10))
    swap = rng.random(300) < 0.3
    seeds = np.arange(0, 300, 7)
    rows = np.setdiff1d(np.arange(300), seeds)
    near = _nearest_seed(q, swap, seeds, rows)
    feat = np.sign(q) * np.log(1.0 + np.abs(q))
    for k, i in enumerate(rows):
        same = seeds[swap[seeds] == swap[i]]
        dist = np.linalg.norm(feat[same] - feat[i], axis=1)
        assert near[k] == same[np.argmin(dist)]
    # No seed in a row's variable: -1.
    only = seeds[~swap[seeds]]
    assert np.all(_nearest_seed(q, swap, only, rows)[swap[rows]] == -1)
