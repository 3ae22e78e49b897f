"""Sampling throughput of RLlib PPO (1 and 2 env runners) beside the SB3 path, in one run.

What is timed is PPO's rollout collection only (no learning), with the project's network
(MLP 2x256, tanh, the saturated mean) sampling stochastic actions, on the same scenario
and the same rollout length: ``--rollout`` env steps (one step of all M sensors) per
round, the default 2048 being one training batch of both paths
(SB3: 8 copies x 256 steps; RLlib: ``train_batch_size`` 2048).

- ``sb3``: ``PPO.collect_rollouts`` on :class:`~activetrack.train.SharedPolicyVecEnv`
  (``--sb3-copies`` copies, batched backend), in this process;
- ``rllib-K``: ``sample(num_timesteps=rollout / K)`` on each of K remote
  ``MultiAgentEnvRunner`` actors at once (``--envs-per-runner`` env copies each), on a
  local Ray; the round ends when every runner has returned.

Rounds are interleaved (sb3, rllib-1, rllib-2, sb3, ...) and the median of ``--rounds``
rounds is reported as env steps/s (agent-steps/s = M times that) and as a ratio to sb3.
One torch thread in the driver; Ray gives each runner one CPU (and one thread).

Run (needs the [ray] extra)::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_rllib.py
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_rllib.py --rounds 2 --json out.json
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import time

import numpy as np


def sb3_sampler(scenario: str, copies: int, rollout: int, seed: int):
    """Return a function that collects one SB3 rollout of ``rollout`` env steps; its count."""
    from activetrack.train.ppo import PPOConfig, build_ppo, make_training_env

    n_steps = max(2, rollout // copies)
    cfg = PPOConfig(n_copies=copies, n_steps=n_steps, batch_size=64)
    venv = make_training_env(scenario, copies, "shared", True, cfg.gamma)
    model = build_ppo(venv, cfg, seed)
    _, callback = model._setup_learn(10**12, None)
    callback.on_training_start(locals(), globals())

    def run() -> int:
        model.collect_rollouts(model.env, callback, model.rollout_buffer, n_steps)
        return n_steps * copies

    return run


def rllib_sampler(scenario: str, runners: int, envs: int, rollout: int, seed: int):
    """Return (a function that samples ``rollout`` env steps over ``runners`` actors, algo)."""
    from activetrack.train import rllib

    cfg = rllib.RLlibPPOConfig(
        num_env_runners=runners, num_envs_per_env_runner=envs, train_batch_size=rollout
    )
    algo = rllib.rllib_ppo_config(scenario, cfg, seed).build_algo()
    per_runner = rollout // runners

    def sample(runner) -> int:
        episodes = runner.sample(num_timesteps=per_runner, explore=True)
        return sum(e.env_steps() for e in episodes)

    def run() -> int:
        counts = algo.env_runner_group.foreach_env_runner(sample, local_env_runner=False)
        return int(sum(counts))

    return run, algo


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="paper")
    parser.add_argument("--rollout", type=int, default=2048, help="env steps per round")
    parser.add_argument("--rounds", type=int, default=5, help="timed rounds per sampler")
    parser.add_argument("--sb3-copies", type=int, default=8)
    parser.add_argument("--envs-per-runner", type=int, default=4)
    parser.add_argument("--runners", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--json", help="also write the figures to this JSON file")
    args = parser.parse_args()

    import ray

    from activetrack.train.utils import configure_torch
    from activetrack.world.scenarios import make_scenario

    configure_torch(1)
    m = make_scenario(args.scenario).n_sensors
    cpus = max(os.cpu_count() or 1, sum(args.runners))
    ray.init(address="local", num_cpus=cpus, include_dashboard=False, log_to_driver=False)
    samplers = {"sb3": sb3_sampler(args.scenario, args.sb3_copies, args.rollout, 0)}
    algos = []
    for k in args.runners:
        run, algo = rllib_sampler(args.scenario, k, args.envs_per_runner, args.rollout, 0)
        samplers[f"rllib-{k}"] = run
        algos.append(algo)
    for run in samplers.values():  # warm-up: first resets, lazy imports, torch kernels
        run()
    rates: dict[str, list[float]] = {name: [] for name in samplers}
    for _ in range(args.rounds):
        for name, run in samplers.items():
            t0 = time.perf_counter()
            steps = run()
            rates[name].append(steps / (time.perf_counter() - t0))
    for algo in algos:
        logdir = algo.logdir
        algo.stop()
        with contextlib.suppress(OSError):  # the empty folder RLlib makes in ~/ray_results
            os.rmdir(logdir)
    ray.shutdown()

    sb3 = float(np.median(rates["sb3"]))
    rows = {}
    print(
        f"{args.scenario} (M = {m}), rollout {args.rollout} env steps, median of "
        f"{args.rounds} interleaved rounds, {os.cpu_count()} CPUs, load "
        f"{os.getloadavg()[0]:.1f}"
    )
    print(f"{'sampler':<10} {'env steps/s':>12} {'agent-steps/s':>14} {'vs sb3':>7}  rounds")
    for name, r in rates.items():
        med = float(np.median(r))
        rows[name] = {"env_steps_per_s": med, "rounds": r, "ratio_to_sb3": med / sb3}
        print(
            f"{name:<10} {med:>12.0f} {m * med:>14.0f} {med / sb3:>7.2f}  "
            + " ".join(f"{x:.0f}" for x in r)
        )
    if args.json:
        from activetrack.files import atomic_write_json

        meta = {"args": vars(args), "platform": platform.platform(), "cpus": os.cpu_count()}
        atomic_write_json(args.json, {"meta": meta, "results": rows})


if __name__ == "__main__":
    main()
