"""The global numerical single-sensor solver against the exact analytic solver and dense search.

References, computed independently of the solver's candidates and refinement:

- the paper's case (K = 1, range and bearing, known pose, trace): the analytic solver of
  Section IV-A (:func:`activetrack.solvers.analytic.solve_single_sensor`), its value recomputed
  here from eq. (17) written out longhand;
- every other case: a dense search of F (a uniform grid over the reach disk, kept where
  feasible, plus dense samples of every circle, kept where feasible), with the objective
  written out longhand (2x2 inverse, J_eff of the design note via (J0^-1 + Sigma)^-1).
"""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from activetrack.models.objective import LOGDET, TRACE, WORST_TRACE
from activetrack.solvers import numeric as solver_numeric
from activetrack.solvers.analytic import solve_single_sensor

from .helpers import random_spd


def longhand_information(s, target, w_d, w_theta, pose_cov):
    """Return sensor information about one target, (..., 2, 2): H^T (R + H S H^T)^-1 H.

    Textbook form with the used rows of the Jacobian (eq. 9, wrt the target) only.
    """
    p = s - target
    n2 = p[..., 0] ** 2 + p[..., 1] ** 2
    u = p / np.sqrt(n2)[..., None]
    v = np.stack([u[..., 1], -u[..., 0]], -1) / np.sqrt(n2)[..., None]
    rows, noise = [], []
    if w_d > 0:
        rows.append(-u)
        noise.append(1.0 / w_d)
    if w_theta > 0:
        rows.append(v)
        noise.append(1.0 / w_theta)
    H = np.stack(rows, -2)  # (..., m, 2)
    R = np.diag(noise)
    if pose_cov is not None:
        R = R + H @ pose_cov @ np.swapaxes(H, -1, -2)
    return np.swapaxes(H, -1, -2) @ np.linalg.solve(R, H)


def longhand_objective(s, targets, prior_info, w_d, w_theta, pose_cov, objective):
    """Return the objective at points s (..., 2): per target Y_k = prior_k + J(s - t_k)."""
    per = []
    for k in range(len(targets)):
        Y = prior_info[k] + longhand_information(s, targets[k], w_d, w_theta, pose_cov)
        if objective is LOGDET:
            per.append(-np.log(np.linalg.det(Y)))
        else:
            per.append(np.trace(np.linalg.inv(Y), axis1=-2, axis2=-1))
    per = np.stack(per, -1)
    return per.max(-1) if objective is WORST_TRACE else per.sum(-1)


def dense_feasible_points(center, r, targets, rho, n_grid=160, n_circle=4000, at_least=20_000):
    """Return feasible points of F: a grid over the reach disk and samples of every circle.

    The grid is refined until at least ``at_least`` points are feasible (if F has area).
    """
    pts = _dense(center, r, targets, rho, n_grid, n_circle)
    while len(pts) < at_least and len(pts) > 0 and n_grid < 2000:
        n_grid *= 2
        pts = _dense(center, r, targets, rho, n_grid, n_circle)
    return pts


def _dense(center, r, targets, rho, n_grid, n_circle):
    u = np.linspace(-r, r, n_grid)
    X, Yg = np.meshgrid(u, u)
    grid = center + np.stack([X.ravel(), Yg.ravel()], -1)
    ang = np.linspace(0.0, 2.0 * np.pi, n_circle, endpoint=False)
    ring = np.stack([np.cos(ang), np.sin(ang)], -1)
    pts = [grid, center + r * ring] + [t + rho * ring for t in targets]
    pts = np.concatenate(pts)
    ok = np.linalg.norm(pts - center, axis=-1) <= r * (1 + 1e-12)
    for t in targets:
        ok &= np.linalg.norm(pts - t, axis=-1) >= rho * (1 - 1e-12)
    return pts[ok]


def random_case(rng, k):
    """Return a random K-target problem: layout, priors, model, pose covariance."""
    center = rng.normal(size=2)
    r = rng.uniform(0.2, 2.0)
    targets = center + rng.normal(size=(k, 2)) * rng.uniform(0.5, 3.0)
    rho = r * rng.uniform(0.05, 0.8)
    priors = np.array([random_spd(rng, 2, rng.uniform(0.1, 5.0)) for _ in range(k)])
    model = rng.integers(0, 3)
    w_d = 0.0 if model == 2 else 10 ** rng.uniform(-1, 1.5)
    w_theta = 0.0 if model == 1 else 10 ** rng.uniform(-1, 1.5)
    pose_cov = random_spd(rng, 2, 10 ** rng.uniform(-3, -0.5)) if rng.random() < 0.5 else None
    return center, r, targets, rho, priors, w_d, w_theta, pose_cov


def analytic_problem(rng):
    """Return a random instance of the paper's problem Pi_3 (eq. 22-24), target at 0."""
    prior = random_spd(rng, 2, rng.uniform(0.1, 10.0))
    c = rng.normal(size=2) * rng.uniform(0.3, 5.0)
    r = rng.uniform(0.1, 3.0)
    rho = r * 10 ** rng.uniform(-3, 0.3)
    return prior, c, r, rho, 10 ** rng.uniform(-2, 1), 10 ** rng.uniform(-3, 0)


