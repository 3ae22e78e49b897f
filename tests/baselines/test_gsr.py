"""GSR: feasibility, monotonicity from the warm start, optimality against brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from activetrack.baselines import GBES, GSR, random_problem
from activetrack.baselines.gsr import Relaxation
from activetrack.baselines.gsr_restarts import mirror
from activetrack.kinematics import geometry
from activetrack.world.problem import PlanningProblem


@st.composite
def problems(draw, max_sensors=4):
    """Random planning problems: any prior, sensors from inside rho to far away."""
    m = draw(st.integers(1, max_sensors))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    lo = draw(st.sampled_from([0.0, 1.0, 2.5]))
    hi = lo + draw(st.sampled_from([1.0, 3.0, 20.0]))
    p = random_problem(rng, m, distance=(lo + 1e-3, hi))
    r = draw(st.sampled_from([0.3, 1.0, 2.5]))
    rho = draw(st.sampled_from([0.5, 2.0]))
    return PlanningProblem(
        p.prior_cov,
        p.target + rng.normal(0, 5, 2),
        p.sensors + p.target,
        r,
        rho,
        p.sigma_d2,
        p.sigma_theta2,
    )


def _reachable(p: PlanningProblem) -> np.ndarray:
    nc = np.hypot(*p.rel_sensors.T)
    return nc + p.r >= p.rho


@settings(max_examples=60, deadline=None)
@given(problems(), st.booleans())
def test_gsr_is_feasible_and_never_worse_than_a_feasible_warm_start(p, restarts):
    res = GSR(restarts=restarts).plan_with_info(p)
    ok = _reachable(p)
    assert np.all(p.violation(res.positions)[ok] <= 1e-9)
    # Unreachable sensors take the farthest reachable point (closed form).
    c = p.rel_sensors[~ok]
    far = c + p.r[~ok, None] * c / np.hypot(*c.T)[:, None]
    assert np.allclose(res.positions[~ok] - p.target, far)
    assert res.value == pytest.approx(p.trace(res.positions), rel=1e-12)
    # The warm start: reachable sensors where they are, unreachable ones at the fallback.
    warm_feasible = bool(np.all(np.hypot(*p.rel_sensors[ok].T) >= p.rho[ok]))
    assert res.warm_feasible == warm_feasible
    if warm_feasible:
        warm = p.sensors.copy()
        warm[~ok] = far + p.target
        assert res.warm_value == pytest.approx(p.trace(warm), rel=1e-12)
        assert res.value <= p.trace(warm) * (1 + 1e-12)


def _dense_single_sensor(p: PlanningProblem) -> float:
    """Return the single-sensor optimum by dense sampling of the curve ADB plus polishing."""
    arcs = geometry.facing_boundary(p.rel_sensors[0], p.r[0], p.rho[0])
    best = math.inf
    for arc in arcs:
        t = np.linspace(arc.t0, arc.t1, 20001)
        vals = p.trace(arc.points(t)[:, None, :] + p.target)
        best = min(best, vals.min())
    return best


@pytest.mark.kernels
def test_gsr_single_sensor_is_the_global_optimum():
    rng = np.random.default_rng(11)
    for _ in range(20):
        p = random_problem(rng, 1, distance=(1.0, 8.0))
        res = GSR().plan_with_info(p)
        assert res.value <= _dense_single_sensor(p) * (1 + 1e-9)
        assert res.n_solves == 1  # one exact solve: nothing else can change


def test_gsr_restarts_match_the_gbes_grid_optimum():
    # The full 500-problem study is benchmarks/bench_gsr_restarts.py.
    rng = np.random.default_rng(2024)
    worst_plain, worst_restarts = 0.0, 0.0
    for _ in range(25):
        p = random_problem(rng, 3)
        grid = GBES().search(p).value
        worst_plain = max(worst_plain, GSR().plan_with_info(p).value / grid)
        worst_restarts = max(worst_restarts, GSR(restarts=True).plan_with_info(p).value / grid)
    assert worst_restarts <= 1 + 1e-6
    assert worst_plain <= 1.05  # plain GSR may stop in a local optimum, but not far off


def test_gsr_escapes_a_known_local_optimum():
    # A problem where GSR from the warm start stops 0.5% above the optimum (found by
    # bench_gsr_restarts.py); the restarts must find the optimum.
    rng = np.random.default_rng(12)
    for _ in range(100):
        p = random_problem(rng, 3)
        plain = GSR().plan_with_info(p).value
        grid = GBES().search(p).value
        if plain > grid * (1 + 1e-3):
            break
    else:
        pytest.skip("no local optimum in this sample")
    res = GSR(restarts=True).plan_with_info(p)
    assert res.value <= grid * (1 + 1e-6)
    assert res.start != "warm"


def test_mirror_preserves_the_objective():
    # Lemma 2: reflecting every sensor across a principal axis of the prior keeps eq. (17).
    rng = np.random.default_rng(4)
    for _ in range(10):
        p = random_problem(rng, 3, distance=(1.0, 10.0))
        run = Relaxation(p, 1e-9, 10)
        s = p.rel_sensors
        w, v = np.linalg.eigh(p.prior_info)
        axis = v[:, 1]  # the principal axis of the larger eigenvalue
        reflected = 2.0 * (s @ axis)[:, None] * axis - s  # independent construction
        assert np.allclose(mirror(run, s), reflected)
        assert p.trace(reflected + p.target) == pytest.approx(p.trace(p.sensors), rel=1e-12)


@pytest.mark.kernels
def test_gsr_converges_to_a_coordinatewise_optimum():
    # At GSR's answer no single sensor can improve (checked by dense sampling of its ADB).
    rng = np.random.default_rng(8)
    for _ in range(5):
        p = random_problem(rng, 3, distance=(1.0, 10.0))
        res = GSR(tol=1e-12).plan_with_info(p)
        rel = res.positions - p.target
        for i in range(3):
            arcs = geometry.facing_boundary(p.rel_sensors[i], p.r[i], p.rho[i])
            pts = geometry.discretize(arcs, 1e-3)
            trial = np.repeat(rel[None], len(pts), axis=0)
            trial[:, i] = pts
            assert p.trace(trial + p.target).min() >= res.value * (1 - 1e-7)


def test_gsr_fixed_sensors():
    p = PlanningProblem(
        np.eye(2),
        np.zeros(2),
        np.array([[3.0, 0.0], [0.0, 0.5], [5.0, 5.0]]),
        np.array([0.0, 1.0, 1.0]),
        2.0,
        1.0,
        0.5,
    )
    out = GSR(restarts=True).plan(p)
    assert np.allclose(out[0], [3.0, 0.0])
    assert np.allclose(out[1], [0.0, 1.5])
    assert np.hypot(*(out[2] - [5.0, 5.0])) <= 1.0 + 1e-9


def test_gsr_reports_sweeps_and_respects_max_sweeps():
    rng = np.random.default_rng(9)
    p = random_problem(rng, 8)
    g = GSR(max_sweeps=1)
    g.plan(p)
    assert g.last_sweeps == 1
    assert g.last_result.n_solves == 8
    g = GSR(tol=0.0, max_sweeps=50)
    g.plan(p)
    assert 1 <= g.last_sweeps <= 50


def test_gsr_cost_is_linear_in_the_team_size():
    # Solves per sensor (sweeps) should not grow with M.
    rng = np.random.default_rng(10)
    per_sensor = {}
    for m in (4, 32):
        solves = [GSR().plan_with_info(random_problem(rng, m)).n_solves for _ in range(5)]
        per_sensor[m] = np.mean(solves) / m
    assert per_sensor[32] <= 2.5 * per_sensor[4]


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"tol": -1e-3}, "tol"),
        ({"tol": float("nan")}, "tol"),
        ({"max_sweeps": 0}, "max_sweeps"),
        ({"max_sweeps": 2.5}, "max_sweeps"),
        ({"starts": ("nope",)}, "starts"),
        ({"starts": ()}, "starts"),
    ],
)
def test_gsr_rejects_bad_parameters(kwargs, word):
    with pytest.raises(ValueError, match=word):
        GSR(**kwargs)


def test_rho_zero_with_reachable_target_is_rejected():
    p = PlanningProblem(np.eye(2), np.zeros(2), np.array([[0.5, 0.0]]), 1.0, 0.0, 1.0, 1.0)
    with pytest.raises(ValueError, match="rho"):
        GSR().plan(p)


def test_gsr_on_a_batch_equals_gsr_copy_by_copy_and_never_worse_than_the_warm_start():
    # The batched sweep (vectorized solver) against the scalar GSR on each copy, and each
    # copy's value against the objective of its warm start computed here from the problem.
    rng = np.random.default_rng(21)
    singles = [random_problem(rng, 3, distance=(0.5, 6.0)) for _ in range(60)]
    batch = PlanningProblem.stack(singles)
    res = GSR().plan_with_info(batch)
    assert res.positions.shape == (60, 3, 2) and res.value.shape == (60,)
    np.testing.assert_allclose(res.value, batch.score(res.positions), rtol=1e-12)
    for b, p in enumerate(singles):
        ref = GSR().plan_with_info(p)
        # One compiled kernel for both: a copy is the single plan bit for bit.
        assert res.value[b] == ref.value and res.sweeps[b] == ref.sweeps
        assert res.n_solves[b] == ref.n_solves
        np.testing.assert_array_equal(res.positions[b], ref.positions)
        ok = _reachable(p)
        assert np.all(p.violation(res.positions[b])[ok] <= 1e-9)
        if np.all(np.hypot(*p.rel_sensors[ok].T) >= p.rho[ok]):  # feasible warm start
            warm = p.sensors.copy()
            c = p.rel_sensors[~ok]
            warm[~ok] = p.target + c + p.r[~ok, None] * c / np.hypot(*c.T)[:, None]
            assert res.value[b] <= p.score(warm) * (1 + 1e-12)


def test_gsr_keeps_extra_batch_axes_and_restarts_go_copy_by_copy():
    rng = np.random.default_rng(22)
    singles = [random_problem(rng, 2) for _ in range(6)]
    flat = PlanningProblem.stack(singles)
    grid = PlanningProblem(
        *(
            getattr(flat, k).reshape((2, 3) + getattr(flat, k).shape[1:])
            for k in ("prior_cov", "target", "sensors", "r", "rho", "sigma_d2", "sigma_theta2")
        )
    )
    assert grid.batch_shape == (2, 3)
    np.testing.assert_array_equal(GSR().plan(grid).reshape(6, 2, 2), GSR().plan(flat))
    out = GSR(restarts=True).plan(grid)
    for b, p in enumerate(singles):
        np.testing.assert_array_equal(out[b // 3, b % 3], GSR(restarts=True).plan(p))


def test_an_objective_not_built_on_the_base_is_refused_by_the_problem():
    class LogDet:
        name = "logdet"

        def of_information(self, Y):
            return -np.log(np.linalg.det(Y))

    p = random_problem(np.random.default_rng(0), 2)
    with pytest.raises(ValueError, match="objective"):
        PlanningProblem(
            p.prior_cov, p.target, p.sensors, p.r, p.rho, p.sigma_d2, p.sigma_theta2,
            objective=LogDet(),
        )  # fmt: skip


def test_gsr_takes_its_exact_step_only_for_the_trace_itself_not_for_its_name():
    from activetrack.models.objective import TRACE, TraceObjective

    class Named(TraceObjective):  # another objective that calls itself "trace"
        def of_entries(self, a, b, c):
            return (0.5 * (a + c) + np.hypot(0.5 * (a - c), b)) / (a * c - b * b)

    class Same(TraceObjective):  # the trace's arithmetic under another class
        name = "same"

    rng = np.random.default_rng(11)
    for _ in range(4):
        p = random_problem(rng, 3)
        args = (p.prior_cov, p.target, p.sensors, p.r, p.rho, p.sigma_d2, p.sigma_theta2)
        named = PlanningProblem(*args, objective=Named())
        assert not named.is_paper
        res = GSR().plan_with_info(named)
        # The value is the objective's own: the largest eigenvalue of the posterior,
        # longhand from the range and bearing Jacobian rows (eq. 9).
        Y = np.linalg.inv(p.prior_cov)
        for s, sd2, st2 in zip(res.positions, p.sigma_d2, p.sigma_theta2, strict=True):
            d = p.target - s
            n2 = d @ d
            h_range, h_bearing = d / np.sqrt(n2), np.array([-d[1], d[0]]) / n2
            Y += np.outer(h_range, h_range) / sd2 + np.outer(h_bearing, h_bearing) / st2
        assert res.value == pytest.approx(np.linalg.eigvalsh(np.linalg.inv(Y))[-1], rel=1e-10)
        # Numerical steps on the trace's arithmetic reach the exact solver's value.
        same = GSR(tol=1e-12).plan_with_info(PlanningProblem(*args, objective=Same()))
        exact = GSR(tol=1e-12).plan_with_info(PlanningProblem(*args, objective=TRACE))
        assert same.value == pytest.approx(exact.value, rel=1e-6)


def test_gsr_plans_other_objectives_numerically_never_worse_than_its_start():
    from activetrack.models.objective import LOGDET, WORST_TRACE

    rng = np.random.default_rng(3)
    for obj in (LOGDET, WORST_TRACE):
        for _ in range(5):
            p = random_problem(rng, 3)
            q = PlanningProblem(
                p.prior_cov, p.target, p.sensors, p.r, p.rho, p.sigma_d2, p.sigma_theta2,
                objective=obj,
            )  # fmt: skip
            res = GSR().plan_with_info(q)
            assert np.max(q.violation(res.positions)) <= 1e-9
            # The value is the problem's own score of the positions, at most the warm start's.
            assert res.value == pytest.approx(float(q.score(res.positions)), rel=1e-12)
            assert res.value <= float(q.score(p.sensors)) + 1e-12 or np.any(
                p.violation(p.sensors) > 0
            )


def _dense_min(others, c, r, rho, sd2, st2):
    """Return the least ``tr((others + info(s))^-1)`` over a dense sampling of the feasible
    set ``|s - c| <= r``, ``|s| >= rho`` (speed circle, rho circle and a 300x300 grid)."""
    t = np.linspace(-np.pi, np.pi, 20_001)
    ring = np.stack([np.cos(t), np.sin(t)], -1)
    g = np.linspace(-1.0, 1.0, 300)
    grid = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    pts = np.concatenate([c + r * ring, rho * ring, c + r * grid])
    pts = pts[(np.linalg.norm(pts - c, axis=1) <= r) & (np.linalg.norm(pts, axis=1) >= rho)]
    x, y = pts[:, 0], pts[:, 1]
    d = x * x + y * y
    a, b = 1.0 / (sd2 * d), 1.0 / (st2 * d * d)  # range and bearing information (eq. 17)
    m11 = others[0, 0] + a * x * x + b * y * y
    m22 = others[1, 1] + a * y * y + b * x * x
    m12 = others[0, 1] + (a - b) * x * y
    return float(np.min((m11 + m22) / (m11 * m22 - m12 * m12)))


def test_the_sweeps_solver_call_is_the_global_optimum_of_the_subproblem():
    """Relaxation.solve calls the solver's kernel directly: on GSR's own subproblems its
    point is feasible and no worse than a dense search of the feasible set (eq. 38)."""
    from activetrack.models.objective import sensor_information

    rng = np.random.default_rng(5)
    for _ in range(10):
        problem = random_problem(rng, 3, distance=(0.5, 6.0))
        run = Relaxation(problem, 1e-9, 100)
        info = sensor_information(problem.rel_sensors, problem.sigma_d2, problem.sigma_theta2)
        for i in range(3):
            others = problem.prior_info + info.sum(axis=0) - info[i]
            c, r, rho = problem.rel_sensors[i], problem.r[i], problem.rho[i]
            sd2, st2 = problem.sigma_d2[i], problem.sigma_theta2[i]
            s = run.solve(others, i)
            if np.linalg.norm(c) + r < rho:
                continue  # infeasible: nothing to compare
            assert np.linalg.norm(s - c) <= r * (1 + 1e-9)
            assert np.linalg.norm(s) >= rho * (1 - 1e-9)
            x, y = s
            d = x * x + y * y
            m = (
                others
                + np.array([[x * x, x * y], [x * y, y * y]]) / (sd2 * d)
                + np.array([[y * y, -x * y], [-x * y, x * x]]) / (st2 * d * d)
            )
            value = np.trace(np.linalg.inv(m))
            assert value <= _dense_min(others, c, r, rho, sd2, st2) * (1 + 1e-9)


@pytest.mark.kernels
def test_compiled_sweeps_follow_the_python_relaxation_rules():
    """The compiled plain sweeps (``GSR()``) and the Python ``Relaxation`` that the restarts
    and pattern moves use: the same rules, so the same plan, value, sweeps and solves."""
    from activetrack.baselines.gsr import Relaxation

    rng = np.random.default_rng(31)
    for m in (1, 2, 3, 4):
        for _ in range(5):
            p = random_problem(rng, m, distance=(0.5, 8.0))
            res = GSR().plan_with_info(p)
            run = Relaxation(p, 1e-9, 100)
            warm, feasible = run.warm_start()
            s, value, converged = run.relax(warm, True, False)  # the warm start is feasible
            np.testing.assert_array_equal(res.positions, s + p.target)
            assert res.value == value and res.converged == converged
            assert (res.sweeps, res.n_solves) == (run.sweeps, run.n_solves)
            assert res.warm_value == run.start_value and res.warm_feasible == feasible


@pytest.mark.kernels
def test_sensor_modes_and_warm_start_follow_their_geometry():
    """The compiled modes and warm start on 400 sensors of every kind (free, still, unable
    to leave the rho disk, starting inside it), by their definitions: free iff it can move
    and its speed disk leaves the rho disk; a sensor that cannot gets the reachable point
    farthest from the target; a free one inside its rho disk starts from the nearest
    feasible point, found by dense sampling of the speed disk."""
    from activetrack.baselines._common import sensor_modes_of
    from activetrack.baselines.gsr import warm_start

    rng = np.random.default_rng(21)
    n = 400
    ang = rng.uniform(-np.pi, np.pi, n)
    nc = rng.uniform(0.05, 4.0, n)
    c = (nc * np.stack([np.cos(ang), np.sin(ang)])).T.reshape(100, 4, 2)
    r = np.where(rng.random(n) < 0.1, 0.0, rng.uniform(0.1, 2.0, n)).reshape(100, 4)
    rho = rng.uniform(0.5, 4.0, n).reshape(100, 4)
    free, fixed = sensor_modes_of(c, r, rho)
    norm = np.hypot(c[..., 0], c[..., 1])
    np.testing.assert_array_equal(free, (r > 0) & (norm + r >= rho))
    away = (r > 0) & ~free
    assert away.sum() > 10 and (~free & (r == 0)).sum() > 10
    np.testing.assert_allclose(
        fixed[away], c[away] + (r[away] / norm[away])[:, None] * c[away], rtol=1e-14
    )
    np.testing.assert_array_equal(fixed[~away], c[~away])
    s, inside = warm_start(c, r, rho, free, fixed)
    np.testing.assert_array_equal(inside, free & (norm < rho))
    np.testing.assert_array_equal(s[~inside], fixed[~inside])
    assert inside.sum() > 20
    t = np.linspace(0, 1, 400)  # radii: steps of r / 399
    phi = np.linspace(-np.pi, np.pi, 721)
    disk = (t[:, None, None] * np.stack([np.cos(phi), np.sin(phi)], -1)).reshape(-1, 2)
    for b, i in zip(*np.nonzero(inside), strict=True):
        q = c[b, i] + r[b, i] * disk  # the speed disk, sampled
        ok = np.hypot(q[:, 0], q[:, 1]) >= rho[b, i]
        best = np.min(np.hypot(*(q[ok] - c[b, i]).T))
        got = s[b, i]
        assert np.hypot(*got) >= rho[b, i] * (1 - 1e-12)
        assert np.hypot(*(got - c[b, i])) <= r[b, i] * (1 + 1e-12)
        assert np.hypot(*(got - c[b, i])) <= best + 1e-12
        # Not farther than a sample next to it (a radial and an angular step).
        assert np.hypot(*(got - c[b, i])) >= best - r[b, i] / 399 - best * 2 * np.pi / 720
