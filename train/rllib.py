"""RLlib (Ray) multi-agent PPO on the tracking game, exported as the library's ``policy.zip``.

Needs the ``[ray]`` extra (``pip install "activetrack[ray]"``); importing this module
without Ray raises an ``ImportError`` that says so. Nothing in :mod:`activetrack.train`
imports it; ``activetrack train rllib-ppo`` loads it on use.

- :func:`register_rllib_envs`: every PettingZoo parallel id of the library
  (``activetrack/...``) becomes an RLlib env name, created as RLlib's
  ``ParallelPettingZooEnv`` over :func:`activetrack.envs.parallel_env`; the ``env_config``
  is the parallel env's keyword arguments (``scenario`` and any scenario field).
- :class:`SharedTrackingModule`: a torch ``RLModule`` holding one
  :class:`~activetrack.train.networks.TrackingPolicy`, the very network the SB3 path trains
  (actor and critic MLPs, the per-sensor saturated Gaussian mean, a state-independent
  ``log_std``). Its action-distribution inputs are ``[s(m), log_std]`` for RLlib's diagonal
  Gaussian, so RLlib's deterministic action is the SB3 policy's deterministic action and
  :func:`export_policy` writes the network's state dict as it is.
- :func:`rllib_ppo_config`: the documented multi-agent PPO configuration
  (:class:`RLlibPPOConfig`): every sensor maps to the one module ``"shared"``
  (parameter sharing, as the SB3 path), PPO-clip without RLlib's KL penalty, SB3's
  defaults for the rest.
- :func:`train_rllib_ppo`: trains on a local Ray or a running cluster (``address``) and
  writes ``policy.zip``, ``config.json``, ``checkpoints/`` and ``tb/``;
  :func:`load_checkpoint_module` reads the module back from a checkpoint.

Reward scale. RLlib has no running reward normalization like SB3's ``VecNormalize``; the
env's own scenario field ``reward_scale`` (:attr:`RLlibPPOConfig.reward_scale`) multiplies
the reward ``-tr P(k|k)_11`` (eq. 12, 17) during training only, so the critic fits values
of order one. The policy is unaffected at evaluation.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from activetrack.baselines.distributed import (
    check_address_form,
    check_reachable,
    quiet_failure_handler,
)
from activetrack.files import RunOutputs, keep_signal_handlers, prepare_output_dir
from activetrack.train.frames import check_frame
from activetrack.train.networks import DEFAULT_NET, NetConfig, build_policy
from activetrack.train.policy_io import save_policy
from activetrack.train.utils import (
    DEFAULT_THREADS,
    check_choice,
    check_float,
    check_int,
    configure_torch,
    seed_everything,
)

INSTALL_HINT = 'pip install "activetrack[ray]"'

try:
    import ray
    from ray.rllib.algorithms.ppo import PPOConfig as _RLlibPPOConfig
    from ray.rllib.core.columns import Columns
    from ray.rllib.core.rl_module.apis.value_function_api import ValueFunctionAPI
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec
    from ray.rllib.core.rl_module.torch import TorchRLModule
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    from ray.tune.registry import register_env
except ImportError as exc:  # pragma: no cover (the [ray] extra is installed in CI)
    raise ImportError(
        f"activetrack.train.rllib needs Ray with RLlib ({exc}); install it with {INSTALL_HINT}"
    ) from exc


#: The one RLModule every sensor maps to (parameter sharing).
MODULE_ID = "shared"
#: What a run writes in its output folder (folders end in "/").
OUTPUTS = ("policy.zip", "config.json", "checkpoints/", "tb/")
#: Bounds of the counts: env runners, envs per runner, iterations, batch sizes.
MAX_RUNNERS, MAX_ENVS, MAX_ITERATIONS, MAX_BATCH = 4096, 1024, 10**7, 10**7
#: The ``kind`` written into an exported ``policy.zip``.
KIND = "rllib_ppo"
GRAD_CLIP_BY = ("global_norm", "norm", "value")


def make_env(env_config: dict[str, Any] | None = None, env_id: str | None = None) -> Any:
    """Return RLlib's ``ParallelPettingZooEnv`` over the parallel env made from ``env_config``.

    ``env_config`` holds the keyword arguments of the registered parallel env
    (``scenario`` and scenario fields); ``env_id`` a PettingZoo parallel id (default the
    library's :data:`~activetrack.envs.ENV_ID`).
    """
    import pettingzoo

    from activetrack.envs import ENV_ID

    kwargs = dict(env_config or {})
    return ParallelPettingZooEnv(pettingzoo.make("parallel", env_id or ENV_ID, **kwargs))


def registered_ids() -> list[str]:
    """Return the library's PettingZoo parallel ids (those starting with ``activetrack/``)."""
    import pettingzoo

    import activetrack.envs  # noqa: F401  (registers the ids)

    return sorted(i for i in pettingzoo.parallel_registry if str(i).startswith("activetrack/"))


def register_rllib_envs() -> list[str]:
    """Register every id of :func:`registered_ids` with RLlib; return the ids.

    After this, ``config.environment("activetrack/ActiveTracking-v0", env_config={...})``
    names the env. Idempotent (Tune's registry overwrites an entry).
    """
    ids = registered_ids()
    for env_id in ids:
        register_env(env_id, _Creator(env_id))
    return ids


class _Creator:
    """A picklable env creator for one id (Ray ships it to the env runners)."""

    def __init__(self, env_id: str) -> None:
        self.env_id = env_id

    def __call__(self, env_config: Any) -> Any:
        return make_env(dict(env_config or {}), self.env_id)


class SharedTrackingModule(TorchRLModule, ValueFunctionAPI):
    """A torch ``RLModule`` around one :class:`~activetrack.train.networks.TrackingPolicy`.

    ``model_config = {"net": NetConfig.to_dict()}``. The forward pass returns
    ``action_dist_inputs = [s(m), log_std]`` (mean and log std of RLlib's
    ``TorchDiagGaussian``, the SB3 policy's Gaussian); :meth:`compute_values` is the SB3
    critic. The wrapped network is :attr:`policy`.
    """

    def setup(self) -> None:
        net = NetConfig.from_dict(dict((self.model_config or {}).get("net", DEFAULT_NET.to_dict())))
        self.net = net
        self.policy = build_policy(self.observation_space, self.action_space, net)
        # SB3 builds an optimizer inside the policy; RLlib's learner has its own.
        self.policy.optimizer = None

    def _forward(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        p = self.policy
        obs = batch[Columns.OBS].float()
        features = p.extract_features(obs, p.pi_features_extractor)
        mean = p.action_mean(p.mlp_extractor.forward_actor(features))
        log_std = p.log_std.expand_as(mean)
        return {Columns.ACTION_DIST_INPUTS: torch.cat([mean, log_std], dim=-1)}

    def compute_values(self, batch: dict[str, Any], embeddings: Any = None) -> torch.Tensor:
        """Return the critic's values (B,) or (B, T) for the batch's observations."""
        return self.policy.predict_values(batch[Columns.OBS].float()).squeeze(-1)


@dataclass
class RLlibPPOConfig:
    """The multi-agent PPO configuration (RLlib's names; counts are env steps unless noted).

    Every field is checked and converted on construction (ValueError naming it and its
    range). The defaults follow the SB3 path (:class:`~activetrack.train.ppo.PPOConfig`):
    an update every ``train_batch_size`` env steps (2048 = 6144 agent-steps on ``paper``,
    as SB3's 8 copies x 256 steps x 3 sensors), minibatches of 512 agent-steps, 10
    epochs, Adam 3e-4, gamma 0.99, GAE 0.95, clip 0.2, value coefficient 0.5, gradients
    clipped to global norm 0.5, no entropy bonus, no KL penalty (RLlib's default
    ``use_kl_loss=True`` is turned off: plain PPO-clip as SB3).

    Attributes:
        num_env_runners: Ray actors that sample (0: sample in the driver).
        num_envs_per_env_runner: env copies each runner steps (vectorized by Gymnasium).
        train_batch_size: env steps per training iteration (all runners together).
        minibatch_size: agent-steps per SGD minibatch of the shared module.
        vf_clip_param: RLlib clips the value loss at this (SB3 does not clip it).
        reward_scale: the env's ``reward_scale`` during training (see the module docstring).
        checkpoint_every: iterations between checkpoints (0: only the last).
        num_cpus_per_env_runner: CPUs Ray reserves per runner.
    """

    num_env_runners: int = 1
    num_envs_per_env_runner: int = 4
    train_batch_size: int = 2048
    minibatch_size: int = 512
    num_epochs: int = 10
    lr: float = 3e-4
    gamma: float = 0.99
    lambda_: float = 0.95
    clip_param: float = 0.2
    vf_loss_coeff: float = 0.5
    vf_clip_param: float = 1e4
    entropy_coeff: float = 0.0
    grad_clip: float = 0.5
    grad_clip_by: str = "global_norm"
    reward_scale: float = 0.05
    checkpoint_every: int = 10
    num_cpus_per_env_runner: int = 1
    net: NetConfig = field(default_factory=lambda: DEFAULT_NET)

    def __post_init__(self) -> None:
        c = self
        c.num_env_runners = check_int("num_env_runners", c.num_env_runners, 0, MAX_RUNNERS)
        c.num_envs_per_env_runner = check_int(
            "num_envs_per_env_runner", c.num_envs_per_env_runner, 1, MAX_ENVS
        )
        c.train_batch_size = check_int("train_batch_size", c.train_batch_size, 2, MAX_BATCH)
        c.minibatch_size = check_int("minibatch_size", c.minibatch_size, 2, MAX_BATCH)
        c.num_epochs = check_int("num_epochs", c.num_epochs, 1, 10_000)
        c.lr = check_float("lr", c.lr, 0, 1, low_open=True)
        c.gamma = check_float("gamma", c.gamma, 0, 1, low_open=True)
        c.lambda_ = check_float("lambda_", c.lambda_, 0, 1)
        c.clip_param = check_float("clip_param", c.clip_param, 0, low_open=True)
        c.vf_loss_coeff = check_float("vf_loss_coeff", c.vf_loss_coeff, 0)
        c.vf_clip_param = check_float("vf_clip_param", c.vf_clip_param, 0, low_open=True)
        c.entropy_coeff = check_float("entropy_coeff", c.entropy_coeff, 0)
        c.grad_clip = check_float("grad_clip", c.grad_clip, 0, low_open=True)
        c.grad_clip_by = check_choice("grad_clip_by", c.grad_clip_by, GRAD_CLIP_BY)
        c.reward_scale = check_float("reward_scale", c.reward_scale, 0, low_open=True)
        c.checkpoint_every = check_int("checkpoint_every", c.checkpoint_every, 0, MAX_ITERATIONS)
        c.num_cpus_per_env_runner = check_int(
            "num_cpus_per_env_runner", c.num_cpus_per_env_runner, 1, 1024
        )
        c.net = NetConfig.coerce(c.net)

    def to_dict(self) -> dict[str, Any]:
        """Return JSON-friendly values."""
        d = asdict(self)
        d["net"] = self.net.to_dict()
        return d


def policy_mapping_fn(agent_id: Any, episode: Any, **kwargs: Any) -> str:
    """Map every sensor to the one shared module (parameter sharing)."""
    return MODULE_ID


def env_config_for(scenario: Any, reward_scale: float, **overrides: Any) -> dict[str, Any]:
    """Return the ``env_config`` of a run: the scenario, its overrides and the reward scale."""
    return {"scenario": scenario, **overrides, "reward_scale": reward_scale}


def rllib_ppo_config(
    scenario: Any = "paper",
    config: RLlibPPOConfig | None = None,
    seed: int = 0,
    **overrides: Any,
) -> _RLlibPPOConfig:
    """Return RLlib's ``PPOConfig`` (new API stack, torch) of a shared-policy PPO run.

    The env is the registered ``activetrack/ActiveTracking-v0`` with ``env_config`` from
    :func:`env_config_for`; one module spec ``"shared"`` (:class:`SharedTrackingModule`
    with ``config.net``) and ``policy_mapping_fn`` mapping every sensor to it.
    """
    from activetrack.envs import ENV_ID, parallel_env

    cfg = config or RLlibPPOConfig()
    if not isinstance(cfg, RLlibPPOConfig):
        raise TypeError(f"config must be an RLlibPPOConfig, got {type(cfg).__name__}")
    register_rllib_envs()
    env_config = env_config_for(scenario, cfg.reward_scale, **overrides)
    probe = parallel_env(**env_config)  # the spaces of the shared module (all agents alike)
    agent = probe.possible_agents[0]
    spec = RLModuleSpec(
        module_class=SharedTrackingModule,
        observation_space=probe.observation_space(agent),
        action_space=probe.action_space(agent),
        model_config={"net": cfg.net.to_dict()},
    )
    return (
        _RLlibPPOConfig()
        .api_stack(enable_rl_module_and_learner=True, enable_env_runner_and_connector_v2=True)
        .framework("torch")
        .environment(ENV_ID, env_config=env_config)
        .env_runners(
            num_env_runners=cfg.num_env_runners,
            num_envs_per_env_runner=cfg.num_envs_per_env_runner,
            num_cpus_per_env_runner=cfg.num_cpus_per_env_runner,
            rollout_fragment_length="auto",
        )
        .multi_agent(
            policies={MODULE_ID},
            policy_mapping_fn=policy_mapping_fn,
            policies_to_train=[MODULE_ID],
        )
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={MODULE_ID: spec}))
        .training(
            train_batch_size_per_learner=cfg.train_batch_size,
            minibatch_size=cfg.minibatch_size,
            num_epochs=cfg.num_epochs,
            lr=cfg.lr,
            gamma=cfg.gamma,
            lambda_=cfg.lambda_,
            clip_param=cfg.clip_param,
            vf_loss_coeff=cfg.vf_loss_coeff,
            vf_clip_param=cfg.vf_clip_param,
            entropy_coeff=cfg.entropy_coeff,
            use_kl_loss=False,
            grad_clip=cfg.grad_clip,
            grad_clip_by=cfg.grad_clip_by,
        )
        .learners(num_learners=0)
        .debugging(seed=seed)
    )


