"""PPO (stable-baselines3) on the tracking game, from scratch or from an imitation warm start.

Two views of the same game:

- ``view="shared"`` (default): parameter sharing, every sensor is a slot of
  :class:`~activetrack.train.sb3_vecenv.SharedPolicyVecEnv` (``n_copies * M`` slots); one
  network maps an agent's observation to its own action. It can start from a BC/DAgger
  ``policy.zip`` (``init=``), whose network has the same architecture.
- ``view="centralized"``: plain SB3 on the Gymnasium view ``activetrack/ActiveTracking-v0``
  (``make_vec_env``, ``n_copies`` envs), one network for the joint action.

Reward scale. The reward is ``-tr P(k|k)_11`` (about 0.05 to 8 m^2 on ``paper``); returns
over 50 steps are O(10). We keep the environment's reward (``reward_scale = 1``, so
logged returns are in the paper's units) and let ``VecNormalize(norm_obs=False,
norm_reward=True)`` divide rewards by a running standard deviation of the discounted
return, training only; observations are already normalized by the env and nothing has to
be saved for evaluation. ``normalize_reward=False`` turns it off; a fixed scale can be set
with the scenario override ``reward_scale``.

Warm start. A BC network has a trained actor and an untrained critic; PPO's first updates
with a random critic would mostly undo the imitation. So the first ``critic_warmup``
timesteps train the critic only (the actor's parameters and ``log_std`` are frozen),
then PPO trains everything, by default with a smaller learning rate.

Outputs in ``out_dir``: ``policy.zip`` (the single-file policy that ``evaluate`` loads),
``model.zip`` (the SB3 model, to resume), ``checkpoints/`` (every ``checkpoint_every``
timesteps), ``tb/``
(TensorBoard), ``config.json`` (everything needed to rerun, seed included).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback, CallbackList, CheckpointCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.vec_env import VecEnv, VecMonitor, VecNormalize

from activetrack.files import RunOutputs, atomic_path, prepare_output_dir
from activetrack.train.frames import check_frame
from activetrack.train.networks import DEFAULT_NET, LOG_STD_RANGE, NetConfig, TrackingPolicy
from activetrack.train.policy_io import VIEWS, load_policy, save_policy
from activetrack.train.sb3_vecenv import make_shared_vec_env
from activetrack.train.utils import (
    DEFAULT_THREADS,
    check_bool,
    check_choice,
    check_float,
    check_int,
    configure_torch,
    seed_everything,
)

#: Validation episodes for model selection use seeds from here (disjoint from evaluation).
VALIDATION_SEED = 500_000
LR_SCHEDULES = ("constant", "linear")
BACKENDS = ("batched", "parallel")
#: Bounds of the counts: timesteps, environment copies, rollout slots per copy and in all.
MAX_TIMESTEPS, MAX_COPIES, MAX_ROLLOUT = 10**10, 1024, 1_000_000
#: What a PPO run writes in its output folder (folders end in "/").
OUTPUTS = ("policy.zip", "model.zip", "config.json", "checkpoints/", "tb/")


@dataclass
class PPOConfig:
    """Hyper-parameters of a PPO run (SB3 names; ``n_steps`` is per slot).

    Every field is checked and converted on construction (ValueError naming it):
    counts are integers in range, ``gamma`` in (0, 1], ``gae_lambda`` in [0, 1],
    ``learning_rate``, ``clip_range``, ``max_grad_norm`` and ``target_kl`` (or None) > 0,
    coefficients >= 0, everything finite.

    Attributes:
        total_timesteps: agent-steps to train for (a slot step counts once; one env step
            of the shared view is M timesteps).
        n_copies: environment copies (the shared view has ``n_copies * M`` slots).
        lr_schedule: ``"constant"`` or ``"linear"`` (decays to 0 over the PPO phase).
        critic_warmup: timesteps of critic-only training before PPO (warm start only),
            counted in ``total_timesteps`` (a longer warm-up stops at the budget).
        log_std_init: if set, overrides the initial log std (also of a warm start).
        eval_every, eval_episodes: every ``eval_every`` timesteps, evaluate the
            deterministic policy on ``eval_episodes`` validation seeds (500000, ...) and
            log its mean trace; with ``keep_best`` the best such policy is the one saved.
        backend: how the shared view steps its copies: ``"batched"`` (one
            ``BatchedActiveTracking``) or ``"parallel"`` (a loop over PettingZoo envs); the
            numbers are the same, the batched one is faster.
    """

    total_timesteps: int = 1_000_000
    n_copies: int = 8
    n_steps: int = 256
    batch_size: int = 512
    n_epochs: int = 10
    learning_rate: float = 3e-4
    lr_schedule: str = "constant"
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    target_kl: float | None = None
    normalize_reward: bool = True
    critic_warmup: int = 50_000
    log_std_init: float | None = None
    checkpoint_every: int = 100_000
    eval_every: int = 0
    eval_episodes: int = 20
    keep_best: bool = False
    view: str = "shared"
    backend: str = "batched"
    net: NetConfig = field(default_factory=lambda: DEFAULT_NET)

    def __post_init__(self) -> None:
        # Every field checked and converted here, once: ValueError naming the field.
        c = self
        c.total_timesteps = check_int("total_timesteps", c.total_timesteps, 1, MAX_TIMESTEPS)
        c.n_copies = check_int("n_copies", c.n_copies, 1, MAX_COPIES)
        # SB3 normalizes advantages over a batch, which needs at least two samples.
        c.n_steps = check_int("n_steps", c.n_steps, 2, MAX_ROLLOUT)
        c.batch_size = check_int("batch_size", c.batch_size, 2, MAX_ROLLOUT)
        if c.n_steps * c.n_copies > MAX_ROLLOUT:
            raise ValueError(
                f"n_steps * n_copies (the rollout) must be at most {MAX_ROLLOUT}, got "
                f"{c.n_steps} * {c.n_copies}"
            )
        c.n_epochs = check_int("n_epochs", c.n_epochs, 1, 10_000)
        c.learning_rate = check_float("learning_rate", c.learning_rate, 0, 1, low_open=True)
        c.lr_schedule = check_choice("lr_schedule", c.lr_schedule, LR_SCHEDULES)
        c.gamma = check_float("gamma", c.gamma, 0, 1, low_open=True)
        c.gae_lambda = check_float("gae_lambda", c.gae_lambda, 0, 1)
        c.clip_range = check_float("clip_range", c.clip_range, 0, low_open=True)
        c.ent_coef = check_float("ent_coef", c.ent_coef, 0)
        c.vf_coef = check_float("vf_coef", c.vf_coef, 0)
        c.max_grad_norm = check_float("max_grad_norm", c.max_grad_norm, 0, low_open=True)
        if c.target_kl is not None:
            c.target_kl = check_float("target_kl", c.target_kl, 0, low_open=True)
        c.normalize_reward = check_bool("normalize_reward", c.normalize_reward)
        c.critic_warmup = check_int("critic_warmup", c.critic_warmup, 0, MAX_TIMESTEPS)
        if c.log_std_init is not None:
            c.log_std_init = check_float("log_std_init", c.log_std_init, *LOG_STD_RANGE)
        c.checkpoint_every = check_int("checkpoint_every", c.checkpoint_every, 0, MAX_TIMESTEPS)
        c.eval_every = check_int("eval_every", c.eval_every, 0, MAX_TIMESTEPS)
        c.eval_episodes = check_int("eval_episodes", c.eval_episodes, 1, 100_000)
        c.keep_best = check_bool("keep_best", c.keep_best)
        if c.keep_best and c.eval_every == 0:
            raise ValueError("keep_best needs eval_every > 0 (the policies it chooses from)")
        c.view = check_choice("view", c.view, VIEWS)
        c.backend = check_choice("backend", c.backend, BACKENDS)
        c.net = NetConfig.coerce(c.net)

    def to_dict(self) -> dict[str, Any]:
        """Return JSON-friendly values."""
        d = asdict(self)
        d["net"] = self.net.to_dict()
        return d


class TqdmCallback(BaseCallback):
    """A tqdm progress bar over timesteps (SB3's ``progress_bar=True`` needs ``rich``)."""

    def __init__(self, total: int, desc: str = "ppo") -> None:
        super().__init__()
        self.total, self.desc, self.bar = total, desc, None

    def _on_training_start(self) -> None:
        from tqdm.auto import tqdm

        # A warm start learns in two calls (critic warm-up, then PPO): continue the count.
        self.bar = tqdm(
            total=self.total,
            initial=self.model.num_timesteps,
            desc=self.desc,
            unit="step",
            dynamic_ncols=True,
        )

    def _on_step(self) -> bool:
        self.bar.update(self.training_env.num_envs)
        return True

    def _on_training_end(self) -> None:
        self.bar.close()


class AtomicCheckpointCallback(CheckpointCallback):
    """SB3's ``CheckpointCallback`` (model only) writing each checkpoint atomically."""

    def _on_step(self) -> bool:
        if self.n_calls % self.save_freq == 0:
            with atomic_path(self._checkpoint_path(extension="zip")) as tmp:
                self.model.save(tmp)
        return True


class ValidationCallback(BaseCallback):
    """Every ``every`` timesteps: the deterministic policy's mean trace on validation seeds.

    Logged as ``eval/mean_trace``; the best state dict is kept in :attr:`best_state`.
    """

    def __init__(self, scenario: Any, overrides: dict, every: int, episodes: int) -> None:
        super().__init__()
        self.scenario, self.overrides = scenario, overrides
        self.every, self.episodes = every, episodes
        self.next_at = every
        self.best_trace = np.inf
        self.best_state: dict[str, torch.Tensor] | None = None
        self.history: list[tuple[int, float]] = []

    def _on_step(self) -> bool:
        if self.num_timesteps >= self.next_at:
            self.next_at += self.every
            trace = validation_trace(
                self.model.policy, self.scenario, self.episodes, self._view(), **self.overrides
            )
            self.history.append((self.num_timesteps, trace))
            self.logger.record("eval/mean_trace", trace)
            if trace < self.best_trace:
                self.best_trace = trace
                self.best_state = {k: v.clone() for k, v in self.model.policy.state_dict().items()}
        return True

    def _view(self) -> str:
        return "centralized" if self.model.action_space.shape[0] > 2 else "shared"


def validation_trace(
    policy: Any,
    scenario: Any,
    episodes: int,
    view: str = "shared",
    *,
    batched: bool = False,
    **overrides: Any,
) -> float:
    """Return the deterministic policy's mean trace over validation seeds 500000, ....

    ``batched``: every episode a copy of one batched world
    (:func:`activetrack.baselines.episodes.run_batched`; equal to the serial episodes to
    float32 rounding), else episode by episode in one environment.
    """
    from activetrack.baselines import rollout as ro
    from activetrack.envs import parallel_env
    from activetrack.train.policy_io import LearnedPolicy

    was_training = policy.training
    learned = LearnedPolicy(policy, {"view": view})
    seeds = range(VALIDATION_SEED, VALIDATION_SEED + episodes)
    if batched:
        from activetrack.baselines.episodes import run_batched

        rows = run_batched(scenario, overrides, learned, list(seeds))
        policy.train(was_training)
        return float(np.mean([row[0] for row in rows]))
    env = parallel_env(scenario, **overrides)
    traces: list[float] = []

    class Traces(ro.Recorder):
        def step(self, step: ro.Step) -> None:
            traces.append(float(step.world.get("trace", 0)))

    ro.rollout(env.world, ro.ActorAgent(learned, env.possible_agents), seeds, Traces())
    policy.train(was_training)
    return float(np.mean(traces))


def make_training_env(
    scenario: Any,
    n_copies: int,
    view: str,
    normalize_reward: bool,
    gamma: float,
    backend: str = "batched",
    **overrides: Any,
) -> VecEnv:
    """Return the (monitored, optionally reward-normalized) VecEnv PPO trains on."""
    if view == "shared":
        venv: VecEnv = VecMonitor(make_shared_vec_env(scenario, n_copies, backend, **overrides))
    elif view == "centralized":
        from stable_baselines3.common.env_util import make_vec_env

        import activetrack.envs  # noqa: F401  (registers the Gymnasium id)

        venv = make_vec_env(
            "activetrack/ActiveTracking-v0",
            n_envs=n_copies,
            env_kwargs={"scenario": scenario, **overrides},
        )
    else:
        raise ValueError(f"view must be 'shared' or 'centralized', got {view!r}")
    if normalize_reward:
        venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=gamma)
    return venv


