"""RLlib (the [ray] extra): env registration and checks, the shared module, export, the CLI.

Compared with independent computations: RLlib's own multi-agent env check and a raw
PettingZoo episode (the wrapper changes nothing); RLlib's env runner (its connectors,
batching and agent mapping) against the exported ``policy.zip`` run by
:class:`~activetrack.train.LearnedPolicy` (SB3's predict); ``activetrack evaluate`` on an
RLlib policy against a hand-written rollout of the loaded file; the RLlib checkpoint's
module against the exported file.
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import fields

import numpy as np
import pytest

from activetrack._registry import TWO_TEAM_ENTRY_POINTS

pytest.importorskip("ray")
pytest.importorskip("ray.rllib")

import torch  # noqa: E402
from ray.rllib.utils.pre_checks.env import check_multiagent_environments  # noqa: E402

from activetrack.cli import main  # noqa: E402
from activetrack.envs import parallel_env  # noqa: E402
from activetrack.train import (  # noqa: E402
    NetConfig,
    load_policy,
    rllib,
)
from activetrack.train import cli as train_cli  # noqa: E402

SMALL_NET = NetConfig(hidden=(32, 32))


@pytest.mark.parametrize("scenario", ["paper", "homogeneous"])
def test_rllib_env_check_passes_for_every_registered_id(scenario):
    from ray.tune.registry import ENV_CREATOR, _global_registry

    ids = rllib.register_rllib_envs()
    assert "activetrack/ActiveTracking-v0" in ids
    for env_id in ids:
        # Through RLlib's registry, as an env runner creates it. A two-team game needs a
        # target an agent moves: its own scenario (its sensors and its target_0).
        if env_id in TWO_TEAM_ENTRY_POINTS:
            env = _global_registry.get(ENV_CREATOR, env_id)({})
            check_multiagent_environments(env)
            assert "target_0" in env.possible_agents
            continue
        env = _global_registry.get(ENV_CREATOR, env_id)({"scenario": scenario})
        check_multiagent_environments(env)
        assert set(env.possible_agents) == set(parallel_env(scenario).possible_agents)


def test_wrapper_episode_equals_the_raw_parallel_env():
    """A whole episode through ParallelPettingZooEnv equals the raw env's, step by step."""
    env = rllib.make_env({"scenario": "paper"})
    raw = parallel_env("paper")
    rng = np.random.default_rng(0)
    obs, _ = env.reset(seed=7)
    raw_obs, _ = raw.reset(seed=7)
    steps = 0
    while True:
        for a in raw.agents:
            assert env.observation_space[a].contains(obs[a])
            np.testing.assert_array_equal(obs[a], raw_obs[a])
        actions = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in raw.agents}
        obs, rew, term, trunc, _ = env.step(actions)
        raw_obs, raw_rew, raw_term, raw_trunc, _ = raw.step(actions)
        steps += 1
        assert {a: rew[a] for a in raw_rew} == raw_rew
        if not raw.agents:
            break
        assert not trunc["__all__"] and not term["__all__"]
    assert steps == raw.scenario.n_steps
    assert trunc["__all__"] and not term["__all__"]


def test_config_maps_every_sensor_to_one_shared_module():
    cfg = rllib.rllib_ppo_config("paper", rllib.RLlibPPOConfig(net=SMALL_NET), seed=1)
    assert cfg.enable_rl_module_and_learner and cfg.enable_env_runner_and_connector_v2
    assert cfg.policies.keys() == {rllib.MODULE_ID}
    for agent in parallel_env("paper").possible_agents:
        assert cfg.policy_mapping_fn(agent, None) == rllib.MODULE_ID
    assert cfg.use_kl_loss is False
    assert cfg.env_config["reward_scale"] == rllib.RLlibPPOConfig().reward_scale


def _perturbed_runner(seed: int = 3):
    """Return a local RLlib env runner whose shared module has random, non-initial weights."""
    from ray.rllib.env.multi_agent_env_runner import MultiAgentEnvRunner

    cfg = rllib.rllib_ppo_config(
        "paper",
        rllib.RLlibPPOConfig(num_env_runners=0, num_envs_per_env_runner=1, net=SMALL_NET),
        seed=seed,
    )
    runner = MultiAgentEnvRunner(config=cfg)
    module = runner.module[rllib.MODULE_ID]
    gen = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in module.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=gen))
    return runner, module


