"""Every preset's world, single and batched, is unchanged bit for bit over 60 seeded steps.

``tests/data/world_hashes.json`` was recorded by ``tools/record_world_hashes.py`` (one
copy of the computation, imported here) before the concepts redesign: a refactoring of
the core must reproduce it exactly. The hash covers targets, estimates, covariances,
sensors, fixes, traces, scores, counters, observations and the global state after every
step of random actions that reach up to 1.5 times the reach (so mended moves are in it).
Compiled kernels only: plain Python rounds some operations differently.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location(
    "record_world_hashes", REPO / "tools" / "record_world_hashes.py"
)
record = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(record)
RECORDED = json.loads(record.OUT.read_text())


def test_every_preset_is_recorded() -> None:
    from activetrack.world.scenarios import PRESETS

    assert sorted(RECORDED) == sorted(PRESETS)


@pytest.mark.parametrize("batched", [False, True], ids=["single", "batched"])
@pytest.mark.parametrize("preset", sorted(RECORDED))
def test_world_hash_unchanged(preset: str, batched: bool) -> None:
    kind = "batched" if batched else "single"
    assert record.world_hash(preset, batched) == RECORDED[preset][kind]
