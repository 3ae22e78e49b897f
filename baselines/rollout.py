"""The one episode loop of the experiments: a world, a policy and seeds -> per-episode records.

:func:`rollout` resets a :class:`activetrack.world.World` from seeds, asks an agent for
every step's moves (next positions, or actions in units of the reach), steps the world and
hands each step to a recorder, which keeps what its caller needs. Every experiment runs
through it: :func:`activetrack.baselines.simulation.simulate` (trajectories, trace, RMSE,
NEES, planning time), :func:`activetrack.baselines.episodes.run_episode` and
``run_batched`` (the evaluation's rows), the imitation labels
(:func:`activetrack.train.imitation.rollout_labels` and ``rollout_labels_batched``:
observations and the expert's actions), PPO's validation episodes
(:func:`activetrack.train.ppo.validation_trace`) and
:func:`activetrack.baselines.lookahead.run_batched`;
their Ray variants run the same functions on chunks of the seeds
(:func:`activetrack.baselines.distributed.map_seeds`).

Two modes, as the callers had them (each reads the world as it did, so the numbers are
unchanged bit for bit):

- serial (``batched=False``): a world of one copy runs the seeds' episodes one after
  another; the copy is read unbatched (``planning_problem(0)``, ``observe(0)``), the
  single environment's fast path;
- batched (``batched=True``): copy ``i`` runs the episode of ``seeds[i]``; the agent
  plans every copy at once (``planning_problem()``) and the live copies step. A copy's
  numbers do not depend on which other copies step with it (the world computes a subset
  with every copy and writes it back alone).

Agents (the adapters below) start the episodes' generators from their seeds (a planner's
``np.random.default_rng([seed, 1])``, the simulation runner's), so an episode's numbers do
not depend on the episodes before it: seeds split over Ray workers give the serial results.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from activetrack.validation import FloatArray
from activetrack.world import World
from activetrack.world.problem import PlanningProblem


class Step:
    """One step of a rollout: what the agent decided and what a recorder reads.

    Attributes:
        world: the world (after the step, when a recorder sees it).
        batched: whether the copies are read batched (see the module docstring).
        copies: the copies that step (live before the step), increasing.
        episodes: their episodes' indices into the seeds (same length as ``copies``).
        problem: the planning problem the agent planned from, if it built one.
        observations: the observations the agent acted on, if it read them (float32,
            (M, D) serial, (N, M, D) batched).
        positions: the planned next positions ((M, 2) serial, (N, M, 2) batched), if any.
        actions: the actions executed by the copies in ``by_actions``, if any.
        by_actions: which of ``copies`` execute ``actions`` (None: all execute
            ``positions``).
        rewards: each copy's reward of this step ((N,), NaN for the copies that did not
            step); set by the rollout after the world steps.
        seconds: the decision's time by the rollout's clock (what :meth:`timed` counted).
        clock: that clock (``time.perf_counter`` for planning time, ``time.process_time``
            for the evaluation's CPU time).
    """

    def __init__(
        self,
        world: World,
        batched: bool,
        copies: np.ndarray,
        episodes: np.ndarray,
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        self.world, self.batched, self.copies, self.episodes = world, batched, copies, episodes
        self.clock = clock
        self.problem: PlanningProblem | None = None
        self.observations: np.ndarray | None = None
        self.positions: FloatArray | None = None
        self.actions: FloatArray | None = None
        self.by_actions: np.ndarray | None = None
        self.rewards: FloatArray | None = None
        self.seconds = 0.0

    @property
    def index(self) -> int | None:
        """Return the copy index that reads the world unbatched (0), or None (batched)."""
        return None if self.batched else 0

    def planning_problem(self) -> PlanningProblem:
        """Return (and keep as :attr:`problem`) the world's planning problem of the step."""
        self.problem = self.world.planning_problem(self.index)
        return self.problem

    def observe(self) -> np.ndarray:
        """Return (and keep as :attr:`observations`) the agents' observations of the step."""
        self.observations = self.world.observe(self.index)
        return self.observations

    def timed(self, fn: Callable[..., Any], *args: Any) -> Any:
        """Return ``fn(*args)``, its time by the rollout's clock added to :attr:`seconds`."""
        start = self.clock()
        out = fn(*args)
        self.seconds += self.clock() - start
        return out


class Recorder:
    """What a rollout keeps: override :meth:`reset` and :meth:`step` (both do nothing)."""

    def reset(self, world: World, copy: int, episode: int) -> None:
        """Called when copy ``copy`` starts episode ``episode`` (after the world's reset)."""

    def step(self, step: Step) -> None:
        """Called after every step of the world (``step.copies`` stepped)."""


class Agent:
    """What decides the moves: override :meth:`decide`; :meth:`start` seeds episodes."""

    def start(self, seeds: Sequence[int], batched: bool) -> None:
        """Start the episodes of ``seeds`` (serial: one seed; batched: every copy's)."""

    def decide(self, step: Step) -> None:
        """Set ``step.positions`` (or ``step.actions`` and ``step.by_actions``)."""
        raise NotImplementedError


def rollout(
    world: World,
    agent: Agent,
    seeds: Sequence[int],
    recorder: Recorder | None = None,
    *,
    batched: bool = False,
    clock: Callable[[], float] = time.perf_counter,
    warm_up: bool = False,
    on_step: Callable[[int], None] | None = None,
) -> int:
    """Run the episodes of ``seeds`` to their end (truncation or termination) and return
    the number of world steps taken.

    Serial: ``world`` has one copy and runs the seeds one after another; batched: it has
    one copy per seed. ``recorder`` sees every reset copy and every step. ``clock`` times
    the agent's decisions (:meth:`Step.timed`). ``warm_up``: in batched mode, one decision
    on the first problem, thrown away and the agent started again (its compilation is not
    timed). ``on_step(k)`` is called after every step with the number of copies that
    stepped (progress).
    """
    recorder = recorder if recorder is not None else Recorder()
    seeds = [int(s) for s in seeds]
    if batched:
        if world.num_copies != len(seeds):
            raise ValueError(f"a batched rollout needs one copy per seed ({len(seeds)})")
        _run(world, agent, seeds, range(len(seeds)), recorder, True, clock, warm_up, on_step)
        return int(np.max(world.get("k")))
    if world.num_copies != 1:
        raise ValueError(f"a serial rollout needs a world of one copy, got {world.num_copies}")
    steps = 0
    for j, seed in enumerate(seeds):
        _run(world, agent, [seed], [j], recorder, False, clock, False, on_step)
        steps += int(world.get("k", 0))
    return steps


def _run(
    world: World,
    agent: Agent,
    seeds: list[int],
    episodes: Sequence[int],
    recorder: Recorder,
    batched: bool,
    clock: Callable[[], float],
    warm_up: bool,
    on_step: Callable[[int], None] | None,
) -> None:
    """Reset ``world`` from ``seeds`` and run its copies' episodes to their end."""
    n = len(seeds)
    episode_of = np.asarray(episodes, dtype=np.int64)
    world.reset(seeds=seeds)
    agent.start(seeds, batched)
    if warm_up:
        agent.decide(Step(world, batched, np.arange(n), episode_of))
        agent.start(seeds, batched)
    for i in range(n):
        recorder.reset(world, i, int(episode_of[i]))
    live = np.ones(n, dtype=bool)
    while live.any():
        copies = np.flatnonzero(live)
        step = Step(world, batched, copies, episode_of[copies], clock)
        agent.decide(step)
        step.rewards = _advance(world, step)
        recorder.step(step)
        ended = np.asarray(world.get("terminated"), bool) | np.asarray(world.get("truncated"), bool)
        live &= ~ended.reshape(-1)
        if on_step is not None:
            on_step(len(copies))


def _advance(world: World, step: Step) -> FloatArray:
    """Step the copies of ``step`` by its positions or actions; return the rewards (N,)."""
    copies = step.copies
    rewards = np.full(world.num_copies, np.nan)
    by_actions = np.zeros(copies.size, dtype=bool) if step.by_actions is None else step.by_actions
    if not by_actions.all():
        res = world.step(step.positions, copies[~by_actions])
        rewards[copies[~by_actions]] = np.asarray(res.reward, dtype=np.float64).reshape(-1)
    if by_actions.any():
        res = world.step_actions(step.actions, copies[by_actions])
        rewards[copies[by_actions]] = np.asarray(res.reward, dtype=np.float64).reshape(-1)
    return rewards


# Agents -----------------------------------------------------------------------------------
class PlannerAgent(Agent):
    """A :class:`~activetrack.Planner` (``plan(problem, rng)``), its generator seeded
    ``np.random.default_rng([seed, 1])`` per episode (serial mode)."""

    def __init__(self, planner: Any) -> None:
        self.planner = planner
        self.rng: np.random.Generator | None = None

    def start(self, seeds: Sequence[int], batched: bool) -> None:
        self.rng = np.random.default_rng([seeds[0], 1])

    def decide(self, step: Step) -> None:
        problem = step.planning_problem()
        nxt = np.asarray(step.timed(self.planner.plan, problem, self.rng), dtype=np.float64)
        shape = problem.sensors.shape
        if nxt.shape != shape or not np.all(np.isfinite(nxt)):
            raise ValueError(
                f"planner {self.planner!r} returned next positions of shape {nxt.shape} "
                f"(must be {shape}, finite)"
            )
        step.positions = nxt


def reset_policy(policy: Any, seed: int) -> None:
    """Reseed a stochastic policy for the episode with seed ``seed``, if it can be.

    The expert policies' ``reset(seed)`` seeds their planner generator as the simulation
    runner does (``default_rng([seed, 1])``); batched, the first copy's seed (the batched
    planners draw nothing; the reset forgets past episodes).
    """
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset(seed)


class ExpertAgent(Agent):
    """An expert policy (``plan(problem) -> positions``, optionally ``reset(seed)``)."""

    def __init__(self, policy: Any) -> None:
        self.policy = policy

    def start(self, seeds: Sequence[int], batched: bool) -> None:
        reset_policy(self.policy, seeds[0])

    def decide(self, step: Step) -> None:
        problem = step.planning_problem()
        step.positions = np.asarray(step.timed(self.policy.plan, problem), dtype=np.float64)


class ActorAgent(Agent):
    """A policy that maps the observations ``{agent: obs}`` to actions ``{agent: action}``
    (``act(observations)`` or a callable; serial mode), optionally ``reset(seed)``."""

    def __init__(self, policy: Any, agents: Sequence[str]) -> None:
        self.policy, self.agents = policy, list(agents)
        self.act = getattr(policy, "act", policy)
        if not callable(self.act):
            raise TypeError(
                f"a policy needs plan(problem) or act(observations), got {type(policy).__name__}"
            )

    def start(self, seeds: Sequence[int], batched: bool) -> None:
        reset_policy(self.policy, seeds[0])

    def decide(self, step: Step) -> None:
        from activetrack.envs.tracking_env import actions_array

        obs = dict(zip(self.agents, step.observe(), strict=True))
        actions = step.timed(self.act, obs)
        step.actions = actions_array(actions, self.agents)
        step.by_actions = np.ones(step.copies.size, dtype=bool)


class BatchActorAgent(Agent):
    """A policy that maps every copy's observations (N, M, D) to actions (N, M, A) in one
    call (``act_batch(observations)``; batched mode), optionally ``reset(seed)``."""

    def __init__(self, policy: Any) -> None:
        self.policy = policy

    def start(self, seeds: Sequence[int], batched: bool) -> None:
        reset_policy(self.policy, seeds[0])

    def decide(self, step: Step) -> None:
        obs = step.observe()
        actions = np.asarray(step.timed(self.policy.act_batch, obs), dtype=np.float64)
        step.actions = actions.reshape(*obs.shape[:2], -1)
        step.by_actions = np.ones(step.copies.size, dtype=bool)


def policy_agent(policy: Any, agents: Sequence[str]) -> Agent:
    """Return the agent of ``policy``: an expert if it has ``plan``, an actor otherwise."""
    if callable(getattr(policy, "plan", None)):
        return ExpertAgent(policy)
    return ActorAgent(policy, agents)


class MixedAgent(Agent):
    """An expert whose plan every copy executes with probability ``beta``, a learner's
    actions otherwise (DAgger's rollouts; ``learner`` maps observations (R, D) to actions
    (R, 2)). One coin per episode, ``np.random.default_rng([seed, 2])``, drawn once per
    live copy and step, and only with a learner. The observations are always read (the
    labels' states)."""

    def __init__(self, expert: Any, learner: Callable | None = None, beta: float = 1.0) -> None:
        self.expert, self.learner, self.beta = expert, learner, beta
        self.coins: list[np.random.Generator] = []

    def start(self, seeds: Sequence[int], batched: bool) -> None:
        reset_policy(self.expert, seeds[0])
        self.coins = [np.random.default_rng([s, 2]) for s in seeds]

    def decide(self, step: Step) -> None:
        obs = step.observe()
        problem = step.planning_problem()
        step.positions = np.asarray(self.expert.plan(problem), dtype=np.float64)
        learner, beta = self.learner, self.beta
        if learner is None:
            return
        coins = self.coins if step.batched else self.coins[:1]
        by_expert = np.array([coins[i].random() < beta for i in step.copies.tolist()])
        if by_expert.all():
            return
        step.by_actions = ~by_expert
        if not step.batched:
            step.actions = np.asarray(learner(obs), dtype=np.float64)
            return
        own = step.copies[~by_expert]
        m, d = obs.shape[1:]
        acts = np.zeros(step.positions.shape)
        acts[own] = np.asarray(learner(obs[own].reshape(-1, d))).reshape(len(own), m, 2)
        step.actions = acts