@pytest.mark.slow
def test_paper_case_matches_the_analytic_solver():
    rng = np.random.default_rng(12)
    n = 2000
    probs = [analytic_problem(rng) for _ in range(n)]
    prior = np.array([q[0] for q in probs])
    c = np.array([q[1] for q in probs])
    r, rho, sd2, st2 = (np.array([q[i] for q in probs]) for i in range(2, 6))
    origin = np.zeros((n, 1, 2))
    base = (prior[:, None, 0, 0], prior[:, None, 0, 1], prior[:, None, 1, 1])
    pos, val = solver_numeric.solve_sensor(base, c, r, origin, rho, 1 / sd2, 1 / st2)
    assert pos.shape == (n, 2) and val.shape == (n,)
    for i in range(n):
        exact = solve_single_sensor(prior[i], c[i], r[i], rho[i], sd2[i], st2[i])
        f_exact, f_mine = (
            longhand_objective(s, origin[i], prior[i][None], 1 / sd2[i], 1 / st2[i], None, TRACE)
            for s in (exact.s, pos[i])
        )
        assert abs(f_mine - f_exact) <= 1e-6 * f_exact, i
        # Both evaluations are good to about cond(Y) eps (Y is ill-conditioned near the target).
        assert abs(val[i] - f_mine) <= 1e-8 * f_mine
        assert np.linalg.norm(pos[i] - c[i]) <= r[i] * (1 + 1e-12)
        # Where F is empty both return the reachable point farthest from the target.
        assert np.linalg.norm(pos[i]) >= rho[i] * (1 - 1e-12) or not exact.feasible


@pytest.mark.slow
@pytest.mark.parametrize("objective", [TRACE, WORST_TRACE, LOGDET], ids=repr)
@pytest.mark.parametrize("k", [1, 2, 3, 4])
def test_never_worse_than_dense_search(k, objective):
    rng = np.random.default_rng(100 * k + len(repr(objective)))
    for _ in range(12):
        center, r, targets, rho, priors, w_d, w_theta, pose_cov = random_case(rng, k)
        pts = dense_feasible_points(center, r, targets, rho)
        assert len(pts) >= 20_000
        ref = longhand_objective(pts, targets, priors, w_d, w_theta, pose_cov, objective).min()
        base = (priors[:, 0, 0], priors[:, 0, 1], priors[:, 1, 1])
        pos, val = solver_numeric.solve_sensor(
            base, center, r, targets, rho, w_d, w_theta, pose_cov, objective
        )
        mine = longhand_objective(pos, targets, priors, w_d, w_theta, pose_cov, objective)
        assert mine <= ref + 1e-6 * abs(ref)
        assert abs(val - mine) <= 1e-8 * abs(mine)
        assert np.linalg.norm(pos - center) <= r * (1 + 1e-12)
        assert np.all(np.linalg.norm(pos - targets, axis=-1) >= rho * (1 - 1e-12))


def solve_one(case, objective=TRACE, **kw):
    center, r, targets, rho, priors, w_d, w_theta, pose_cov = case
    base = (priors[:, 0, 0], priors[:, 0, 1], priors[:, 1, 1])
    return solver_numeric.solve_sensor(
        base, center, r, targets, rho, w_d, w_theta, pose_cov, objective, **kw
    )


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), k=st.integers(1, 4))
def test_batched_rows_equal_single_calls(seed, k):
    rng = np.random.default_rng(seed)
    cases = [random_case(rng, k) for _ in range(5)]
    # Same model and pose covariance for the batch; per-row layouts, priors and weights.
    w_d, w_theta, pose_cov = cases[0][5], cases[0][6], cases[0][7]
    cases = [(*c[:5], w_d, w_theta, pose_cov) for c in cases]
    stack = [np.array([c[i] for c in cases]) for i in range(5)]
    center, r, targets, rho, priors = stack
    base = (priors[..., 0, 0], priors[..., 0, 1], priors[..., 1, 1])
    pc = None if pose_cov is None else np.broadcast_to(pose_cov, (5, 2, 2))
    pos, val = solver_numeric.solve_sensor(base, center, r, targets, rho, w_d, w_theta, pc)
    for i, case in enumerate(cases):
        p1, v1 = solve_one(case)
        assert p1.shape == (2,) and v1.shape == ()
        np.testing.assert_allclose(val[i], v1, rtol=1e-12)
        np.testing.assert_allclose(pos[i], p1, rtol=0, atol=1e-9)