def test_exported_policy_acts_as_rllib_deterministic_actions(tmp_path):
    """RLlib's env runner (explore=False) and the exported policy.zip agree to 1e-6."""
    runner, module = _perturbed_runner()
    episode = runner.sample(num_episodes=1, explore=False)[0]
    path = rllib.export_policy(module, tmp_path / "policy.zip", scenario={"name": "paper"}, seed=3)
    learned = load_policy(path)
    assert learned.meta["kind"] == rllib.KIND and learned.view == "shared"
    moved = 0.0
    for sa in episode.agent_episodes.values():
        obs = np.asarray(sa.get_observations())[:-1]
        acted = np.asarray(sa.get_actions())
        assert obs.shape[0] == acted.shape[0] == parallel_env("paper").scenario.n_steps
        np.testing.assert_allclose(learned.predict(obs), acted, rtol=0, atol=1e-6)
        np.testing.assert_allclose(
            rllib.deterministic_actions(module, obs), acted, rtol=0, atol=1e-6
        )
        moved = max(moved, float(np.abs(acted).max()))
    assert moved > 0.1  # the perturbed network does act (not a trivially zero policy)
    # The saturated head: every deterministic move lies in the unit disk.
    assert np.all(np.linalg.norm(learned.predict(obs), axis=-1) <= 1 + 1e-6)


def test_config_validation_names_the_field():
    for kw, name in [
        ({"num_env_runners": -1}, "num_env_runners"),
        ({"num_envs_per_env_runner": 0}, "num_envs_per_env_runner"),
        ({"lr": 0.0}, "lr"),
        ({"gamma": 1.5}, "gamma"),
        ({"lambda_": -0.1}, "lambda_"),
        ({"reward_scale": float("nan")}, "reward_scale"),
        ({"grad_clip_by": "l3"}, "grad_clip_by"),
        ({"train_batch_size": 1}, "train_batch_size"),
    ]:
        with pytest.raises(ValueError, match=name):
            rllib.RLlibPPOConfig(**kw)
    with pytest.raises(ValueError, match="address"):
        rllib.check_address("  ")
    with pytest.raises(ValueError, match="iterations"):
        rllib.train_rllib_ppo("paper", iterations=0)
    with pytest.raises(ValueError, match="not an RLlib checkpoint"):
        rllib.load_checkpoint_module("/nonexistent")


def test_cli_defaults_are_the_config_defaults():
    defaults = {f.name: f.default for f in fields(rllib.RLlibPPOConfig) if f.name != "net"}
    for name, value in train_cli._RLLIB_DEFAULTS.items():
        assert defaults[name] == value, name
    assert {n for n, _, _ in train_cli._RLLIB_OPTIONS.values()} == set(train_cli._RLLIB_DEFAULTS)


def test_cli_rejects_bad_input_before_starting_ray(tmp_path, capsys):
    import ray

    out = tmp_path / "run"
    rc = main(["train", "rllib-ppo", "--num-env-runners", "-1", "--out", str(out)])
    assert rc == 2 and "num_env_runners" in capsys.readouterr().err
    rc = main(["train", "rllib-ppo", "--iterations", "0", "--out", str(out)])
    assert rc == 2 and "iterations" in capsys.readouterr().err
    assert not out.exists()  # nothing created for a bad configuration
    out.mkdir()
    (out / "config.json").write_text("{}")
    rc = main(["train", "rllib-ppo", "--out", str(out)])
    assert rc == 2 and "--overwrite" in capsys.readouterr().err
    assert not ray.is_initialized()


