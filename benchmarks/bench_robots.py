"""Speed of the robots' task (unicycles) beside the peers, in one run.

The task is the paper's scenario with every sensor a :class:`activetrack.Unicycle` of the
paper's top speed and a turning limit, ``make_scenario("paper", kinematics=Unicycle(0,
10, pi))`` (M = 3). Measured, with one BLAS thread and torch with one thread:

1. ``single``: the PettingZoo parallel env (random actions, autoresets every 50 steps),
   steps/s, beside MPE2 ``simple_spread`` with as many agents (continuous actions, 50
   steps an episode) and, for reference, the paper's disk task; interleaved quarter-second
   chunks (``bench_env.measure``). Target: at least 5x ``simple_spread``.
2. ``batched``: the batched env (:class:`activetrack.envs.batched.BatchedActiveTracking`)
   at N = 1024 copies, env-steps/s (copies x steps), beside VMAS on CPU at the same N
   with as many agents, timed in alternating chunks of 10 steps (ours with its
   autoresets, VMAS without episode ends), ``--repeats`` times (5; each half the
   seconds of the single env's timing): every rate and ratio is the median of the
   repeats, each repeat's ratio printed too. Two VMAS workloads:

   - ``vmas_diffdrive``: a scenario of 3 agents, each with VMAS's differential-drive
     dynamics (``vmas.simulator.dynamics.diff_drive.DiffDrive``, RK4, the default as in
     VMAS's example), one physics substep, no collisions (our unicycle task has no
     separation rule either), observations of position, velocity and heading, reward the
     negative distance to the origin (:class:`DiffDriveTeam`). The light peer: the
     target is to be at least as fast as it.
   - ``vmas_diff_drive``: VMAS's own ``diff_drive`` scenario with ``n_agents=3`` (agent 0
     differential drive, the others holonomic with rotation; collisions, 10 substeps), as
     shipped.

The peers are installed beside the library (the ``bench`` extra, or
``.venv/bin/python -m pip install mpe2 vmas``). Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_robots.py --out robots.json
    OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_robots.py --quick

``--out`` is written atomically (a temporary file renamed into place) and is never
overwritten: the script refuses a path that exists before measuring anything.
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

#: The issue's targets: ours over the peer's rate.
SINGLE_TARGET = 5.0
BATCHED_TARGET = 1.0
N_AGENTS = 3


def unicycle_scenario() -> Any:
    """Return the paper's scenario with unicycles (v in [0, 10] m/s, |w| <= pi rad/s)."""
    import activetrack
    from activetrack.world.scenarios import make_scenario

    return make_scenario("paper", kinematics=activetrack.Unicycle(0.0, 10.0, np.pi))


def single_env(seconds: float) -> dict[str, float]:
    """Return steps/s of the unicycle parallel env, of MPE2 ``simple_spread`` (as many
    agents) and of the paper's disk env, timed interleaved, and the ratio to MPE2."""
    from bench_env import _Runner, measure
    from mpe2 import simple_spread_v3

    from activetrack.envs import parallel_env

    scenario = unicycle_scenario()
    rates = measure(
        {
            "unicycle": _Runner(lambda: parallel_env(scenario=scenario)),
            "simple_spread": _Runner(
                lambda: simple_spread_v3.parallel_env(
                    N=N_AGENTS, continuous_actions=True, max_cycles=50
                )
            ),
            "paper": _Runner(lambda: parallel_env(scenario="paper")),
        },
        seconds,
    )
    rates["ratio"] = rates["unicycle"] / rates["simple_spread"]
    return rates


def _diff_drive_team_class() -> type:
    """Return :class:`DiffDriveTeam`, VMAS's ``BaseScenario`` of 3 differential drives
    (defined on first use: VMAS imports torch)."""
    import torch
    from vmas.simulator.core import Agent, World
    from vmas.simulator.dynamics.diff_drive import DiffDrive
    from vmas.simulator.scenario import BaseScenario
    from vmas.simulator.utils import ScenarioUtils

    class DiffDriveTeam(BaseScenario):
        """``n_agents`` VMAS agents with differential-drive dynamics (RK4), no collisions."""

        def make_world(self, batch_dim: int, device: torch.device, **kwargs: Any) -> Any:
            n = kwargs.pop("n_agents", N_AGENTS)
            ScenarioUtils.check_kwargs_consumed(kwargs)
            world = World(batch_dim, device)
            for i in range(n):
                world.add_agent(
                    Agent(
                        name=f"diff_drive_{i}",
                        collide=False,
                        u_range=[1, 1],
                        u_multiplier=[1, 1],
                        dynamics=DiffDrive(world, integration="rk4"),
                    )
                )
            return world

        def reset_world_at(self, env_index: int | None = None) -> None:
            ScenarioUtils.spawn_entities_randomly(
                self.world.agents, self.world, env_index, min_dist_between_entities=0.1,
                x_bounds=(-1, 1), y_bounds=(-1, 1),
            )  # fmt: skip

        def observation(self, agent: Any) -> torch.Tensor:
            return torch.cat([agent.state.pos, agent.state.vel, agent.state.rot], dim=-1)

        def reward(self, agent: Any) -> torch.Tensor:
            return -torch.linalg.vector_norm(agent.state.pos, dim=-1)

    return DiffDriveTeam


