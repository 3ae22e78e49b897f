"""``activetrack bench-learn`` (issue 40): BenchMARL's MAPPO, IPPO and MASAC on ``paper``
and ``two_targets`` end to end with tiny budgets; its marl-eval JSON read by marl-eval's
own loader; its numbers checked against independent evaluations; and a training run that
learns (its policy beats its own untrained start on the same held-out episodes)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

needs_benchmarl = pytest.mark.skipif(
    importlib.util.find_spec("benchmarl") is None,
    reason="BenchMARL is not installed (the [marl] extra: pip install --no-deps benchmarl==1.5.2)",
)

TASKS = ("paper", "two_targets")
ALGORITHMS = ("mappo", "ippo", "masac")
# Tiny budget: two batches of 100 frames (two updates), 3 final and 2 curve episodes.
FRAMES, BATCH, EPISODES, CURVE, SEED = 200, 100, 3, 2, 1000


def _argv(out, *extra):
    argv = ["bench-learn", "--seeds", "1", "--frames", str(FRAMES)]
    argv += ["--frames-per-batch", str(BATCH), "--eval-episodes", str(EPISODES)]
    argv += ["--curve-episodes", str(CURVE), "--curve-points", "2", "--eval-seed", str(SEED)]
    for t in TASKS:
        argv += ["--task", t]
    for a in ALGORITHMS:
        argv += ["--algorithm", a]
    return [*argv, "--out", str(out), "--no-progress", *extra]


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """The command's output folder after one tiny run of every case (trained once)."""
    if importlib.util.find_spec("benchmarl") is None:
        pytest.skip("BenchMARL is not installed")
    from activetrack.cli import main

    out = tmp_path_factory.mktemp("bench") / "out"
    assert main(_argv(out)) == 0
    return out


def _check_schema(data):
    """Check marl-eval's raw-data structure (its README's "Data Structure for Raw Experiment
    data"): env -> task -> algorithm -> run -> step_i {step_count: int, metric: [numbers]}
    and absolute_metrics {metric: [numbers]}, the same metrics and steps everywhere."""
    (env,) = data
    steps_seen, metrics_seen = set(), set()
    for tasks in data[env].values():
        for runs in tasks.values():
            for run in runs.values():
                assert "absolute_metrics" in run
                steps = [k for k in run if k != "absolute_metrics"]
                steps_seen.add(tuple(steps))
                for k in steps:
                    point = run[k]
                    assert isinstance(point["step_count"], int)
                    metrics_seen.add(frozenset(point))
                    assert all(np.isfinite(v).all() for v in point.values())
                metrics_seen.add(frozenset(run["absolute_metrics"]) | {"step_count"})
    assert len(steps_seen) == 1 and len(metrics_seen) == 1, (steps_seen, metrics_seen)


