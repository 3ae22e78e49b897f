"""GBES on every planning problem (K targets, mixed models, uncertain poses, every
objective) against brute force scored by ``PlanningProblem.score``."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from activetrack.baselines import GBES
from activetrack.baselines.gbes import _target_features, _TargetsSearch
from activetrack.kinematics import geometry
from activetrack.models.objective import LOGDET, TRACE, WORST_TRACE
from tests.baselines._multi import dense_boundary, multi_problem

OBJECTIVES = [TRACE, WORST_TRACE, LOGDET]


def _brute_force(problem, grids):
    """Return the smallest ``problem.score`` over all combinations of absolute ``grids``."""
    configs = np.array(list(itertools.product(*grids)))  # (N, M, 2)
    return float(problem.score(configs).min())


def _close(a, b, rtol=1e-11):
    return abs(a - b) <= rtol * max(abs(a), abs(b), 1.0)


@pytest.mark.parametrize("objective", OBJECTIVES, ids=lambda o: o.name)
@pytest.mark.parametrize("m, k, spacing", [(2, 2, 0.25), (2, 3, 0.3), (3, 2, 0.7)])
def test_multi_target_gbes_equals_brute_force(objective, m, k, spacing):
    rng = np.random.default_rng(10 * m + k)
    for _ in range(3):
        p = multi_problem(rng, m, k, objective)
        gbes = GBES(spacing=spacing, block=4)
        grids = [g + p.targets[0] for g in gbes.candidates(p)]
        best = _brute_force(p, grids)
        res = gbes.search(p)
        assert _close(res.value, best)
        assert _close(GBES(spacing=spacing, block=4, prune=False).search(p).value, best)
        assert np.max(p.violation(res.positions)) <= 1e-9
        for i, g in enumerate(grids):  # the answer is a grid point
            assert np.min(np.linalg.norm(g - res.positions[i], axis=-1)) == 0.0


@pytest.mark.parametrize("objective", OBJECTIVES, ids=lambda o: o.name)
@pytest.mark.parametrize("multi_target", [False, True])
def test_one_target_gbes_with_models_and_poses_equals_brute_force_on_adb(objective, multi_target):
    # One target: the grid is the curve ADB (Lemma 3), discretized here independently.
    rng = np.random.default_rng(20)
    for _ in range(4):
        p = multi_problem(rng, 2, 1, objective, multi_target=multi_target)
        t = p.targets[0]
        grids = [
            geometry.discretize(geometry.facing_boundary(p.sensors[i] - t, p.r[i], p.rho[i]), 0.08)
            + t
            for i in range(2)
        ]
        res = GBES(spacing=0.08, block=4).search(p)
        assert _close(res.value, _brute_force(p, grids))
        assert np.max(p.violation(res.positions)) <= 1e-9


def test_one_target_problem_as_multi_target_plans_the_same():
    for objective in OBJECTIVES:
        p1 = multi_problem(np.random.default_rng(5), 3, 1, objective, multi_target=False)
        pk = multi_problem(np.random.default_rng(5), 3, 1, objective, multi_target=True)
        a, b = GBES(spacing=0.05).search(p1), GBES(spacing=0.05).search(pk)
        np.testing.assert_array_equal(a.positions, b.positions)
        assert a.value == b.value


@pytest.mark.parametrize("objective", OBJECTIVES, ids=lambda o: o.name)
def test_gbes_beats_random_configurations_of_its_grid(objective):
    # M = 4, K = 2, about 1e5 combinations: no brute force, but 1000 random grid
    # configurations (scored independently) are never better.
    rng = np.random.default_rng(30)
    for _ in range(2):
        p = multi_problem(rng, 4, 2, objective)
        gbes = GBES(spacing=0.35)
        grids = [g + p.targets[0] for g in gbes.candidates(p)]
        res = gbes.search(p)
        picks = np.stack([g[rng.integers(0, len(g), 1000)] for g in grids], axis=1)  # (1000, M, 2)
        vals = p.score(picks)
        assert res.value <= vals.min() + 1e-12 * abs(vals.min())
        assert _close(GBES(spacing=0.35, prune=False).search(p).value, res.value)


def test_multi_target_grid_covers_the_boundary_within_half_a_spacing():
    # Every feasible boundary point found by dense sampling is within spacing / 2 (a chord)
    # of a candidate, and every candidate is feasible.
    rng = np.random.default_rng(40)
    spacing = 0.2
    for _ in range(10):
        p = multi_problem(rng, 2, 3)
        free = [len(c) > 1 for c in GBES(spacing=spacing).candidates(p)]
        for i, cand in enumerate(GBES(spacing=spacing).candidates(p)):
            cand = cand + p.targets[0]
            assert np.all(p.violation(np.broadcast_to(cand[:, None], (len(cand), 2, 2)))[:, i]
                          <= 1e-9)  # fmt: skip
            if not free[i]:
                continue
            for centre, radius, theta, ok in dense_boundary(
                p.sensors[i], p.r[i], p.targets, p.rho[i], 4000
            ):
                pts = centre + radius * np.stack([np.cos(theta[ok]), np.sin(theta[ok])], -1)
                if len(pts):
                    d = np.linalg.norm(pts[:, None] - cand[None], axis=-1).min(axis=1)
                    assert d.max() <= spacing / 2 + 1e-9


def test_multi_target_grid_is_counted_before_it_is_built():
    rng = np.random.default_rng(50)
    for spacing in (0.05, 0.3, 2.0):
        for _ in range(20):
            p = multi_problem(rng, 3, 3, distance=(0.0, 4.0))
            gbes = GBES(spacing=spacing)
            assert gbes.grid_sizes(p) == [len(c) for c in gbes.candidates(p)]
    import tracemalloc

    p = multi_problem(np.random.default_rng(51), 3, 2)
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match="max_combinations"):
            GBES(spacing=1e-9, adapt=False).plan(p)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20


def test_multi_target_candidates_include_the_feasible_circle_intersections():
    rng = np.random.default_rng(55)
    checked = 0
    for _ in range(10):
        p = multi_problem(rng, 1, 2, distance=(0.5, 2.0))
        cand = GBES(spacing=0.3).candidates(p)[0] + p.targets[0]
        if len(cand) == 1:
            continue
        s, r, rho = p.sensors[0], p.r[0], p.rho[0]
        circles = [(s, r)] + [(t, rho) for t in p.targets]
        for (c1, r1), (c2, r2) in itertools.combinations(circles, 2):
            d = np.linalg.norm(c2 - c1)
            if not abs(r1 - r2) < d < r1 + r2:
                continue
            a = (r1 * r1 - r2 * r2 + d * d) / (2 * d)
            h = math.sqrt(r1 * r1 - a * a)
            u = (c2 - c1) / d
            for sign in (1, -1):
                x = c1 + a * u + sign * h * np.array([-u[1], u[0]])
                if p.violation(x[None])[0] <= 1e-12:
                    assert np.min(np.linalg.norm(cand - x, axis=-1)) <= 1e-9
                    checked += 1
    assert checked >= 10


@pytest.mark.parametrize("objective", OBJECTIVES, ids=lambda o: o.name)
def test_multi_target_block_bound_is_below_every_configuration(objective):
    rng = np.random.default_rng(60)
    for _ in range(3):
        p = multi_problem(rng, 2, 3, objective)
        cands = GBES(spacing=0.15).candidates(p)
        search = _TargetsSearch(
            _target_features(p, cands),
            np.stack([p.prior_infos[:, 0, 0], p.prior_infos[:, 0, 1], p.prior_infos[:, 1, 1]], -1),
            5,
            1 << 16,
            objective,
        )
        flat, lb = search._bounds(0)
        for f, bound in zip(flat, lb, strict=True):
            b0, b1 = np.unravel_index(f, search.nblocks)
            pts0 = cands[0][b0 * 5 : b0 * 5 + 5] + p.targets[0]
            pts1 = cands[1][b1 * 5 : b1 * 5 + 5] + p.targets[0]
            rel = np.stack(np.broadcast_arrays(pts0[:, None], pts1[None, :]), -2)
            best = p.score(rel).min()
            assert bound <= best + 1e-12 * abs(best)


def test_gbes_plans_a_multi_target_batch_copy_by_copy():
    from activetrack.world.problem import PlanningProblem

    rng = np.random.default_rng(70)
    singles = [multi_problem(rng, 2, 2) for _ in range(3)]
    out = GBES(spacing=0.2).plan(PlanningProblem.stack(singles))
    for b, p in enumerate(singles):
        np.testing.assert_array_equal(out[b], GBES(spacing=0.2).plan(p))


def test_gbes_refuses_an_objective_it_cannot_bound():
    class Mean(type(TRACE)):
        name = "mean"

        def combine(self, values, axis=-1):
            return np.mean(values, axis=axis)

    p = multi_problem(np.random.default_rng(80), 2, 2, Mean())
    with pytest.raises(ValueError, match="sum or a max"):
        GBES(spacing=0.5).plan(p)