def export_policy(
    module: SharedTrackingModule,
    path: str | Path,
    *,
    scenario: dict[str, Any],
    seed: int | None,
    train_config: dict[str, Any] | None = None,
) -> Path:
    """Write the module's network as the library's ``policy.zip`` (atomically); return the path.

    ``activetrack evaluate --policy PATH`` and :func:`~activetrack.train.load_policy` load
    it like any other policy (``kind="rllib_ppo"``, ``view="shared"``).
    """
    if not isinstance(module, SharedTrackingModule):
        raise TypeError(f"module must be a SharedTrackingModule, got {type(module).__name__}")
    return save_policy(
        path,
        module.policy,
        module.net,
        kind=KIND,
        scenario=scenario,
        seed=seed,
        view="shared",
        train_config=train_config,
    )


def load_checkpoint_module(checkpoint: str | Path) -> SharedTrackingModule:
    """Return the trained shared module of an RLlib checkpoint folder (``checkpoints/iter_N``).

    With :func:`export_policy` this turns any checkpoint of a run (one that was stopped,
    say) into a ``policy.zip``. Raises ``ValueError`` naming the folder if it holds none.
    """
    folder = Path(checkpoint) / "learner_group" / "learner" / "rl_module" / MODULE_ID
    if not folder.is_dir():
        raise ValueError(f"{checkpoint}: not an RLlib checkpoint of a shared module ({folder})")
    from ray.rllib.core.rl_module.rl_module import RLModule

    module = RLModule.from_checkpoint(str(folder.resolve()))
    if not isinstance(module, SharedTrackingModule):
        raise ValueError(f"{checkpoint}: holds a {type(module).__name__}, not a shared module")
    return module.eval()