@needs_benchmarl
@pytest.mark.slow  # the six tiny runs and their evaluations: about a minute
def test_bench_learn_end_to_end(bench, tmp_path):
    from activetrack.cli import main
    from activetrack.world.scenarios import make_scenario

    data = json.loads((bench / "marl_eval.json").read_text())
    summary = json.loads((bench / "summary.json").read_text())
    _check_schema(data)
    assert set(data) == {"activetrack"}
    assert set(data["activetrack"]) == set(TASKS)
    curve_frames = [0, BATCH, FRAMES]
    assert summary["curve_frames"] == curve_frames
    assert len(summary["runs"]) == len(TASKS) * len(ALGORITHMS)

    for task in TASKS:
        scenario = make_scenario(task)
        assert scenario.objective in (None, "trace"), scenario.objective
        scale = scenario.reward_scale * scenario.n_steps
        assert set(data["activetrack"][task]) == set(ALGORITHMS)
        episodes = json.loads((bench / "eval" / task / "episodes.json").read_text())["policies"]
        rows = json.loads((bench / "eval" / task / "results.json").read_text())
        assert episodes["gsr"]["seeds"] == list(range(SEED, SEED + EPISODES))
        for algorithm in ALGORITHMS:
            run = data["activetrack"][task][algorithm]["seed_0"]
            steps = [run[f"step_{i}"] for i in range(len(curve_frames))]
            assert [p["step_count"] for p in steps] == curve_frames
            times = [p["elapsed_time"] for p in steps]
            assert times[0] >= 0 and np.all(np.diff(times) > 0)
            # Return and mean trace are the env's rewards and the world's traces, two
            # readings of one episode: the reward is -reward_scale times the trace (the
            # objective of these tasks) per step, summed over n_steps steps, where the
            # mean trace averages the trace over them.
            for p in [*steps, run["absolute_metrics"]]:
                np.testing.assert_allclose(p["return"], -scale * np.asarray(p["mean_trace"]))
            # The run's training time (summary.json's): from the last update on, only the
            # checkpoint is written, so it is at least the last step's.
            (row,) = [
                r for r in summary["runs"] if (r["task"], r["algorithm"]) == (task, algorithm)
            ]
            assert run["absolute_metrics"]["elapsed_time"] == row["seconds"] >= times[-1]
            # absolute_metrics: the final evaluation's episodes of this run.
            label = f"{algorithm}-seed0"
            assert run["absolute_metrics"]["return"] == episodes[label]["return"]
            # The curve's last point is the trained policy in memory, the final evaluation
            # the checkpoint reloaded through the .pt loader: on the curve's episodes (the
            # first CURVE of the evaluation's) they act alike.
            np.testing.assert_allclose(
                steps[-1]["return"], episodes[label]["return"][:CURVE], rtol=1e-6
            )
            # The pooled row of the protocol (one training seed here) is that run's.
            pooled = next(r for r in rows if r["policy"] == algorithm)
            assert pooled["runs"] == 1 and pooled["pooled"] == [label]
            np.testing.assert_allclose(pooled["mean_trace"], np.mean(episodes[label]["mean_trace"]))
            gsr = np.asarray(episodes["gsr"]["mean_trace"])
            ratio = np.mean(episodes[label]["mean_trace"]) / np.mean(gsr)
            np.testing.assert_allclose(pooled["ratio_to_gsr"], ratio, rtol=1e-12)
            assert pooled["ratio_to_gsr_ci95"][0] <= ratio <= pooled["ratio_to_gsr_ci95"][1]
        assert {"gsr", "rm"} <= {r["policy"] for r in rows}

    # One checkpoint through `activetrack evaluate --policy` (its own process of loading
    # and rolling out): the returns bench-learn recorded for that run.
    run = next(
        r for r in summary["runs"] if r["task"] == "two_targets" and r["algorithm"] == "ippo"
    )
    checkpoint = bench / run["checkpoint"]
    assert checkpoint.is_file() and checkpoint.name == f"checkpoint_{FRAMES}.pt"
    out = tmp_path / "eval"
    argv = ["evaluate", "--scenario", "two_targets", "--policy", str(checkpoint)]
    argv += ["--episodes", str(EPISODES), "--seed", str(SEED), "--out", str(out), "--no-plot"]
    assert main([*argv, "--no-progress"]) == 0
    evaluated = json.loads((out / "episodes.json").read_text())["policies"][str(checkpoint)]
    recorded = data["activetrack"]["two_targets"]["ippo"]["seed_0"]["absolute_metrics"]
    np.testing.assert_allclose(evaluated["return"], recorded["return"], rtol=1e-9)

    # The figure: one row of four panels per task.
    import matplotlib.image

    image = matplotlib.image.imread(bench / "learning_curves.png")
    assert image.shape[0] > 500 and image.shape[1] > 1000


