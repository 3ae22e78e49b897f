"""The paper's kinematics: a disk of radius ``r = vmax dt`` (eq. 13-16), :class:`Disk`.

Its methods are this package's functions (compiled where the world uses them), so a
scenario whose sensors all move by a :class:`Disk` keeps the world's compiled paths bit
for bit (``Scenario.capabilities.disk_kinematics``):

- :meth:`Disk.clip` and :meth:`Disk.apply` are the kernels of
  :func:`activetrack.kinematics.sensor_motion.move_to` and
  :func:`~activetrack.kinematics.sensor_motion.apply_actions` before the ``rho`` rule (a
  displacement, or an action, longer than the radius, or 1, scaled onto the circle);
- :meth:`Disk.command` is :func:`~activetrack.kinematics.sensor_motion.actions_to_reach`;
- :meth:`Disk.project`, :meth:`Disk.boundary` and :meth:`Disk.sample` are
  :func:`activetrack.kinematics.feasible_set.project`,
  :func:`~activetrack.kinematics.feasible_set.boundary_arcs` (discretized) and
  :func:`~activetrack.kinematics.feasible_set.sample_interior` (exact circle geometry).
"""

from __future__ import annotations

import numpy as np

from activetrack.kinematics import feasible_set, geometry, sensor_motion
from activetrack.kinematics.base import TOL, Kinematics
from activetrack.validation import FloatArray

#: The largest radius accepted (the scenario's length limit).
RADIUS_MAX = 1e9


def _pairs(points: FloatArray, position: FloatArray) -> tuple[FloatArray, FloatArray, tuple]:
    """Return ``points`` and ``position`` broadcast to one shape (..., 1, 2) (a team of one
    sensor, the shape of the package's functions) and that shape's leading axes."""
    points, position = np.asarray(points, np.float64), np.asarray(position, np.float64)
    shape = np.broadcast_shapes(points.shape, position.shape)
    lead = shape[:-1]
    return (
        np.broadcast_to(points, shape).reshape(*lead, 1, 2),
        np.broadcast_to(position, shape).reshape(*lead, 1, 2),
        lead,
    )


class Disk(Kinematics):
    """Every point within ``radius`` of the sensor (the paper's reach ``r = vmax dt``).

    Args:
        radius: the reach per step, a real number in ``[0, 1e9]`` (0: the sensor stays).
    """

    name = "disk"

    def __init__(self, radius: float) -> None:
        if isinstance(radius, (bool, np.bool_)) or not isinstance(
            radius, (int, float, np.integer, np.floating)
        ):
            raise ValueError(f"radius must be a real number in [0, {RADIUS_MAX:g}], got {radius!r}")
        if not 0.0 <= float(radius) <= RADIUS_MAX:
            raise ValueError(f"radius must be a real number in [0, {RADIUS_MAX:g}], got {radius!r}")
        self._r = float(radius)

    @property
    def radius(self) -> float:
        """Return the disk's radius, the reach per step."""
        return self._r

    def __eq__(self, other: object) -> bool:
        return type(other) is Disk and other._r == self._r

    def __hash__(self) -> int:
        return hash(("Disk", self._r))

    def reaches(self, points: FloatArray, position: FloatArray) -> np.ndarray:
        """Return whether ``|points - position| <= radius (1 + TOL)``."""
        d = np.asarray(points, np.float64) - np.asarray(position, np.float64)
        return np.hypot(d[..., 0], d[..., 1]) <= self._r * (1.0 + TOL)

    def clip(self, wanted: FloatArray, position: FloatArray) -> FloatArray:
        """Return ``wanted``, or its displacement scaled onto the circle when longer than
        ``radius (1 + TOL)`` (the world's rule, :func:`sensor_motion.move_to`)."""
        q, p, lead = _pairs(wanted, position)
        return sensor_motion._moves(q, p, self._r, True).reshape(*lead, 2)

    def apply(self, actions: FloatArray, position: FloatArray) -> FloatArray:
        """Return ``position + radius a``, an action longer than 1 first scaled onto the unit
        disk (:func:`sensor_motion.apply_actions` before the ``rho`` rule)."""
        a, p, lead = _pairs(actions, position)
        return sensor_motion._moves(a, p, self._r, False).reshape(*lead, 2)

    def command(self, points: FloatArray, position: FloatArray) -> FloatArray:
        """Return :func:`sensor_motion.actions_to_reach` of ``points`` (bit-exact round trip
        through :meth:`apply` whenever a float action can give it)."""
        q, p, lead = _pairs(points, position)
        return sensor_motion.actions_to_reach(q, p, self._r).reshape(*lead, 2)

    def reach_boundary(self, position: FloatArray, spacing: float) -> FloatArray:
        """Return points of the circle of radius ``radius`` around ``position``."""
        if not self._r > 0.0:
            return np.empty((0, 2))
        arc = geometry.Arc(tuple(np.asarray(position, np.float64).reshape(2)), self._r, -np.pi,
                           np.pi)  # fmt: skip
        return geometry.discretize([arc], spacing)

    def boundary(
        self, position: FloatArray, targets: FloatArray, rho: float, spacing: float
    ) -> FloatArray:
        """Return points of :func:`feasible_set.boundary_arcs`, at most ``spacing`` apart."""
        arcs = feasible_set.boundary_arcs(position, self._r, targets, rho)
        return geometry.discretize(arcs, spacing)

    def sample(
        self,
        position: FloatArray,
        targets: FloatArray,
        rho: float,
        rng: np.random.Generator,
        n: int,
    ) -> FloatArray:
        """Return :func:`feasible_set.sample_interior` (``n`` points uniform in ``F``)."""
        return feasible_set.sample_interior(position, self._r, targets, rho, rng, n)

    def project(
        self, wanted: FloatArray, position: FloatArray, targets: FloatArray, rho: float
    ) -> FloatArray:
        """Return :func:`feasible_set.project`: the point of ``F`` nearest to ``wanted``
        (exact circle geometry; its fallback when ``F`` is empty)."""
        position = np.asarray(position, np.float64).reshape(2)
        if not self._r > 0.0:
            return position.copy()
        targets = np.asarray(targets, np.float64).reshape(-1, 2)
        return feasible_set.project(np.asarray(wanted, np.float64).reshape(2), position,
                                    self._r, targets, rho)  # fmt: skip

    def __repr__(self) -> str:
        return f"Disk({self._r!r})"
