"""The agents' action spaces, from each sensor's kinematics (``Scenario.kinematics_models``).

An agent's action is what its :class:`activetrack.Kinematics` turns into a wanted point
(:meth:`~activetrack.Kinematics.apply`); its bounds are the kinematics' ``action_low`` and
``action_high``. For the paper's :class:`activetrack.Disk` that is today's
``Box(-1, 1, (2,), float32)``, the displacement as a fraction of the reach.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from activetrack.world.scenarios import Scenario


def bounds(sc: Scenario) -> tuple[np.ndarray, np.ndarray]:
    """Return every agent's action bounds ``(low, high)``, float32 (M, 2)."""
    team = sc.kinematics_models
    low = np.array([k.action_low for k in team], dtype=np.float32).reshape(len(team), 2)
    high = np.array([k.action_high for k in team], dtype=np.float32).reshape(len(team), 2)
    return low, high


def agent_spaces(sc: Scenario, agents: list[str]) -> dict[str, spaces.Box]:
    """Return one action space per agent (a new object each: PettingZoo seeds them apart)."""
    if sc.kinematics is None:  # the paper's disks: today's space, exactly
        return {a: spaces.Box(-1.0, 1.0, (2,), dtype=np.float32) for a in agents}
    low, high = bounds(sc)
    return {a: spaces.Box(low[i], high[i], dtype=np.float32) for i, a in enumerate(agents)}


def joint_space(sc: Scenario) -> spaces.Box:
    """Return the joint action space ``(2M,)``: the agents' actions concatenated."""
    if sc.kinematics is None:
        return spaces.Box(-1.0, 1.0, (2 * sc.n_sensors,), dtype=np.float32)
    low, high = bounds(sc)
    return spaces.Box(low.ravel(), high.ravel(), dtype=np.float32)