@needs_benchmarl
@pytest.mark.slow
def test_marl_eval_reads_the_json(bench):
    """marl-eval's own pipeline reads the file: its processing adds the per-step means,
    and its rliable matrices hold the final evaluation's mean (runs x tasks)."""
    pytest.importorskip("marl_eval", reason="marl-eval is not installed (make test installs it)")
    from marl_eval.utils.data_processing_utils import (
        create_matrices_for_rliable,
        data_process_pipeline,
    )
    from marl_eval.utils.diagnose_data_errors import DiagnoseData

    raw = json.loads((bench / "marl_eval.json").read_text())
    checks = DiagnoseData(json.loads(json.dumps(raw))).check_data()["activetrack"]
    assert all(checks.values()), checks
    processed = data_process_pipeline(raw_data=raw, metrics_to_normalize=["return"])
    assert "extra" in processed  # (marl-eval returns the raw data on a format error)
    assert processed["extra"]["number_of_runs"] == 1
    assert processed["extra"]["algorithm_list"] == list(ALGORITHMS)
    final, curves = create_matrices_for_rliable(processed, "activetrack", ["return"])
    for j, task in enumerate(processed["activetrack"]):
        for algorithm in ALGORITHMS:
            traces = raw["activetrack"][task][algorithm]["seed_0"]["absolute_metrics"]
            np.testing.assert_allclose(
                final["mean_mean_trace"][algorithm][0, j], np.mean(traces["mean_trace"])
            )
            assert curves["mean_mean_trace"][algorithm].shape == (1, len(TASKS), 3)


@needs_benchmarl
@pytest.mark.slow  # two updates of MAPPO on 1000 frames each, 40 episodes: about 30 s
def test_mappo_learns_against_its_measured_start(tmp_path):
    """A small MAPPO budget (2000 frames, Adam at 3e-4) on ``paper``: the trained
    checkpoint, evaluated by ``evaluate`` through the .pt loader, has a lower mean trace
    than the same run's untrained policy (the curve's step 0) on the same 20 held-out
    episodes, by more than three standard errors of the paired differences and by at
    least a tenth of the start (a policy that barely moved, at a learning rate a million
    times smaller, improves every episode by 1e-6 of its trace: consistent, not learning)."""
    from activetrack.baselines.evaluation import evaluate
    from activetrack.train.bench_learn import BenchConfig, train_run

    n = 20
    config = BenchConfig(
        tasks=("paper",), algorithms=("mappo",), seeds=1, frames=2000, frames_per_batch=1000,
        eval_episodes=n, eval_seed=SEED, curve_points=1, curve_episodes=n, lr=3e-4,
    )  # fmt: skip
    record = train_run("paper", "mappo", 0, config, tmp_path)
    start = record.curve[0]
    assert start["step_count"] == 0 and len(start["mean_trace"]) == n
    (trained, _gsr) = evaluate({"trained": str(record.checkpoint)}, "paper", n, SEED, False)
    assert trained.seeds == list(range(SEED, SEED + n))
    d = np.asarray(start["mean_trace"]) - trained.mean_trace
    margin = max(3 * np.std(d, ddof=1) / np.sqrt(n), 0.1 * np.mean(start["mean_trace"]))
    assert np.mean(d) > margin, (np.mean(start["mean_trace"]), np.mean(trained.mean_trace), margin)


