"""Sensor motion of the environments: the core's :mod:`activetrack.kinematics.sensor_motion`.

Kept as an import path for existing code; the rule lives in the core.
"""

from activetrack.kinematics.sensor_motion import TOL, actions_to_reach, apply_actions, move_to

__all__ = ["TOL", "actions_to_reach", "apply_actions", "move_to"]
