"""A team's kinematics: the scenario's ``kinematics`` field, and the world's generic moves.

A scenario composes one :class:`~activetrack.kinematics.base.Kinematics` per sensor
(``Scenario.kinematics``: None, the paper's :class:`~activetrack.kinematics.disk.Disk` of
radius ``vmax_i dt`` for each sensor; one object for every sensor; or a tuple of M).
:func:`converted` checks the field once, at validation, and :func:`models` gives the M
objects. When every sensor moves by a built-in :class:`Disk` the world keeps its compiled
moves (:mod:`activetrack.kinematics.sensor_motion`, ``Scenario.capabilities``); otherwise
its move stage is :class:`TeamMotion`: each sensor's kinematics clips the wanted point (or
turns the action into one), and a move that ends inside a ``rho`` disk goes to the
kinematics' :meth:`~activetrack.kinematics.base.Kinematics.project`, the rule of the disk.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.kinematics import sensor_motion
from activetrack.kinematics.base import TOL, Kinematics
from activetrack.kinematics.disk import RADIUS_MAX, Disk
from activetrack.validation import FloatArray

_WHAT = (
    "kinematics must be None (a Disk of radius vmax dt per sensor), an "
    "activetrack.Kinematics instance (every sensor) or a tuple of one per sensor"
)


def converted(value: object, m: int) -> Any:
    """Return the scenario field ``kinematics`` checked: None, one instance or a tuple of
    ``m``; each new kinematics probed once (a ``ValueError`` naming the field)."""
    if value is None:
        return None
    if isinstance(value, Kinematics):
        _probe(value, "kinematics")
        return value
    if isinstance(value, (tuple, list)) and all(isinstance(v, Kinematics) for v in value):
        if len(value) != m:
            raise ValueError(f"{_WHAT} ({m}), got {len(value)} entries")
        for i, v in enumerate(value):
            _probe(v, f"kinematics[{i}]")
        return tuple(value)
    raise ValueError(f"{_WHAT}, got {value!r}")


def models(kinematics: Any, r: FloatArray) -> tuple[Kinematics, ...]:
    """Return one kinematics per sensor: ``Disk(r_i)`` when the field is None."""
    m = len(r)
    if kinematics is None:
        return tuple(Disk(float(x)) for x in r)
    if isinstance(kinematics, Kinematics):
        return (kinematics,) * m
    return tuple(kinematics)


def radii(kinematics: Any, m: int) -> FloatArray:
    """Return each sensor's :attr:`Kinematics.radius` (M,) (a field that is not None)."""
    return np.array([k.radius for k in models(kinematics, np.zeros(m))], dtype=np.float64)


def all_disks(team: tuple[Kinematics, ...]) -> bool:
    """Return whether every sensor moves by a built-in :class:`Disk` (compiled paths)."""
    return all(type(k) is Disk for k in team)


def actions_to_reach(
    kinematics: Any, points: FloatArray, sensors: FloatArray, r: FloatArray
) -> FloatArray:
    """Return the actions (..., M, 2) that move ``sensors`` to reachable ``points``: the
    disk's :func:`sensor_motion.actions_to_reach` (radius ``r``) when ``kinematics`` (a
    problem's) is None or all disks, else each sensor's :meth:`Kinematics.command`."""
    if kinematics is None or all_disks(kinematics):
        return sensor_motion.actions_to_reach(points, sensors, r)
    return TeamMotion(kinematics).commands(points, sensors)


def _probe(kin: Kinematics, field: str) -> None:
    """Raise ValueError naming ``field`` unless ``kin`` has a name, a radius in [0, 1e9],
    2-D action bounds, and a finite clip and apply of a probe point of the shape asked."""
    if not isinstance(kin.name, str) or not kin.name:
        raise ValueError(f"{field} {kin!r} must have a name (a non-empty string)")
    try:
        r = float(kin.radius)
        low, high = np.asarray(kin.action_low, float), np.asarray(kin.action_high, float)
        pos = np.array([[0.0, 0.0], [1.0, -2.0]])
        outs = (kin.clip(pos + 1e3 * max(r, 1.0), pos), kin.apply(np.zeros((2, 2)), pos))
    except Exception as exc:  # a bug of the new kinematics: said here, not deep in a step
        raise ValueError(f"{field} {kin!r} failed on a valid input: {exc!r}") from exc
    if not 0.0 <= r <= RADIUS_MAX:
        raise ValueError(f"{field} {kin!r}: radius must lie in [0, {RADIUS_MAX:g}], got {r!r}")
    if low.shape != (2,) or high.shape != (2,) or not np.all(low < high):
        raise ValueError(
            f"{field} {kin!r}: action_low and action_high must be 2 numbers each, low < high"
        )
    for out in outs:
        if np.shape(out) != (2, 2) or not np.all(np.isfinite(out)):
            raise ValueError(
                f"{field} {kin!r}: clip and apply must return finite points of the input's "
                f"shape (2, 2), got {out!r}"
            )


