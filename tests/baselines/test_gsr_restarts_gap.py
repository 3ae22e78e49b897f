"""GSR(restarts=True) against an independent global optimum, sensors close to the target.

The class of problems (issue 14, "GSR's own gap"): three sensors within 1.5 reaches of the
predicted target, each with its own reach ``r`` and minimum distance ``rho``, a random
prior and random noise. There the curves ADB (Lemma 3) are short arcs of the ``rho``
circles and of the reach circles meeting at corners, optima often sit at corners, and the
prior is often weak next to the sensors' information, so that turning the team together
is a flat valley along which coordinate descent crawls. The restarts used to end up to
2.3e-4 above the optimum on such problems (64 of 300 by more than 1e-9).

The reference (:func:`reference_optimum`) is computed here without GSR: an exhaustive
grid over every sensor's curve ADB (about 2e6 combinations, arc end points included),
every local minimum of that grid within :data:`WINDOW` of its best, and the GBES
optimum at pi/200, each refined by a bounded quasi-Newton search (scipy's L-BFGS-B,
finite-difference gradients) over the sensors' angles on their arcs, trying both arcs
at a corner. The objective is written out again from eq. (17) with explicit 2x2 algebra.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

from activetrack.baselines import GBES, GSR
from activetrack.baselines.gsr import Relaxation
from activetrack.baselines.gsr_restarts import _ArcSet
from activetrack.kinematics import geometry
from activetrack.world.problem import PlanningProblem

#: Grid combinations of the reference's exhaustive search.
COMBINATIONS = 2_000_000
#: Grid local minima within this (relative) of the grid's best are refined. The grid's own
#: error is first order in its step at a corner that is not a grid point (none: arc end
#: points are grid points) and second order at a smooth minimum: with about 125 points
#: per sensor, about (27 / 125)^2 ~ 1/20 of that of GSR's 27-point coarse grid, which
#: reaches 2e-3, so about 1e-4. A basin whose refined optimum beats the best has a grid
#: local minimum within that error of the grid's best.
WINDOW = 1e-3
#: At most this many grid local minima are refined.
MAX_STARTS = 40
#: GSR's answer must be within this (relative) of the reference: the reference is itself
#: a refined continuous optimum (its L-BFGS-B stops within about 1e-13), so the margin
#: covers rounding and GSR's own stopping tolerance (1e-9 per sweep), not a grid error.
RTOL = 1e-9

#: Seeds of :func:`close_problem` on which GSR(restarts=True) missed before this test
#: (commit d6b3f70), its gap to the reference then, and why: "valley" (coordinate descent
#: crawled and stopped short; the joint polish alone closes it) or "basin" (the optimum
#: lies in a basin no start reached). ``tools/search_gsr_gap.py --old`` lists them: 64 of
#: seeds 0-299 missed by more than 1e-9, 20 by more than 1e-6.
KNOWN_MISSES = {
    227: (2.3e-4, "valley"),
    172: (1.9e-4, "basin"),
    192: (1.5e-4, "valley"),
    249: (5.8e-5, "basin"),
    5: (5.5e-5, "basin and valley"),
    84: (4.4e-5, "valley"),
    # Sensor 0's rho arc has nearly opposite ends: a point near one end and the other end's
    # reflection carry nearly the same information but lie in different basins.
    287: (2.7e-9, "basin"),
}


def close_problem(rng: np.random.Generator, n_sensors: int = 3) -> PlanningProblem:
    """Return a random problem with every sensor within 1.5 reaches of the target.

    Per sensor: ``r`` uniform in [0.5, 1.5], ``rho / r`` uniform in [0.2, 2], distance
    uniform in ``(max(rho - r, 0), 1.5 r)`` (so the minimum distance can be kept and the
    sensor is free), direction uniform; the prior as in ``random_problem`` (eigenvalues
    log-uniform in [0.05, 20], random orientation), range variances in [0.5, 5] m^2 and
    bearing variances in [0.05, 1] rad^2, the predicted target anywhere.
    """
    eig = np.exp(rng.uniform(np.log(0.05), np.log(20.0), 2))
    phi = rng.uniform(0.0, np.pi)
    rot = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    cov = rot @ np.diag(eig) @ rot.T
    r = rng.uniform(0.5, 1.5, n_sensors)
    rho = r * rng.uniform(0.2, 2.0, n_sensors)
    lo = np.maximum(rho - r, 0.0) + 1e-3 * r
    dist = rng.uniform(lo, 1.5 * r)
    ang = rng.uniform(0.0, 2.0 * np.pi, n_sensors)
    target = rng.normal(0.0, 5.0, 2)
    rel = dist[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    return PlanningProblem(
        prior_cov=0.5 * (cov + cov.T),
        target=target,
        sensors=target + rel,
        r=r,
        rho=rho,
        sigma_d2=rng.uniform(0.5, 5.0, n_sensors),
        sigma_theta2=rng.uniform(0.05, 1.0, n_sensors),
    )


def _entries(p: PlanningProblem, i: int, pts: np.ndarray) -> tuple[np.ndarray, ...]:
    """Return sensor ``i``'s information entries (a, b, c) at relative points (K, 2), eq. (17).

    Range along ``u = p / |p|`` with variance sigma_d^2, bearing across it with variance
    sigma_theta^2 |p|^2.
    """
    d2 = pts[:, 0] ** 2 + pts[:, 1] ** 2
    ux, uy = pts[:, 0] / np.sqrt(d2), pts[:, 1] / np.sqrt(d2)
    wr, wb = 1.0 / p.sigma_d2[i], 1.0 / (p.sigma_theta2[i] * d2)
    return wr * ux * ux + wb * uy * uy, (wr - wb) * ux * uy, wr * uy * uy + wb * ux * ux


def _trace(p: PlanningProblem, rel: np.ndarray) -> float:
    """Return tr((P11^{-1} + sum_i info_i)^{-1}) for one configuration (M, 2), explicitly."""
    y = np.linalg.inv(p.prior_cov)
    for i, q in enumerate(rel):
        a, b, c = (e[0] for e in _entries(p, i, q[None, :]))
        y = y + np.array([[a, b], [b, c]])
    det = y[0, 0] * y[1, 1] - y[0, 1] ** 2
    return float((y[0, 0] + y[1, 1]) / det)


def _grid(arcs: list[geometry.Arc], n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return about ``n`` points on ``arcs`` by arc length, end points included:
    points (K, 2), their arc index (K,) and angle (K,)."""
    total = sum(a.length for a in arcs)
    pts, which, ang = [], [], []
    for k, arc in enumerate(arcs):
        m = max(2, int(math.ceil(n * arc.length / total)))
        t = np.linspace(arc.t0, arc.t1, m)
        pts.append(arc.points(t))
        which.append(np.full(m, k))
        ang.append(t)
    return np.concatenate(pts), np.concatenate(which), np.concatenate(ang)