def test_config_is_checked_at_the_boundary():
    from activetrack.train.bench_learn import BenchConfig

    cases = [
        ({"tasks": ("paper", "nope")}, "tasks must be one or more distinct names"),
        ({"tasks": ("paper", "paper")}, "tasks must be one or more distinct names"),
        ({"tasks": ()}, "tasks must be one or more distinct names"),
        ({"algorithms": ("qmix",)}, "algorithms must be one or more distinct names"),
        ({"seeds": 0}, r"seeds must be an integer in \[1, 100\]"),
        ({"frames_per_batch": 0}, r"frames_per_batch must be an integer in \[1, 10000000\]"),
        ({"frames": 50, "frames_per_batch": 100}, r"frames must be an integer in \[100, "),
        ({"frames": 250, "frames_per_batch": 100}, "frames must be a multiple of"),
        ({"eval_episodes": 0}, r"eval_episodes must be an integer in \[1, 100000\]"),
        ({"eval_seed": -1}, r"eval_seed must be an integer in \[0, "),
        ({"eval_seed": 2**31 - 1}, r"eval_seed must be an integer in \[0, 2147483547\]"),
        ({"curve_points": 0}, r"curve_points must be an integer in \[1, 10000\]"),
        ({"curve_episodes": 11, "eval_episodes": 10}, r"curve_episodes .* in \[1, 10\]"),
        ({"threads": 0}, r"threads must be an integer in \[1, "),
        ({"lr": 0.0}, r"lr must be a number in \(0, 1\]"),
        ({"lr": float("nan")}, "lr must be"),
        ({"seeds": 2.5}, r"seeds must be an integer"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=message):
            BenchConfig(**kwargs)
    with pytest.raises(TypeError, match="unexpected keyword argument 'budget'"):
        BenchConfig(budget=3)
    if importlib.util.find_spec("benchmarl") is None:
        return
    from activetrack.train.bench_learn import train_run

    for args, message in (
        (("nope", "mappo", 0), "task must be one or more distinct names"),
        (("paper", "qmix", 0), "algorithm must be one or more distinct names"),
        (("paper", "mappo", -1), r"seed must be an integer in \[0, 2147483647\]"),
    ):
        with pytest.raises(ValueError, match=message):
            train_run(*args, BenchConfig(), Path("."))
    with pytest.raises(ValueError, match="is not a directory"):
        train_run("paper", "mappo", 0, BenchConfig(), Path("no/such/folder"))


def test_curve_frames_and_optimisation_settings():
    from activetrack.train.bench_learn import BenchConfig

    # 10 batches, 4 points: every ceil(10 / 4) = 3 batches, and always the last.
    c = BenchConfig(frames=1000, frames_per_batch=100, curve_points=4)
    assert c.curve_frames() == [0, 300, 600, 900, 1000]
    assert BenchConfig(frames=300, frames_per_batch=100, curve_points=10).curve_frames() == [
        0,
        100,
        200,
        300,
    ]
    # BenchMARL's defaults: 45 passes of minibatches of 400 (of a smaller batch: the
    # batch), 1000 off-policy steps per 6000 frames.
    assert c.experiment_fields("mappo") == {
        "lr": 5e-5,
        "on_policy_n_minibatch_iters": 45,
        "on_policy_minibatch_size": 100,
    }
    big = BenchConfig(frames=12000, frames_per_batch=6000)
    assert big.experiment_fields("ippo")["on_policy_minibatch_size"] == 400
    assert big.experiment_fields("masac")["off_policy_n_optimizer_steps"] == 1000
    assert big.experiment_fields("masac")["off_policy_memory_size"] == 12000


def test_cli_checks_before_training(tmp_path, capsys):
    """Bad values and a folder holding results are refused before any run starts (no
    BenchMARL needed for the arguments; the folder is left as it was)."""
    from activetrack.cli import main

    assert main(["bench-learn", "--frames", "250", "--frames-per-batch", "100",
                 "--out", str(tmp_path / "a")]) == 2  # fmt: skip
    assert "frames must be a multiple of frames_per_batch" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()
    with pytest.raises(SystemExit):
        main(["bench-learn", "--task", "nope", "--out", str(tmp_path / "b")])
    if importlib.util.find_spec("benchmarl") is None:
        return
    out = tmp_path / "old"
    out.mkdir()
    (out / "marl_eval.json").write_text("{}")
    assert main(_argv(out)) == 2
    err = capsys.readouterr().err
    assert "already holds results (marl_eval.json)" in err and "--overwrite" in err
    assert sorted(p.name for p in out.iterdir()) == ["marl_eval.json"]
    assert (out / "marl_eval.json").read_text() == "{}"


def test_without_benchmarl_the_error_names_the_marl_extra(tmp_path):
    """Without BenchMARL the command says how to install it (exit 2), before any folder."""
    import subprocess
    import sys

    code = (
        "import sys; sys.modules['benchmarl'] = None\n"  # import benchmarl fails
        "from activetrack.cli import main\n"
        f"raise SystemExit(main(['bench-learn', '--out', {str(tmp_path / 'out')!r}]))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 2, out.stderr[-2000:]
    assert "bench-learn: error: BenchMARL is not installed" in out.stderr, out.stderr[-2000:]
    assert "[marl] extra" in out.stderr and "Traceback" not in out.stderr
    assert not (tmp_path / "out").exists()
