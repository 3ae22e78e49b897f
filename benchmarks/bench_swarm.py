"""Speed of a large team (``swarm``: 32 robots, 8 targets) beside VMAS, in one run.

The batched env (:class:`activetrack.envs.batched.BatchedActiveTracking`) of the task at
N = 256 copies, random actions, autoresets at the episodes' ends, beside VMAS on CPU at
the same N with as many agents (torch with one thread), timed in alternating chunks of
10 steps (``bench_tasks.interleaved_rates``; VMAS without episode ends), ``--repeats``
times: every rate and ratio is the median of the repeats. The unit is *robot-steps per
second* (copies x agents x steps / s). Two VMAS scenarios, as shipped:

- ``dispersion`` with ``n_agents=32`` (agents spread over food particles, collisions);
- ``discovery`` with ``n_agents=32, n_targets=8`` (agents find targets, which respawn:
  the VMAS task closest to ours).

The target (issue 37): ours at least as fast as each. The peer comes from the ``[bench]``
extra (``.venv/bin/python -m pip install vmas``). Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_swarm.py --out swarm.json
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_swarm.py --quick

``--out`` is written atomically and never overwritten (a path that exists is refused
before anything is measured).
"""

from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before NumPy loads OpenBLAS

import argparse  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

#: The issue's target: ours over each peer's robot-steps/s.
TARGET = 1.0
#: The VMAS scenarios timed beside ours, with their keywords.
PEERS = {
    "vmas_dispersion": ("dispersion", {"n_agents": 32}),
    "vmas_discovery": ("discovery", {"n_agents": 32, "n_targets": 8}),
}


def vmas_stepper(n: int, scenario: str, kwargs: dict) -> tuple[Any, int]:
    """Return (``step(k)``, agents) of VMAS ``scenario`` on CPU at ``n`` copies, random
    actions in [-1, 1] from a pool of 8."""
    import torch
    import vmas

    env = vmas.make_env(
        scenario=scenario, num_envs=n, device="cpu", continuous_actions=True, seed=0, **kwargs
    )
    env.reset()
    g = torch.Generator().manual_seed(0)
    sizes = [env.get_agent_action_size(a) for a in env.agents]
    pool = [[torch.rand(n, s, generator=g) * 2 - 1 for s in sizes] for _ in range(8)]

    def step(k: int) -> None:  # no episode ends: VMAS's step alone, a generous comparison
        env.step(pool[k % 8])

    return step, len(env.agents)


def batched(task: str, n: int, seconds: float, repeats: int) -> dict[str, Any]:
    """Return robot-steps/s of ``task``'s batched env and of each VMAS peer at ``n``
    copies (medians of ``repeats`` interleaved timings) and the ratios ours / peer."""
    from bench_tasks import interleaved_rates

    from activetrack.envs.batched import BatchedActiveTracking

    env = BatchedActiveTracking(n, scenario=task)
    env.reset(seed=0)
    m = env.n_sensors
    rng = np.random.default_rng(0)
    pool = [rng.uniform(-1, 1, env.action_space.shape).astype(np.float32) for _ in range(8)]
    steppers: dict[str, Any] = {"activetrack": lambda k: env.step(pool[k % 8])}
    agents = {"activetrack": m}
    for name, (scenario, kwargs) in PEERS.items():
        steppers[name], agents[name] = vmas_stepper(n, scenario, kwargs)
    runs = []
    for _ in range(repeats):
        rates = interleaved_rates(steppers, n, seconds, chunk=10)
        runs.append({k: v * agents[k] for k, v in rates.items()})  # robot-steps/s
    out: dict[str, Any] = {k: float(np.median([r[k] for r in runs])) for k in steppers}
    out["agents"] = agents
    for peer in PEERS:
        ratios = [r["activetrack"] / r[peer] for r in runs]
        out[f"ratios_{peer}"] = ratios
        out[f"ratio_{peer}"] = float(np.median(ratios))
    return out


def main(argv: list[str] | None = None) -> dict:
    """Print the rates and ratios; return them as a dict (and write ``--out``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--task", default="swarm", help="the task (a preset name)")
    parser.add_argument("--n", type=int, default=256, help="copies (ours and VMAS's)")
    parser.add_argument("--repeats", type=int, default=5, help="interleaved timings (median)")
    parser.add_argument("--quick", action="store_true", help="shorter timing (noisier)")
    parser.add_argument("--out", type=Path, help="write the figures to this new JSON file")
    args = parser.parse_args(argv)
    if args.n < 1:
        parser.error(f"--n must be a positive integer, got {args.n}")
    if args.repeats < 1:
        parser.error(f"--repeats must be a positive integer, got {args.repeats}")
    from bench_robots import _check_out  # (a new file in an existing folder)

    _check_out(args.out)
    import torch
    import vmas

    torch.set_num_threads(1)
    seconds = 1.0 if args.quick else 4.0
    out: dict[str, Any] = {
        "python": platform.python_version(), "numpy": np.__version__,
        "torch": torch.__version__, "vmas": vmas.__version__, "torch_threads": 1,
        "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS"), "n": args.n,
        "repeats": args.repeats, "task": args.task,
    }  # fmt: skip
    print(f"batched, N = {args.n}, robot-steps/s (alternating chunks; median of "
          f"{args.repeats})", flush=True)  # fmt: skip
    b = out["batched"] = batched(args.task, args.n, seconds, args.repeats)
    for name, rate in b.items():
        if isinstance(rate, float) and not name.startswith("ratio"):
            print(f"   {name:18s} {rate:12.0f}  ({b['agents'][name]} agents)")
    for peer in PEERS:
        each = ", ".join(f"{r:.2f}" for r in b[f"ratios_{peer}"])
        print(f"   ratio / {peer}: {b[f'ratio_{peer}']:.2f} (each repeat: {each}; "
              f"target >= {TARGET:g})")  # fmt: skip
    out["target_met"] = all(b[f"ratio_{p}"] >= TARGET for p in PEERS)
    if args.out is not None:
        from activetrack.files import atomic_write_json

        atomic_write_json(args.out, out)
        print(f"wrote {args.out}")
    return out


if __name__ == "__main__":
    main()
