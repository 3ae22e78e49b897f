"""Training defaults shared by the imitation and PPO scripts: threads, seeding, field checks.

On a small CPU machine torch's intra-op thread pool fights the environment loop for the
cores (the README gives the measurement), so every training entry point calls
:func:`configure_torch` first, which sets one thread unless told otherwise. The
``check_*`` functions validate the fields of the configuration dataclasses.
"""

from __future__ import annotations

import random

import numpy as np
import torch

# The field checks of the configuration dataclasses live in the core (the planners'
# settings use them too); re-exported here for the training modules.
from activetrack.validation import check_bool as check_bool
from activetrack.validation import check_choice as check_choice
from activetrack.validation import check_float as check_float
from activetrack.validation import check_int as check_int

DEFAULT_THREADS = 1
#: Most torch threads accepted (``--threads``).
MAX_THREADS = 1024


def configure_torch(num_threads: int = DEFAULT_THREADS) -> int:
    """Set torch's intra-op thread count (default 1) and return the count now in effect."""
    torch.set_num_threads(check_int("threads", num_threads, 1, MAX_THREADS))
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
