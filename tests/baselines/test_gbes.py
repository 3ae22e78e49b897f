"""GBES against an independent brute force, and its exact branch-and-bound bound."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from activetrack.baselines import GBES, random_problem
from activetrack.baselines.gbes import _BlockSearch, _entries
from activetrack.kinematics import geometry
from activetrack.models.objective import sensor_information


def _naive_optimum(problem, spacing):
    """Return the grid optimum by a plain loop with explicit 2x2 inverses (independent)."""
    grids = []
    for i in range(problem.n_sensors):
        arcs = geometry.facing_boundary(problem.rel_sensors[i], problem.r[i], problem.rho[i])
        grids.append(geometry.discretize(arcs, spacing))
    best = math.inf
    for combo in itertools.product(*grids):
        info = problem.prior_info.copy()
        for i, p in enumerate(combo):
            d2 = p @ p
            u = p / math.sqrt(d2)
            v = np.array([u[1], -u[0]])
            info += np.outer(u, u) / problem.sigma_d2[i]
            info += np.outer(v, v) / (problem.sigma_theta2[i] * d2)
        best = min(best, np.trace(np.linalg.inv(info)))
    return best


@pytest.mark.parametrize("m, spacing", [(1, 0.02), (2, 0.1), (3, 0.35)])
@pytest.mark.parametrize("prune", [True, False])
def test_gbes_equals_naive_brute_force(m, spacing, prune):
    rng = np.random.default_rng(100 + m)
    for _ in range(4):
        p = random_problem(rng, m)
        res = GBES(spacing=spacing, prune=prune, block=4).search(p)
        assert res.value == pytest.approx(_naive_optimum(p, spacing), rel=1e-11)
        assert np.max(p.violation(res.positions)) <= 1e-9
        assert res.n_evaluated <= res.n_combinations or not prune


def test_gbes_far_sensors_default_spacing_matches_exhaustive():
    # Far sensors (flat objective, many near-ties) are the hard case for the bound.
    rng = np.random.default_rng(7)
    for _ in range(3):
        p = random_problem(rng, 3, distance=(15.0, 40.0))
        pruned = GBES().search(p)
        full = GBES(prune=False).search(p)
        assert pruned.value <= full.value * (1 + 1e-12)
        assert pruned.n_evaluated < full.n_combinations / 20


def test_block_bound_is_a_lower_bound_of_every_configuration():
    rng = np.random.default_rng(3)
    for _ in range(5):
        p = random_problem(rng, 2, distance=(1.0, 6.0))
        grids = [
            geometry.discretize(geometry.facing_boundary(p.rel_sensors[i], p.r[i], p.rho[i]), 0.05)
            for i in range(2)
        ]
        feats = [
            _entries(sensor_information(g, p.sigma_d2[i], p.sigma_theta2[i]))
            for i, g in enumerate(grids)
        ]
        search = _BlockSearch(feats, _entries(p.prior_info), 8, 1 << 16)
        flat, lb = search._bounds(0)
        nb = search.nblocks
        for f, bound in zip(flat, lb, strict=True):
            b0, b1 = np.unravel_index(f, nb)
            pts0 = grids[0][b0 * 8 : b0 * 8 + 8]
            pts1 = grids[1][b1 * 8 : b1 * 8 + 8]
            rel = np.stack(np.broadcast_arrays(pts0[:, None], pts1[None, :]), -2)
            vals = p.trace(rel + p.target)
            assert bound <= vals.min() * (1 + 1e-12)


def test_gbes_fixed_sensors_stay_or_fall_back():
    rng = np.random.default_rng(5)
    p = random_problem(rng, 2)
    p = type(p)(
        prior_cov=p.prior_cov,
        target=p.target,
        sensors=np.array([[3.0, 0.0], [0.0, 0.5]]),
        r=np.array([0.0, 1.0]),
        rho=2.0,
        sigma_d2=p.sigma_d2,
        sigma_theta2=p.sigma_theta2,
    )
    out = GBES().plan(p)
    assert np.allclose(out[0], [3.0, 0.0])  # r = 0: stays
    assert np.allclose(out[1], [0.0, 1.5])  # unreachable: farthest reachable point


@pytest.mark.parametrize(
    "kwargs, word",
    [
        ({"spacing": 0.0}, "spacing"),
        ({"spacing": -1.0}, "spacing"),
        ({"spacing": float("nan")}, "spacing"),
        ({"max_combinations": 0}, "max_combinations"),
        ({"block": 0}, "block"),
    ],
)
def test_gbes_rejects_bad_parameters(kwargs, word):
    with pytest.raises(ValueError, match=word):
        GBES(**kwargs)


def test_gbes_refuses_too_many_combinations_with_their_number():
    p = random_problem(np.random.default_rng(1), 3)
    n = GBES().n_combinations(p)
    with pytest.raises(ValueError, match=r"max_combinations") as err:
        GBES(max_combinations=n - 1, adapt=False).plan(p)
    assert f"{n:.3g}" in str(err.value)
    assert GBES(max_combinations=n).search(p).n_combinations == n
    # The default (adapt) widens the spacing instead, just past the paper's.
    wide = GBES(max_combinations=n - 1).search(p)
    assert wide.n_combinations <= n - 1 and wide.spacing > GBES().spacing


def _count_from_arc_lengths(problem, spacing):
    """Grid size per sensor from the arc lengths alone: ceil(L / spacing) + 1 points per
    arc, minus one where an arc starts at the point (A or B, Fig. 3) where the previous
    one ended (the grid lists the arcs in order and drops repeated points)."""
    sizes = []
    for i in range(problem.n_sensors):
        arcs = geometry.facing_boundary(problem.rel_sensors[i], problem.r[i], problem.rho[i])
        n = sum(max(1, math.ceil(a.length / spacing)) + 1 for a in arcs)
        for prev, nxt in zip(arcs[:-1], arcs[1:], strict=True):
            end = np.add(prev.center, prev.radius * np.array([np.cos(prev.t1), np.sin(prev.t1)]))
            start = np.add(nxt.center, nxt.radius * np.array([np.cos(nxt.t0), np.sin(nxt.t0)]))
            n -= int(np.hypot(*(end - start)) < 1e-12)
        sizes.append(n)
    return sizes


def test_gbes_counts_its_grid_from_the_arc_lengths():
    rng = np.random.default_rng(31)
    for spacing in (math.pi / 200, 0.05, 0.7):
        for _ in range(30):
            p = random_problem(rng, 3, distance=(0.5 + 2.0, 8.0))  # every sensor free
            gbes = GBES(spacing=spacing)
            expected = _count_from_arc_lengths(p, spacing)
            assert gbes.grid_sizes(p) == expected
            assert [len(c) for c in gbes.candidates(p)] == expected
            assert gbes.n_combinations(p) == math.prod(expected)


def test_gbes_refuses_a_too_fine_grid_before_building_it():
    # At 1e-9 m the grid would hold ~1e9 points per sensor (GBs): the count must come first.
    import tracemalloc

    p = random_problem(np.random.default_rng(32), 3, distance=(3.0, 8.0))
    n = math.prod(_count_from_arc_lengths(p, 1e-9))
    assert n > 1e24
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match="max_combinations") as err:
            GBES(spacing=1e-9, adapt=False).plan(p)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20  # well under a megabyte: nothing of the grid's size was built
    assert f"{n:.3g}" in str(err.value)


def test_gbes_plans_a_batch_copy_by_copy():
    from activetrack.world.problem import PlanningProblem

    rng = np.random.default_rng(33)
    singles = [random_problem(rng, 2) for _ in range(4)]
    out = GBES(spacing=0.1).plan(PlanningProblem.stack(singles))
    for b, p in enumerate(singles):
        np.testing.assert_array_equal(out[b], GBES(spacing=0.1).plan(p))


def test_blocks_shrink_to_the_memory_bound_and_stay_exact(monkeypatch):
    """With more sensors than the batch fits (block^M configurations over
    ``batch_elements``), every evaluated array stays within the bound and the optimum is
    still the naive brute force's (8 GB were allocated for 8 sensors before the blocks
    shrank)."""
    sizes = []
    real = _BlockSearch._evaluate

    def recording(self, flat):
        sizes.append(len(flat) * math.prod(self.bsize))
        return real(self, flat)

    monkeypatch.setattr(_BlockSearch, "_evaluate", recording)
    rng = np.random.default_rng(11)
    for _ in range(3):
        p = random_problem(rng, 3)
        res = GBES(spacing=0.35, block=8, batch_elements=20).search(p)
        assert res.value == pytest.approx(_naive_optimum(p, 0.35), rel=1e-11)
    assert sizes and max(sizes) <= 20