def vmas_stepper(n: int, scenario: str) -> Any:
    """Return ``step(k)`` of a VMAS env on CPU at ``n`` copies with 3 agents, random
    actions in [-1, 1] from a pool of 8: ``scenario`` ``"vmas_diffdrive"``
    (:class:`DiffDriveTeam`) or ``"vmas_diff_drive"`` (VMAS's ``diff_drive``)."""
    import torch
    import vmas

    which = _diff_drive_team_class()() if scenario == "vmas_diffdrive" else "diff_drive"
    env = vmas.make_env(
        scenario=which, num_envs=n, device="cpu", continuous_actions=True,
        n_agents=N_AGENTS, seed=0,
    )  # fmt: skip
    env.reset()
    g = torch.Generator().manual_seed(0)
    sizes = [env.get_agent_action_size(a) for a in env.agents]
    pool = [[torch.rand(n, s, generator=g) * 2 - 1 for s in sizes] for _ in range(8)]

    def step(k: int) -> None:  # no episode ends: VMAS's step alone, a generous comparison
        env.step(pool[k % 8])

    return step


def batched_env(n: int, seconds: float, repeats: int = 1, chunk: int = 10) -> dict[str, Any]:
    """Return env-steps/s of the unicycle batched env and of both VMAS scenarios at ``n``
    copies, each the median of ``repeats`` interleaved timings (alternating chunks of
    ``chunk`` steps until each ran ``seconds``), and the ratios ``ratio_<peer>`` (ours over
    the peer's): the median of the repeats' ratios, each repeat's in ``ratios_<peer>``."""
    from bench_tasks import interleaved_rates

    from activetrack.envs.batched import BatchedActiveTracking

    env = BatchedActiveTracking(n, scenario=unicycle_scenario())
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    pool = [rng.uniform(-1, 1, (n, 2 * N_AGENTS)).astype(np.float32) for _ in range(8)]
    steppers = {
        "unicycle": lambda k: env.step(pool[k % 8]),
        "vmas_diffdrive": vmas_stepper(n, "vmas_diffdrive"),
        "vmas_diff_drive": vmas_stepper(n, "vmas_diff_drive"),
    }
    runs = [interleaved_rates(steppers, n, seconds, chunk) for _ in range(repeats)]
    rates: dict[str, Any] = {k: float(np.median([r[k] for r in runs])) for k in steppers}
    for peer in ("vmas_diffdrive", "vmas_diff_drive"):
        ratios = [r["unicycle"] / r[peer] for r in runs]
        rates[f"ratios_{peer}"] = ratios
        rates[f"ratio_{peer}"] = float(np.median(ratios))
    return rates


def _check_out(path: Path | None) -> None:
    """Raise SystemExit unless ``path`` (if given) is a new file in an existing folder."""
    if path is None:
        return
    if not path.parent.is_dir():
        raise SystemExit(f"--out: no folder {path.parent}")
    if path.exists():
        raise SystemExit(f"--out: {path} exists (results are not overwritten)")


def main(argv: list[str] | None = None) -> dict:
    """Print every figure and ratio; return them as a dict (and write ``--out``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter timing (noisier)")
    parser.add_argument("--out", type=Path, help="write the figures to this new JSON file")
    parser.add_argument("--n", type=int, default=1024, help="copies of the batched env")
    parser.add_argument(
        "--repeats", type=int, default=5, help="interleaved timings of the batched env (median)"
    )
    args = parser.parse_args(argv)
    if args.n < 1:
        parser.error(f"--n must be a positive integer, got {args.n}")
    if args.repeats < 1:
        parser.error(f"--repeats must be a positive integer, got {args.repeats}")
    _check_out(args.out)
    import torch

    torch.set_num_threads(1)
    seconds = 1.0 if args.quick else 5.0
    out: dict = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
        "n_agents": N_AGENTS,
    }
    try:
        import vmas

        out["vmas"] = vmas.__version__
    except ImportError:
        pass

    print(f"1. single env, M = {N_AGENTS}, random actions, steps/s (interleaved)", flush=True)
    s = out["single"] = single_env(seconds)
    print(f"   unicycle          {s['unicycle']:10.0f}")
    print(f"   MPE2 simple_spread {s['simple_spread']:9.0f}  (N = {N_AGENTS})")
    print(f"   paper (disks)     {s['paper']:10.0f}")
    print(f"   ratio unicycle / simple_spread {s['ratio']:.2f} (target >= {SINGLE_TARGET:g})")

    print(f"2. batched env, N = {args.n}, env-steps/s (alternating chunks; median of "
          f"{args.repeats})", flush=True)  # fmt: skip
    b = out["batched"] = batched_env(args.n, seconds / 2.0, args.repeats)
    b["n"], b["repeats"] = args.n, args.repeats
    print(f"   unicycle          {b['unicycle']:10.0f}")
    print(f"   VMAS 3 DiffDrive  {b['vmas_diffdrive']:10.0f}  (RK4, no collisions)")
    print(f"   VMAS diff_drive   {b['vmas_diff_drive']:10.0f}  (n_agents = {N_AGENTS})")
    print(f"   ratio / 3 DiffDrive {b['ratio_vmas_diffdrive']:.2f}, / diff_drive "
          f"{b['ratio_vmas_diff_drive']:.2f} (medians; target >= {BATCHED_TARGET:g})")  # fmt: skip
    for peer in ("vmas_diffdrive", "vmas_diff_drive"):
        each = ", ".join(f"{r:.2f}" for r in b[f"ratios_{peer}"])
        print(f"   each repeat / {peer}: {each}")
    out["targets_met"] = {
        "single": s["ratio"] >= SINGLE_TARGET,
        "batched": min(b["ratio_vmas_diffdrive"], b["ratio_vmas_diff_drive"]) >= BATCHED_TARGET,
    }
    if args.out is not None:
        from activetrack.files import atomic_write_json

        atomic_write_json(args.out, out)
        print(f"wrote {args.out}")
    return out


if __name__ == "__main__":
    main()