def _arcs_at(arcs: list[geometry.Arc], q: np.ndarray) -> list[tuple[int, float]]:
    """Return ``(arc index, angle)`` of every arc passing through ``q`` (to 1e-9)."""
    out = []
    for k, arc in enumerate(arcs):
        t = math.atan2(q[1] - arc.center[1], q[0] - arc.center[0])
        for tt in (t - 2 * math.pi, t, t + 2 * math.pi):
            if arc.t0 - 1e-9 <= tt <= arc.t1 + 1e-9:
                if np.hypot(*(arc.points(np.array([tt]))[0] - q)) <= 1e-9:
                    out.append((k, min(max(tt, arc.t0), arc.t1)))
                    break
    return out


def _refine(p: PlanningProblem, arcs: list, start: np.ndarray) -> tuple[float, np.ndarray]:
    """Return the best bounded local optimum over the arcs through ``start``'s points."""
    options = [_arcs_at(arcs[i], start[i]) for i in range(len(start))]
    best, best_pos = math.inf, start
    for combo in itertools.product(*options):
        sel = [arcs[i][k] for i, (k, _) in enumerate(combo)]

        def pos(t, sel=sel):
            return np.stack([a.points(np.array([ti]))[0] for a, ti in zip(sel, t, strict=True)])

        res = minimize(
            lambda t, pos=pos: _trace(p, pos(t)),
            np.array([t for _, t in combo]),
            method="L-BFGS-B",
            bounds=[(a.t0, a.t1) for a in sel],
            options={"ftol": 1e-16, "gtol": 1e-12, "maxiter": 500},
        )
        q = pos(np.clip(res.x, [a.t0 for a in sel], [a.t1 for a in sel]))
        v = _trace(p, q)
        if v < best:
            best, best_pos = v, q
    return best, best_pos


