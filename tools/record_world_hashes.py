"""Record every preset's world hash over 60 seeded steps, single and batched.

The hash covers the world's whole visible state after each step (true and estimated
targets, covariances, sensors and fixes, traces, scores, counters, observations and the
global state), so a refactoring of the core that changes any bit of it changes the hash.
``tests/test_world_hashes.py`` compares with ``tests/data/world_hashes.json``.

    .venv/bin/python tools/record_world_hashes.py   # rewrites tests/data/world_hashes.json
    .venv/bin/python tools/record_world_hashes.py radio swarm   # adds (or re-records) those
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path

import numpy as np

from activetrack.world import World
from activetrack.world.scenarios import PRESETS

STEPS = 60
SEEDS = (3, 4, 5)
FIELDS = ("x_true", "x_hat", "P", "x_pred", "P_pred", "sensors", "fixes", "k", "trace",
          "score", "projected", "n_projected", "terminated", "truncated", "detected")  # fmt: skip
OUT = Path(__file__).resolve().parents[1] / "tests" / "data" / "world_hashes.json"


def world_hash(preset: str, batched: bool) -> str:
    """Return the sha256 of the world's state over ``STEPS`` steps of seeded random actions.

    Actions reach up to 1.5 times the reach, so the mending of infeasible moves is hashed too.
    """
    n = len(SEEDS) if batched else 1
    world = World(preset, num_copies=n)
    world.reset(seeds=list(SEEDS[:n]))
    rng = np.random.default_rng(12345)
    digest = hashlib.sha256()

    def absorb() -> None:
        for name in FIELDS:
            for k in range(world.n_targets) if name in ("x_true", "x_hat", "P", "x_pred",
                                                        "P_pred") else (None,):  # fmt: skip
                value = world.get(name) if k is None else world.get(name, target=k)
                digest.update(np.ascontiguousarray(value).tobytes())
        digest.update(np.ascontiguousarray(world.observe()).tobytes())
        digest.update(np.ascontiguousarray(world.state()).tobytes())
        if world.decentralized:  # a filter per robot (the radio tasks): theirs too
            for k in range(world.n_targets):
                for name in ("x_hat", "P", "x_pred", "P_pred"):
                    digest.update(np.ascontiguousarray(world.team_get(name, None, k)).tobytes())
            digest.update(np.ascontiguousarray(world.links()).tobytes())
            digest.update(np.ascontiguousarray(world.robot_scores()).tobytes())

    absorb()
    for _ in range(STEPS):
        if world.truncated.all() or world.terminated.all():
            break
        actions = rng.uniform(-1.5, 1.5, size=(n, world.n_sensors, 2))
        world.step_actions(actions if batched else actions[0])
        absorb()
    return digest.hexdigest()


def all_hashes() -> dict[str, dict[str, str]]:
    """Return ``{preset: {"single": hash, "batched": hash}}`` for every preset."""
    return {
        name: {"single": world_hash(name, False), "batched": world_hash(name, True)}
        for name in sorted(PRESETS)
    }


if __name__ == "__main__":
    hashes = all_hashes() if len(sys.argv) < 2 else {
        **json.loads(OUT.read_text()),
        **{name: {"single": world_hash(name, False), "batched": world_hash(name, True)}
           for name in sys.argv[1:]},
    }  # fmt: skip
    tmp = OUT.with_suffix(".tmp")
    tmp.write_text(json.dumps(hashes, indent=1, sort_keys=True) + "\n")
    os.replace(tmp, OUT)
    json.dump(hashes, sys.stdout, indent=1)
