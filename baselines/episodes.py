"""The evaluation's episodes: one policy's episodes as rows of metrics, each a use of the
one episode loop (:func:`activetrack.baselines.rollout.rollout`).

A row is ``(mean_trace, rmse, return, mean_nees, ms_per_step, no_detection,
longest_gap, track_loss, robot_score_mean, robot_score_worst, disagreement, gospa,
fraction_tracked, first_detection, all_tracked)`` over steps 1..n_steps of an episode
(``track_loss``: :func:`activetrack.baselines.protocol.track_loss_rate` at the threshold
``loss_trace``, by default each target's prior position trace; the team's three, with a
filter per robot, the means over the steps of :meth:`activetrack.world.World.team_metrics`,
else NaN; the last four, with targets that appear and leave (the field ``births``),
:class:`activetrack.metrics.track_census.TrackCensus`'s mean GOSPA, mean over the
episode's targets of the fraction of time tracked and of the time to first detection (s;
over those detected), and 1.0 if every target was tracked, else 0.0; NaN without births or
targets): serially in an environment's world (:func:`run_episode`, a chunk of seeds in
:func:`run_episodes`, one Ray task), or every episode a copy of one batched world
(:func:`run_batched`). ``ms_per_step`` is the CPU time (``time.process_time``) of the
policy's decisions per step, after a warm-up decision that is not counted
(:func:`warm_up`: the compiled kernels' first compilation).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from activetrack.baselines.protocol import prior_traces, track_loss_rate
from activetrack.baselines.rollout import (
    BatchActorAgent,
    ExpertAgent,
    Recorder,
    Step,
    policy_agent,
    reset_policy,
    rollout,
)
from activetrack.baselines.simulation import detection_gaps
from activetrack.metrics.track_census import TrackCensus, census_of

#: The row's entries with targets that appear and leave (NaN without births).
CENSUS_FIELDS = ("gospa", "fraction_tracked", "first_detection", "all_tracked")


def _mean_of_finite(values: list[float]) -> float:
    """Return the mean of the finite values (NaN: a step without a track of a present
    target, with ``births``), NaN if none is; the plain mean when all are."""
    arr = np.asarray(values)
    ok = np.isfinite(arr)
    return float(np.mean(arr)) if ok.all() else float(np.mean(arr[ok])) if ok.any() else np.nan


def warm_up(env: Any, policy: Any, seed: int) -> None:
    """Make one decision of ``policy`` on the first observation of the episode ``seed``
    and forget it (the policy reset again): compiles what its first call compiles, so
    that the timing of the episodes counts none of it."""
    reset_policy(policy, seed)
    obs, _ = env.reset(seed=seed)
    if callable(getattr(policy, "plan", None)):
        policy.plan(env.unwrapped.planning_problem())
    else:
        getattr(policy, "act", policy)(obs)
    reset_policy(policy, seed)


class _RowRecorder(Recorder):
    """Keeps the metrics of :func:`run_episode`'s row per episode (serial: the single
    environment's infos, :meth:`~activetrack.world.World.copy_info`; batched: the world's
    fields of each copy), and each target's position trace per step for the track-loss
    rate at ``loss_trace`` (m^2; None: each target's prior position trace)."""

    def __init__(self, n: int, on_step: Any = None, loss_trace: float | None = None) -> None:
        self.traces: list[list[float]] = [[] for _ in range(n)]
        self.errors: list[list[float]] = [[] for _ in range(n)]
        self.nees: list[list[float]] = [[] for _ in range(n)]
        self.seen: list[list[np.ndarray]] = [[] for _ in range(n)]
        # With births: which slots hold a target (the detection metrics count only those).
        self.present: list[list[np.ndarray]] = [[] for _ in range(n)]
        self.target_traces: list[list[list[float]]] = [[] for _ in range(n)]
        # With a filter per robot: the team's metrics per step (team_filters.team_metrics).
        self.team: list[list[list[float]]] = [[] for _ in range(n)]
        self.loss_trace = loss_trace
        self.totals = [0.0] * n
        self.seconds = 0.0
        self.on_step = on_step
        self.census: list[TrackCensus | None] = [None] * n

    def step(self, step: Step) -> None:
        world = step.world
        self.seconds += step.seconds
        births = world.scenario.births is not None
        for i, j in zip(step.copies.tolist(), step.episodes.tolist(), strict=True):
            if births:  # targets that appear and leave: the multi-target metrics
                if self.census[j] is None:
                    self.census[j] = TrackCensus(world.scenario.dt)
                self.census[j].add(*census_of(world, i))
            if step.batched:
                trace, error = float(world.get("trace", i)), float(world.position_error(i))
            else:
                _, trace, error, _, _ = world.copy_info(i)
            self.traces[j].append(trace)
            self.errors[j].append(error)
            self.nees[j].append(float(world.position_nees(i)))
            self.seen[j].append(world.get("detected", i).any(axis=-1))
            # Read only (the world's numbers unchanged): each target's own trace; a present
            # target the team holds no track of is as lost as can be (inf).
            traces = [float(np.trace(world.get("P", i, k)[:2, :2])) for k in range(world.n_targets)]
            if births:
                self.present[j].append(world.present[i].copy())
                traces = np.where(world.tracked[i], traces, np.inf).tolist()
            self.target_traces[j].append(traces)
            self.totals[j] += float(step.rewards[i])
            if world.decentralized:
                self.team[j].append(list(world.team_metrics(i).values()))
        if self.loss_trace is None:
            self.loss_trace = prior_traces(world.scenario)
        if self.on_step is not None and not step.batched:
            self.on_step()

    def row(self, j: int, ms: float) -> tuple[float, ...]:
        """Return episode ``j``'s row (``ms``: the CPU ms per decision)."""
        present = np.array(self.present[j]) if self.present[j] else None
        return (
            float(np.mean(self.traces[j])),
            float(np.sqrt(np.mean(np.square(self.errors[j])))),
            self.totals[j],
            _mean_of_finite(self.nees[j]),
            ms,
            *detection_gaps(np.array(self.seen[j]), present),
            track_loss_rate(
                np.array(self.seen[j]).reshape(-1, len(self.target_traces[j][0])),
                np.array(self.target_traces[j]),
                self.loss_trace,
                present,
            ),
            *(np.mean(self.team[j], axis=0).tolist() if self.team[j] else [np.nan] * 3),
            *self._census_row(j),
        )

    def _census_row(self, j: int) -> tuple[float, ...]:
        """Return episode ``j``'s census entries (:data:`CENSUS_FIELDS`), NaN without births."""
        if self.census[j] is None:
            return (np.nan,) * len(CENSUS_FIELDS)
        s = self.census[j].summary()
        first = [t for t in s["first_detection"] if t is not None]
        return (
            s["gospa"],
            float(np.mean(s["fraction_tracked"])) if s["fraction_tracked"] else np.nan,
            float(np.mean(first)) if first else np.nan,
            float(s["all_tracked"]),
        )


def run_episode(
    env: Any, policy: Any, seed: int, on_step: Any = None, loss_trace: float | None = None
) -> tuple[float, ...]:
    """Return ``(mean_trace, rmse, return, mean_nees, ms_per_step, no_detection,
    longest_gap, track_loss)`` of one episode of ``policy`` from ``seed`` in ``env``'s world (the
    rollout of :mod:`activetrack.baselines.rollout`, serial; ``ms_per_step``: the
    policy's CPU time per decision in ms; the last two as
    :func:`activetrack.baselines.simulation.detection_gaps`; the last the track-loss rate
    at ``loss_trace``, see the module docstring). ``on_step()`` is called
    after every step (progress). The environment is reset to ``seed`` first and holds
    the episode's end after it."""
    base = env.unwrapped
    env.reset(seed=seed)  # the env's own state (agents, renderer) starts the episode
    recorder = _RowRecorder(1, on_step, loss_trace)
    steps = rollout(
        base.world, policy_agent(policy, base.possible_agents), [seed], recorder,
        clock=time.process_time,
    )  # fmt: skip
    base.agents = []  # the episode ended in its world
    return recorder.row(0, 1e3 * recorder.seconds / steps)


def run_batched(
    scenario: Any,
    overrides: dict[str, Any],
    policy: Any,
    seeds: list[int],
    on_step: Any = None,
    loss_trace: float | None = None,
) -> list[tuple[float, ...]]:
    """Return :func:`run_episode`'s rows for a planner policy (or a policy with
    ``act_batch``, a learned one), each seed's episode a copy of one batched
    :class:`~activetrack.world.World` (the policy plans, or acts on, every copy at once;
    the rollout of :mod:`activetrack.baselines.rollout`, batched).

    The world's copies are the environment's episodes (same seeds, same draws; a copy's
    numbers equal a single environment's bit for bit) and the planners' batched paths plan
    each copy as alone, so a deterministic planner's rows equal the serial ones bit for
    bit (tests/baselines/test_batch_independence.py: GSR on every preset), and a copy's
    row does not depend on the batch: the same seed gives the same row alone (a batch of
    one) or among any other copies. A learned policy's network runs on all copies' rows
    at once; its float32 arithmetic can round a row differently in another batch, so its
    rows equal the serial ones to that rounding (tests/train/test_batched_evaluation.py).
    ``ms_per_step`` is the batch's CPU time per decision divided by the number of copies,
    after a warm-up decision (the batch's first, planned twice).
    ``on_step(k)`` is called after every step with the number of copies that stepped.
    """
    from activetrack.world import World

    n = len(seeds)
    world = World(scenario, n, **overrides)
    recorder = _RowRecorder(n, loss_trace=loss_trace)
    planner = callable(getattr(policy, "plan", None))
    agent = ExpertAgent(policy) if planner else BatchActorAgent(policy)
    steps = rollout(
        world, agent, seeds, recorder, batched=True, clock=time.process_time,
        warm_up=True, on_step=on_step,
    )  # fmt: skip
    ms = 1e3 * recorder.seconds / (n * steps)
    return [recorder.row(i, ms) for i in range(n)]


def run_episodes(
    scenario: Any,
    overrides: dict[str, Any],
    policy: Any,
    seeds: list[int],
    loss_trace: float | None = None,
) -> list[tuple[float, ...]]:
    """Return :func:`run_episode` on each of ``seeds`` in a new environment (one Ray task)."""
    from activetrack.envs import parallel_env

    env = parallel_env(scenario, **overrides)
    try:
        warm_up(env, policy, seeds[0])
        return [run_episode(env, policy, s, loss_trace=loss_trace) for s in seeds]
    finally:
        env.close()