@contextlib.contextmanager
def ray_session(address: str | None = None, num_cpus: int | None = None) -> Iterator[None]:
    """Connect to the Ray cluster at ``address`` or start a local Ray; shut down what we start.

    ``address=None`` always starts a new local Ray with ``num_cpus`` CPUs. A Ray already
    initialized in this process is used as it is.
    """
    if ray.is_initialized():
        yield
        return
    kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False}
    if address is None:
        # "local": a new Ray for this run, even if `ray start` left a cluster on this
        # machine (ray.init() would connect to that one).
        address, kwargs["num_cpus"] = "local", num_cpus
    else:
        check_reachable(address)
    try:
        quiet_failure_handler()
        with keep_signal_handlers():  # Ray's SIGTERM handler would skip the clean-up
            ray.init(address=address, **kwargs)
        yield
    finally:
        if ray.is_initialized():
            ray.shutdown()


def check_address(address: Any) -> str | None:
    """Return ``address`` (a Ray address such as ``"auto"`` or ``"HOST:6379"``) or None."""
    if address is None:
        return None
    if not isinstance(address, str) or not address.strip():
        raise ValueError(f"address must be a non-empty Ray address such as 'auto', got {address!r}")
    return check_address_form(address)


@dataclass
class RLlibResult:
    """What :func:`train_rllib_ppo` returns: the policy file, per-iteration stats, timings."""

    policy_path: Path | None
    history: list[dict[str, float]]
    seconds: float
    env_steps: int
    agent_steps: int
    module: SharedTrackingModule


