"""The library's tasks as BenchMARL tasks: MAPPO, IPPO and BenchMARL's other algorithms on
any registered id (the ``[marl]`` extra).

BenchMARL builds its PettingZoo tasks as a :class:`~benchmarl.environments.Task` enum (the
task names) with a :class:`~benchmarl.environments.TaskClass` that makes the TorchRL
environment and tells the experiment its specs; :class:`ActiveTrackingTask` and
:class:`ActiveTrackingClass` do the same over :func:`activetrack.envs.parallel_env`
wrapped in TorchRL's ``PettingZooWrapper``. The sensors form one group (``"sensor"``),
each with its own observation; the world's state is the centralized critic's input::

    from activetrack.train.benchmarl_task import ActiveTrackingTask, run_experiment

    task = ActiveTrackingTask.PAPER.get_task()  # or get_task(config={"scenario": ...})
    checkpoint = run_experiment(task, "mappo", save_folder="runs", max_frames=400)

:func:`load_policy` loads a run's checkpoint as a policy that ``activetrack evaluate``
runs (registered for ``.pt`` files under the entry-point group
``activetrack.policy_loaders``).

Versions: BenchMARL 1.5.2 declares ``torchrl>=0.10,<0.12``; the library keeps torch 2.13
and torchrl 0.14.1, so BenchMARL is installed without its dependencies (``pip install
--no-deps benchmarl==1.5.2 hydra-core``). Its only import that torchrl 0.14 no longer has
is the collector's old name ``SyncDataCollector`` (removed in torchrl 0.13, renamed
``Collector`` with the same arguments); :func:`import_benchmarl` restores that name
before importing BenchMARL.
"""

from __future__ import annotations

import copy
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from activetrack._registry import ALL_IDS
from activetrack.train.utils import DEFAULT_THREADS, configure_torch

#: BenchMARL's algorithms by their command-line name (``benchmarl.algorithms``).
ALGORITHMS = ("mappo", "ippo", "masac", "isac", "maddpg", "iddpg")
#: The group of the sensors in TorchRL's PettingZoo wrapper (agents ``sensor_<i>``).
GROUP = "sensor"


def import_benchmarl() -> Any:
    """Return the ``benchmarl`` module, imported beside torchrl 0.14.

    Raises ``ImportError`` naming the ``[marl]`` extra when BenchMARL is not installed.
    """
    import torchrl.collectors

    # torchrl 0.13 removed the name BenchMARL 1.5.2 imports; Collector is the same class.
    if not hasattr(torchrl.collectors, "SyncDataCollector"):
        torchrl.collectors.SyncDataCollector = torchrl.collectors.Collector
    try:
        import benchmarl
    except ImportError as exc:
        raise ImportError(
            f"BenchMARL is not installed ({exc}): pip install --no-deps benchmarl==1.5.2 "
            "hydra-core (see the [marl] extra)"
        ) from exc
    return benchmarl


import_benchmarl()

from benchmarl.environments.common import Task, TaskClass  # noqa: E402
from benchmarl.experiment.callback import Callback  # noqa: E402
from torchrl.data import Composite  # noqa: E402
from torchrl.envs import EnvBase, PettingZooWrapper  # noqa: E402


def _make_env(config: dict[str, Any], seed: int | None, device: Any) -> EnvBase:
    """Return our parallel env for ``config`` in TorchRL's PettingZoo wrapper."""
    import warnings

    from activetrack.envs import parallel_env

    with warnings.catch_warnings():  # TorchRL's note on the PettingZoo version it tests
        warnings.filterwarnings("ignore", "PettingZoo in TorchRL is tested", UserWarning)
        return PettingZooWrapper(
            parallel_env(**config),
            use_mask=False,  # every agent acts at every step until all are truncated
            return_state=True,
            categorical_actions=True,
            device=device,
            seed=seed,
        )


def _only(spec: Composite, groups: Any, key: str) -> Composite:
    """Return a copy of ``spec`` with each group keeping only ``key`` and no state."""
    spec = spec.clone()
    for group in groups:
        for k in list(spec[group].keys()):
            if k != key:
                del spec[group][k]
    if "state" in spec.keys():
        del spec["state"]
    return spec


