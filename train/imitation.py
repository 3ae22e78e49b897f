"""Imitation of the GSR expert: behaviour cloning and DAgger, in plain torch.

The expert is :class:`activetrack.baselines.policies.GSRPolicy`: at every step it solves
the planning problem of the environment (``env.planning_problem()``) and returns the
sensors' next positions. The label of each agent is that position in its heading frame
over its reach, which the kinematics turns into the command that reaches it
(``target="position"``, the default: :mod:`activetrack.train.action_targets`), or the
action that reaches it (``target="command"``:
:func:`activetrack.kinematics.team.actions_to_reach`; the two agree on disks). With
parameter sharing every (agent, step) pair is one sample ``(observation, expert action)``;
the *label budget* counts them.

- **BC** rolls out the expert for ``episodes`` episodes and regresses the network's mean
  action on the expert's (mean squared error), for ``epochs`` passes.
- **DAgger** (Ross et al., 2011) spends the same number of episodes over ``iterations``
  rounds: round 0 is expert rollouts (BC), round ``i >= 1`` rolls out the mixture that
  executes the expert's action with probability ``beta_i = beta ** i`` at each step and the
  learner's otherwise, labels every visited state with the expert, aggregates and retrains.
  With one round it is BC. Each episode's coin (and the expert's generator) is seeded
  from the episode's seed, so an episode's labels do not depend on the others.

Labels can be collected on Ray workers (``workers``/``address`` of :func:`train_imitation`,
chunks of episodes as tasks, :mod:`activetrack.baselines.distributed`): the same labels,
in the same order, as the serial loop; the network is trained in this process.

The network is an SB3 ``ActorCriticPolicy`` (:mod:`activetrack.train.networks`); only its
actor (features -> actor MLP -> ``action_net``) is trained, so ``PPO(...).policy`` can load
its state dict and fine-tune it. Training episodes use seeds drawn from ``seed`` in
``[TRAIN_SEED_LOW, 2**31)``, far from the evaluation seeds (1000 and up by default).
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.policies import ActorCriticPolicy

from activetrack.baselines.rollout import MixedAgent, Recorder, Step, rollout
from activetrack.kinematics.team import actions_to_reach
from activetrack.train.action_targets import POSITION, PositionActions, check_target
from activetrack.train.frames import check_frame
from activetrack.train.networks import DEFAULT_NET, NetConfig, build_policy, mean_action
from activetrack.train.utils import (
    DEFAULT_THREADS,
    check_float,
    check_int,
    configure_torch,
    seed_everything,
)

#: Training episodes use seeds at or above this, disjoint from held-out evaluation seeds.
TRAIN_SEED_LOW = 1_000_000
#: Bounds of the label budget (episodes) and of the passes over the data.
MAX_EPISODES, MAX_EPOCHS = 1_000_000, 1_000_000
#: The network's action box with position targets (its saturated mean is in the unit disk).
_UNIT_BOX = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)


@dataclass
class Dataset:
    """Aggregated ``(observation, expert action)`` samples, float32."""

    obs: np.ndarray
    actions: np.ndarray

    @classmethod
    def empty(cls, obs_dim: int, act_dim: int = 2) -> Dataset:
        """Return a dataset with no samples."""
        return cls(np.zeros((0, obs_dim), np.float32), np.zeros((0, act_dim), np.float32))

    def __len__(self) -> int:
        return int(self.obs.shape[0])

    def extend(self, other: Dataset) -> Dataset:
        """Return the concatenation of ``self`` and ``other``."""
        return Dataset(
            np.concatenate([self.obs, other.obs]), np.concatenate([self.actions, other.actions])
        )


@dataclass
class ImitationConfig:
    """Budget and optimizer of BC/DAgger.

    Every field is checked and converted on construction (ValueError naming it): counts
    are integers >= 1 with ``iterations <= episodes``, ``beta`` in [0, 1], ``lr`` in
    (0, 1], ``weight_decay`` in [0, 1].

    Attributes:
        episodes: expert-labelled episodes in total (the label budget is
            ``episodes * n_steps * M`` samples), shared by all DAgger rounds.
        epochs: passes over the data for BC; for DAgger, passes after *each* round.
        iterations: DAgger rounds (1 = BC).
        beta: DAgger's expert-mixing decay: round i executes the expert with prob ``beta**i``.
        batch_size, lr, weight_decay: Adam on the mean squared error of the mean action;
            the learning rate decays to 10% by a cosine schedule over each training call.
        net: the network architecture.
        target: what the network predicts (:mod:`activetrack.train.action_targets`):
            ``"position"``, the expert's next position in the sensor's heading frame over
            its reach, turned into the command by the kinematics (the same as
            ``"command"`` on a team of disks); or ``"command"``, the env's action itself.
    """

    episodes: int = 100
    epochs: int = 100
    iterations: int = 1
    beta: float = 0.5
    batch_size: int = 256
    lr: float = 1e-3
    weight_decay: float = 0.0
    net: NetConfig = field(default_factory=lambda: DEFAULT_NET)
    target: str = POSITION

    def __post_init__(self) -> None:
        # Every field checked and converted here, once: ValueError naming the field.
        self.episodes = check_int("episodes", self.episodes, 1, MAX_EPISODES)
        self.epochs = check_int("epochs", self.epochs, 1, MAX_EPOCHS)
        self.iterations = check_int("iterations", self.iterations, 1, self.episodes)
        self.beta = check_float("beta", self.beta, 0, 1)
        self.batch_size = check_int("batch_size", self.batch_size, 1, 10**7)
        self.lr = check_float("lr", self.lr, 0, 1, low_open=True)
        self.weight_decay = check_float("weight_decay", self.weight_decay, 0, 1)
        self.net = NetConfig.coerce(self.net)
        self.target = check_target(self.target)

    def to_dict(self) -> dict[str, Any]:
        """Return JSON-friendly values."""
        d = asdict(self)
        d["net"] = self.net.to_dict()
        return d


#: DAgger's own defaults (``activetrack train dagger``); the other fields as for BC.
DAGGER_DEFAULTS: dict[str, Any] = {"epochs": 40, "iterations": 5}


def train_seeds(seed: int, n: int) -> list[int]:
    """Return ``n`` distinct training-episode seeds drawn from ``seed`` (all >= TRAIN_SEED_LOW)."""
    rng = np.random.default_rng([seed, 0x1A])
    seeds: dict[int, None] = {}  # insertion-ordered set
    while len(seeds) < n:
        for s in rng.integers(TRAIN_SEED_LOW, 2**31, size=n - len(seeds)):
            seeds[int(s)] = None
    return list(seeds)


class _LabelRecorder(Recorder):
    """Keeps each episode's observations, the expert's labels (the actions that reach its
    planned positions) and posterior traces, in episode order."""

    def __init__(
        self,
        n: int,
        on_step: Callable[[int], None] | None = None,
        head: PositionActions | None = None,
    ) -> None:
        self.head = head
        self.obs: list[list[np.ndarray]] = [[] for _ in range(n)]
        self.actions: list[list[np.ndarray]] = [[] for _ in range(n)]
        self.traces: list[list[float]] = [[] for _ in range(n)]
        self.on_step = on_step

    def step(self, step: Step) -> None:
        problem = step.problem
        states = problem.sensors if problem.sensor_states is None else problem.sensor_states
        if self.head is None:
            labels = actions_to_reach(problem.kinematics, step.positions, states, problem.r)
        else:
            labels = self.head.labels(step.positions, states)
        labels = labels.astype(np.float32)
        for i, j in zip(step.copies.tolist(), step.episodes.tolist(), strict=True):
            self.obs[j].append(step.observations[i] if step.batched else step.observations)
            self.actions[j].append(labels[i] if step.batched else labels)
            self.traces[j].append(float(step.world.get("trace", i)))
        if self.on_step is not None:
            self.on_step(len(step.copies))

    def result(self) -> tuple[Dataset, list[float]]:
        d = self.obs[0][0].shape[-1]
        obs = np.concatenate([np.stack(o) for o in self.obs]).reshape(-1, d)
        actions = np.concatenate([np.stack(a) for a in self.actions]).reshape(-1, 2)
        return Dataset(obs.astype(np.float32), actions), [float(np.mean(t)) for t in self.traces]


def rollout_labels(
    env: Any,
    expert: Any,
    seeds: list[int],
    learner: Callable[[np.ndarray], np.ndarray] | None = None,
    beta: float = 1.0,
    on_step: Callable[[int], None] | None = None,
    head: PositionActions | None = None,
) -> tuple[Dataset, list[float]]:
    """Return the expert-labelled states visited on ``seeds`` and each episode's mean trace.

    At every step the expert labels all agents' observations; the team then executes the
    expert's actions with probability ``beta`` (or always, without a ``learner``) and the
    learner's otherwise (``learner`` maps observations (M, D) to actions (M, 2)). The
    episodes run in ``env``'s world (the rollout of :mod:`activetrack.baselines.rollout`,
    serial, with its :class:`~activetrack.baselines.rollout.MixedAgent`).

    Every episode draws from its own generators, made from its seed: the expert's is reset
    with ``reset(seed)`` when it has one (:class:`~activetrack.baselines.PlannerPolicy`:
    ``default_rng([seed, 1])``, as the simulation runner) and the mixing coin is
    ``default_rng([seed, 2])``. So an episode's labels do not depend on which episodes ran
    before it, and seeds split over Ray workers give the same labels as one loop.
    ``on_step(1)`` is called after every step (progress). The labels are the actions
    that reach the expert's positions, or with a ``head`` (position targets) its
    :meth:`~activetrack.train.action_targets.PositionActions.labels`.
    """
    base = env.unwrapped
    recorder = _LabelRecorder(len(seeds), on_step, head)
    rollout(base.world, MixedAgent(expert, learner, beta), seeds, recorder)
    base.agents = []  # the last episode ended in its world
    return recorder.result()


def rollout_labels_batched(
    scenario: Any,
    overrides: dict[str, Any],
    expert: Any,
    seeds: list[int],
    learner: Callable[[np.ndarray], np.ndarray] | None = None,
    beta: float = 1.0,
    on_step: Callable[[int], None] | None = None,
    head: PositionActions | None = None,
) -> tuple[Dataset, list[float]]:
    """Return :func:`rollout_labels`' data for a batched expert, every episode a copy of one
    :class:`~activetrack.world.World`: the expert labels all copies with one ``plan`` call
    per step (the look-ahead planner's labels cost a fraction of the serial ones').

    The same seeds, coins and episodes as :func:`rollout_labels`, the data in the same
    order (episode by episode); the labels equal the serial ones to the planner's
    tolerance (:func:`activetrack.baselines.evaluation.run_batched`). ``learner`` maps
    observations (R, D) to actions (R, 2) for any number of rows R. ``on_step(k)`` is
    called after every step with the number of copies that stepped (progress).
    """
    from activetrack.world import World

    world = World(scenario, len(seeds), **overrides)
    recorder = _LabelRecorder(len(seeds), on_step, head)
    rollout(world, MixedAgent(expert, learner, beta), seeds, recorder, batched=True)
    return recorder.result()


def label_seeds(
    scenario: Any,
    overrides: dict[str, Any],
    expert: Any,
    seeds: list[int],
    policy: ActorCriticPolicy | None = None,
    beta: float = 1.0,
    threads: int = DEFAULT_THREADS,
    head: PositionActions | None = None,
) -> tuple[Dataset, list[float]]:
    """Return :func:`rollout_labels` on ``seeds`` in a new environment (one Ray task's chunk).

    ``policy`` is the learner (DAgger rounds >= 1), run with ``threads`` torch threads as
    in the training process; ``head``: the position targets, if any.
    """
    from activetrack.envs import parallel_env

    env = parallel_env(scenario, **overrides)
    try:
        if policy is None:
            return rollout_labels(env, expert, seeds, head=head)
        configure_torch(threads)
        return rollout_labels(env, expert, seeds, learner_fn(policy, head), beta, head=head)
    finally:
        env.close()


def _labels_on_ray(
    scenario: Any,
    overrides: dict[str, Any],
    expert: Any,
    seeds: list[int],
    policy: ActorCriticPolicy | None,
    beta: float,
    threads: int,
    cpus: int,
    on_episodes: Callable[[int], None] | None = None,
    head: PositionActions | None = None,
) -> tuple[Dataset, list[float]]:
    """Return :func:`label_seeds` over ``seeds``, as Ray tasks on chunks, joined in order
    (``on_episodes(k)`` called as a chunk of ``k`` episodes completes)."""
    from activetrack.baselines import distributed

    case = {
        "scenario": scenario, "overrides": overrides, "expert": expert, "policy": policy,
        "beta": beta, "threads": threads, "head": head,
    }  # fmt: skip
    (done,) = distributed.map_seeds(label_seeds, [case], seeds, cpus, on_done=on_episodes)
    data = Dataset(
        np.concatenate([d.obs for d, _ in done]), np.concatenate([d.actions for d, _ in done])
    )
    return data, [t for _, traces in done for t in traces]


def fit(
    policy: ActorCriticPolicy,
    data: Dataset,
    epochs: int,
    batch_size: int = 256,
    lr: float = 1e-3,
    weight_decay: float = 0.0,
    generator: torch.Generator | None = None,
    log: Callable[[str, float, int], None] | None = None,
    step0: int = 0,
    on_epoch: Callable[[int], None] | None = None,
) -> list[float]:
    """Train the actor's mean action on ``data`` by MSE; return the mean loss of each epoch
    (``on_epoch(1)`` called after each, for progress)."""
    obs = torch.as_tensor(data.obs)
    target = torch.as_tensor(data.actions)
    n = len(data)
    batches_per_epoch = max(1, int(np.ceil(n / batch_size)))
    opt = torch.optim.Adam(
        [p for p in policy.parameters() if p.requires_grad], lr=lr, weight_decay=weight_decay
    )
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(
        opt, T_max=max(1, epochs * batches_per_epoch), eta_min=0.1 * lr
    )
    policy.train()
    losses = []
    for epoch in range(epochs):
        perm = torch.randperm(n, generator=generator)
        total = 0.0
        for b in range(batches_per_epoch):
            idx = perm[b * batch_size : (b + 1) * batch_size]
            loss = torch.nn.functional.mse_loss(mean_action(policy, obs[idx]), target[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(idx)
        losses.append(total / n)
        if log is not None:
            log("imitation/mse", losses[-1], step0 + epoch)
        if on_epoch is not None:
            on_epoch(1)
    policy.eval()
    return losses


def learner_fn(
    policy: ActorCriticPolicy, head: PositionActions | None = None
) -> Callable[[np.ndarray], np.ndarray]:
    """Return ``obs (R, D) -> clipped deterministic actions (R, 2)`` of ``policy`` (rows: a
    team's agents, copy after copy); with a ``head`` the network's outputs are position
    targets, turned into the env's actions by
    :meth:`~activetrack.train.action_targets.PositionActions.actions`."""

    def act(obs: np.ndarray) -> np.ndarray:
        out = policy.predict(obs, deterministic=True)[0]
        return out if head is None else head.actions(out)

    return act


@dataclass
class ImitationResult:
    """What :func:`train_imitation` returns.

    Attributes:
        policy: the trained SB3 ``ActorCriticPolicy``.
        head: the position targets that turn its outputs into actions (None: its outputs
            are the actions).
        data: the aggregated dataset (its size is the label budget spent).
        losses: the final MSE of each training call (one per round).
        rollout_traces: per round, the mean trace of the rollouts that collected its data.
        seconds: wall-clock time.
    """

    policy: ActorCriticPolicy
    head: PositionActions | None
    data: Dataset
    losses: list[float]
    rollout_traces: list[float]
    seconds: float


def train_imitation(
    scenario: Any = "paper",
    seed: int = 0,
    config: ImitationConfig | None = None,
    tensorboard_dir: str | None = None,
    progress: bool = False,
    expert: Any | None = None,
    threads: int = DEFAULT_THREADS,
    *,
    workers: int = 1,
    address: str | None = None,
    batched: bool = False,
    **overrides: Any,
) -> ImitationResult:
    """Return a policy trained by BC (``iterations == 1``) or DAgger on the expert's labels.

    ``scenario`` and ``overrides`` configure the parallel env as in
    :func:`activetrack.envs.parallel_env`. The expert defaults to ``GSRPolicy()``; any
    object with ``plan(problem) -> positions`` works. ``threads`` torch threads (1: see
    :mod:`activetrack.train.utils`). Deterministic for a given ``seed``.

    ``workers > 1`` or an ``address`` collects each round's labels as Ray tasks
    (:mod:`activetrack.baselines.distributed`: a local Ray with ``workers`` CPUs, or the
    cluster at ``address``), the same labels as the serial loop; training stays here.
    ``batched`` collects them in one batched world instead
    (:func:`rollout_labels_batched`; GSR and the look-ahead planner as experts).
    """
    from activetrack.baselines import distributed
    from activetrack.envs import parallel_env

    cfg = config or ImitationConfig()
    if not isinstance(cfg, ImitationConfig):
        raise TypeError(f"config must be an ImitationConfig, got {type(cfg).__name__}")
    workers, address = distributed.check_options(workers, address)
    on_ray = distributed.is_distributed(workers, address)
    if expert is None:
        from activetrack.baselines.policies import GSRPolicy

        expert = GSRPolicy()
    _check_batched(batched, workers, address, expert)
    check_frame(cfg.net.frame, scenario, **overrides)
    configure_torch(threads)
    t0 = time.perf_counter()
    seed_everything(seed)
    gen = torch.Generator().manual_seed(seed)
    env = parallel_env(scenario, **overrides)
    agent = env.possible_agents[0]
    head = None
    if cfg.target == POSITION:
        head = PositionActions.from_scenario(env.unwrapped.world.scenario)
    # Position targets live in the unit disk (the heading frame over the reach).
    space = env.action_space(agent) if head is None else _UNIT_BOX
    policy = build_policy(env.observation_space(agent), space, cfg.net, cfg.lr)

    writer = None
    if tensorboard_dir is not None:
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(tensorboard_dir)
    log = writer.add_scalar if writer is not None else None

    # Split the episode budget as evenly as possible over the rounds.
    seeds = train_seeds(seed, cfg.episodes)
    splits = np.array_split(np.arange(cfg.episodes), cfg.iterations)
    data = Dataset.empty(env.observation_space(agent).shape[0])
    losses, traces = [], []
    from tqdm.auto import tqdm

    # Progress of the two parts that take the time: labelling (environment steps, every
    # round's episodes) and training (epochs, every round's).
    n_steps = env.unwrapped.world.scenario.n_steps
    labelling = tqdm(
        total=cfg.episodes * n_steps, desc="labelling", unit="step", unit_scale=True,
        disable=not progress, position=0,
    )  # fmt: skip
    training = tqdm(
        total=cfg.iterations * cfg.epochs, desc="training", unit="epoch",
        disable=not progress, position=1,
    )  # fmt: skip
    # One Ray for all rounds (started once); the serial loop uses this process's env.
    ray_or_none = distributed.session(workers, address) if on_ray else contextlib.nullcontext(1)
    with ray_or_none as cpus, labelling, training:
        for i, idx in enumerate(splits):
            round_seeds = [seeds[j] for j in idx]
            learner, beta = (None, 1.0) if i == 0 else (policy, cfg.beta**i)
            labelling.set_postfix_str(f"round {i + 1}/{len(splits)}")
            done = labelling.n
            if on_ray:
                new, tr = _labels_on_ray(
                    scenario, overrides, expert, round_seeds, learner, beta, threads, cpus,
                    on_episodes=lambda k: labelling.update(k * n_steps), head=head,
                )  # fmt: skip
            elif batched:
                act = None if learner is None else learner_fn(learner, head)
                new, tr = rollout_labels_batched(
                    scenario, overrides, expert, round_seeds, act, beta, labelling.update, head
                )
            else:
                act = None if learner is None else learner_fn(learner, head)
                new, tr = rollout_labels(
                    env, expert, round_seeds, act, beta, labelling.update, head
                )
            # Episodes that ended early: the round's share of the bar, whole.
            labelling.update(done + len(round_seeds) * n_steps - labelling.n)
            data = data.extend(new)
            traces.append(float(np.mean(tr)))
            epoch_losses = fit(
                policy,
                data,
                cfg.epochs,
                cfg.batch_size,
                cfg.lr,
                cfg.weight_decay,
                gen,
                log,
                step0=i * cfg.epochs,
                on_epoch=training.update,
            )
            losses.append(epoch_losses[-1])
            if log is not None:
                log("imitation/rollout_mean_trace", traces[-1], i)
                log("imitation/samples", len(data), i)
    if writer is not None:
        writer.close()
    env.close()
    return ImitationResult(policy, head, data, losses, traces, time.perf_counter() - t0)


def _check_batched(batched: object, workers: object, address: object, expert: Any) -> None:
    """Raise ValueError unless ``batched`` is a bool that the other options and the expert
    allow."""
    from activetrack.baselines.evaluation import batchable, check_batched

    check_batched(batched, workers, address)
    if batched and not batchable(expert):
        raise ValueError(
            f"batched labels need a batched deterministic expert (GSRPolicy or "
            f"LookaheadPolicy), got {expert!r}"
        )