def train_rllib_ppo(
    scenario: Any = "paper",
    seed: int = 0,
    iterations: int = 10,
    config: RLlibPPOConfig | None = None,
    out_dir: str | Path | RunOutputs | None = None,
    address: str | None = None,
    progress: bool = False,
    threads: int = DEFAULT_THREADS,
    overwrite: bool = False,
    **overrides: Any,
) -> RLlibResult:
    """Train shared-policy PPO with RLlib for ``iterations`` iterations; return the result.

    ``address``: a running Ray cluster (``"auto"``, ``"HOST:PORT"``, ``"ray://..."``);
    None starts a local Ray for the run (with at least as many CPUs as env runners). With
    ``out_dir`` (a folder, or the :class:`~activetrack.files.RunOutputs` of one prepared with
    :data:`OUTPUTS`) it writes ``policy.zip``, ``config.json`` (committed together at the
    end), ``checkpoints/iter_NNNNNN`` (RLlib checkpoints, every ``checkpoint_every``
    iterations and the last) and ``tb/`` (TensorBoard scalars of every iteration's results).
    Everything is checked before Ray starts.
    """
    cfg = config or RLlibPPOConfig()
    if not isinstance(cfg, RLlibPPOConfig):
        raise TypeError(f"config must be an RLlibPPOConfig, got {type(cfg).__name__}")
    iterations = check_int("iterations", iterations, 1, MAX_ITERATIONS)
    seed = check_int("seed", seed, 0, 2**31 - 1)
    address = check_address(address)
    check_frame(cfg.net.frame, scenario, **overrides)
    if out_dir is not None and not isinstance(out_dir, RunOutputs):
        with prepare_output_dir(out_dir, OUTPUTS, overwrite) as outputs:  # locked for the run
            return train_rllib_ppo(
                scenario, seed, iterations, cfg, outputs, address, progress, threads, **overrides
            )
    outputs = out_dir
    from activetrack.world.scenarios import make_scenario

    scenario_dict = make_scenario(scenario, **overrides).to_dict()  # checks the overrides
    algo_config = rllib_ppo_config(scenario, cfg, seed, **overrides)
    configure_torch(threads)
    seed_everything(seed)
    t0 = time.perf_counter()
    num_cpus = max(os.cpu_count() or 1, cfg.num_env_runners * cfg.num_cpus_per_env_runner)
    with ray_session(address, num_cpus):
        algo = algo_config.build_algo()
        try:
            history, writer = [], _tb_writer(outputs)
            bar = _progress(iterations, progress)
            for it in range(1, iterations + 1):
                result = algo.train()
                stats = _summary(result)
                history.append(stats)
                if writer is not None:
                    _log_scalars(writer, result, it)
                bar.update(1)
                ret = stats.get("episode_return_mean")  # none until an episode finishes
                bar.set_postfix(ret="-" if ret is None else f"{ret:.3g}", refresh=False)
                every = cfg.checkpoint_every
                if outputs is not None and (it == iterations or (every and it % every == 0)):
                    _checkpoint(algo, outputs.staged("checkpoints/"), it)
            bar.close()
            if writer is not None:
                writer.close()
            module = algo.get_module(MODULE_ID)
            module = _detached_copy(module, algo_config)
        finally:
            logdir = getattr(algo, "logdir", None)
            algo.stop()
            _remove_empty(logdir)
    seconds = time.perf_counter() - t0
    env_steps = int(history[-1].get("env_steps_lifetime", 0))
    agent_steps = int(history[-1].get("agent_steps_lifetime", 0))
    policy_path = None
    if outputs is not None:
        train_config = {
            "algo": "rllib_ppo",
            "iterations": iterations,
            "env_steps": env_steps,
            "agent_steps": agent_steps,
            "seconds": seconds,
            "address": address,
            "ray": ray.__version__,
            "overrides": overrides,
            "history": history,
            **cfg.to_dict(),
        }
        with outputs:
            export_policy(
                module,
                outputs.staged("policy.zip"),
                scenario=scenario_dict,
                seed=seed,
                train_config=train_config,
            )
            outputs.write_json(
                "config.json", {"seed": seed, "scenario": scenario_dict, **train_config}
            )
            policy_path = outputs.commit()["policy.zip"]
    return RLlibResult(policy_path, history, seconds, env_steps, agent_steps, module)