def build_ppo(
    venv: VecEnv, config: PPOConfig, seed: int, tensorboard_log: str | None = None
) -> PPO:
    """Return an SB3 PPO model with the project's architecture and ``config``."""
    kwargs = config.net.policy_kwargs()
    if config.log_std_init is not None:
        kwargs["log_std_init"] = config.log_std_init
    lr = config.learning_rate
    # SB3 calls a schedule with the fraction of the current learn() call still to go.
    schedule = lr if config.lr_schedule == "constant" else (lambda remaining: remaining * lr)
    model = PPO(
        TrackingPolicy,
        venv,
        learning_rate=schedule,
        n_steps=config.n_steps,
        batch_size=config.batch_size,
        n_epochs=config.n_epochs,
        gamma=config.gamma,
        gae_lambda=config.gae_lambda,
        clip_range=config.clip_range,
        ent_coef=config.ent_coef,
        vf_coef=config.vf_coef,
        max_grad_norm=config.max_grad_norm,
        target_kl=config.target_kl,
        policy_kwargs=kwargs,
        tensorboard_log=tensorboard_log,
        seed=seed,
        device="cpu",
        verbose=0,
    )
    if tensorboard_log is None:
        # Without a log folder SB3 makes an empty ``SB3-<date>`` folder in the system's
        # temporary folder at every ``learn``; a logger with no outputs writes nothing.
        model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def check_warm_start(learned: Any, init: str | Path) -> None:
    """Raise ValueError unless the loaded policy ``learned`` (of the file ``init``) acts in
    the env's action space itself (PPO samples commands; a network trained on position
    targets predicts points)."""
    if getattr(learned, "head", None) is not None:
        raise ValueError(
            f"{init}: its network predicts position targets, not the env's actions; PPO can "
            "warm-start from a policy trained with --target command"
        )