class ActiveTrackingClass(TaskClass):
    """One of the library's tasks for BenchMARL; ``config`` holds the keyword arguments of
    :func:`activetrack.envs.parallel_env` (``scenario`` and its overrides)."""

    def get_env_fun(
        self, num_envs: int, continuous_actions: bool, seed: int | None, device: Any
    ) -> Callable[[], EnvBase]:
        """Return a function that makes the task's TorchRL environment."""
        if not continuous_actions:
            raise ValueError("continuous_actions must be True: the sensors' actions are boxes")
        config = copy.deepcopy(self.config)
        return lambda: _make_env(config, seed, device)

    def supports_continuous_actions(self) -> bool:
        """Return True: each sensor's action is a velocity in a box."""
        return True

    def supports_discrete_actions(self) -> bool:
        """Return False (no discretized action variant yet)."""
        return False

    def has_state(self) -> bool:
        """Return True: the world's state is the centralized critic's input."""
        return True

    def has_render(self, env: EnvBase) -> bool:
        """Return False (BenchMARL's video logging is not wired to our renderer)."""
        return False

    def max_steps(self, env: EnvBase) -> int:
        """Return the episode length of the task's scenario (it is truncated after it)."""
        from activetrack.world.scenarios import make_scenario

        config = dict(self.config)
        return int(make_scenario(config.pop("scenario", "paper"), **config).n_steps)

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        """Return the wrapper's groups (one, ``"sensor"``)."""
        return env.group_map

    def state_spec(self, env: EnvBase) -> Composite | None:
        """Return the spec of the world's state."""
        return Composite({"state": env.observation_spec["state"].clone()})

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        """Return None: every action is always allowed."""
        return None

    def observation_spec(self, env: EnvBase) -> Composite:
        """Return each group's observation spec."""
        return _only(env.observation_spec, self.group_map(env), "observation")

    def info_spec(self, env: EnvBase) -> Composite | None:
        """Return each group's info spec (trace, position error, ...)."""
        return _only(env.observation_spec, self.group_map(env), "info")

    def action_spec(self, env: EnvBase) -> Composite:
        """Return the wrapper's full action spec."""
        return env.full_action_spec

    @staticmethod
    def env_name() -> str:
        """Return the environment's name in BenchMARL's run names."""
        return "activetrack"


def _task_names() -> dict[str, str]:
    """Return {enum name: preset} for every registered id (``TWO_TARGETS``: ``two_targets``)."""
    return {preset.upper(): preset for preset in ALL_IDS.values()}


class _TaskEnum(Task):
    @staticmethod
    def associated_class() -> type[TaskClass]:
        return ActiveTrackingClass

    def get_task(self, config: dict[str, Any] | None = None) -> TaskClass:
        """Return the task; without ``config``, the preset of the same name with no
        overrides (BenchMARL would look for a yaml file inside its own package)."""
        if config is None:
            config = {"scenario": _task_names()[self.name]}
        return self.associated_class()(name=self.name, config=config)


#: The registered tasks as BenchMARL's Task enum (``ActiveTrackingTask.PAPER``, ...).
ActiveTrackingTask = _TaskEnum(
    "ActiveTrackingTask", {n: None for n in _task_names()}, module=__name__
)


