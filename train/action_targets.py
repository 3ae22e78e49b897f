"""What an imitation network predicts: the robot's command, or the point it should reach.

A robot's action is a command (a unicycle's forward speed and turn rate,
:class:`activetrack.kinematics.unicycle.Unicycle`). GSR's command is discontinuous in the
observation where the geometry of the command is singular: near a standstill the turn
rate of a short step is arbitrary (every turn rate reaches the sensor's own position at
zero speed), so two close states can carry opposite turn labels. The point GSR plans to
reach is continuous there. With :data:`POSITION` targets the network predicts that point
and the kinematics turns it into the command (:class:`PositionActions`):

- **label**: the planned next position ``p`` of a sensor at state ``(x, y, theta)``,
  relative to the sensor, in its heading frame, over its reach ``r``:
  ``u = R(-theta) (p - (x, y)) / r``, in the unit disk (``r`` is the longest step);
- **action**: the network's ``u`` (the saturated mean of
  :class:`activetrack.train.networks.TrackingPolicy`, in the unit disk) is the wanted
  point ``r u`` in the heading frame, that is from the state ``(0, 0, 0)``; its
  projection onto the reach set (:meth:`Kinematics.clip`) and the command that reaches
  the projection (:meth:`Kinematics.command`) are the action. A step and a reach set
  depend on the position and heading only through that frame (a rigid motion), so the
  conversion needs no part of the observation. Where the projection is the sensor's own
  position (a wanted point behind a robot that can stop), every turn rate reaches it at
  zero speed: the action turns toward the wanted point (the largest turn toward its
  side), so the robot does not freeze facing away.

On the paper's disks the point is the command already (the action is the step over the
reach, in the world frame, which for a disk is the heading frame), so a team of disks
keeps the command target. Supported: :class:`~activetrack.kinematics.disk.Disk` and
:class:`~activetrack.kinematics.unicycle.Unicycle` teams (a kinematics with more state,
a double integrator's velocity, would need it from the observation).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.kinematics.disk import Disk
from activetrack.kinematics.unicycle import Unicycle

#: The imitation targets: the env's command, or the point to reach (this module).
COMMAND, POSITION = "command", "position"
TARGETS = (COMMAND, POSITION)
#: A projection within this fraction of the reach from the position is a standstill.
STANDSTILL = 1e-12
#: Most sensors a policy file's head may describe (as the files' space sizes).
MAX_SENSORS = 65_536


def _rotate(d: np.ndarray, cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """Return the vectors ``d`` (..., 2) rotated by the angles of ``(cos, sin)`` (...)."""
    out = np.empty(np.broadcast_shapes(d.shape, cos.shape + (2,)))
    out[..., 0] = cos * d[..., 0] - sin * d[..., 1]
    out[..., 1] = sin * d[..., 0] + cos * d[..., 1]
    return out


class PositionActions:
    """A team's position targets: labels from planned points, actions from predicted ones.

    Args:
        models: each sensor's kinematics (M,), a :class:`Disk` or a :class:`Unicycle` with
            its ``dt`` bound (a scenario's ``kinematics_models``).
    """

    def __init__(self, models: Any) -> None:
        models = tuple(models)
        if not 1 <= len(models) <= MAX_SENSORS:
            raise ValueError(f"models must hold 1 to {MAX_SENSORS} kinematics, got {len(models)}")
        for k in models:
            if type(k) is not Disk and not isinstance(k, Unicycle):
                raise ValueError(
                    f"position targets support Disk and Unicycle kinematics, got {k!r}: "
                    f"use the {COMMAND!r} target"
                )
            k.radius  # noqa: B018 (a Unicycle without dt raises ValueError here)
        self.models = models
        self.radii = np.array([k.radius for k in models], dtype=np.float64)
        # Sensors with equal kinematics share one call of each method (a team is usually
        # one model: the projection's cost is mostly per call).
        self._groups: list[tuple[Any, np.ndarray]] = []
        for j, k in enumerate(models):
            for g, (kg, members) in enumerate(self._groups):
                if kg == k:
                    self._groups[g] = (kg, np.append(members, j))
                    break
            else:
                self._groups.append((k, np.array([j])))

    @classmethod
    def from_scenario(cls, scenario: Any) -> PositionActions | None:
        """Return the position targets of ``scenario``'s team, or None for a team of disks
        (whose commands are their points already)."""
        models = scenario.kinematics_models
        if all(type(k) is Disk for k in models):
            return None
        return cls(models)

    @property
    def n_sensors(self) -> int:
        """Return the team size M."""
        return len(self.models)

    # Labels ---------------------------------------------------------------------------
    def labels(self, points: np.ndarray, states: np.ndarray) -> np.ndarray:
        """Return the targets ``u`` (..., M, 2) of the planned ``points`` (..., M, 2) from
        the team's ``states`` (..., M, S): ``R(-theta) (p - position) / r`` (0 for a sensor
        of reach 0)."""
        points, states = np.asarray(points, np.float64), np.asarray(states, np.float64)
        d = points - states[..., :2]
        for j, k in enumerate(self.models):
            if isinstance(k, Unicycle):
                theta = states[..., j, 2]
                d[..., j, :] = _rotate(d[..., j, :], np.cos(theta), -np.sin(theta))
        r = self.radii
        return np.where(r[:, None] > 0.0, d / np.where(r > 0.0, r, 1.0)[:, None], 0.0)

    # Actions --------------------------------------------------------------------------
    def wanted_points(self, u: np.ndarray) -> np.ndarray:
        """Return the reachable points (N, 2), in each sensor's heading frame, nearest to
        the wanted ``r u`` (N, 2) (row ``i`` is sensor ``i mod M``)."""
        u = np.asarray(u, np.float64)
        idx = np.arange(u.shape[0]) % self.n_sensors
        out = np.empty_like(u)
        for k, members in self._groups:
            rows = np.isin(idx, members)
            if rows.any():
                out[rows] = k.clip(k.radius * u[rows], self._origin(k))
        return out

    def actions(self, u: np.ndarray) -> np.ndarray:
        """Return the env's actions (N, 2) for the network's targets ``u`` (N, 2): the
        command that reaches the projection of the wanted point ``r u`` onto the reach set
        (module docstring); row ``i`` is sensor ``i mod M`` (a team's rows, copy after
        copy)."""
        u = np.asarray(u, np.float64)
        if u.ndim != 2 or u.shape[1] != 2 or u.shape[0] % self.n_sensors:
            raise ValueError(
                f"u must have shape (N, 2) with N a multiple of the team size "
                f"{self.n_sensors}, got {u.shape}"
            )
        pts = self.wanted_points(u)
        idx = np.arange(u.shape[0]) % self.n_sensors
        out = np.empty_like(u)
        for k, members in self._groups:
            rows = np.isin(idx, members)
            if not rows.any():
                continue
            a = k.command(pts[rows], self._origin(k))
            if isinstance(k, Unicycle) and k.v_min == 0.0 and k.w_max > 0.0:
                # A standstill: every turn rate reaches it; turn toward the wanted point.
                still = np.hypot(*pts[rows].T) <= STANDSTILL * k.radius
                if still.any():
                    want = u[rows][still]
                    turn = np.where(want[:, 1] < 0.0, -1.0, 1.0)  # (straight behind: left)
                    a[still, 0] = -1.0  # v = v_min = 0
                    a[still, 1] = np.where(np.any(want != 0.0, axis=1), turn, 0.0)
            out[rows] = a
        return out

    @staticmethod
    def _origin(k: Any) -> np.ndarray:
        """Return the state at the origin facing +x (the heading frame's)."""
        return np.zeros(k.state_dim)

    # Records ---------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Return the team's kinematics as JSON values (for a policy file)."""
        sensors = []
        for k in self.models:
            if isinstance(k, Unicycle):
                sensors.append(
                    {"name": "unicycle", "v_min": k.v_min, "v_max": k.v_max, "w_max": k.w_max,
                     "dt": k.dt}
                )  # fmt: skip
            else:
                sensors.append({"name": "disk", "radius": k.radius})
        return {"target": POSITION, "frame": "heading", "sensors": sensors}

    @classmethod
    def from_dict(cls, d: Any) -> PositionActions:
        """Return the targets saved by :meth:`to_dict` (ValueError naming what is wrong)."""
        if not isinstance(d, dict) or d.get("target") != POSITION or d.get("frame") != "heading":
            raise ValueError(
                "action_target must be an object with target 'position', frame 'heading' and "
                "sensors"
            )
        sensors = d.get("sensors")
        if not isinstance(sensors, list) or not 1 <= len(sensors) <= MAX_SENSORS:
            raise ValueError(f"action_target: sensors must be a list of 1 to {MAX_SENSORS}")
        keys = {"unicycle": ("v_min", "v_max", "w_max", "dt"), "disk": ("radius",)}
        models = []
        for s in sensors:
            name = s.get("name") if isinstance(s, dict) else None
            if name not in keys or set(s) != {"name", *keys[name]}:
                raise ValueError(
                    "action_target: each sensor must be {'name': 'unicycle', 'v_min', "
                    f"'v_max', 'w_max', 'dt'}} or {{'name': 'disk', 'radius'}}, got {s!r}"
                )
            if name == "unicycle":
                if s["dt"] is None:
                    raise ValueError("action_target: a unicycle's dt must be a number")
                models.append(Unicycle(s["v_min"], s["v_max"], s["w_max"], s["dt"]))
            else:
                models.append(Disk(s["radius"]))
        return cls(models)

    def __repr__(self) -> str:
        return f"PositionActions({list(self.models)!r})"


def check_target(value: Any) -> str:
    """Return ``value`` if it is one of :data:`TARGETS`, else raise ValueError naming
    ``target``."""
    if not isinstance(value, str) or value not in TARGETS:
        raise ValueError(f"target must be one of {list(TARGETS)}, got {value!r}")
    return value