def _detached_copy(module: SharedTrackingModule, algo_config: Any) -> SharedTrackingModule:
    """Return a fresh module in this process with the trained weights (Ray may shut down)."""
    spec = algo_config.rl_module_spec.rl_module_specs[MODULE_ID]
    copy = spec.build()
    copy.load_state_dict({k: v.detach().cpu().clone() for k, v in module.state_dict().items()})
    return copy.eval()


#: Result entries summarized per iteration (RLlib's new-stack metric names).
_SUMMARY = {
    "episode_return_mean": ("env_runners", "episode_return_mean"),
    "episode_len_mean": ("env_runners", "episode_len_mean"),
    "env_steps_lifetime": ("env_runners", "num_env_steps_sampled_lifetime"),
    "agent_steps_lifetime": ("env_runners", "num_agent_steps_sampled_lifetime"),
    "policy_loss": ("learners", MODULE_ID, "policy_loss"),
    "vf_loss": ("learners", MODULE_ID, "vf_loss"),
    "entropy": ("learners", MODULE_ID, "entropy"),
}


def _get(result: dict[str, Any], keys: tuple[str, ...]) -> Any:
    for k in keys:
        if not isinstance(result, dict) or k not in result:
            return None
        result = result[k]
    return result


def _summary(result: dict[str, Any]) -> dict[str, float]:
    out = {}
    for name, keys in _SUMMARY.items():
        v = _get(result, keys)
        if isinstance(v, dict):  # lifetime agent steps come per agent
            v = sum(x for x in v.values() if isinstance(x, (int, float)))
        if isinstance(v, (int, float, np.integer, np.floating)) and math.isfinite(float(v)):
            out[name] = float(v)
    return out