def reference_optimum(p: PlanningProblem) -> tuple[float, np.ndarray]:
    """Return the global optimum ``(trace, relative positions (M, 2))`` without GSR."""
    m = p.n_sensors
    arcs = [geometry.facing_boundary(p.rel_sensors[i], p.r[i], p.rho[i]) for i in range(m)]
    n = int(COMBINATIONS ** (1.0 / m))
    grids = [_grid(a, n)[0] for a in arcs]
    y = np.linalg.inv(p.prior_cov)
    tot = [y[0, 0], y[0, 1], y[1, 1]]
    for i, pts in enumerate(grids):
        shape = [1] * m
        shape[i] = len(pts)
        for e, v in enumerate(_entries(p, i, pts)):
            tot[e] = tot[e] + v.reshape(shape)
    a, b, c = np.broadcast_arrays(*tot)
    val = (a + c) / (a * c - b * b)
    # Local minima along every axis (a superset of the grid's local minima).
    loc = np.ones(val.shape, dtype=bool)
    for ax in range(m):
        for d in (-1, 1):
            nb = np.roll(val, d, axis=ax)
            edge = [slice(None)] * m
            edge[ax] = 0 if d == 1 else -1
            nb[tuple(edge)] = np.inf
            loc &= val <= nb
    idx, v = np.argwhere(loc), val[loc]
    order = np.argsort(v)
    starts = [GBES().search(p).positions - p.target]
    for j in order[:MAX_STARTS]:
        if v[j] > (1.0 + WINDOW) * v[order[0]]:
            break
        starts.append(np.stack([grids[i][idx[j][i]] for i in range(m)]))
    best, best_pos = math.inf, starts[0]
    for s in starts:
        f, q = _refine(p, arcs, s)
        if f < best:
            best, best_pos = f, q
    return best, best_pos


@pytest.mark.slow
def test_reference_is_a_global_optimum_on_a_small_case():
    # Two sensors: a brute-force grid of 4e6 combinations bounds the reference from above
    # by at most its own (second-order) resolution error, and never lies below it.
    rng = np.random.default_rng(5)
    for _ in range(3):
        p = close_problem(rng, n_sensors=2)
        ref, pos = reference_optimum(p)
        assert ref == pytest.approx(_trace(p, pos), rel=1e-14)
        assert np.all(np.hypot(*pos.T) >= p.rho * (1 - 1e-12))
        assert np.all(np.hypot(*(pos - p.rel_sensors).T) <= p.r * (1 + 1e-12))
        arcs = [geometry.facing_boundary(p.rel_sensors[i], p.r[i], p.rho[i]) for i in range(2)]
        g = [_grid(a, 2000)[0] for a in arcs]
        e0, e1 = _entries(p, 0, g[0]), _entries(p, 1, g[1])
        y = np.linalg.inv(p.prior_cov)
        a = y[0, 0] + e0[0][:, None] + e1[0][None, :]
        b = y[0, 1] + e0[1][:, None] + e1[1][None, :]
        c = y[1, 1] + e0[2][:, None] + e1[2][None, :]
        brute = float(np.min((a + c) / (a * c - b * b)))
        assert ref <= brute * (1 + 1e-12)
        assert brute <= ref * (1 + 1e-5)


