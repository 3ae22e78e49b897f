"""Planners under the team rule ``d_sep`` (:mod:`activetrack.baselines.separated`).

On a crowded team (8 sensors, one target, ``d_sep = 1``) in a batched world, GSR, GBES,
RM and the look-ahead wrapped by :class:`Separated` plan moves the world executes as
planned (their plans keep the rule, checked by brute force: every pair at least
``d_sep`` apart, every path sampled clear of the sensors where they stand and of the
others' paths at the same instants, outside the ``rho`` disk), so the world counts no
collision; GSR's episodes are no worse than RM's; a plan that already keeps the
separation is returned unchanged.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.baselines.gbes import GBES
from activetrack.baselines.gsr import GSR
from activetrack.baselines.lookahead import LookaheadPlanner
from activetrack.baselines.random_motion import RandomMotion
from activetrack.baselines.separated import Separated, separate
from activetrack.kinematics.separation import pair_distances
from activetrack.world import World

M = 8
CROWDED = dict(
    n_sensors=M, d_sep=1.0, sensor_center=(8.0, 0.0), sensor_radius=5.0, x0=(0.0, 0.0, 0.0, 0.0),
    x0_hat=(0.0, 0.0, 0.0, 0.0), q=1.0, n_steps=30,
)  # fmt: skip
S = np.linspace(0.0, 1.0, 65)


def _dist(a, b):
    return np.hypot(*(np.asarray(a) - np.asarray(b)).T)


def _episode(planner, n=3, steps=30, seed=0):
    """Run ``n`` copies with ``Separated(planner)``; check each plan; return the mean
    trace over the steps."""
    world = World("paper", n, **CROWDED)
    world.reset(seeds=range(seed, seed + n))
    sep = Separated(planner, 1.0)
    d = pair_distances(1.0, M)
    rng = np.random.default_rng(seed)
    traces, checked = [], 0
    for _ in range(steps):
        old = world.get("sensors").copy()
        pred = world.get("x_pred")[:, :2].copy()
        plans = np.stack([sep.plan(world.planning_problem(c), rng) for c in range(n)])
        n_stuck = world.get("n_stuck").copy()
        world.step(plans)
        for c in range(n):
            inside = np.any(_dist(plans[c], pred[c]) < 2.0 * (1 - 1e-9))
            if world.get("n_stuck")[c] > n_stuck[c] or inside:
                continue  # (a sensor with no feasible point: the world's own choice)
            assert world.get("collisions")[c] == 0
            checked += 1
            np.testing.assert_array_equal(world.get("sensors")[c], plans[c])
            for i in range(M):
                assert _dist(plans[c, i], pred[c]) >= 2.0 * (1 - 1e-9)
                path = old[c, i] + S[:, None] * (plans[c, i] - old[c, i])
                for j in range(M):
                    if j != i:
                        there = plans[c, j] if j < i else old[c, j]
                        assert np.min(_dist(path, there)) >= d[i, j] * (1 - 1e-9)
                        # Moving together: j's path at the same instants.
                        path_j = old[c, j] + S[:, None] * (plans[c, j] - old[c, j])
                        assert np.min(_dist(path, path_j)) >= d[i, j] * (1 - 1e-9)
        traces.append(world.get("trace").copy())
    assert checked >= n * steps // 2  # (most steps are plans the world executes as given)
    return float(np.mean(traces))


@pytest.mark.parametrize(
    "planner", [GSR(), RandomMotion(), GBES(max_combinations=1e4), LookaheadPlanner(horizon=2)],
    ids=["gsr", "rm", "gbes", "lookahead"],
)  # fmt: skip
def test_plans_keep_the_separation(planner):
    _episode(planner, n=2, steps=8)


def test_gsr_no_worse_than_rm():
    assert _episode(GSR()) <= _episode(RandomMotion())


def test_feasible_plan_unchanged():
    world = World("paper", 1, **dict(CROWDED, d_sep=0.01))
    world.reset(seeds=[4])
    problem = world.planning_problem(0)
    plan = GSR().plan(problem)
    d = _dist(plan[:, None], plan[None]) + np.eye(M)
    if np.all(d >= 0.05):  # far enough apart that no path comes near
        np.testing.assert_array_equal(separate(problem, plan, 0.01), plan)
