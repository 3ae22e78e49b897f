"""BenchMARL on our tasks (issue 40): a tiny run finishes and checkpoints, every update
runs on the torch threads asked for, the checkpoint restores the trained actor (not a
fresh one), the actor acts in our env, and ``activetrack evaluate`` runs it.
(``activetrack bench-learn``'s end-to-end test, tests/train/test_bench_learn.py, runs
MAPPO, IPPO and MASAC on ``paper`` and ``two_targets``.)"""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

pytestmark = pytest.mark.skipif(
    importlib.util.find_spec("benchmarl") is None,
    reason="BenchMARL is not installed (the [marl] extra: pip install --no-deps benchmarl==1.5.2)",
)

# MAPPO and IPPO on the paper and a multi-target task; MASAC: one off-policy algorithm.
CASES = [(a, t) for a in ("mappo", "ippo") for t in ("PAPER", "TWO_TARGETS")]
CASES += [("masac", "PAPER")]


def _actor_params(experiment):
    """Return the actor's parameters as {name: array} (copies)."""
    policy = experiment.policy
    return {k: p.detach().clone().numpy() for k, p in policy.named_parameters()}


def _own_rollout(policy, scenario, seed):
    """Return (team return, actions seen) of one episode of ``policy`` in our parallel env,
    stepped here (independently of the evaluation's rollout)."""
    from activetrack.envs import parallel_env

    env = parallel_env(scenario)
    obs, _ = env.reset(seed=seed)
    total, actions = 0.0, []
    spaces = {a: env.action_space(a) for a in env.possible_agents}
    while env.agents:
        act = policy.act(obs)
        actions.append((act, spaces))
        obs, rewards, _, _, _ = env.step(act)
        # Every agent gets the team's reward: the return is one agent's sum.
        total += float(rewards[env.possible_agents[0]])
    return total, actions


@pytest.mark.slow  # about 30-60 s of training per case on this machine
@pytest.mark.parametrize(("algorithm", "task_name"), CASES)
def test_benchmarl_trains_checkpoints_and_evaluates(algorithm, task_name, tmp_path):
    import torch

    from activetrack.cli import main
    from activetrack.train.benchmarl_task import ActiveTrackingTask, load_policy, make_experiment

    task = ActiveTrackingTask[task_name].get_task()
    scenario = task.config["scenario"]
    runs = tmp_path / "runs"
    runs.mkdir()
    experiment = make_experiment(task, algorithm, seed=0, save_folder=runs, max_frames=400)
    before = _actor_params(experiment)
    # Every update runs on the one torch thread asked for (default 1), the last one too:
    # the collector closes its env when the budget is collected, and TorchRL raises the
    # thread count then (KeepThreads sets it back).
    threads, optimize = [], experiment._optimizer_loop

    def counting(group):
        threads.append(torch.get_num_threads())
        return optimize(group)

    experiment._optimizer_loop = counting
    experiment.run()
    trained = _actor_params(experiment)
    assert experiment.total_frames == 400  # the whole budget was collected
    assert len(threads) >= 2 and set(threads) == {1}, threads

    checkpoints = list((runs / experiment.name / "checkpoints").glob("checkpoint_*.pt"))
    assert [c.name for c in checkpoints] == ["checkpoint_400.pt"]
    checkpoint = checkpoints[0]

    # The checkpoint holds the trained actor: its parameters are the ones after training,
    # which training moved away from the initial ones.
    run_files = {p: p.read_bytes() for p in (runs / experiment.name).rglob("*") if p.is_file()}
    policy = load_policy(checkpoint)
    # Loading leaves the run as it was (BenchMARL's reload rewrites config.pkl in place).
    after = {p: p.read_bytes() for p in (runs / experiment.name).rglob("*") if p.is_file()}
    assert after == run_files
    assert sorted(p.name for p in runs.iterdir()) == [experiment.name]
    loaded = _actor_params(policy.experiment)
    assert loaded.keys() == trained.keys()
    for k in trained:
        np.testing.assert_array_equal(loaded[k], trained[k])
    assert any(not np.array_equal(before[k], trained[k]) for k in trained)

    # It acts in our env: one episode of finite actions inside each agent's box.
    own_returns = []
    for seed in (1000, 1001):
        total, steps = _own_rollout(policy, scenario, seed)
        assert np.isfinite(total)
        for act, spaces in steps:
            for agent, a in act.items():
                low, high = spaces[agent].low, spaces[agent].high
                assert a.shape == low.shape and np.all(np.isfinite(a))
                assert np.all((a >= low) & (a <= high)), (agent, a)
        own_returns.append(total)

    # `activetrack evaluate` loads the checkpoint through the .pt policy loader and runs
    # it on the same two seeds: its returns are the ones stepped here.
    out = tmp_path / "eval"
    argv = ["evaluate", "--scenario", scenario, "--policy", str(checkpoint)]
    argv += ["--episodes", "2", "--seed", "1000", "--out", str(out), "--no-plot"]
    assert main([*argv, "--no-progress"]) == 0
    episodes = json.loads((out / "episodes.json").read_text())["policies"]
    row = episodes[str(checkpoint)]
    assert row["seeds"] == [1000, 1001]
    np.testing.assert_allclose(row["return"], own_returns, rtol=1e-9)


def test_unknown_algorithm_and_budgets_are_rejected(tmp_path):
    from activetrack.train.benchmarl_task import (
        ActiveTrackingTask,
        algorithm_config,
        experiment_config,
        load_policy,
        make_experiment,
    )

    with pytest.raises(ValueError, match="algorithm must be one of"):
        algorithm_config("qmixx")
    with pytest.raises(ValueError, match="max_frames must be a positive int"):
        experiment_config(tmp_path, max_frames=0)
    with pytest.raises(ValueError, match="multiple of frames_per_batch"):
        experiment_config(tmp_path, max_frames=300, frames_per_batch=200)
    with pytest.raises(ValueError, match="save_folder"):
        experiment_config(tmp_path / "missing")
    with pytest.raises(ValueError, match="threads"):
        make_experiment(ActiveTrackingTask.PAPER.get_task(), "mappo", threads=0)
    bad = tmp_path / "checkpoint_1.pt"
    bad.write_bytes(b"")
    with pytest.raises(ValueError, match="not a BenchMARL checkpoint"):
        load_policy(bad)
    # Every registered id is a task, with its preset's episode length.
    from activetrack._registry import ALL_IDS
    from activetrack.world.scenarios import make_scenario

    assert {t.get_task().config["scenario"] for t in ActiveTrackingTask} == set(ALL_IDS.values())
    paper = ActiveTrackingTask.PAPER.get_task()
    assert paper.max_steps(None) == make_scenario("paper").n_steps


def test_evaluate_without_benchmarl_names_the_marl_extra(tmp_path):
    """A .pt policy file in an install without BenchMARL: the error names the [marl]
    extra, not the [rl] one (which the install has)."""
    import subprocess
    import sys

    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "config.pkl").write_bytes(b"")
    checkpoint = run / "checkpoints" / "checkpoint_400.pt"
    checkpoint.write_bytes(b"")
    code = (
        "import sys; sys.modules['benchmarl'] = None\n"  # import benchmarl fails
        "from activetrack.baselines.policy_specs import resolve_policy\n"
        "try:\n"
        f"    resolve_policy({str(checkpoint)!r})\n"
        "except ImportError as exc:\n"
        "    print(exc)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "benchmarl_task:load_policy cannot be imported" in out.stdout, out
    assert "[marl]" in out.stdout and "activetrack[rl]" not in out.stdout, out.stdout