def test_missing_ray_is_a_clear_error(tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # "import ray" now raises ImportError
    monkeypatch.delitem(sys.modules, "activetrack.train.rllib")
    monkeypatch.delattr(sys.modules["activetrack.train"], "rllib")
    rc = main(["train", "rllib-ppo", "--out", str(tmp_path / "run")])
    captured = capsys.readouterr()
    assert rc == 2
    assert 'pip install "activetrack[ray]"' in captured.out + captured.err
    assert not (tmp_path / "run").exists()


def test_importing_the_train_package_does_not_import_ray():
    code = (
        "import sys, activetrack.train, activetrack.train.cli, activetrack.cli;"
        "assert 'ray' not in sys.modules, 'ray imported'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def _mean_trace_by_hand(path, seeds) -> float:
    """Mean of tr P(k|k)_11 over every step of every episode, the loaded policy acting."""
    policy = load_policy(path)
    env = parallel_env("paper")
    per_episode = []
    for s in seeds:
        obs, _ = env.reset(seed=s)
        traces = []
        while env.agents:
            obs, _, _, _, infos = env.step(policy.act(obs))
            traces.append(infos[env.possible_agents[0]]["trace"])
        per_episode.append(np.mean(traces))
    return float(np.mean(per_episode))


@pytest.mark.slow
def test_train_rllib_ppo_two_iterations_then_evaluate(tmp_path):
    out = tmp_path / "run"
    argv = ["train", "rllib-ppo", "--scenario", "paper", "--seed", "0"]
    argv += ["--num-env-runners", "1", "--envs-per-runner", "2", "--iterations", "2"]
    argv += ["--train-batch-size", "200", "--minibatch-size", "100", "--num-epochs", "2"]
    argv += ["--hidden", "32", "32", "--no-progress", "--out", str(out)]
    assert main(argv) == 0
    assert {p.name for p in out.iterdir()} == {"policy.zip", "config.json", "checkpoints", "tb"}
    assert list((out / "tb").glob("events.out.tfevents.*"))
    config = json.loads((out / "config.json").read_text())
    assert config["iterations"] == 2 and config["env_steps"] >= 400
    assert config["agent_steps"] == 3 * config["env_steps"]  # 3 sensors on paper
    checkpoint = out / "checkpoints" / "iter_000002"
    assert (checkpoint / "rllib_checkpoint.json").is_file()

    # The checkpoint's learner module is the exported network.
    module = rllib.load_checkpoint_module(checkpoint)
    learned = load_policy(out / "policy.zip")
    obs, _ = parallel_env("paper").reset(seed=11)
    stacked = np.stack(list(obs.values()))
    np.testing.assert_allclose(
        learned.predict(stacked), rllib.deterministic_actions(module, stacked), atol=1e-6
    )

    # evaluate loads it and measures it on held-out seeds like any policy.
    ev = tmp_path / "eval"
    policy = str(out / "policy.zip")
    argv = ["evaluate", "--scenario", "paper", "--policy", policy, "--episodes", "2"]
    argv += ["--seed", "1000", "--no-plot", "--no-progress", "--out", str(ev)]
    assert main(argv) == 0
    rows = {r["policy"]: r for r in json.loads((ev / "results.json").read_text())}
    row = rows[policy]
    assert row["mean_trace"] == pytest.approx(_mean_trace_by_hand(policy, [1000, 1001]), rel=1e-12)


@pytest.mark.slow
def test_train_rllib_ppo_on_a_running_cluster_via_address(tmp_path):
    """--address: the command (another process) joins a running Ray and trains on it."""
    import ray

    ray.init(address="local", num_cpus=2, include_dashboard=False)
    try:
        address = ray.get_runtime_context().gcs_address
        out = tmp_path / "run"
        argv = ["train", "rllib-ppo", "--address", address, "--num-env-runners", "1"]
        argv += ["--iterations", "1", "--train-batch-size", "100", "--minibatch-size", "50"]
        argv += ["--num-epochs", "1", "--hidden", "16", "--no-progress", "--out", str(out)]
        code = "import sys; from activetrack.cli import main; sys.exit(main(sys.argv[1:]))"
        subprocess.run([sys.executable, "-c", code, *argv], check=True, timeout=600)
        # The command disconnected from the cluster it joined and left it running.
        assert ray.get(ray.put(7)) == 7 and all(n["Alive"] for n in ray.nodes())
        config = json.loads((out / "config.json").read_text())
        assert config["address"] == address and config["env_steps"] >= 100
        load_policy(out / "policy.zip")
    finally:
        ray.shutdown()
