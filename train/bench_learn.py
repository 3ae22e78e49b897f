"""``activetrack bench-learn``: the field's MARL algorithms (BenchMARL) on the library's
tasks under a fixed budget, reported as the project's protocol asks (the ``[marl]`` extra).

For every task x algorithm x training seed, one BenchMARL run
(:mod:`activetrack.train.benchmarl_task`) of exactly ``frames`` environment steps
(world steps: one frame is one step of all sensors together), collected
``frames_per_batch`` at a time. Along the way the policy is evaluated ``curve_points``
times (and once untrained, at step 0) on ``curve_episodes`` held-out episodes, its
deterministic action in our env (the same episode loop as ``activetrack evaluate``);
the time axis is the run's wall time without those evaluations. After the runs, each
task's final checkpoints are evaluated with GSR and RM by
:func:`activetrack.baselines.evaluation.evaluate` (the checkpoints load through the
``.pt`` policy loader, as ``activetrack evaluate --policy`` loads them) on ``eval_episodes``
held-out seeds from ``eval_seed``, and each algorithm's training seeds are pooled into one
row of the protocol (:func:`activetrack.baselines.protocol.pooled_summary`: mean, IQM and
median of the episodes' mean traces with two-way bootstrap intervals over training seeds
and episodes, the paired ratios to GSR, the track-loss rate where targets can be lost).

The curve's episodes are the first ``curve_episodes`` of the final evaluation's seeds:
nothing is selected on them (the final checkpoint is the one evaluated), so they need no
separate seeds. Neither evaluation draws from torch's generator, so they leave the
training itself unchanged.

Outputs in ``out`` (checked and locked before the first run; a folder holding results
needs ``overwrite``; everything is staged and moved into place together at the end, see
:func:`activetrack.files.prepare_output_dir`):

- ``marl_eval.json``: marl-eval's raw-data format ``{"activetrack": {task: {algorithm:
  {"seed_<k>": {"step_<i>": {"step_count", "elapsed_time", "return": [...],
  "mean_trace": [...]}, ..., "absolute_metrics": {"elapsed_time", "return": [...],
  "mean_trace": [...]}}}}}}``, the steps the curve's evaluations and ``absolute_metrics``
  the final evaluation's episodes and the run's training time (as marl-eval's
  ``JsonLogger`` names runs and steps);
- ``learning_curves.png``: per task, the return and the mean trace against environment
  steps and against wall time, one line per algorithm (the median over training seeds of
  each run's mean over the curve's episodes) with the interquartile band over seeds, and
  GSR and RM on the same episodes as dashed lines;
- ``eval/<task>/``: ``activetrack evaluate``'s files (``results.json`` with the pooled
  rows, ``episodes.json``, ``mean_trace.png``);
- ``runs/<task>/<algorithm>/seed_<k>/``: the BenchMARL run folders (checkpoints);
- ``summary.json``: the configuration, each run's wall time and checkpoint, and each
  task's protocol rows.
"""

from __future__ import annotations

import argparse
import contextlib
import time
from collections.abc import Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from activetrack.validation import check_float, check_int

#: Environment name in marl-eval's JSON and in BenchMARL's run names.
ENV_NAME = "activetrack"
#: The files and folders the command writes in its output folder.
OUTPUTS = ("marl_eval.json", "summary.json", "learning_curves.png", "eval/", "runs/")
#: The algorithms the command accepts (BenchMARL's continuous-action ones on our boxes).
ALGORITHMS = ("mappo", "ippo", "masac", "isac", "maddpg", "iddpg")
#: On-policy algorithms (the others replay).
ON_POLICY = ("mappo", "ippo")
#: Default budget per run, in environment frames (world steps), and frames per batch.
#: On this 2-core machine under load (one torch thread) a run on ``paper`` took 85 s per
#: 10,000 frames with MAPPO, 86 s with IPPO and 117 s with MASAC (``summary.json``'s
#: ``seconds_per_10k_frames``; docs/guide/learning.md): 48,000 frames (8 batches) keep one
#: run under about 10 minutes (MAPPO 6.8, MASAC 9.4).
DEFAULT_FRAMES = 48_000
DEFAULT_FRAMES_PER_BATCH = 6_000
#: BenchMARL's optimisation defaults (its base_experiment.yaml): on-policy 45 passes of
#: minibatches of 400 per batch; off-policy 1000 optimizer steps of 128 samples per 6000
#: collected frames (kept as a ratio for other batch sizes).
MINIBATCH_ITERS, MINIBATCH_SIZE = 45, 400
OFF_POLICY_STEPS_PER_FRAME, OFF_POLICY_BATCH = 1000 / 6000, 128
#: BenchMARL's learning rate (Adam, every algorithm).
LR = 5e-5
#: The largest training seed and evaluation seed (as the other commands').
MAX_SEED = 2**31 - 1


