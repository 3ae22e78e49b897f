"""Reinforcement-learning environments for multi-robot active target tracking.

- :func:`parallel_env` / :func:`env`: the PettingZoo parallel and AEC games, one agent per
  sensor (:mod:`activetrack.envs.tracking_env`);
- :class:`CentralizedTrackingEnv`: the Gymnasium single-agent view, registered as
  ``activetrack/ActiveTracking-v0`` when this package is imported;
- :class:`BatchedActiveTracking`: N copies over a leading axis, a Gymnasium ``VectorEnv``
  (the id's ``vector_entry_point``: ``gymnasium.make_vec(ENV_ID, num_envs=N)``);
- :func:`policy_step`: step an env by an expert (positions) or a learned policy (actions);
- :func:`record_video`: an episode as a GIF/MP4.

All of them adapt the core's closed loop, :class:`activetrack.world.World`; the sensor
motion (:mod:`activetrack.kinematics.sensor_motion`: ``apply_actions``,
``actions_to_reach``) and the observation encoding (:mod:`activetrack.world.observation`)
live in the core too. Configuration is the core
:class:`activetrack.Scenario`: ``scenario="paper"`` or
``"homogeneous"`` plus any field override, e.g.
``parallel_env(scenario="homogeneous", n_sensors=8, rho=1.5)``.

The ids are registered by ``import activetrack`` already (:mod:`activetrack._registry`);
importing this package registers them again, idempotently, and the environment modules
load on first use of a name below (PEP 562). From a fresh interpreter
``gymnasium.make("activetrack:activetrack/ActiveTracking-v0")`` imports activetrack first.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .registration import ENV_ID, register_envs

if TYPE_CHECKING:
    from .batched import BatchedActiveTracking
    from .centralized import CentralizedTrackingEnv
    from .tracking_env import (
        TrackingAECEnv,
        TrackingParallelEnv,
        env,
        parallel_env,
        policy_step,
        raw_env,
    )
    from .video import record_video

_LAZY = {
    "BatchedActiveTracking": ".batched",
    "CentralizedTrackingEnv": ".centralized",
    "TrackingAECEnv": ".tracking_env",
    "TrackingParallelEnv": ".tracking_env",
    "env": ".tracking_env",
    "parallel_env": ".tracking_env",
    "policy_step": ".tracking_env",
    "raw_env": ".tracking_env",
    "record_video": ".video",
}

__all__ = [
    "BatchedActiveTracking",
    "ENV_ID",
    "CentralizedTrackingEnv",
    "TrackingAECEnv",
    "TrackingParallelEnv",
    "env",
    "parallel_env",
    "policy_step",
    "raw_env",
    "record_video",
    "register_envs",
]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)


register_envs()