def _check_against_reference(p: PlanningProblem) -> None:
    res = GSR(restarts=True).plan_with_info(p)
    rel = res.positions - p.target
    assert np.all(np.hypot(*rel.T) >= p.rho * (1 - 1e-12))
    assert np.all(np.hypot(*(rel - p.rel_sensors).T) <= p.r * (1 + 1e-12))
    assert res.value == pytest.approx(_trace(p, rel), rel=1e-12)
    assert res.value <= GSR().plan_with_info(p).value  # never worse than plain GSR
    ref, _ = reference_optimum(p)
    assert res.value <= ref * (1 + RTOL)


@pytest.mark.slow
def test_no_feasible_point_improves_the_reference_sensor_by_sensor():
    # The reference searches the curves ADB only (Lemma 3); check without them that no
    # point of a dense grid over a sensor's whole feasible set (its reach disk outside its
    # rho disk) improves the reference with the other sensors where they are.
    rng = np.random.default_rng(9)
    for _ in range(3):
        p = close_problem(rng)
        ref, pos = reference_optimum(p)
        for i in range(3):
            g = np.linspace(-1.0, 1.0, 301) * p.r[i]
            q = p.rel_sensors[i] + np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
            ok = (np.hypot(*(q - p.rel_sensors[i]).T) <= p.r[i]) & (np.hypot(*q.T) >= p.rho[i])
            y = np.linalg.inv(p.prior_cov)
            for j in range(3):
                if j != i:
                    a, b, c = (e[0] for e in _entries(p, j, pos[j][None, :]))
                    y = y + np.array([[a, b], [b, c]])
            a, b, c = _entries(p, i, q[ok])
            a, b, c = y[0, 0] + a, y[0, 1] + b, y[1, 1] + c
            assert np.min((a + c) / (a * c - b * b)) >= ref * (1 - 1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("seed", sorted(KNOWN_MISSES))
def test_gsr_restarts_close_the_known_misses(seed):
    _check_against_reference(close_problem(np.random.default_rng(seed)))


@pytest.mark.slow
@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_gsr_restarts_reach_the_global_optimum_near_the_target(seed):
    _check_against_reference(close_problem(np.random.default_rng(seed)))


def test_polish_derivatives_match_finite_differences():
    # The projected Newton step of the polish uses an analytic gradient and Hessian of the
    # trace in the sensors' angles on their arcs; compare with central differences of the
    # objective itself (computed here from eq. 17).
    rng = np.random.default_rng(8)
    for _ in range(5):
        p = close_problem(rng)
        run = Relaxation(p, 1e-9, 100)
        par = []
        for i in range(3):
            arc = max(
                geometry.facing_boundary(p.rel_sensors[i], p.r[i], p.rho[i]), key=lambda a: a.length
            )
            par.append((i, arc))
        s = p.rel_sensors.copy()
        arcs = _ArcSet(run, s, par)
        theta = np.array([a.t0 + rng.uniform(0.2, 0.8) * (a.t1 - a.t0) for _, a in par])
        f, g, hess = arcs.derivatives(theta)

        def trace_at(th, arcs=arcs, p=p):
            return _trace(p, arcs.positions(th))

        assert f == pytest.approx(trace_at(theta), rel=1e-12)
        h = 1e-4
        eye = np.eye(3) * h
        g_fd = np.array([(trace_at(theta + e) - trace_at(theta - e)) / (2 * h) for e in eye])
        np.testing.assert_allclose(g, g_fd, rtol=1e-6, atol=1e-9 * abs(f))
        h2 = 1e-3
        hess_fd = np.array(
            [
                [
                    (
                        trace_at(theta + a + b)
                        - trace_at(theta + a - b)
                        - trace_at(theta - a + b)
                        + trace_at(theta - a - b)
                    )
                    / (4 * h2 * h2)
                    for b in np.eye(3) * h2
                ]
                for a in np.eye(3) * h2
            ]
        )
        np.testing.assert_allclose(hess, hess_fd, rtol=1e-4, atol=1e-6 * np.abs(hess).max())