def _names(name: str, value: Any, allowed: Sequence[str]) -> tuple[str, ...]:
    """Return ``value`` (names) as a tuple of distinct allowed names; raise ValueError."""
    if isinstance(value, str):
        value = (value,)
    try:
        items = tuple(value)
    except TypeError:
        raise ValueError(
            f"{name} must be a list of names from {list(allowed)}, got {value!r}"
        ) from None
    bad = [v for v in items if not isinstance(v, str) or v not in allowed]
    if not items or bad or len(set(items)) != len(items):
        raise ValueError(
            f"{name} must be one or more distinct names from {list(allowed)}, got {list(items)}"
        )
    return items


def task_names() -> tuple[str, ...]:
    """Return the tasks the command runs on: every registered id's preset."""
    from activetrack._registry import ALL_IDS

    return tuple(sorted(set(ALL_IDS.values())))


@dataclass(frozen=True)
class BenchConfig:
    """What ``bench-learn`` runs; every field is checked on construction (ValueError
    naming the field and its allowed range).

    Attributes:
        tasks: the tasks (registered ids' presets, :func:`task_names`).
        algorithms: BenchMARL algorithms (:data:`ALGORITHMS`).
        seeds: training seeds per task and algorithm (seeds 0 .. seeds - 1), 1 to 100.
        frames: environment frames per run, a multiple of ``frames_per_batch``.
        frames_per_batch: frames collected between two updates.
        eval_episodes: held-out episodes of the final evaluation (seeds from ``eval_seed``).
        eval_seed: the first held-out episode seed.
        curve_points: evaluations along each run (besides the untrained one), at most one
            per batch.
        curve_episodes: episodes per curve evaluation, at most ``eval_episodes``.
        lr: Adam's learning rate, in (0, 1] (BenchMARL's default 5e-5).
        threads: torch intra-op threads.
    """

    tasks: tuple[str, ...] = ("paper",)
    algorithms: tuple[str, ...] = ("mappo", "ippo", "masac")
    seeds: int = 5
    frames: int = DEFAULT_FRAMES
    frames_per_batch: int = DEFAULT_FRAMES_PER_BATCH
    eval_episodes: int = 100
    eval_seed: int = 1000
    curve_points: int = 10
    curve_episodes: int = 10
    lr: float = LR
    threads: int = 1

    def __post_init__(self) -> None:
        from activetrack.train.utils import MAX_THREADS

        set_ = object.__setattr__
        set_(self, "tasks", _names("tasks", self.tasks, task_names()))
        set_(self, "algorithms", _names("algorithms", self.algorithms, ALGORITHMS))
        set_(self, "seeds", check_int("seeds", self.seeds, 1, 100))
        fpb = check_int("frames_per_batch", self.frames_per_batch, 1, 10**7)
        set_(self, "frames_per_batch", fpb)
        frames = check_int("frames", self.frames, fpb, 10**9)
        if frames % fpb:
            raise ValueError(f"frames must be a multiple of frames_per_batch ({fpb}), got {frames}")
        set_(self, "frames", frames)
        episodes = check_int("eval_episodes", self.eval_episodes, 1, 100_000)
        set_(self, "eval_episodes", episodes)
        set_(self, "eval_seed", check_int("eval_seed", self.eval_seed, 0, MAX_SEED - episodes))
        set_(self, "curve_points", check_int("curve_points", self.curve_points, 1, 10_000))
        set_(self, "curve_episodes", check_int("curve_episodes", self.curve_episodes, 1, episodes))
        set_(self, "lr", check_float("lr", self.lr, 0.0, 1.0, low_open=True))
        set_(self, "threads", check_int("threads", self.threads, 1, MAX_THREADS))

    @property
    def batches(self) -> int:
        """Return the number of collection batches (updates) per run."""
        return self.frames // self.frames_per_batch

    def curve_frames(self) -> list[int]:
        """Return the frame counts at which the curve evaluates: 0, then every
        ``ceil(batches / curve_points)`` batches, and always the last batch."""
        every = -(-self.batches // self.curve_points)
        done = [b for b in range(1, self.batches + 1) if b % every == 0 or b == self.batches]
        return [0] + [b * self.frames_per_batch for b in done]

    def experiment_fields(self, algorithm: str) -> dict[str, Any]:
        """Return the ``ExperimentConfig`` fields of a benchmark run of ``algorithm``:
        BenchMARL's optimisation defaults (:data:`MINIBATCH_ITERS`, ...) for our batch."""
        fpb = self.frames_per_batch
        if algorithm in ON_POLICY:
            return {
                "lr": self.lr,
                "on_policy_n_minibatch_iters": MINIBATCH_ITERS,
                "on_policy_minibatch_size": min(MINIBATCH_SIZE, fpb),
            }
        return {
            "lr": self.lr,
            "off_policy_n_optimizer_steps": max(1, round(OFF_POLICY_STEPS_PER_FRAME * fpb)),
            "off_policy_train_batch_size": OFF_POLICY_BATCH,
            "off_policy_memory_size": min(1_000_000, self.frames),
        }


@dataclass
class RunRecord:
    """One training run: its curve (one dict per evaluation: ``step_count``,
    ``elapsed_time`` (s), ``return`` and ``mean_trace`` per episode), its training wall
    time (s, without the curve's evaluations) and its final checkpoint."""

    task: str
    algorithm: str
    seed: int
    checkpoint: Path
    seconds: float
    curve: list[dict[str, Any]] = field(default_factory=list)


class CurveCallback:
    """A BenchMARL callback (its ``Callback``'s hooks, duck-typed so that this module
    imports without BenchMARL) that evaluates the policy after the updates that reach one
    of ``frames`` (and, by :meth:`start`, before the first) on ``seeds`` of ``scenario``;
    ``points`` holds the evaluations (marl-eval's step entries)."""

    def __init__(self, scenario: str, seeds: list[int], frames: list[int], bar: Any = None):
        self.experiment: Any = None  # set by BenchMARL's CallbackNotifier
        self.scenario, self.seeds, self.frames = scenario, list(seeds), list(frames)
        self.bar = bar
        self.points: list[dict[str, Any]] = []
        self.t0 = 0.0
        self.eval_seconds = 0.0
        self.last_frames = 0
        self._env: Any = None

    def __getstate__(self) -> dict[str, Any]:
        # BenchMARL pickles its callbacks into the run's config.pkl: keep the settings,
        # not the experiment, the env or the progress bar.
        state = dict(self.__dict__)
        state.update(experiment=None, _env=None, bar=None, points=[])
        return state

    # BenchMARL's hooks this callback does not use.
    def on_setup(self) -> None:
        """Do nothing (BenchMARL's hook)."""

    def on_load_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Do nothing (BenchMARL's hook)."""

    def on_batch_collected(self, batch: Any) -> None:
        """Do nothing (BenchMARL's hook)."""

    def on_train_step(self, batch: Any, group: str) -> None:
        """Return None: no extra loss (BenchMARL's hook)."""
        return None

    def on_evaluation_end(self, rollouts: Any) -> None:
        """Do nothing (BenchMARL's hook; its own evaluation is off)."""

    def on_state_dict(self, state_dict: dict[str, Any]) -> None:
        """Do nothing (BenchMARL's hook)."""

    def start(self) -> None:
        """Evaluate the untrained policy (step 0) and start the clock."""
        self.points = []
        self.eval_seconds = 0.0
        self.t0 = time.perf_counter()
        self._evaluate(0)

    def on_train_end(self, training_td: Any, group: str) -> None:
        """After an update: advance the progress bar; evaluate at the curve's frames."""
        frames = int(self.experiment.total_frames)
        if self.bar is not None:
            self.bar.update(frames - self.last_frames)
        self.last_frames = frames
        done = self.points[-1]["step_count"] if self.points else -1
        if frames in self.frames and frames > done:
            self._evaluate(frames)

    def elapsed(self) -> float:
        """Return the wall time since :meth:`start` without the evaluations (s)."""
        return time.perf_counter() - self.t0 - self.eval_seconds

    def _evaluate(self, frames: int) -> None:
        from activetrack.baselines.episodes import run_episode
        from activetrack.envs import parallel_env
        from activetrack.train.benchmarl_task import BenchmarlPolicy

        elapsed = self.elapsed()
        begin = time.perf_counter()
        if self._env is None:
            self._env = parallel_env(self.scenario)
        policy = BenchmarlPolicy(self.experiment)
        rows = [run_episode(self._env, policy, s) for s in self.seeds]
        self.points.append(
            {
                "step_count": frames,
                "elapsed_time": elapsed,
                "return": [float(r[2]) for r in rows],
                "mean_trace": [float(r[0]) for r in rows],
            }
        )
        self.eval_seconds += time.perf_counter() - begin

    def close(self) -> None:
        """Close the evaluation env."""
        if self._env is not None:
            self._env.close()
            self._env = None


@contextlib.contextmanager
def _quiet_benchmarl() -> Iterator[None]:
    """Hide BenchMARL's own per-run progress bar (the command shows one for all runs)."""
    import functools

    import benchmarl.experiment.experiment as module

    original = module.tqdm
    module.tqdm = functools.partial(original, disable=True)
    try:
        yield
    finally:
        module.tqdm = original


def train_run(
    task: str, algorithm: str, seed: int, config: BenchConfig, folder: Path, bar: Any = None
) -> RunRecord:
    """Train one run of ``algorithm`` on ``task`` with training seed ``seed`` in ``folder``
    (an existing folder; BenchMARL makes its run folder inside); return its record."""
    from activetrack.train.benchmarl_task import ActiveTrackingTask, make_experiment
    from activetrack.train.utils import configure_torch

    (task,) = _names("task", task, task_names())
    (algorithm,) = _names("algorithm", algorithm, ALGORITHMS)
    seed = check_int("seed", seed, 0, MAX_SEED)
    if not isinstance(config, BenchConfig):
        raise ValueError(f"config must be a BenchConfig, got {type(config).__name__}")
    if not Path(folder).is_dir():
        raise ValueError(f"folder {str(folder)!r} is not a directory")

    callback = CurveCallback(
        task,
        [config.eval_seed + j for j in range(config.curve_episodes)],
        config.curve_frames()[1:],
        bar,
    )
    experiment = make_experiment(
        ActiveTrackingTask[task.upper()].get_task(),
        algorithm,
        seed=seed,
        threads=config.threads,
        callbacks=[callback],
        save_folder=folder,
        max_frames=config.frames,
        frames_per_batch=config.frames_per_batch,
        **config.experiment_fields(algorithm),
    )
    try:
        with _quiet_benchmarl():
            callback.start()
            experiment.run()
        seconds = callback.elapsed()
    finally:
        callback.close()
        configure_torch(config.threads)  # closing the run's envs raised torch's threads
    if experiment.total_frames != config.frames:
        raise RuntimeError(f"{task}/{algorithm}/seed {seed}: ran {experiment.total_frames} frames")
    checkpoint = Path(experiment.folder_name) / "checkpoints" / f"checkpoint_{config.frames}.pt"
    if not checkpoint.is_file():
        raise RuntimeError(f"BenchMARL wrote no final checkpoint {checkpoint}")
    return RunRecord(task, algorithm, seed, checkpoint, seconds, callback.points)


def run_label(algorithm: str, seed: int) -> str:
    """Return a run's label in the evaluation's tables (``mappo-seed0``)."""
    return f"{algorithm}-seed{seed}"


def marl_eval_data(
    records: Sequence[RunRecord], finals: dict[tuple[str, str], Any]
) -> dict[str, Any]:
    """Return marl-eval's raw-data dict of ``records``; ``finals`` maps (task, label) to
    the run's :class:`~activetrack.baselines.evaluation.PolicyEvaluation` (the absolute
    metrics)."""
    data: dict[str, Any] = {ENV_NAME: {}}
    for r in records:
        runs = data[ENV_NAME].setdefault(r.task, {}).setdefault(r.algorithm, {})
        run = {f"step_{i}": dict(point) for i, point in enumerate(r.curve)}
        final = finals[(r.task, run_label(r.algorithm, r.seed))]
        run["absolute_metrics"] = {
            # The steps' metrics, so that marl-eval's DiagnoseData finds the same in both.
            "elapsed_time": r.seconds,
            "return": [float(x) for x in final.returns],
            "mean_trace": [float(x) for x in final.mean_trace],
        }
        runs[f"seed_{r.seed}"] = run
    return data


def plot_curves(
    records: Sequence[RunRecord],
    references: dict[str, dict[str, dict[str, float]]],
    path: Path,
) -> Path:
    """Write the learning curves of ``records`` to ``path``; return it.

    One row per task, four panels: the return and the mean trace against environment
    steps and against wall time. Per algorithm, the median over training seeds of each
    run's mean over the curve's episodes, with the band between the 25th and 75th
    percentiles over seeds (the wall-time axis: each point's mean time over seeds).
    ``references[task][policy]`` holds GSR's and RM's ``return`` and ``mean_trace`` on
    the same episodes (dashed lines).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tasks = list(dict.fromkeys(r.task for r in records))
    algorithms = list(dict.fromkeys(r.algorithm for r in records))
    fig, axes = plt.subplots(len(tasks), 4, figsize=(16, 3.6 * len(tasks)), squeeze=False)
    metrics = (("return", "return"), ("mean_trace", "mean trace (m$^2$)"))
    for row, task in zip(axes, tasks, strict=True):
        for k, algorithm in enumerate(algorithms):
            runs = [r for r in records if r.task == task and r.algorithm == algorithm]
            steps = np.array([p["step_count"] for p in runs[0].curve], dtype=float)
            wall = np.mean([[p["elapsed_time"] for p in r.curve] for r in runs], axis=0)
            for m, (metric, label) in enumerate(metrics):
                values = np.array([[np.mean(p[metric]) for p in r.curve] for r in runs])
                lo, mid, hi = np.percentile(values, [25, 50, 75], axis=0)
                for ax, x, xlabel in (
                    (row[m], steps, "environment steps"),
                    (row[2 + m], wall, "wall time (s)"),
                ):
                    ax.plot(
                        x,
                        mid,
                        color=f"C{k}",
                        label=f"{algorithm} ({len(runs)} seed{'s' if len(runs) > 1 else ''})",
                    )
                    ax.fill_between(x, lo, hi, color=f"C{k}", alpha=0.2)
                    ax.set_xlabel(xlabel)
                    ax.set_ylabel(label)
        for m, (metric, _) in enumerate(metrics):
            for j, (policy, values) in enumerate(references.get(task, {}).items()):
                for ax in (row[m], row[2 + m]):
                    ax.axhline(
                        values[metric], color=f"C{len(algorithms) + j}", ls="--", label=policy
                    )
            if metric == "mean_trace":
                for ax in (row[m], row[2 + m]):
                    ax.set_yscale("log")
        row[0].set_title(f"{task}: return")
        row[1].set_title(f"{task}: mean trace")
        row[2].set_title(f"{task}: return vs wall time")
        row[3].set_title(f"{task}: mean trace vs wall time")
        row[0].legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def run_bench_learn(
    config: BenchConfig, out: str | Path, overwrite: bool = False, progress: bool = True
) -> dict[str, Any]:
    """Run the benchmark ``config`` and write its outputs in ``out``; return the summary
    (``summary.json``'s content).

    Checked before the first run: BenchMARL importable, the configuration, the output
    folder (one holding results needs ``overwrite``; it is locked for the run).
    """
    from tqdm.auto import tqdm

    from activetrack.baselines.evaluation import (
        evaluate,
        format_table,
        json_safe,
        summaries,
        write_results,
    )
    from activetrack.files import prepare_output_dir
    from activetrack.train.benchmarl_task import import_benchmarl

    import_benchmarl()  # ImportError naming the [marl] extra, before any folder is made
    if not isinstance(config, BenchConfig):
        raise ValueError(f"config must be a BenchConfig, got {type(config).__name__}")
    runs = [(t, a, s) for t in config.tasks for a in config.algorithms for s in range(config.seeds)]
    with prepare_output_dir(out, OUTPUTS, overwrite) as outputs:
        run_root = outputs.staged("runs/")
        eval_root = outputs.staged("eval/")
        records: list[RunRecord] = []
        bar = tqdm(
            total=len(runs) * config.frames, unit="frame", unit_scale=True, disable=not progress
        )
        try:
            for task, algorithm, seed in runs:
                bar.set_description(f"{task} {algorithm} seed {seed}")
                folder = run_root / task / algorithm / f"seed_{seed}"
                folder.mkdir(parents=True)
                records.append(train_run(task, algorithm, seed, config, folder, bar))
        finally:
            bar.close()

        finals: dict[tuple[str, str], Any] = {}
        references: dict[str, dict[str, dict[str, float]]] = {}
        tables: dict[str, Any] = {}
        n_curve = config.curve_episodes
        for task in config.tasks:
            mine = [r for r in records if r.task == task]
            policies: dict[str, Any] = {
                run_label(r.algorithm, r.seed): str(r.checkpoint) for r in mine
            }
            policies.update(gsr="gsr", rm="rm")
            results = evaluate(policies, task, config.eval_episodes, config.eval_seed, progress)
            pools = {a: [run_label(a, s) for s in range(config.seeds)] for a in config.algorithms}
            rows = summaries(results, pools)
            print(f"{task}: {config.eval_episodes} episodes from seed {config.eval_seed}")
            print(format_table(rows))
            meta = {"scenario": task, "episodes": config.eval_episodes, "seed": config.eval_seed}
            write_results(results, eval_root / task, meta, pools=pools)
            for res in results:
                finals[(task, res.policy)] = res
            references[task] = {
                p: {
                    "return": float(np.mean(finals[(task, p)].returns[:n_curve])),
                    "mean_trace": float(np.mean(finals[(task, p)].mean_trace[:n_curve])),
                }
                for p in ("gsr", "rm")
            }
            tables[task] = json_safe(rows)

        summary = {
            "config": {
                k: list(v) if isinstance(v, tuple) else v for k, v in asdict(config).items()
            },
            "curve_frames": config.curve_frames(),
            "runs": [
                {
                    "task": r.task,
                    "algorithm": r.algorithm,
                    "seed": r.seed,
                    "frames": config.frames,
                    "seconds": r.seconds,
                    "seconds_per_10k_frames": 1e4 * r.seconds / config.frames,
                    "checkpoint": str(r.checkpoint.relative_to(run_root.parent)),
                }
                for r in records
            ],
            "results": tables,
        }
        outputs.write_json("marl_eval.json", marl_eval_data(records, finals))
        outputs.write_json("summary.json", summary)
        plot_curves(records, references, outputs.staged("learning_curves.png"))
        written = outputs.commit()
    print("wrote " + ", ".join(str(p) for p in written.values()))
    return summary


def add_parser(sub: argparse._SubParsersAction, help_text: str) -> argparse.ArgumentParser:
    """Add ``bench-learn`` to the ``activetrack`` subparsers ``sub``; return its parser."""
    from activetrack.cli import add_output_arguments, field_default, positive_int, seed_int

    def default(name: str) -> Any:
        return field_default(BenchConfig, name)

    p = sub.add_parser(
        "bench-learn",
        help=help_text,
        description="Train BenchMARL's algorithms on the library's tasks with a fixed budget "
        "of environment frames per run and several training seeds; write marl-eval's JSON, "
        "learning curves and the final evaluation against GSR and RM (the [marl] extra).",
    )
    p.add_argument(
        "--task",
        action="append",
        choices=task_names(),
        metavar="TASK",
        help=f"a task (repeatable; default {' '.join(default('tasks'))})",
    )
    p.add_argument(
        "--algorithm",
        action="append",
        choices=ALGORITHMS,
        help=f"a BenchMARL algorithm (repeatable; default {' '.join(default('algorithms'))})",
    )
    p.add_argument(
        "--seeds",
        type=positive_int,
        default=default("seeds"),
        help="training seeds per task and algorithm, 0..SEEDS-1 (default %(default)s)",
    )
    p.add_argument(
        "--frames",
        type=positive_int,
        default=default("frames"),
        help="environment frames (world steps) per run (default %(default)s)",
    )
    p.add_argument(
        "--frames-per-batch",
        type=positive_int,
        default=default("frames_per_batch"),
        help="frames collected per update (default %(default)s)",
    )
    p.add_argument(
        "--eval-episodes",
        type=positive_int,
        default=default("eval_episodes"),
        help="held-out episodes of the final evaluation (default %(default)s)",
    )
    p.add_argument(
        "--eval-seed",
        type=seed_int,
        default=default("eval_seed"),
        help="first held-out episode seed (default %(default)s)",
    )
    p.add_argument(
        "--curve-points",
        type=positive_int,
        default=default("curve_points"),
        help="evaluations along each run (default %(default)s)",
    )
    p.add_argument(
        "--curve-episodes",
        type=positive_int,
        default=default("curve_episodes"),
        help="episodes per curve evaluation (default %(default)s)",
    )
    p.add_argument(
        "--lr", type=float, default=default("lr"), help="Adam's learning rate (default %(default)s)"
    )
    p.add_argument(
        "--threads",
        type=positive_int,
        default=default("threads"),
        help="torch threads (default %(default)s)",
    )
    add_output_arguments(p, None, required=True)
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run_command, parser=p)
    return p


def run_command(args: argparse.Namespace) -> int:
    """Run ``activetrack bench-learn`` from parsed arguments; return the exit code.

    Without BenchMARL installed it says how to install it (exit 2), as ``train rllib-ppo``
    does without Ray.
    """
    import sys

    config = BenchConfig(
        tasks=tuple(args.task or BenchConfig.tasks),
        algorithms=tuple(args.algorithm or BenchConfig.algorithms),
        seeds=args.seeds,
        frames=args.frames,
        frames_per_batch=args.frames_per_batch,
        eval_episodes=args.eval_episodes,
        eval_seed=args.eval_seed,
        curve_points=args.curve_points,
        curve_episodes=args.curve_episodes,
        lr=args.lr,
        threads=args.threads,
    )
    try:
        from activetrack.train.benchmarl_task import import_benchmarl

        import_benchmarl()
    except ImportError as exc:
        args.parser.print_usage(sys.stderr)
        print(f"{args.parser.prog}: error: {exc}", file=sys.stderr)
        return 2
    run_bench_learn(config, args.out, args.overwrite, progress=not args.no_progress)
    return 0


__all__ = [
    "ALGORITHMS",
    "BenchConfig",
    "OUTPUTS",
    "RunRecord",
    "add_parser",
    "marl_eval_data",
    "plot_curves",
    "run_bench_learn",
    "run_command",
    "task_names",
    "train_run",
]