class TeamMotion:
    """The world's moves when a sensor's kinematics is not a built-in :class:`Disk`.

    :meth:`move_to` and :meth:`apply_actions` have the signatures and the rules of
    :func:`sensor_motion.move_to` and :func:`sensor_motion.apply_actions`, with each
    sensor's own kinematics: ``(next_positions, projected)`` from proposed positions or
    actions (..., M, 2), the sensors (..., M, 2), the predicted target(s) (..., 2) or
    (..., K, 2), and ``rho`` (..., M) (``r`` is each kinematics' radius, unused).
    """

    def __init__(self, team: tuple[Kinematics, ...]) -> None:
        self.team = team

    def of(self, move: Any) -> Any:
        """Return this team's move in place of the disk's ``move`` (the same kind)."""
        return self.move_to if move is sensor_motion.move_to else self.apply_actions

    def commands(self, points: FloatArray, sensors: FloatArray) -> FloatArray:
        """Return the actions (..., M, 2) that move ``sensors`` to reachable ``points``
        (..., M, 2), each sensor's :meth:`Kinematics.command` (what
        :func:`sensor_motion.actions_to_reach` does for the disk; imitation labels)."""
        points, sensors = np.asarray(points, np.float64), np.asarray(sensors, np.float64)
        out = np.empty(np.broadcast_shapes(points.shape, sensors.shape))
        for i, kin in enumerate(self.team):
            out[..., i, :] = kin.command(points[..., i, :], sensors[..., i, :])
        return out

    def move_to(self, positions, sensors, target_pred, r, rho):
        """Return ``(next_positions, projected)`` from proposed absolute positions."""
        return self._move(True, positions, sensors, target_pred, rho)

    def apply_actions(self, actions, sensors, target_pred, r, rho):
        """Return ``(next_positions, projected)`` from the agents' actions."""
        return self._move(False, actions, sensors, target_pred, rho)

    def _move(
        self, absolute: bool, x: FloatArray, sensors: FloatArray, where: FloatArray, rho: Any
    ) -> tuple[FloatArray, np.ndarray]:
        x, sensors = np.asarray(x, np.float64), np.asarray(sensors, np.float64)
        targets = where[..., None, :] if where.ndim == x.ndim - 1 else where  # (..., K, 2)
        rho = np.broadcast_to(np.asarray(rho, np.float64), x.shape[:-1])
        out = np.empty(x.shape)
        projected = np.zeros(x.shape[:-1], dtype=bool)
        for i, kin in enumerate(self.team):
            p = sensors[..., i, :]
            want = kin.clip(x[..., i, :], p) if absolute else kin.apply(x[..., i, :], p)
            if not np.all(np.isfinite(want)):  # a bug of the kinematics: said, not stored
                raise ValueError(
                    f"kinematics[{i}] {kin.name!r} ({type(kin).__name__}) returned NaN or "
                    f"inf from its {'clip' if absolute else 'apply'} on this step's positions"
                )
            out[..., i, :] = want
            if not kin.radius > 0.0:  # a sensor that cannot move stays, even inside
                continue
            e = want[..., None, :] - targets
            dist = np.hypot(e[..., 0], e[..., 1])  # (..., K)
            inside = np.any(dist < rho[..., i, None] * (1.0 - TOL), axis=-1)
            for idx in np.ndindex(inside.shape):  # (few: a move that ended inside)
                if not inside[idx]:
                    continue
                out[idx + (i,)] = kin.project(want[idx], p[idx], targets[idx], rho[idx + (i,)])
                projected[idx + (i,)] = True
            if not np.all(np.isfinite(out[..., i, :])):
                raise ValueError(
                    f"kinematics[{i}] {kin.name!r} ({type(kin).__name__}) returned NaN or "
                    "inf from its project (the move out of a rho disk) on this step"
                )
        return out, projected
