"""Training defaults shared by the imitation and PPO scripts: threads, seeding, field checks.

On a small CPU machine torch's intra-op thread pool fights the environment loop for the
cores (the README gives the measurement), so every training entry point calls
:func:`configure_torch` first, which sets one thread unless told otherwise. The
``check_*`` functions validate the fields of the configuration dataclasses.
"""

from __future__ import annotations

import math
import random
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

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


# Field checks of the configuration dataclasses: each returns the value converted to its
# type or raises a ValueError naming the field and the allowed range.
def check_int(name: str, value: Any, low: int, high: int | None = None) -> int:
    """Return ``value`` as an int in ``[low, high]`` (integral floats accepted, bools not)."""
    bound = f">= {low}" if high is None else f"in [{low}, {high}]"
    ok = isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
    if isinstance(value, (float, np.floating)) and math.isfinite(value) and value == int(value):
        ok, value = True, int(value)
    if not ok or value < low or (high is not None and value > high):
        raise ValueError(f"{name} must be an integer {bound}, got {value!r}")
    return int(value)


def check_float(
    name: str,
    value: Any,
    low: float = -math.inf,
    high: float = math.inf,
    *,
    low_open: bool = False,
    high_open: bool = False,
) -> float:
    """Return ``value`` as a finite float in the interval from ``low`` to ``high``.

    ``low_open``/``high_open`` exclude the bound itself (e.g. ``> 0``).
    """
    if math.isinf(low) and math.isinf(high):
        bound = "finite"
    elif math.isinf(high):
        bound = f"finite and {'>' if low_open else '>='} {low:g}"
    elif math.isinf(low):
        bound = f"finite and {'<' if high_open else '<='} {high:g}"
    else:
        bound = f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    ok = isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)
    )
    if ok:
        value = float(value)
        ok = math.isfinite(value) and (value > low if low_open else value >= low)
        ok = ok and (value < high if high_open else value <= high)
    if not ok:
        raise ValueError(f"{name} must be a number {bound}, got {value!r}")
    return value


def check_bool(name: str, value: Any) -> bool:
    """Return ``value`` if it is a bool (numpy's included) or raise a ValueError."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be True or False, got {value!r}")
    return bool(value)


def check_choice(name: str, value: Any, choices: Sequence[str]) -> str:
    """Return ``value`` if it is one of ``choices`` or raise a ValueError listing them."""
    if not isinstance(value, str) or value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
    return value