def experiment_config(
    save_folder: str | Path, max_frames: int = 400, frames_per_batch: int = 200, **fields: Any
) -> Any:
    """Return BenchMARL's ``ExperimentConfig`` for a short CPU run: ``max_frames``
    environment steps (of all sensors together, one per world step) collected
    ``frames_per_batch`` at a time, a checkpoint at the end, no evaluation or loggers.

    ``fields`` set further ``ExperimentConfig`` fields last (e.g. BenchMARL's own
    optimisation defaults for a benchmark run, :mod:`activetrack.train.bench_learn`);
    a name that is not a field raises ``TypeError``.
    """
    from benchmarl.experiment import ExperimentConfig

    for name, value in (("max_frames", max_frames), ("frames_per_batch", frames_per_batch)):
        if not isinstance(value, int) or value < 1:
            raise ValueError(f"{name} must be a positive int, got {value!r}")
    if max_frames % frames_per_batch:
        raise ValueError(
            f"max_frames ({max_frames}) must be a multiple of frames_per_batch ({frames_per_batch})"
        )
    folder = Path(save_folder)
    if not folder.is_dir():
        raise ValueError(f"save_folder {str(folder)!r} is not a directory")
    ec = ExperimentConfig.get_from_yaml()
    ec.sampling_device = ec.train_device = ec.buffer_device = "cpu"
    ec.max_n_frames = max_frames
    ec.on_policy_collected_frames_per_batch = frames_per_batch
    ec.off_policy_collected_frames_per_batch = frames_per_batch
    ec.on_policy_n_envs_per_worker = ec.off_policy_n_envs_per_worker = 1
    ec.on_policy_n_minibatch_iters = 1
    ec.on_policy_minibatch_size = min(100, frames_per_batch)
    ec.off_policy_n_optimizer_steps = 1
    ec.off_policy_train_batch_size = min(100, frames_per_batch)
    ec.off_policy_init_random_frames = 0
    ec.off_policy_memory_size = max(frames_per_batch, max_frames)
    ec.evaluation = False
    ec.loggers = []
    ec.create_json = False
    ec.render = False
    ec.save_folder = str(folder)
    ec.checkpoint_interval = 0
    ec.checkpoint_at_end = True
    for name, value in fields.items():
        if not hasattr(ec, name):
            raise TypeError(f"experiment_config() got an unexpected keyword argument {name!r}")
        setattr(ec, name, value)
    return ec


def algorithm_config(name: str) -> Any:
    """Return BenchMARL's default config of the algorithm ``name`` (:data:`ALGORITHMS`)."""
    from benchmarl import algorithms

    if name not in ALGORITHMS:
        raise ValueError(f"algorithm must be one of {list(ALGORITHMS)}, got {name!r}")
    cls = getattr(algorithms, {"mappo": "MappoConfig", "ippo": "IppoConfig"}.get(name, ""), None)
    cls = cls or getattr(algorithms, name.capitalize() + "Config")
    return cls.get_from_yaml()


class KeepThreads(Callback):
    """A BenchMARL callback that sets torch's intra-op threads back to ``threads`` after
    every collection.

    Why: when the collector has collected its budget it closes its environment, and
    TorchRL's batched env (``SerialEnv``) raises torch's thread count by its number of
    workers on closing (``BatchedEnvBase.close``); the run's last update then ran on two
    threads instead of one: 15 to 21 s per 100 minibatch steps of MAPPO on ``paper``
    (minibatches of 400) instead of 2 s, on this 2-core machine under load
    (tests/train/test_benchmarl.py checks every update's thread count).
    """

    def __init__(self, threads: int):
        super().__init__()
        self.threads = threads

    def __getstate__(self) -> dict[str, Any]:
        # BenchMARL pickles its callbacks into the run's config.pkl: not the experiment.
        return {**self.__dict__, "experiment": None}

    def on_batch_collected(self, batch: Any) -> None:
        """Set torch's threads back before the update."""
        import torch

        torch.set_num_threads(self.threads)


def make_experiment(
    task: TaskClass,
    algorithm: str,
    seed: int = 0,
    threads: int = DEFAULT_THREADS,
    callbacks: list[Any] | None = None,
    **config: Any,
) -> Any:
    """Return a BenchMARL ``Experiment`` of ``algorithm`` on ``task`` with MLP actor and
    critic, torch set to ``threads`` intra-op threads; ``config`` goes to
    :func:`experiment_config`, ``callbacks`` (BenchMARL ``Callback`` objects) to the
    experiment after a :class:`KeepThreads` (torch keeps ``threads`` through the run;
    after ``run()`` call :func:`~activetrack.train.utils.configure_torch` again: closing
    the run's environments raises the count).

    One thread by default, as the library's other training entry points: on this 2-core
    machine under load a 400-frame MAPPO run on ``paper`` took 2.5 s with one thread and
    19.3 s with two (the time of ``run_experiment`` with ``threads=1`` and ``threads=2``).
    """
    from benchmarl.experiment import Experiment
    from benchmarl.models.mlp import MlpConfig

    threads = configure_torch(threads)
    return Experiment(
        task=task,
        algorithm_config=algorithm_config(algorithm),
        model_config=MlpConfig.get_from_yaml(),
        critic_model_config=MlpConfig.get_from_yaml(),
        seed=seed,
        config=experiment_config(**config),
        callbacks=[KeepThreads(threads), *(callbacks or [])],
    )