def _tb_writer(outputs: RunOutputs | None) -> Any:
    if outputs is None:
        return None
    from torch.utils.tensorboard import SummaryWriter

    return SummaryWriter(str(outputs.staged("tb/")))


def _log_scalars(writer: Any, result: dict[str, Any], step: int, prefix: str = "") -> None:
    """Write every finite number of RLlib's (nested) result dict as a TensorBoard scalar."""
    for key, value in result.items():
        tag = f"{prefix}{key}"
        if isinstance(value, dict):
            _log_scalars(writer, value, step, f"{tag}/")
        elif isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
            value, bool
        ):
            if math.isfinite(float(value)):
                writer.add_scalar(tag, float(value), step)


def _checkpoint(algo: Any, folder: Path, iteration: int) -> Path:
    """Save an RLlib checkpoint to ``folder/iter_NNNNNN`` (written aside, then renamed)."""
    folder.mkdir(parents=True, exist_ok=True)
    final = folder / f"iter_{iteration:06d}"
    tmp = folder / f".tmp-iter_{iteration:06d}"
    shutil.rmtree(tmp, ignore_errors=True)
    algo.save_to_path(str(tmp.resolve()))
    if final.exists():
        shutil.rmtree(final)
    os.replace(tmp, final)
    return final


def _remove_empty(folder: Any) -> None:
    """Remove the empty run folder RLlib's Trainable creates under ~/ray_results."""
    if folder:
        with contextlib.suppress(OSError):
            os.rmdir(folder)


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def set_postfix(self, **kw: Any) -> None:
        pass

    def close(self) -> None:
        pass


def _progress(total: int, show: bool) -> Any:
    if not show:
        return _NoBar()
    from tqdm.auto import tqdm

    return tqdm(total=total, desc="rllib-ppo", unit="iter", dynamic_ncols=True)


def deterministic_actions(module: SharedTrackingModule, obs: np.ndarray) -> np.ndarray:
    """Return RLlib's deterministic actions (N, 2) of ``module`` for observations (N, D).

    RLlib's inference path: ``forward_inference``, the inference distribution class
    ``from_logits``, ``to_deterministic().sample()``, then the unsquashing to the action box
    of the module-to-env connector (``normalize_actions=True``, RLlib's default).
    """
    from ray.rllib.utils.spaces.space_utils import unsquash_action

    with torch.no_grad():
        out = module.forward_inference({Columns.OBS: torch.as_tensor(np.asarray(obs))})
        dist_cls = module.get_inference_action_dist_cls()
        dist = dist_cls.from_logits(out[Columns.ACTION_DIST_INPUTS])
        actions = dist.to_deterministic().sample().numpy()
    return unsquash_action(actions, module.action_space)


__all__ = [
    "INSTALL_HINT",
    "KIND",
    "MODULE_ID",
    "OUTPUTS",
    "RLlibPPOConfig",
    "RLlibResult",
    "SharedTrackingModule",
    "check_address",
    "deterministic_actions",
    "env_config_for",
    "export_policy",
    "load_checkpoint_module",
    "make_env",
    "policy_mapping_fn",
    "ray_session",
    "register_rllib_envs",
    "registered_ids",
    "rllib_ppo_config",
    "train_rllib_ppo",
]