def test_leading_axes_and_determinism():
    rng = np.random.default_rng(3)
    k = 2
    priors = np.array([[random_spd(rng, 2) for _ in range(k)] for _ in range(6)]).reshape(
        2, 3, k, 2, 2
    )
    base = (priors[..., 0, 0], priors[..., 0, 1], priors[..., 1, 1])
    center = rng.normal(size=(2, 3, 2))
    targets = rng.normal(size=(2, 3, k, 2)) * 2
    args = (base, center, 1.0, targets, 0.3, 1.0, rng.uniform(1, 5, (2, 3)))
    pos, val = solver_numeric.solve_sensor(*args)
    assert pos.shape == (2, 3, 2) and val.shape == (2, 3)
    pos2, val2 = solver_numeric.solve_sensor(*args)
    np.testing.assert_array_equal(pos, pos2)
    np.testing.assert_array_equal(val, val2)


def test_special_cases_are_finite():
    prior = np.eye(2)[None]
    base = (prior[:, 0, 0], prior[:, 0, 1], prior[:, 1, 1])
    t = np.array([[0.0, 0.0]])
    # r = 0: the sensor stays, feasible or not.
    for c in ([2.0, 0.0], [0.1, 0.0]):
        pos, val = solver_numeric.solve_sensor(base, c, 0.0, t, 0.5, 1.0, 2.0)
        np.testing.assert_array_equal(pos, c)
        want = longhand_objective(np.array(c), t, prior, 1.0, 2.0, None, TRACE)
        np.testing.assert_allclose(val, want, rtol=1e-12)
    # F empty: the fallback point of feasible_set, with its (finite) value.
    pos, val = solver_numeric.solve_sensor(base, [0.3, 0.0], 0.5, t, 2.0, 1.0, 2.0)
    np.testing.assert_allclose(pos, [0.8, 0.0], atol=1e-15)
    assert np.isfinite(val)
    # rho = 0 with a target on the grid (zero distance: no information about it there).
    two = np.array([[0.0, 0.0], [1.0, 0.0]])
    pr2 = np.stack([np.eye(2), np.eye(2)])
    base2 = (pr2[:, 0, 0], pr2[:, 0, 1], pr2[:, 1, 1])
    pos, val = solver_numeric.solve_sensor(base2, [0.0, 0.0], 1.0, two, 0.0, 1.0, 1.0)
    assert np.all(np.isfinite(pos)) and np.isfinite(val)
    # r = 0 with two targets (the interior grids collapse onto the sensor): it stays.
    pos, val = solver_numeric.solve_sensor(base2, [0.5, 0.5], 0.0, two, 0.2, 1.0, 1.0)
    np.testing.assert_array_equal(pos, [0.5, 0.5])
    want = longhand_objective(np.array([0.5, 0.5]), two, pr2, 1.0, 1.0, None, TRACE)
    np.testing.assert_allclose(val, want, rtol=1e-12)
    # Bearing only with a pose covariance, range only: finite.
    for w_d, w_t in ((0.0, 3.0), (3.0, 0.0)):
        pos, val = solver_numeric.solve_sensor(
            base2, [0.5, 0.5], 1.0, two, 0.2, w_d, w_t, 0.01 * np.eye(2), WORST_TRACE
        )
        assert np.all(np.isfinite(pos)) and np.isfinite(val)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), k=st.integers(1, 3))
def test_prepared_solves_equal_fresh_solves(seed, k):
    """A prepared batch solved for two bases gives a fresh solve's answer for each; with
    ``remember`` (the relaxation's warm refinement) the second is the same optimum to the
    refinement's tolerance, never worse than the fresh solve's by more than 1e-9."""
    rng = np.random.default_rng(seed)
    case = random_case(rng, k)
    center, r, targets, rho, priors, w_d, w_theta, pose_cov = case
    pc = None if pose_cov is None else pose_cov[None]
    prepared = solver_numeric.prepare(
        center[None], np.array([r]), targets[None], np.array([rho]), np.array([w_d]),
        np.array([w_theta]), pc,
    )  # fmt: skip
    warm = solver_numeric.prepare(
        center[None], np.array([r]), targets[None], np.array([rho]), np.array([w_d]),
        np.array([w_theta]), pc,
    )  # fmt: skip
    warm.remember = True
    for step in range(3):
        # The other sensors' information grows a little each sweep.
        grown = priors + step * 0.05 * np.array([random_spd(rng, 2) for _ in range(k)])
        base = (grown[:, 0, 0], grown[:, 0, 1], grown[:, 1, 1])
        fresh_pos, fresh_val = solve_one((*case[:4], grown, *case[5:]))
        pos, val = solver_numeric.solve_prepared(prepared, tuple(b[None] for b in base))
        np.testing.assert_array_equal(pos[0], fresh_pos)
        np.testing.assert_array_equal(val[0], fresh_val)
        wpos, wval = solver_numeric.solve_prepared(warm, tuple(b[None] for b in base))
        assert wval[0] <= fresh_val + 1e-9 * abs(fresh_val)
        mine = longhand_objective(wpos[0], targets, grown, w_d, w_theta, pose_cov, TRACE)
        assert abs(wval[0] - mine) <= 1e-8 * abs(mine)
        assert np.linalg.norm(wpos[0] - center) <= r * (1 + 1e-12)
        assert np.all(np.linalg.norm(wpos[0] - targets, axis=-1) >= rho * (1 - 1e-12))
