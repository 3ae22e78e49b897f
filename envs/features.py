"""Observation and global-state encoding: the core's :mod:`activetrack.world.observation`.

Kept as an import path for existing code; the encoding lives in the core, where
:meth:`activetrack.world.World.observe` assembles it.
"""

from activetrack.world.observation import (
    SENSOR_DIM,
    TARGET_DIM,
    cyclic_order,
    decode_sensors,
    decode_target,
    global_state,
    length_scale,
    obs_dim,
    observation_bounds,
    observations,
    sensor_constants,
    sensor_features,
    state_bounds,
    state_dim,
    target_features,
)

__all__ = [
    "SENSOR_DIM",
    "TARGET_DIM",
    "cyclic_order",
    "decode_sensors",
    "decode_target",
    "global_state",
    "length_scale",
    "obs_dim",
    "observation_bounds",
    "observations",
    "sensor_constants",
    "sensor_features",
    "state_bounds",
    "state_dim",
    "target_features",
]
