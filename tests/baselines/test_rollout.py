"""The one episode loop (activetrack.baselines.rollout) against longhand loops over World.

Each reference below is written here from the World API alone (reset, planning_problem,
observe, step, step_actions), serial and batched, for a planner, an expert policy, a
policy acting on observations and the imitation labels' mixture of an expert and a
learner; the experiments' entry points (simulate, run_episode, run_batched, the labels,
the look-ahead's run_batched) must give exactly these numbers. And no module of the
baselines or train layers steps a world, or an env's world, outside the rollout.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from activetrack import make_scenario
from activetrack.baselines import GSR, RandomMotion, simulate
from activetrack.baselines import rollout as ro
from activetrack.baselines.evaluation import run_batched, run_episode
from activetrack.baselines.policies import GSRPolicy, RMPolicy
from activetrack.envs import parallel_env
from activetrack.kinematics.sensor_motion import actions_to_reach
from activetrack.world import World

SEEDS = [11, 12, 13]
ROOT = Path(__file__).resolve().parents[2]


def _learner(obs):
    """A deterministic learner: actions from the observations, in [-1, 1] (rows (R, D))."""
    return np.tanh(obs[..., :2].astype(np.float64) + 0.3 * obs[..., 2:4])


def _serial_longhand(sc, decide, seeds):
    """Return per episode ``(traces, errors, rewards)`` of a longhand serial loop."""
    out = []
    world = World(sc, 1)
    for s in seeds:
        world.reset(seeds=[s])
        rng = np.random.default_rng([s, 1])
        traces, errors, rewards = [], [], []
        done = False
        while not done:
            kind, moves = decide(world, rng)
            res = world.step(moves) if kind == "positions" else world.step_actions(moves)
            traces.append(float(world.get("trace", 0)))
            errors.append(float(world.position_error(0)))
            rewards.append(float(res.reward))
            done = bool(res.terminated) or bool(res.truncated)
        out.append((traces, errors, rewards))
    return out


@pytest.mark.parametrize("scenario", ["paper", "two_targets"])
def test_simulate_is_a_longhand_serial_loop_of_a_planner(scenario):
    sc = make_scenario(scenario, n_steps=8)
    planner = RandomMotion()  # draws from its generator: the per-episode stream matters
    ref = _serial_longhand(
        sc, lambda w, rng: ("positions", planner.plan(w.planning_problem(0), rng)), SEEDS
    )
    for s, (traces, errors, _) in zip(SEEDS, ref, strict=True):
        rec = simulate(sc, planner, s)
        assert rec.trace.tolist() == traces
        assert rec.error.tolist() == errors


def test_run_episode_is_a_longhand_serial_loop_of_an_expert_and_of_an_actor():
    sc = make_scenario("mixed", n_steps=6)
    env = parallel_env(sc)
    expert = RMPolicy()
    ref = _serial_longhand(
        sc, lambda w, rng: ("positions", RandomMotion().plan(w.planning_problem(0), rng)), SEEDS
    )
    for s, (traces, errors, rewards) in zip(SEEDS, ref, strict=True):
        row = run_episode(env, expert, s)
        assert row[0] == np.mean(traces)
        assert row[2] == sum(rewards)
        np.testing.assert_allclose(row[1], np.sqrt(np.mean(np.square(errors))), rtol=1e-15)

    agents = env.possible_agents

    def act(observations):  # a policy on the observations, {agent: action}
        a = _learner(np.stack([observations[k] for k in agents]))
        return dict(zip(agents, a, strict=True))

    ref = _serial_longhand(sc, lambda w, rng: ("actions", _learner(w.observe(0))), SEEDS)
    for s, (traces, _, rewards) in zip(SEEDS, ref, strict=True):
        row = run_episode(env, act, s)
        assert row[0] == np.mean(traces)
        assert row[2] == sum(rewards)


def _batched_longhand(sc, seeds, plan, learner=None, beta=1.0):
    """Return per copy ``(traces, rewards, obs, labels)`` of a longhand batched loop."""
    n = len(seeds)
    world = World(sc, n)
    world.reset(seeds=seeds)
    coins = [np.random.default_rng([s, 2]) for s in seeds]
    traces, rewards = [[] for _ in range(n)], [0.0] * n
    obs_by, labels_by = [[] for _ in range(n)], [[] for _ in range(n)]
    live = np.ones(n, dtype=bool)
    while live.any():
        rows = np.flatnonzero(live)
        obs = world.observe()
        problem = world.planning_problem()
        planned = plan(problem)
        labels = actions_to_reach(planned, problem.sensors, problem.r).astype(np.float32)
        expert_rows = [i for i in rows if learner is None or coins[i].random() < beta]
        own = np.setdiff1d(rows, expert_rows)
        if expert_rows:
            res = world.step(planned, np.array(expert_rows))
            for i, r in zip(expert_rows, np.atleast_1d(res.reward), strict=True):
                rewards[i] += float(r)
        if own.size:
            acts = np.zeros(planned.shape)
            acts[own] = _learner(obs[own])
            res = world.step_actions(acts, own)
            for i, r in zip(own, np.atleast_1d(res.reward), strict=True):
                rewards[i] += float(r)
        for i in rows:
            traces[i].append(float(world.get("trace", i)))
            obs_by[i].append(obs[i])
            labels_by[i].append(labels[i])
        live &= ~(world.terminated | world.truncated)
    return traces, rewards, obs_by, labels_by


def _serial_mixed_longhand(sc, seeds, plan, beta):
    """Return per episode ``(traces, obs, labels)`` of the mixture, serially in one copy."""
    out = []
    world = World(sc, 1)
    for s in seeds:
        world.reset(seeds=[s])
        coin = np.random.default_rng([s, 2])
        traces, obs_list, labels_list = [], [], []
        done = False
        while not done:
            obs = world.observe(0)
            problem = world.planning_problem(0)
            planned = plan(problem)
            obs_list.append(obs)
            labels_list.append(
                actions_to_reach(planned, problem.sensors, problem.r).astype(np.float32)
            )
            if coin.random() < beta:
                res = world.step(planned)
            else:
                res = world.step_actions(_learner(obs))
            traces.append(float(world.get("trace", 0)))
            done = bool(res.terminated) or bool(res.truncated)
        out.append((traces, obs_list, labels_list))
    return out


def test_run_batched_is_a_longhand_batched_loop_of_a_planner():
    sc = make_scenario("paper", n_steps=6, max_trace=6.0)  # copies end at steps 2, 3, 6
    traces, rewards, _, _ = _batched_longhand(sc, SEEDS, GSR().plan)
    assert len({len(t) for t in traces}) > 1  # the early ends are exercised
    rows = run_batched(sc, {}, GSRPolicy(), SEEDS)
    for row, t, r in zip(rows, traces, rewards, strict=True):
        assert row[0] == np.mean(t)
        assert row[2] == r


def test_the_lookaheads_batched_runs_are_a_longhand_batched_loop():
    from activetrack.baselines import lookahead

    traces, _, _, _ = _batched_longhand(make_scenario("paper", n_steps=5), SEEDS, GSR().plan)
    mean, deepest = lookahead.run_batched(make_scenario("paper", n_steps=5), SEEDS)
    assert mean.tolist() == [np.mean(t) for t in traces]
    assert deepest.shape == (len(SEEDS),) and np.all(deepest >= 0)


@pytest.mark.parametrize("batched", [False, True])
def test_the_labels_mixture_is_a_longhand_loop(batched):
    # The imitation labels' rollout (expert plans, coins, a learner on the other copies),
    # through the driver directly: the train layer's functions are thin uses of it.
    sc = make_scenario("paper", n_steps=5)
    gsr = GSR()
    if batched:
        traces, _, obs_by, labels_by = _batched_longhand(sc, SEEDS, gsr.plan, _learner, 0.5)
    else:
        traces, obs_by, labels_by = zip(
            *_serial_mixed_longhand(sc, SEEDS, gsr.plan, 0.5), strict=True
        )
    rec = _Keep(len(SEEDS))
    world = World(sc, len(SEEDS) if batched else 1)
    ro.rollout(world, ro.MixedAgent(GSRPolicy(), _learner, 0.5), SEEDS, rec, batched=batched)
    assert rec.traces == list(traces)
    for j in range(len(SEEDS)):
        np.testing.assert_array_equal(np.stack(rec.obs[j]), np.stack(obs_by[j]))
        np.testing.assert_array_equal(np.stack(rec.labels[j]), np.stack(labels_by[j]))


class _Keep(ro.Recorder):
    def __init__(self, n):
        self.traces, self.obs, self.labels = ([[] for _ in range(n)] for _ in range(3))

    def step(self, step):
        p = step.problem
        labels = actions_to_reach(step.positions, p.sensors, p.r).astype(np.float32)
        for i, j in zip(step.copies.tolist(), step.episodes.tolist(), strict=True):
            self.traces[j].append(float(step.world.get("trace", i)))
            self.obs[j].append(step.observations[i] if step.batched else step.observations)
            self.labels[j].append(labels[i] if step.batched else labels)


def test_rollout_checks_its_world():
    with pytest.raises(ValueError, match="one copy per seed"):
        ro.rollout(World("paper", 2), ro.ExpertAgent(GSRPolicy()), SEEDS, batched=True)
    with pytest.raises(ValueError, match="world of one copy"):
        ro.rollout(World("paper", 2), ro.ExpertAgent(GSRPolicy()), SEEDS)


def _steps_a_world(path: Path) -> list[int]:
    """Return the lines of ``path`` that call ``step``/``step_actions`` on a world, or
    ``step_positions`` (an env's world stepped by an expert's plan), or loop over an
    environment's episode (``while env.agents``)."""
    lines = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.While) and ast.unparse(node.test).endswith(".agents"):
            lines.append(node.lineno)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            name, owner = node.func.attr, ast.unparse(node.func.value)
            if name == "step_positions" or (
                name in ("step", "step_actions") and "world" in owner.lower()
            ):
                lines.append(node.lineno)
    return lines


def test_the_rollout_is_the_only_episode_loop_of_the_experiments():
    found = {
        str(p.relative_to(ROOT)): _steps_a_world(p)
        for folder in ("baselines", "train")
        for p in sorted((ROOT / folder).glob("*.py"))
        if p.name != "rollout.py"
    }
    # The two-team game (issue 38) steps both teams: its evader's Gymnasium view and the
    # planners-against-evaders episodes; the rollout has no target agents (yet).
    two_team = found.pop("train/selfplay.py")
    assert len(two_team) <= 3
    assert {k: v for k, v in found.items() if v} == {}
    assert _steps_a_world(ROOT / "baselines" / "rollout.py")  # the scan finds its loop