def warm_start(model: PPO, init: str | Path, log_std_init: float | None) -> dict[str, Any]:
    """Load the actor of the policy file ``init`` into ``model.policy``; return its metadata.

    The critic keeps its fresh initialization (BC does not train it); ``log_std`` is set to
    ``log_std_init`` if given.
    """
    learned = load_policy(init)
    check_warm_start(learned, init)
    state = learned.policy.state_dict()
    own = model.policy.state_dict()
    if state.keys() != own.keys() or any(state[k].shape != own[k].shape for k in own):
        raise ValueError(
            f"{init}: its network ({learned.meta['net']}, view {learned.view}) does not match "
            "this PPO run's; pass the same --hidden/--activation and view"
        )
    # Only the actor: critic weights in a BC file are untrained noise.
    actor = {
        k: v for k, v in state.items() if not k.startswith(("value_net", "mlp_extractor.value_net"))
    }
    model.policy.load_state_dict(actor, strict=False)
    if log_std_init is not None:
        with torch.no_grad():
            model.policy.log_std.fill_(log_std_init)
    return learned.meta


def _set_actor_trainable(model: PPO, trainable: bool) -> None:
    p = model.policy
    for module in (p.mlp_extractor.policy_net, p.action_net):
        for param in module.parameters():
            param.requires_grad_(trainable)
    p.log_std.requires_grad_(trainable)


