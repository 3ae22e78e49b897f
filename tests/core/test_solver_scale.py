"""The solver's accepted scale range: answer correctly inside it, refuse outside it.

Inputs are drawn over extreme magnitudes (1e-70 .. 1e70, prior condition numbers up to
1e12, ``||c|| / r`` and ``rho / r`` far beyond the range). Every input must either raise a
``ValueError`` that names a parameter, or give a finite answer that is feasible when it
says so, whose value is the objective at the returned point (evaluated independently in
400-digit arithmetic, which no float64 conditioning can spoil), and which is never worse
than the dense boundary search of ``test_solver.brute_force`` (run on the same problem
rescaled to ``r = 1`` and unit information, on which the objective is exactly scaled).
No RuntimeWarning may escape (``warnings.simplefilter("error")``) and LAPACK must print
nothing. Inputs inside the documented range (written out here from the module docstring,
with a margin) must be accepted.
"""

import math
import warnings
from unittest import mock

import mpmath as mp
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

from activetrack.solvers.analytic import solve_single_sensor, solve_single_sensor_batch
from tests.core import test_solver
from tests.core.test_solver import brute_force, rotation

NAMES = ("prior_info", "c", "r", "rho", "sigma_d2", "sigma_theta2")


def hp_f0(prior, s, sd2, st2, dps=400):
    """Return f0 (eq. 22) at ``s`` as ``tr(M) / det(M)`` of the information matrix built
    entry by entry (eq. 9) in ``dps``-digit arithmetic (exponents unbounded in mpmath)."""
    with mp.workdps(dps):
        x, y = mp.mpf(float(s[0])), mp.mpf(float(s[1]))
        n2 = x * x + y * y
        p, q = (x, y), (y, -x)  # s and J s
        m = [
            [
                mp.mpf(float(prior[i, j]))
                + p[i] * p[j] / (mp.mpf(float(sd2)) * n2)
                + q[i] * q[j] / (mp.mpf(float(st2)) * n2 * n2)
                for j in range(2)
            ]
            for i in range(2)
        ]
        return float((m[0][0] + m[1][1]) / (m[0][0] * m[1][1] - m[0][1] * m[1][0]))


def dense_search(prior, c, r, rho, sd2, st2):
    """Return the dense boundary search's optimum of the problem, via its rescaled twin.

    Lengths divided by ``r``: the range term of eq. (9) is scale-free and the bearing
    term scales as ``1 / |s|^2``, so ``sigma_theta2 r^2`` keeps the information. The
    information divided by ``mu`` (prior / mu, variances times mu) multiplies f0 by
    ``mu``. ``brute_force`` then sees O(1) lengths and information; its final values are
    taken in 400-digit arithmetic.
    """
    mu = max(np.linalg.eigvalsh(prior)[-1], 1.0 / sd2, 1.0 / (st2 * r * r))
    args = (prior / mu, c / r, 1.0, rho / r, sd2 * mu, st2 * mu * r * r)
    with mock.patch.object(test_solver, "mp_f0", hp_f0), np.errstate(all="ignore"):
        return brute_force(*args, n_total=20_000) / mu


def inside_range(l1, l2, nc, r, rho, sd2, st2, margin=1.01):
    """Return whether the drawn problem is inside the documented range, by ``margin``."""
    lo, hi = 1e-50 * margin, 1e50 / margin

    def ok(v):
        return v == 0.0 or lo <= v <= hi

    if not all(ok(v) for v in (l1, l2, nc, r, rho, sd2, st2)):
        return False
    if l1 / l2 > 1e8 / margin:
        return False
    if r > 0.0 and (nc > 1e5 / margin * r or 0.0 < rho < 1e-9 * margin * r):
        return False
    if r > 0.0:
        low, mid, top = sorted((l1, 1.0 / sd2, 1.0 / (st2 * r * r)))
        return mid >= 1e-30 * margin * top
    return True


def exponent(draw, wide):
    """Draw a decimal exponent: often ordinary, else anywhere in [-wide, wide]."""
    return draw(st.one_of(st.floats(-3.0, 3.0), st.floats(-wide, wide)))


