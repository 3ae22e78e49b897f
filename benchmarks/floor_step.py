"""What a batched step's random draws and bearings cost at N copies, beside the whole step
and VMAS's: how much of "twice VMAS" (issue 17) is left for everything else.

Per copy-step, one thread, ``paper`` (M = 3 sensors, a 4-state target), all in one run:

- VMAS ``simple_spread`` (3 agents, CPU, one torch thread) and the batched env's whole
  step, random actions, as ``throughput.py`` measures them (the faster of two runs);
  twice VMAS's rate is half its time a copy-step;
- the step's ``n + 2M`` standard normals drawn as the world draws them: each copy from its
  own ``np.random.Generator`` (what makes copy ``i`` of a batch equal a single env seeded
  with seed ``i``), a block of ``World.noise_block`` steps a call;
- the same normals from one generator for every copy (what a shared stream would cost);
- the ``M`` bearings' ``atan2`` a step's measurements need, compiled, nothing else around
  them (the EKF's innovations need ``M`` more, at the predicted target);
- two costs of copies that equal single envs after early ends and of the single env's
  infos: saving each copy's generator state before its noise block (one save a block of
  ``min(noise_block, n_steps)`` steps), and the infos' ``position_error`` (``World``'s).

Usage: ``OPENBLAS_NUM_THREADS=1 python benchmarks/floor_step.py [--n 8192] [--steps 24]``
(VMAS from the ``[bench]`` extra).
"""

from __future__ import annotations

import argparse
import math
import time

import numba
import numpy as np
from throughput import batched_env, vmas_env

from activetrack.world import World


@numba.njit(cache=False)
def _bearings(dx: np.ndarray, dy: np.ndarray) -> float:
    """Return the sum of ``atan2(dy, dx)`` over every entry (the sum keeps the calls)."""
    total = 0.0
    for b in range(dx.shape[0]):
        for i in range(dx.shape[1]):
            total += math.atan2(dy[b, i], dx[b, i])
    return total


def _best(fn, repeats: int) -> float:
    """Return the least of ``repeats`` timings of ``fn()`` in seconds."""
    out = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        out = min(out, time.perf_counter() - start)
    return out


def floor(n: int, steps: int, repeats: int = 5) -> dict[str, float]:
    """Return microseconds a copy-step of each part (see the module docstring)."""
    world = World("paper", n)
    world.reset(seeds=list(range(n)))
    block, draws = world.noise_block, world._n_noise  # noqa: SLF001 (the world's own sizes)
    m = world.params.rho.shape[-1]
    rngs = [np.random.default_rng(i) for i in range(n)]
    shared = np.random.default_rng(0)
    xy = np.random.default_rng(1).normal(size=(2, n, m)) * 20.0
    _bearings(xy[0], xy[1])  # compile
    per = 1e6 / n
    return {
        "vmas_step": 1e6 / max(vmas_env(n, steps) for _ in range(2)),
        "env_step": 1e6 / max(batched_env(n, steps) for _ in range(2)),
        "normals_per_copy": per / block * _best(
            lambda: [g.standard_normal((block, draws)) for g in rngs], repeats),
        "normals_shared": per / block * _best(
            lambda: shared.standard_normal((n * block, draws)), repeats),
        "bearings": per * _best(lambda: _bearings(xy[0], xy[1]), repeats),
        "state_saves": per / min(block, world.episode_steps) * _best(
            lambda: [g.bit_generator.state for g in rngs], repeats),
        "position_error": per * _best(world.position_error, repeats),
        "normals_a_step": float(draws),
    }  # fmt: skip


def main(argv: list[str] | None = None) -> dict[str, float]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=8192, help="copies")
    ap.add_argument("--steps", type=int, default=24, help="steps timed for the two envs")
    args = ap.parse_args(argv)
    import torch  # VMAS's: one thread, as throughput.py

    torch.set_num_threads(1)
    f = floor(args.n, args.steps)
    budget = 0.5 * f["vmas_step"]
    fixed = f["normals_per_copy"] + f["bearings"]
    print(f"N = {args.n}, us a copy-step")
    print(f"  VMAS simple_spread step           {f['vmas_step']:.3f}  (twice VMAS: {budget:.3f})")
    print(f"  activetrack batched step          {f['env_step']:.3f}")
    print(
        f"  {f['normals_a_step']:.0f} normals, each copy's generator   {f['normals_per_copy']:.3f}"
    )
    print(f"  the same, one shared generator    {f['normals_shared']:.3f}")
    print(f"  the bearings' atan2               {f['bearings']:.3f}")
    print(f"  draws + bearings: {fixed:.3f} = {100 * fixed / budget:.0f}% of twice VMAS's budget")
    print(f"  generator state saves             {f['state_saves']:.3f}")
    print(f"  the infos' position_error         {f['position_error']:.3f}")
    return f


if __name__ == "__main__":
    main()
