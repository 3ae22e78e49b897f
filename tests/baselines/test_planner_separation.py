"""The team rule ``d_sep`` inside GSR, GBES and RM (``problem.d_sep``), against brute force.

- Over closed-loop steps of a crowded team (``d_sep`` that binds: the planners without it
  would break it), every plan keeps every pair at least ``d_sep`` apart, and the straight
  paths, sampled, in the world's agent order and moving together (at the same instants),
  never come closer; the world executes the plans as given (its rule has nothing to
  mend).
- GSR's plan under ``d_sep`` is optimal for each sensor's subproblem (the others at their
  planned points) against a brute force over a dense polar grid of the reach disk and the
  ``rho`` circle, filtered by the rule's conditions written out pair by pair.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from activetrack.baselines.gbes import GBES
from activetrack.baselines.gsr import GSR
from activetrack.baselines.random_motion import RandomMotion
from activetrack.kinematics.separation import segment_distance
from activetrack.world import World
from activetrack.world.scenarios import make_scenario

D_SEP = 4.0
PLANNERS = {"GSR": GSR, "GBES": GBES, "RM": RandomMotion}


def paths_keep(old, plan, d):
    """Return whether the straight paths, sampled at 201 points, moved in agent order keep
    ``d`` (sensor b moves after a < b: a's path against b's old point, b's path against a's
    new point) and moved together (a's and b's paths at the same instants)."""
    t = np.linspace(0.0, 1.0, 201)[:, None]
    m = len(plan)
    for a in range(m):
        for b in range(a + 1, m):
            path_a = old[a] + t * (plan[a] - old[a])
            path_b = old[b] + t * (plan[b] - old[b])
            if (
                np.min(np.hypot(*(path_a - old[b]).T)) < d
                or np.min(np.hypot(*(path_b - plan[a]).T)) < d
                or np.min(np.hypot(*(path_a - path_b).T)) < d  # together, the same instant
            ):
                return False
    return True


def crowded_world(copies):
    sc = make_scenario(
        "paper", d_sep=D_SEP, n_sensors=3, sensor_radius=5.0, n_steps=40, sensor_center=(4.0, 0.0)
    )  # near the target: the rule binds
    world = World(sc, copies)
    world.reset(seeds=list(range(11, 11 + copies)))
    return world


@pytest.mark.parametrize("name", list(PLANNERS))
def test_plans_keep_d_sep_and_the_world_executes_them(name):
    world = crowded_world(2)
    planner = PLANNERS[name]()
    rng = np.random.default_rng(3)
    binding = 0
    for _ in range(12):
        problem = world.planning_problem()
        assert problem.d_sep == D_SEP
        plan = planner.plan(problem, rng)
        free = PLANNERS[name]().plan(dataclasses.replace(problem, d_sep=None), rng)
        for b in range(2):
            e = plan[b][:, None] - plan[b][None]
            dist = np.hypot(e[..., 0], e[..., 1])[np.triu_indices(3, 1)]
            assert np.all(dist >= D_SEP), dist
            assert paths_keep(problem.sensors[b], plan[b], D_SEP)
            binding += not paths_keep(problem.sensors[b], free[b], D_SEP)
        world.step(plan)
        np.testing.assert_array_equal(world.get("sensors"), plan)
    assert binding > 0  # the rule mattered: without it the plans would break it


def brute_force(problem, plan, i, d):
    """Return the least objective of sensor ``i`` over a dense polar grid of its reach disk
    and its ``rho`` circle, the others at ``plan``, among the points meeting the rule."""
    o, r, rho = problem.sensors, float(problem.r[i]), float(problem.rho[i])
    rad = np.linspace(0.0, 1.0, 301)[:, None, None] * r
    ang = np.linspace(0.0, 2 * np.pi, 1441)[:-1]
    ring = np.stack([np.cos(ang), np.sin(ang)], -1)
    pts = np.concatenate([(o[i] + rad * ring).reshape(-1, 2), problem.target + rho * ring])
    ok = np.hypot(*(pts - o[i]).T) <= r
    ok &= np.hypot(*(pts - problem.target).T) >= rho
    for j in range(len(plan)):
        if j != i:  # moving together: the relative path A + t B, t in [0, 1], keeps d
            rel_a, rel_b = o[i] - o[j], (pts - o[i]) - (plan[j] - o[j])
            den = np.sum(rel_b * rel_b, -1)
            t = np.clip(-(rel_b @ rel_a) / np.where(den > 0, den, 1.0), 0.0, 1.0)
            ok &= np.hypot(*(rel_a + t[:, None] * rel_b).T) >= d
        if j > i:  # i moves first: its path against j's old point; j's path against i's
            ok &= segment_distance(o[i], pts, o[j]) >= d
            ok &= segment_distance(o[j], plan[j], pts) >= d
        elif j < i:  # j has moved: i's path against j's new point
            ok &= segment_distance(o[i], pts, plan[j]) >= d
    trial = np.broadcast_to(plan, (int(ok.sum()),) + plan.shape).copy()
    trial[:, i] = pts[ok]
    return float(np.min(problem.score(trial)))


def test_gsr_under_d_sep_is_optimal_per_subproblem():
    world = crowded_world(2)
    checked = 0
    for step in range(14):
        problem = world.planning_problem()
        plan = GSR().plan(problem)
        if step % 3 == 2:
            for b in range(2):
                p = problem[b]
                value = float(p.score(plan[b]))
                for i in range(3):
                    assert value <= brute_force(p, plan[b], i, D_SEP) * (1 + 1e-9), (step, b, i)
                    checked += 1
        world.step(plan)
    assert checked == 24


class _Blind:
    """A planner that ignores the rule (GSR on the problem without ``d_sep``)."""

    def plan(self, problem, rng=None):
        return GSR().plan(dataclasses.replace(problem, d_sep=None))


def test_policies_keep_d_sep_for_planners_that_do_not():
    from activetrack.baselines.policies import GSRPolicy, PlannerPolicy

    world = crowded_world(2)
    blind, gsr = PlannerPolicy(_Blind(), seed=0), GSRPolicy(seed=0)
    broke = 0
    for _ in range(10):
        problem = world.planning_problem()
        raw = _Blind().plan(problem)
        for plan in (blind.plan(problem), gsr.plan(problem)):
            for b in range(2):
                assert paths_keep(problem.sensors[b], plan[b], D_SEP)
        broke += sum(not paths_keep(problem.sensors[b], raw[b], D_SEP) for b in range(2))
        world.step(gsr.plan(problem))
    assert broke > 0  # the wrapped planner's own plans broke the rule


@pytest.mark.parametrize("name", ["gsr", "gbes", "rm", "lookahead", "blind"])
def test_experts_in_the_environment_never_collide(name):
    """The world counts the pairs of wanted points closer than ``d_sep`` (``collisions``,
    before its rule mends them): an expert's plans give none (a planner blind to the rule,
    run without a policy, gives some: the episode is crowded enough to tell)."""
    from activetrack import envs
    from activetrack.baselines.policy_specs import resolve_policy

    sc = make_scenario("paper", d_sep=D_SEP, n_sensors=3, sensor_radius=5.0, n_steps=8,
                       sensor_center=(4.0, 0.0))  # fmt: skip
    env = envs.parallel_env(scenario=sc)
    expert = _Blind() if name == "blind" else resolve_policy(name)
    _, infos = env.reset(seed=21)
    lowest = np.inf
    while env.agents:
        _, _, _, _, infos = env.step_positions(expert.plan(env.planning_problem()))
        info = infos[env.possible_agents[0]]
        lowest = min(lowest, info["min_separation"])
    assert lowest >= D_SEP  # the world's rule, whoever plans
    if name == "blind":
        assert info["n_collisions"] > 0
    else:
        assert info["n_collisions"] == 0


def _sampled_pair(oa, pa, ob, pb, d):
    """Return whether sensors a < b moving straight from ``oa``, ``ob`` to ``pa``, ``pb``
    keep ``d`` by the three conditions, on 401 samples of the paths, and the least margin
    of the three (to skip the pairs too close to call by sampling)."""
    t = np.linspace(0.0, 1.0, 401)[:, None]
    path_a, path_b = oa + t * (pa - oa), ob + t * (pb - ob)
    low = min(
        np.min(np.hypot(*(path_a - ob).T)),
        np.min(np.hypot(*(path_b - pa).T)),
        np.min(np.hypot(*(path_a - path_b).T)),
    )
    static = min(np.min(np.hypot(*(path_a - ob).T)), np.min(np.hypot(*(path_b - pa).T)))
    return low >= d, abs(low - d), static >= d


def test_gbes_pair_masks_against_sampled_paths():
    """GBES's filter (``pair_masks``) against the three conditions on sampled paths; some
    pairs keep the two sequential conditions and fail the same instant alone."""
    from activetrack.baselines.gsr_separation import pair_masks

    rng = np.random.default_rng(8)
    d = np.full((3, 3), 2.0)
    np.fill_diagonal(d, 0.0)
    only_same = 0
    for _ in range(20):
        old = rng.uniform(-2.5, 2.5, (3, 2))
        cands = [old[i] + rng.uniform(-3, 3, (12, 2)) for i in range(3)]
        for a, b, ok in pair_masks(d, old, cands):
            for ka in range(12):
                for kb in range(12):
                    want, margin, static = _sampled_pair(
                        old[a], cands[a][ka], old[b], cands[b][kb], 2.0
                    )
                    if margin > 1e-3:  # (a sampled path misses the exact minimum by less)
                        assert ok[ka, kb] == want
                    only_same += static and not want
    assert only_same > 20


def test_rm_redraws_keep_the_same_instant():
    """RM's draws, many per problem, keep the three conditions on sampled paths."""
    world = crowded_world(2)
    problem = world.planning_problem()
    rng = np.random.default_rng(4)
    for _ in range(60):
        plan = RandomMotion().plan(problem, rng)
        for b in range(2):
            assert paths_keep(problem.sensors[b], plan[b], D_SEP)