@st.composite
def extreme_problems(draw, wide=70.0, max_cond=12.0):
    """Draw one problem spanning extreme magnitudes (and the edges of the range).

    Decimal exponents of the magnitudes up to ``wide``, of the prior's condition number
    up to ``max_cond``.
    """
    l1 = 10.0 ** exponent(draw, wide)
    l2 = l1 * 10.0 ** -draw(st.floats(0.0, max_cond))
    phi = draw(st.floats(0.0, math.pi))
    prior = rotation(phi) @ np.diag([l1, l2]) @ rotation(phi).T
    prior = 0.5 * (prior + prior.T)
    r = 0.0 if draw(st.integers(0, 9)) == 0 else 10.0 ** exponent(draw, wide)
    kind = draw(st.integers(0, 5))
    if kind == 0:
        nc = 0.0
    elif kind <= 3 and r > 0.0:
        nc = r * 10.0 ** draw(st.floats(-12.0, 8.0))
    else:
        nc = 10.0 ** exponent(draw, wide)
    ang = draw(st.floats(-math.pi, math.pi))
    c = nc * np.array([math.cos(ang), math.sin(ang)])
    kind = draw(st.integers(0, 4))
    if kind == 0:
        rho = 0.0
    elif kind <= 2:
        rho = nc * draw(st.floats(0.0, 1.3))
    elif r > 0.0:
        rho = r * 10.0 ** draw(st.floats(-14.0, 2.0))
    else:
        rho = 10.0 ** exponent(draw, wide)
    sd2 = 10.0 ** exponent(draw, wide)
    st2 = 10.0 ** exponent(draw, wide)
    return prior, c, r, rho, sd2, st2, (l1, l2)


SETTINGS = settings(
    max_examples=300,
    deadline=None,
    derandomize=True,
    suppress_health_check=[
        HealthCheck.too_slow,
        HealthCheck.filter_too_much,
        HealthCheck.function_scoped_fixture,
    ],
)