def run_experiment(task: TaskClass, algorithm: str, seed: int = 0, **config: Any) -> Path:
    """Train ``algorithm`` on ``task`` and return the path of the final checkpoint."""
    experiment = make_experiment(task, algorithm, seed, **config)
    experiment.run()
    configure_torch(config.get("threads", DEFAULT_THREADS))  # closing the envs raised it
    checkpoints = sorted(
        (Path(experiment.folder_name) / "checkpoints").glob("checkpoint_*.pt"),
        key=lambda p: int(p.stem.rsplit("_", 1)[1]),
    )
    if not checkpoints:
        raise RuntimeError(f"BenchMARL wrote no checkpoint in {experiment.folder_name}")
    return checkpoints[-1]


class BenchmarlPolicy:
    """A trained BenchMARL actor as a policy of our env: ``act(observations)`` returns each
    sensor's action, the actor's deterministic output (the tanh-squashed mean, in the box).
    """

    def __init__(self, experiment: Any, name: str = "benchmarl"):
        self.experiment = experiment
        self.name = name
        self.policy = experiment.policy
        self.meta = {"kind": f"benchmarl-{experiment.algorithm_name}"}

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Return ``{agent: action}`` for the observations of the agents present."""
        import torch
        from tensordict import TensorDict
        from torchrl.envs.utils import ExplorationType, set_exploration_type

        agents = list(observations)
        obs = torch.as_tensor(np.stack([observations[a] for a in agents]), dtype=torch.float32)
        td = TensorDict({GROUP: TensorDict({"observation": obs}, [len(agents)])}, [])
        with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
            out = self.policy(td)
        actions = out.get((GROUP, "action")).numpy().astype(np.float64)
        return {a: actions[j] for j, a in enumerate(agents)}

    def __repr__(self) -> str:
        return f"BenchmarlPolicy({self.name!r}, kind={self.meta['kind']!r})"


def load_policy(path: str | Path) -> BenchmarlPolicy:
    """Return the policy of a BenchMARL checkpoint (``<run>/checkpoints/checkpoint_N.pt``
    beside ``<run>/config.pkl``, as :func:`run_experiment` writes it).

    The run's ``config.pkl`` is a pickle: load only runs you made.
    """
    from benchmarl.experiment import Experiment

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such checkpoint file")
    if not (path.parent.parent / "config.pkl").is_file():
        raise ValueError(
            f"{path}: not a BenchMARL checkpoint (no config.pkl two folders up, "
            "<run>/checkpoints/checkpoint_N.pt)"
        )
    # BenchMARL's reload rewrites config.pkl in the run's folder (with the restore path in
    # it): reload from a copy so that loading never changes the user's run.
    with tempfile.TemporaryDirectory() as folder:
        run = Path(folder) / path.parent.parent.name
        (run / "checkpoints").mkdir(parents=True)
        shutil.copyfile(path.parent.parent / "config.pkl", run / "config.pkl")
        shutil.copyfile(path, run / "checkpoints" / path.name)
        checkpoint = str(run / "checkpoints" / path.name)
        experiment = Experiment.reload_from_file(checkpoint, {"save_folder": folder})
    return BenchmarlPolicy(experiment, name=path.parent.parent.name)


__all__ = [
    "ALGORITHMS",
    "ActiveTrackingClass",
    "ActiveTrackingTask",
    "BenchmarlPolicy",
    "algorithm_config",
    "experiment_config",
    "import_benchmarl",
    "load_policy",
    "make_experiment",
    "run_experiment",
]
