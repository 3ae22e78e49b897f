"""Throughput at scale: single env, batched env and the GSR expert, beside the peers.

Prints, in one run on this machine:

1. single environment (M = 3, random actions) steps/s beside PettingZoo MPE
   ``simple_spread`` (mpe2, 3 agents, continuous actions), interleaved timing;
2. batched environment env-steps/s (copies x steps per second) at N = 1, 64, 1024, 8192
   beside VMAS ``simple_spread`` on CPU at the same N (3 agents, continuous actions);
3. GSR expert plans per second for M = 3: the scalar GSR (one plan per call) and the
   batched GSR (a whole batch of N = 1024 copies per call), each plan a converged GSR;
4. the peak resident memory of a process running the batched env at N = 8192.

torch runs with one thread (this machine has 2 cores, and numpy here is single-threaded
too). The peers come from the ``[bench]`` extra: ``pip install -e ".[bench]"``.

Run::

    .venv/bin/python benchmarks/throughput.py            # about 2 minutes
    .venv/bin/python benchmarks/throughput.py --quick    # about 30 s, fewer repeats
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

N_VALUES = (1, 64, 1024, 8192)


def single_env(seconds: float) -> dict[str, float]:
    """Return steps/s of the parallel env (M = 3) and of MPE simple_spread, interleaved."""
    from bench_env import _Runner, measure
    from mpe2 import simple_spread_v3

    from activetrack.envs import parallel_env

    rates = measure(
        {
            "activetrack": _Runner(lambda: parallel_env(scenario="paper")),
            "simple_spread": _Runner(
                lambda: simple_spread_v3.parallel_env(N=3, continuous_actions=True, max_cycles=50)
            ),
        },
        seconds,
    )
    rates["ratio"] = rates["activetrack"] / rates["simple_spread"]
    return rates


def _time_steps(step, steps: int) -> float:
    """Return the seconds ``steps`` calls of ``step(k)`` take (after two warm-up calls)."""
    step(0)
    step(1)
    start = time.perf_counter()
    for k in range(steps):
        step(k)
    return time.perf_counter() - start


def batched_env(n: int, steps: int) -> float:
    """Return env-steps/s of :class:`BatchedActiveTracking` at ``n`` copies (random actions)."""
    from activetrack.envs.batched import BatchedActiveTracking

    env = BatchedActiveTracking(n, scenario="paper")
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    pool = [rng.uniform(-1, 1, (n, 6)).astype(np.float32) for _ in range(8)]
    return n * steps / _time_steps(lambda k: env.step(pool[k % 8]), steps)


def vmas_env(n: int, steps: int) -> float:
    """Return env-steps/s of VMAS simple_spread (3 agents, CPU) at ``n`` copies."""
    return vmas_env_agents(n, steps, 3)


def vmas_env_agents(n: int, steps: int, agents: int) -> float:
    """Return env-steps/s of VMAS simple_spread with ``agents`` agents (CPU) at ``n`` copies."""
    return n * steps / _time_steps(vmas_stepper(n, agents), steps)


def vmas_stepper(n: int, agents: int):
    """Return ``step(k)`` of VMAS simple_spread with ``agents`` agents (CPU) at ``n`` copies,
    random actions from a pool of 8."""
    import torch
    import vmas

    env = vmas.make_env(
        scenario="simple_spread",
        num_envs=n,
        device="cpu",
        continuous_actions=True,
        n_agents=agents,
        seed=0,
    )
    env.reset()
    g = torch.Generator().manual_seed(0)
    pool = [[torch.rand(n, 2, generator=g) * 2 - 1 for _ in range(agents)] for _ in range(8)]

    def step(k: int) -> None:  # no episode ends: VMAS's step alone, a generous comparison
        env.step(pool[k % 8])

    return step


def gsr_rates(n: int, episodes: int) -> dict[str, float]:
    """Return GSR plans/s for M = 3: scalar GSR per copy, and batched GSR per batch of ``n``."""
    from activetrack import PlanningProblem
    from activetrack.baselines import GSR
    from activetrack.envs.batched import BatchedActiveTracking

    env = BatchedActiveTracking(n, scenario="paper")
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    problems = []  # states along random-action episodes: realistic, varied problems
    for _ in range(episodes):
        problems.append(
            (env.P_pred[:, :2, :2].copy(), env.x_pred[:, :2].copy(), env.sensors.copy())
        )
        env.step(rng.uniform(-1, 1, (n, 6)))
    p = env.params
    plan_batch = _batched_gsr()
    plan_batch(*problems[0], p.r, p.rho, p.sigma_d2, p.sigma_theta2)  # load kernels
    start = time.perf_counter()
    for P, target, sensors in problems:
        plan_batch(P, target, sensors, p.r, p.rho, p.sigma_d2, p.sigma_theta2)
    batched_rate = n * len(problems) / (time.perf_counter() - start)

    solves = _count_solves(plan_batch, problems, p)  # untimed
    scalar = GSR()
    count = min(n, 300)
    P, target, sensors = problems[len(problems) // 2]
    probs = [
        PlanningProblem(P[i], target[i], sensors[i], p.r, p.rho, p.sigma_d2, p.sigma_theta2)
        for i in range(count)
    ]
    scalar.plan(probs[0])  # load the kernels first
    start = time.perf_counter()
    for prob in probs:
        scalar.plan(prob)
    scalar_rate = count / (time.perf_counter() - start)
    plans = n * len(problems)
    return {
        "scalar": scalar_rate,
        "batched": batched_rate,
        "ratio": batched_rate / scalar_rate,
        "solves_per_plan": solves / plans,
    }


def _batched_gsr():
    """Return GSR on a batch given as arrays, ``(P, target, sensors, r, rho, sigma_d2,
    sigma_theta2) -> batch result``: ``GSR().plan_with_info`` on a batched planning problem,
    or, on an old checkout (benchmarked side by side), its ``BatchedGSR().plan_batch``."""
    from activetrack import PlanningProblem
    from activetrack.baselines import GSR

    try:
        from activetrack.baselines.batched_gsr import BatchedGSR  # old checkouts only
    except ImportError:
        gsr = GSR()
        return lambda *arrays: gsr.plan_with_info(PlanningProblem(*arrays))
    return BatchedGSR().plan_batch


def _count_solves(plan_batch, problems, p) -> int:
    """Return how many single-sensor problems ``plan_batch`` solves over ``problems`` (the
    kernel counts them: ``n_solves`` of each batch result)."""
    return sum(
        int(plan_batch(P, target, sensors, p.r, p.rho, p.sigma_d2, p.sigma_theta2)
            .n_solves.sum())
        for P, target, sensors in problems
    )  # fmt: skip


def peak_rss_mb(n: int, steps: int) -> float:
    """Return the peak RSS (MB) of a fresh process that runs the batched env at ``n`` copies."""
    code = (
        "import resource, numpy as np\n"
        "from activetrack.envs.batched import BatchedActiveTracking\n"
        f"env = BatchedActiveTracking({n}); env.reset(seed=0)\n"
        f"a = np.zeros(({n}, 6))\n"
        f"for _ in range({steps}): env.step(a)\n"
        "print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return float(out.stdout.strip())


def main(argv: list[str] | None = None) -> dict:
    """Print every figure and ratio; return them as a dict."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats (noisier)")
    parser.add_argument("--json", help="also write the figures to this JSON file")
    args = parser.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    scale = 0.25 if args.quick else 1.0
    out: dict = {"python": platform.python_version(), "numpy": np.__version__}

    print("1. single environment, M = 3, random actions (interleaved timing)")
    single = single_env(5.0 * scale)
    out["single"] = single
    print(f"   activetrack      {single['activetrack']:10.0f} steps/s")
    print(f"   simple_spread    {single['simple_spread']:10.0f} steps/s (mpe2, N = 3)")
    print(f"   ratio            {single['ratio']:10.2f}")

    print("2. batched environment vs VMAS simple_spread (CPU), env-steps/s")
    print(f"   {'N':>6s} {'activetrack':>12s} {'vmas':>12s} {'ratio':>7s}")
    out["batched"] = {}
    for n in N_VALUES:
        steps = max(20, int(scale * min(2000, 200_000 // n)))
        ours = max(batched_env(n, steps) for _ in range(2))
        theirs = max(vmas_env(n, steps) for _ in range(2))
        out["batched"][n] = {"activetrack": ours, "vmas": theirs, "ratio": ours / theirs}
        print(f"   {n:6d} {ours:12.0f} {theirs:12.0f} {ours / theirs:7.2f}")

    print("3. GSR expert, M = 3, converged plans per second")
    g = gsr_rates(1024, max(2, int(10 * scale)))
    out["gsr"] = g
    print(f"   scalar GSR       {g['scalar']:10.0f} plans/s")
    print(f"   batched GSR      {g['batched']:10.0f} plans/s (N = 1024 per call)")
    print(f"   ratio            {g['ratio']:10.1f}")
    print(f"   per plan: {g['solves_per_plan']:.2f} single-sensor solves")

    rss = peak_rss_mb(8192, 100)
    out["peak_rss_mb_N8192"] = rss
    print(f"4. peak RSS of a process running the batched env at N = 8192: {rss:.0f} MB")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2, default=float)
    return out


if __name__ == "__main__":
    main()