def solve_strictly(fn, *args):
    """Return ``fn(*args)`` or the ValueError it raised; any warning is an error."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        try:
            return fn(*args)
        except ValueError as exc:
            return exc


def check_answer(prior, c, r, rho, sd2, st2, s, value, feasible, cond):
    """Assert the answer is finite, feasible when claimed, exact in value and optimal."""
    assert np.all(np.isfinite(s)) and math.isfinite(value)
    nc = float(np.hypot(*c))
    # Relative accuracy of the objective where the prior dominates it: l2 is computed from
    # the determinant, good to a few eps * l1 (the module docstring's condition bound).
    tol = 1e-9 + 1e-14 * cond
    if not feasible:
        assert nc + r < rho
        np.testing.assert_allclose(s, c + r * (c / nc if nc > 0 else np.array([1.0, 0.0])))
        if np.any(s):
            assert value == pytest.approx(hp_f0(prior, s, sd2, st2), rel=tol)
        return
    assert np.hypot(*(s - c)) <= r * (1 + 1e-9)
    assert np.hypot(*s) >= rho * (1 - 1e-9)
    if r == 0.0 or not np.any(s):
        return  # stays put, or the rho = 0 infimum (tested in test_solver)
    true = hp_f0(prior, s, sd2, st2)
    assert value == pytest.approx(true, rel=tol)
    if rho > 0.0:  # the dense search needs a rho circle; rho = 0 is an infimum
        event("compared with the dense search")
        assert true <= dense_search(prior, c, r, rho, sd2, st2) * (1 + tol)


@pytest.mark.slow
@SETTINGS
@given(extreme_problems())
def test_scalar_answers_or_refuses(capfd, p):
    prior, c, r, rho, sd2, st2, (l1, l2) = p
    out = solve_strictly(solve_single_sensor, prior, c, r, rho, sd2, st2)
    assert capfd.readouterr().err == ""  # nothing from LAPACK
    if isinstance(out, ValueError):
        event("refused")
        assert any(name in str(out) for name in NAMES), str(out)
        assert not inside_range(l1, l2, float(np.hypot(*c)), r, rho, sd2, st2), str(out)
        return
    event("answered")
    check_answer(prior, c, r, rho, sd2, st2, out.s, out.value, out.feasible, l1 / l2)


@pytest.mark.slow
@SETTINGS
@given(extreme_problems(wide=48.0, max_cond=8.0))
def test_inside_the_range_every_answer_is_right(capfd, p):
    prior, c, r, rho, sd2, st2, (l1, l2) = p
    assume(inside_range(l1, l2, float(np.hypot(*c)), r, rho, sd2, st2))
    out = solve_strictly(solve_single_sensor, prior, c, r, rho, sd2, st2)
    assert capfd.readouterr().err == ""  # nothing from LAPACK
    assert not isinstance(out, ValueError), str(out)
    event("feasible" if out.feasible else "infeasible")
    check_answer(prior, c, r, rho, sd2, st2, out.s, out.value, out.feasible, l1 / l2)


@SETTINGS
@given(extreme_problems())
def test_batch_answers_or_refuses_as_the_scalar_solver(capfd, p):
    prior, c, r, rho, sd2, st2, (l1, l2) = p
    # The problem beside an ordinary one: a row outside the range fails the whole call.
    P = np.stack([prior, np.diag([2.0, 1.0])])
    C = np.stack([c, np.array([3.0, 1.0])])
    args = (np.array([r, 1.0]), np.array([rho, 0.5]), np.array([sd2, 0.1]))
    out = solve_strictly(solve_single_sensor_batch, P, C, *args, np.array([st2, 0.01]))
    one = solve_strictly(solve_single_sensor, prior, c, r, rho, sd2, st2)
    assert capfd.readouterr().err == ""  # nothing from LAPACK
    if isinstance(out, ValueError):
        assert any(name in str(out) for name in NAMES), str(out)
        assert isinstance(one, ValueError)  # the same inputs refused alike
        return
    assert not isinstance(one, ValueError)
    assert np.all(np.isfinite(out.s)) and np.all(np.isfinite(out.value))
    nc = float(np.hypot(*c))
    # ||c|| is math.hypot in one path and np.hypot in the other (last bit): the case and
    # feasibility are compared away from their boundaries ||c|| = r and ||c|| + r = rho.
    if abs(nc - r) > 1e-12 * nc and abs(nc + r - rho) > 1e-12 * (nc + r):
        assert out.feasible[0] == one.feasible and out.case[0] == one.case
    tol = 1e-10 + 1e-14 * l1 / l2
    assert out.value[0] == pytest.approx(one.value, rel=tol)
    if out.feasible[0]:
        assert np.hypot(*(out.s[0] - c)) <= r * (1 + 1e-9)
        assert np.hypot(*out.s[0]) >= rho * (1 - 1e-9)


@pytest.mark.parametrize(
    ("name", "kwargs", "why"),
    [
        ("r", dict(r=1e-170, c=[2e-170, 0.0], rho=1e-170), "r"),
        ("prior_info", dict(prior_info=np.diag([1e160, 1e160])), "entries"),
        ("prior_info", dict(prior_info=np.diag([1e45, 1e45]) * 1e6), "entries"),
        ("prior_info", dict(prior_info=np.diag([1e-45, 1e-55])), "smallest eigenvalue"),
        ("prior_info", dict(prior_info=np.diag([1.0, 1e-10])), "condition number"),
        ("c", dict(c=[1e80, 0.0]), "||c||"),
        ("c", dict(c=[1e40, 0.0]), "||c|| / r"),
        ("c", dict(c=[3e6, 1.0]), "||c|| / r"),
        ("sigma_d2", dict(sigma_d2=1e-150), "sigma_d2"),
        ("sigma_theta2", dict(sigma_theta2=1e150), "sigma_theta2"),
        ("sigma_theta2", dict(sigma_theta2=1e-40), "information scales"),
        ("rho", dict(rho=1e-12), "rho / r"),
    ],
)
def test_reported_failures_are_refused(name, kwargs, why):
    """The inputs of the hardening issue (and the range's other edges) raise, naming it."""
    base = dict(
        prior_info=np.array([[2.0, 0.3], [0.3, 1.0]]),
        c=[3.0, 1.0],
        r=1.0,
        rho=0.5,
        sigma_d2=0.1,
        sigma_theta2=0.01,
    )
    kw = dict(base, **kwargs)
    with pytest.raises(ValueError, match=name) as err:
        solve_single_sensor(**kw)
    assert why in str(err.value)
    # Float64 arrays and floats take the one-call path (checks in the compiled solve);
    # what it refuses is explained by the same named checks.
    arrays = dict(kw, prior_info=np.asarray(kw["prior_info"], float), c=np.asarray(kw["c"], float))
    with pytest.raises(ValueError, match=name) as fast:
        solve_single_sensor(**arrays)
    assert str(fast.value) == str(err.value)
    batch = {k: np.stack([np.asarray(v, dtype=float)] * 3) for k, v in kw.items()}
    with pytest.raises(ValueError, match=name):
        solve_single_sensor_batch(**batch)


@pytest.mark.kernels
def test_range_edges_are_decided_on_pythons_hypot():
    """At the edges ``||c|| / r = 1e5`` and ``||c|| = 1e-50`` the decision is the one the
    named checks explain: ``||c||`` by Python's ``math.hypot`` (correctly rounded; numba's
    differs in the last bit on about 0.6% of inputs), refused iff the product test and the
    quotient test both fail, whichever path (float64 arrays: checks in the compiled call;
    lists: the Python conversion) the inputs take."""
    rng = np.random.default_rng(7)
    prior = np.array([[2.0, 0.3], [0.3, 1.0]])
    for _ in range(600):
        ang = rng.uniform(-math.pi, math.pi)
        c = rng.uniform(0.5, 3.0) * np.array([math.cos(ang), math.sin(ang)])
        nc = math.hypot(*c)
        r = nc / 1e5 * (1.0 + rng.integers(-3, 4) * 2.2e-16)
        refused = nc > 1e5 * r and nc / r > 1e5
        tiny = c * 1e-50 / nc * (1.0 + rng.integers(-3, 4) * 2.2e-16)
        tiny_refused = math.hypot(*tiny) < 1e-50
        for cc, rr, expect in ((c, r, refused), (tiny, 1.0, tiny_refused)):
            for args in ((prior, cc, rr), (prior.tolist(), cc.tolist(), rr)):
                out = solve_strictly(solve_single_sensor, *args, 0.0, 1.0, 1.0)
                assert isinstance(out, ValueError) == expect, (cc, rr, out)


def test_nearly_singular_prior_is_refused_without_a_crash():
    """Symmetric within 1e-9 but singular once symmetrized: refused, naming prior_info."""
    P = np.array([[1.0, 1.0 + 4e-10], [1.0 - 4e-10, 1.0]])  # det = 1.6e-19 > 0 as given
    for solve, args in (
        (solve_single_sensor, (P, [3.0, 1.0], 1.0, 0.5, 0.1, 0.01)),
        (solve_single_sensor_batch, (P[None], [[3.0, 1.0]], 1.0, 0.5, 0.1, 0.01)),
    ):
        out = solve_strictly(solve, *args)
        assert isinstance(out, ValueError) and "prior_info" in str(out), out


def _edge_reaches(ratio: float, above: bool, n: int = 3) -> list[float]:
    """Return reaches ``r`` where the product ``ratio * r`` and the quotient disagree:
    ``fl(fl(ratio * r) / r)`` is above ``ratio`` (``above``) or below it."""
    out = []
    for r in np.random.default_rng(11).uniform(0.01, 10.0, 20000):
        q = (ratio * r) / r
        if (q > ratio) if above else (q < ratio):
            out.append(float(r))
            if len(out) == n:
                break
    return out


@pytest.mark.kernels
def test_the_range_edges_are_decided_alike_by_the_scalar_and_the_batched_solver():
    """At ``||c|| = 1e5 r`` and ``rho = 1e-9 r`` computed as products, where the quotients
    round past the bound, both solvers accept (one rule decides both, compiled) and agree
    bit for bit; one float further out, both refuse, naming the parameter."""
    from activetrack.solvers._inputs import MAX_DISTANCE_RATIO
    from activetrack.solvers._steps import RHO_FLOOR

    prior = np.array([[2.0, 0.3], [0.3, 1.0]])
    cases = [(r, MAX_DISTANCE_RATIO * r, 0.5 * r) for r in _edge_reaches(MAX_DISTANCE_RATIO, True)]
    cases += [(r, 3.0 * r, RHO_FLOOR * r) for r in _edge_reaches(RHO_FLOOR, False)]
    assert len(cases) == 6
    for r, nc, rho in cases:
        c = np.array([nc, 0.0])
        one = solve_single_sensor(prior, c, r, rho, 0.1, 0.01)
        batch = solve_single_sensor_batch(prior[None], c[None], [r], [rho], [0.1], [0.01])
        assert np.array_equal(batch.s[0], one.s) and batch.value[0] == one.value
        if nc > 10 * r:  # the ||c|| edge: one float farther
            far, near, why = np.array([np.nextafter(nc, np.inf), 0.0]), rho, r"\|\|c\|\| / r"
        else:  # the rho edge: one float nearer
            far, near, why = c, np.nextafter(rho, 0.0), "rho / r"
        with pytest.raises(ValueError, match=why):
            solve_single_sensor(prior, far, r, near, 0.1, 0.01)
        with pytest.raises(ValueError, match=why):
            solve_single_sensor_batch(prior[None], far[None], [r], [near], [0.1], [0.01])
