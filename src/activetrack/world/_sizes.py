"""How much memory a world takes: checked before anything is allocated."""

from __future__ import annotations

#: Most bytes a world's arrays may take (:func:`world_bytes`): 4 GiB, a sixth of this
#: project's 24 GiB test machine, so a few worlds run side by side. A world beyond it is
#: refused at construction (ValueError naming the sizes), before anything is allocated.
WORLD_BYTES_MAX = 4 * 2**30


def world_bytes(num_copies: int, noise_block: int, n_sensors: int, n_targets: int,
                state_dim: int) -> int:  # fmt: skip
    """Return an upper estimate of the bytes of a world's arrays (float64): per copy, a
    noise block (``noise_block`` steps of every normal a step draws), the per-sensor and
    per-target state, and the observation's features, whose pairwise sensor terms grow as
    M^2 and M^2 K; checked above tracemalloc's peak over a batched env's construction,
    reset and step (tests/envs/test_batched.py)."""
    m, k, n = n_sensors, n_targets, state_dim
    n_noise = k * n + 2 * m * k + 2 * m + m * k
    per_copy = noise_block * n_noise + 24 * m * m + 3 * m * m * k + 64 * m * k + 8 * k * n * n
    return 8 * num_copies * per_copy
