"""Training defaults shared by the imitation and PPO scripts: threads, seeding, devices.

This machine class (2 CPU cores, no GPU) is the reference: torch's intra-op thread pool
fights the environment loop for the cores, and with two threads PPO ran 16x slower under
load. Every training entry point therefore calls :func:`configure_torch` first, which sets
one thread unless told otherwise.
"""

from __future__ import annotations

import random

import numpy as np
import torch

DEFAULT_THREADS = 1


def configure_torch(num_threads: int = DEFAULT_THREADS) -> int:
    """Set torch's intra-op thread count (default 1) and return the count now in effect."""
    torch.set_num_threads(num_threads)
    return torch.get_num_threads()


def seed_everything(seed: int) -> np.random.Generator:
    """Seed python, numpy's global state and torch; return a fresh numpy generator for ``seed``."""
    random.seed(seed)
    np.random.seed(seed % 2**32)  # noqa: NPY002 (SB3 and torch code draw from the global state)
    torch.manual_seed(seed)
    return np.random.default_rng(seed)


def params_vector(module: torch.nn.Module) -> np.ndarray:
    """Return all parameters of ``module`` flattened into one float64 array (for comparisons)."""
    with torch.no_grad():
        return np.concatenate(
            [p.detach().cpu().double().reshape(-1).numpy() for p in module.parameters()]
        )
