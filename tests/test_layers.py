"""The layers depend one way, core <- envs <- baselines <- train, and load only what they need.

Each layer is imported in a fresh interpreter (so nothing an earlier test imported hides
a dependency) and the modules it pulled into ``sys.modules`` are compared with the set
the layering allows.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

LAYERS = ["activetrack", "activetrack.envs", "activetrack.baselines", "activetrack.train"]
HEAVY = ["gymnasium", "pettingzoo", "torch", "matplotlib", "scipy.stats", "stable_baselines3",
         "numba"]  # fmt: skip

# What importing each layer must not load: the layers above it, and the frameworks it
# does not use at import time (torch only from activetrack.train on; numba in no layer:
# it loads with the first kernel call, activetrack._jit).
FORBIDDEN = {
    "activetrack": {*LAYERS[1:], *HEAVY},
    "activetrack.envs": {"activetrack.baselines", "activetrack.train", "torch",
                         "stable_baselines3", "matplotlib", "scipy.stats", "numba"},
    "activetrack.baselines": {"activetrack.train", "torch", "stable_baselines3", "matplotlib",
                              "numba"},
    "activetrack.train": {"numba"},
}  # fmt: skip


def loaded_after_import(module: str, tmp_path) -> set[str]:
    """Return which of LAYERS and HEAVY are in ``sys.modules`` after importing ``module``."""
    code = (
        "import importlib, json, sys\n"
        f"importlib.import_module({module!r})\n"
        f"print(json.dumps([m for m in {LAYERS + HEAVY!r} if m in sys.modules]))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path
    )
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


@pytest.mark.parametrize("module", LAYERS)
def test_a_layer_loads_no_layer_above_it_nor_unused_frameworks(module, tmp_path):
    loaded = loaded_after_import(module, tmp_path)
    assert "activetrack" in loaded and module in loaded  # the probe itself works
    assert loaded & FORBIDDEN[module] == set(), f"import {module} pulled in {sorted(loaded)}"


def test_envs_import_registers_with_gymnasium_and_pettingzoo(tmp_path):
    # The envs layer is the one that loads the frameworks (registration), not the core.
    assert {"gymnasium", "pettingzoo"} <= loaded_after_import("activetrack.envs", tmp_path)


def test_baselines_import_leaves_scipy_stats_unloaded(tmp_path):
    assert "scipy.stats" not in loaded_after_import("activetrack.baselines", tmp_path)