@dataclass
class PPOResult:
    """What :func:`train_ppo` returns: the model, the saved policy file and timings."""

    model: PPO
    policy_path: Path | None
    seconds: float
    validation: list[tuple[int, float]]


def train_ppo(
    scenario: Any = "paper",
    seed: int = 0,
    config: PPOConfig | None = None,
    out_dir: str | Path | None = None,
    init: str | Path | None = None,
    progress: bool = False,
    threads: int = DEFAULT_THREADS,
    overwrite: bool = False,
    **overrides: Any,
) -> PPOResult:
    """Train PPO (from scratch, or from the policy file ``init``); return the result.

    With ``out_dir`` (a folder, or the :class:`~activetrack.files.RunOutputs` of one
    prepared with :data:`OUTPUTS`) it writes ``policy.zip``, ``model.zip``,
    ``config.json``, ``checkpoints/`` and ``tb/`` there. The folder is checked and locked
    before training (a folder holding results needs ``overwrite``); everything is written
    in its staging folder and committed together at the end, so a failed run leaves the
    previous outputs, folders included. Deterministic for a
    given seed (with ``threads=1``, the default).
    """
    cfg = config or PPOConfig()
    if not isinstance(cfg, PPOConfig):
        raise TypeError(f"config must be a PPOConfig, got {type(cfg).__name__}")
    if out_dir is not None and not isinstance(out_dir, RunOutputs):
        with prepare_output_dir(out_dir, OUTPUTS, overwrite) as outputs:  # locked for the run
            return train_ppo(scenario, seed, cfg, outputs, init, progress, threads, **overrides)
    outputs = out_dir
    check_frame(cfg.net.frame, scenario, **overrides)
    configure_torch(threads)
    seed_everything(seed)
    t0 = time.perf_counter()
    venv = make_training_env(
        scenario,
        cfg.n_copies,
        cfg.view,
        cfg.normalize_reward,
        cfg.gamma,
        cfg.backend,
        **overrides,
    )
    rollout = cfg.n_steps * venv.num_envs
    if cfg.batch_size > rollout:
        venv.close()
        raise ValueError(
            f"batch_size must be at most the rollout, n_steps * slots = {cfg.n_steps} * "
            f"{venv.num_envs} = {rollout}, got {cfg.batch_size}"
        )
    tb = str(outputs.staged("tb/")) if outputs is not None else None
    model = build_ppo(venv, cfg, seed, tb)

    callbacks: list[BaseCallback] = []
    if progress:
        callbacks.append(TqdmCallback(cfg.total_timesteps))
    if outputs is not None and cfg.checkpoint_every > 0:
        callbacks.append(
            AtomicCheckpointCallback(
                save_freq=max(1, cfg.checkpoint_every // venv.num_envs),
                save_path=str(outputs.staged("checkpoints/")),
                name_prefix="ppo",
            )
        )
    validation = None
    if cfg.eval_every > 0:
        validation = ValidationCallback(scenario, overrides, cfg.eval_every, cfg.eval_episodes)
        callbacks.append(validation)

    init_meta = None
    remaining = cfg.total_timesteps
    if init is not None:
        init_meta = warm_start(model, init, cfg.log_std_init)
        warmup = min(cfg.critic_warmup, cfg.total_timesteps)  # part of the budget
        if warmup > 0:
            # Critic-only phase: frozen parameters get no gradient, so Adam leaves them alone.
            _set_actor_trainable(model, False)
            model.learn(warmup, callback=CallbackList(list(callbacks)), tb_log_name="ppo")
            _set_actor_trainable(model, True)
            remaining = cfg.total_timesteps - warmup
    if remaining > 0:
        model.learn(
            remaining,
            callback=CallbackList(list(callbacks)),
            tb_log_name="ppo",
            reset_num_timesteps=init is None or cfg.critic_warmup <= 0,
        )

    if validation is not None and cfg.keep_best and validation.best_state is not None:
        model.policy.load_state_dict(validation.best_state)
    policy_path = None
    if outputs is not None:
        train_config = {
            "algo": "ppo",
            "init": str(init) if init is not None else None,
            "init_meta": {k: init_meta[k] for k in ("kind", "seed", "train_config")}
            if init_meta
            else None,
            "overrides": overrides,
            "validation": validation.history if validation is not None else [],
            "seconds": time.perf_counter() - t0,
            **cfg.to_dict(),
        }
        kind = "ppo" if init is None else "ppo_warm"
        sc = _scenario_dict(scenario, overrides)
        with outputs:
            save_policy(
                outputs.staged("policy.zip"),
                model.policy,
                cfg.net,
                kind=kind,
                scenario=sc,
                seed=seed,
                view=cfg.view,
                train_config=train_config,
            )
            model.save(outputs.staged("model.zip"))
            config = {"seed": seed, "scenario": sc, **train_config}
            outputs.write_json("config.json", config, default=str)
            policy_path = outputs.commit()["policy.zip"]
    venv.close()
    hist = validation.history if validation is not None else []
    return PPOResult(model, policy_path, time.perf_counter() - t0, hist)


def _scenario_dict(scenario: Any, overrides: dict[str, Any]) -> dict[str, Any]:
    from activetrack.world.scenarios import make_scenario

    return make_scenario(scenario, **overrides).to_dict()
