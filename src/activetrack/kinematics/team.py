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

A team's *states* (..., M, S) stack each sensor's state (``S`` the largest
``state_dim``; sensor i's is ``states[..., i, :state_dim_i]``, the rest zero): the
position first, then what its kinematics carries beyond it (a heading, a velocity). After
a move the state beyond the position is :meth:`Kinematics.advance` of the agent's action
when the move is the action's, else of :meth:`Kinematics.command` of the point the sensor
went to (a clipped or projected move); its position is that point, exactly.
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


def converted(value: object, m: int, dt: float | None = None) -> Any:
    """Return the scenario field ``kinematics`` checked: None, one instance or a tuple of
    ``m``, each bound to the step ``dt`` (:meth:`Kinematics.bind`; None: as given) and
    probed once (a ``ValueError`` naming the field)."""
    if value is None:
        return None
    if isinstance(value, Kinematics):
        value = value if dt is None else value.bind(dt)
        _probe(value, "kinematics")
        return value
    if isinstance(value, (tuple, list)) and all(isinstance(v, Kinematics) for v in value):
        if len(value) != m:
            raise ValueError(f"{_WHAT} ({m}), got {len(value)} entries")
        value = tuple(value) if dt is None else tuple(v.bind(dt) for v in value)
        for i, v in enumerate(value):
            _probe(v, f"kinematics[{i}]")
        return value
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
    problem's) is None or all disks, else each sensor's :meth:`Kinematics.command`
    (``sensors`` then the team's states (..., M, S), or positions when S is 2)."""
    if kinematics is None or all_disks(kinematics):
        return sensor_motion.actions_to_reach(points, sensors, r)
    return TeamMotion(kinematics).commands(points, sensors)


def state_of(kin: Kinematics, states: FloatArray) -> FloatArray:
    """Return one sensor's state (..., ``kin.state_dim``) from a team's states row(s)
    (..., S) (or a position (..., 2) when ``kin.state_dim`` is 2)."""
    return np.asarray(states, np.float64)[..., : kin.state_dim]


def _probe(kin: Kinematics, field: str) -> None:
    """Raise ValueError naming ``field`` unless ``kin`` has a name, a radius in [0, 1e9],
    2-D action bounds, and a finite clip and apply of a probe point of the shape asked."""
    if not isinstance(kin.name, str) or not kin.name:
        raise ValueError(f"{field} {kin!r} must have a name (a non-empty string)")
    try:
        r = float(kin.radius)
        low, high = np.asarray(kin.action_low, float), np.asarray(kin.action_high, float)
        dim, nf = kin.state_dim, kin.n_features
        if isinstance(dim, bool) or not isinstance(dim, (int, np.integer)) or dim < 2:
            raise ValueError(f"state_dim must be an integer >= 2, got {dim!r}")
        if isinstance(nf, bool) or not isinstance(nf, (int, np.integer)) or nf < 0:
            raise ValueError(f"n_features must be an integer >= 0, got {nf!r}")
        pos = np.zeros((2, int(dim)))
        pos[1, :2] = (1.0, -2.0)
        outs = (kin.clip(pos[:, :2] + 1e3 * max(r, 1.0), pos), kin.apply(np.zeros((2, 2)), pos))
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
        #: S, the team's state size (the largest ``state_dim``), and F, the most features.
        self.state_dim = max(int(k.state_dim) for k in team)
        self.n_features = max(int(k.n_features) for k in team)
        #: The one kinematics of every sensor (equal by value), else None: then a step's
        #: moves and features are one call for the whole team (:meth:`_move_shared`), not
        #: one per sensor (the same numbers: the methods work row by row).
        self.shared = team[0] if all(k == team[0] for k in team) else None
        #: The shared kinematics' one-copy step (:meth:`activetrack.Unicycle.team_step_one`)
        #: or None: a single env's step without the batched path's reshaping.
        self._step_one = getattr(self.shared, "team_step_one", None)

    def states(self, positions: FloatArray, motion: FloatArray | None) -> FloatArray:
        """Return the team's states (..., M, S): ``positions`` (..., M, 2) then ``motion``
        (..., M, S - 2), the states beyond the positions (None when S is 2)."""
        positions = np.asarray(positions, np.float64)
        if self.state_dim == 2 or motion is None:
            return positions
        return np.concatenate([positions, np.asarray(motion, np.float64)], -1)

    def initial(self, positions: FloatArray, toward: FloatArray) -> FloatArray:
        """Return the team's states (..., M, S) at a reset: each sensor's
        :meth:`Kinematics.initial_state` at ``positions`` (..., M, 2), facing ``toward`` (2,)."""
        positions = np.asarray(positions, np.float64)
        out = np.zeros(positions.shape[:-1] + (self.state_dim,))
        for i, kin in enumerate(self.team):
            p = positions[..., i, :]
            out[..., i, : kin.state_dim] = kin.initial_state(p, np.broadcast_to(toward, p.shape))
        return out

    def features(self, states: FloatArray) -> FloatArray:
        """Return every sensor's :meth:`Kinematics.features` (..., M, F), zero-padded."""
        states = np.asarray(states, np.float64)
        shared = self.shared
        if shared is not None and shared.n_features == self.n_features:
            return np.asarray(shared.features(state_of(shared, states)), np.float64)
        out = np.zeros(states.shape[:-1] + (self.n_features,))
        for i, kin in enumerate(self.team):
            if kin.n_features:
                out[..., i, : kin.n_features] = kin.features(state_of(kin, states[..., i, :]))
        return out

    def of(self, move: Any) -> Any:
        """Return this team's move in place of the disk's ``move`` (the same kind)."""
        return self.move_to if move is sensor_motion.move_to else self.apply_actions

    def commands(self, points: FloatArray, sensors: FloatArray) -> FloatArray:
        """Return the actions (..., M, 2) that move ``sensors`` to reachable ``points``
        (..., M, 2), each sensor's :meth:`Kinematics.command` (what
        :func:`sensor_motion.actions_to_reach` does for the disk; imitation labels)."""
        points, sensors = np.asarray(points, np.float64), np.asarray(sensors, np.float64)
        out = np.empty(np.broadcast_shapes(points.shape, sensors[..., :2].shape))
        for i, kin in enumerate(self.team):
            out[..., i, :] = kin.command(points[..., i, :], state_of(kin, sensors[..., i, :]))
        return out

    def move_to(self, positions, sensors, target_pred, r, rho):
        """Return ``(next_positions, projected)`` from proposed absolute positions
        (``sensors``: the team's states, or positions when S is 2)."""
        return self.move(True, positions, sensors, target_pred, rho)[:2]

    def apply_actions(self, actions, sensors, target_pred, r, rho):
        """Return ``(next_positions, projected)`` from the agents' actions."""
        return self.move(False, actions, sensors, target_pred, rho)[:2]

    def restate(self, points: FloatArray, states: FloatArray) -> FloatArray:
        """Return the states (..., M, S) after moves from ``states`` to the reachable
        ``points`` (..., M, 2): :meth:`Kinematics.advance` of :meth:`Kinematics.command`,
        the position set to ``points`` exactly."""
        points, states = np.asarray(points, np.float64), np.asarray(states, np.float64)
        out = np.zeros(states.shape)
        for i, kin in enumerate(self.team):
            st = state_of(kin, states[..., i, :])
            if kin.state_dim > 2:
                out[..., i, : kin.state_dim] = kin.advance(kin.command(points[..., i, :], st), st)
            out[..., i, :2] = points[..., i, :]
        return out

    def move(
        self, absolute: bool, x: FloatArray, sensors: FloatArray, where: FloatArray, rho: Any
    ) -> tuple[FloatArray, np.ndarray, FloatArray]:
        """Return ``(next_positions, projected, next_states)`` (..., M, 2), (..., M) and
        (..., M, S) from proposed absolute positions (``absolute``) or actions ``x``, the
        team's states ``sensors`` (..., M, S) (positions when S is 2), the predicted
        target(s) ``where`` (..., 2) or (..., K, 2) and ``rho`` (..., M)."""
        x, sensors = np.asarray(x, np.float64), np.asarray(sensors, np.float64)
        if self._step_one is not None and not absolute and x.ndim == 2:
            # One copy, no move into a rho disk (the usual step): the compiled step alone.
            # Else (or NaN) the general rule below, which gives the same numbers.
            done = self._step_one(x, sensors, where, rho)
            if done is not None:
                return done
        targets = where[..., None, :] if where.ndim == x.ndim - 1 else where  # (..., K, 2)
        rho = np.broadcast_to(np.asarray(rho, np.float64), x.shape[:-1])
        if self.shared is not None and not absolute:
            return self._move_shared(self.shared, x, sensors, targets, rho)
        out = np.empty(x.shape)
        nxt = np.zeros(x.shape[:-1] + (sensors.shape[-1],))
        projected = np.zeros(x.shape[:-1], dtype=bool)
        for i, kin in enumerate(self.team):
            p = state_of(kin, sensors[..., i, :])
            want = kin.clip(x[..., i, :], p) if absolute else kin.apply(x[..., i, :], p)
            if not np.all(np.isfinite(want)):  # a bug of the kinematics: said, not stored
                raise ValueError(
                    f"kinematics[{i}] {kin.name!r} ({type(kin).__name__}) returned NaN or "
                    f"inf from its {'clip' if absolute else 'apply'} on this step's positions"
                )
            out[..., i, :] = want
            e = want[..., None, :] - targets
            dist = np.hypot(e[..., 0], e[..., 1])  # (..., K)
            inside = np.any(dist < rho[..., i, None] * (1.0 - TOL), axis=-1)
            # (a sensor that cannot move stays, even inside)
            inside &= kin.radius > 0.0
            for idx in map(tuple, np.argwhere(inside)):  # (few: a move that ended inside)
                out[idx + (i,)] = kin.project(want[idx], p[idx], targets[idx], rho[idx + (i,)])
                projected[idx + (i,)] = True
            if not np.all(np.isfinite(out[..., i, :])):
                raise ValueError(
                    f"kinematics[{i}] {kin.name!r} ({type(kin).__name__}) returned NaN or "
                    "inf from its project (the move out of a rho disk) on this step"
                )
            if kin.state_dim > 2:  # the rest of the state: the action's, or the point's
                cmd = np.array(np.broadcast_to(x[..., i, :], out[..., i, :].shape))
                redo = projected[..., i] | absolute
                if np.any(redo):
                    cmd[redo] = kin.command(out[..., i, :][redo], p[redo])
                nxt[..., i, : kin.state_dim] = kin.advance(cmd, p)
            nxt[..., i, :2] = out[..., i, :]
        return out, projected, nxt

    def _move_shared(
        self, kin: Kinematics, x: FloatArray, sensors: FloatArray, targets: FloatArray,
        rho: FloatArray,
    ) -> tuple[FloatArray, np.ndarray, FloatArray]:  # fmt: skip
        """:meth:`move` of the actions ``x`` (..., M, 2) when every sensor moves by ``kin``:
        the same rule, each stage one call for the whole team (``targets`` (..., K, 2),
        ``rho`` (..., M)). A kinematics with a ``team_step`` (:meth:`activetrack.Unicycle.
        team_step`) gives the advance and the ``rho`` test in one call."""
        p = state_of(kin, sensors)
        deep = kin.state_dim > 2
        team_step = getattr(kin, "team_step", None)
        if team_step is not None:  # (advance and the rho test in one compiled call)
            adv, projected = team_step(x, p, targets, rho * (1.0 - TOL))
            want = adv[..., :2]
        else:
            adv = kin.advance(x, p) if deep else None
            want = kin.apply(x, p)
            e = want[..., None, :] - targets[..., None, :, :]  # (..., M, K, 2)
            dist = np.hypot(e[..., 0], e[..., 1])
            projected = (dist < rho[..., None] * (1.0 - TOL)).any(-1)
        if not np.isfinite(want).all():  # a bug of the kinematics: said, not stored
            i = int(np.argwhere(~np.isfinite(want))[0][-2])
            raise ValueError(
                f"kinematics[{i}] {kin.name!r} ({type(kin).__name__}) returned NaN or "
                "inf from its apply on this step's positions"
            )
        out = np.array(want)
        if kin.radius <= 0.0:  # (a sensor that cannot move stays, even inside)
            projected[...] = False
        some = projected.any()
        for idx in map(tuple, np.argwhere(projected) if some else ()):  # (few)
            out[idx] = kin.project(want[idx], p[idx], targets[idx[:-1]], rho[idx])
        if some and not np.isfinite(out).all():
            i = int(np.argwhere(~np.isfinite(out))[0][-2])
            raise ValueError(
                f"kinematics[{i}] {kin.name!r} ({type(kin).__name__}) returned NaN or "
                "inf from its project (the move out of a rho disk) on this step"
            )
        nxt = np.zeros(x.shape[:-1] + (sensors.shape[-1],))
        if deep:  # the rest of the state: the action's, or the point's
            if some:
                adv = np.array(adv)
                pp = p[projected]
                adv[projected] = kin.advance(kin.command(out[projected], pp), pp)
            nxt[..., : kin.state_dim] = adv
        nxt[..., :2] = out
        return out, projected, nxt


def checked_states(value: Any, sensors: FloatArray, kinematics: Any) -> FloatArray:
    """Return a planning problem's ``sensor_states`` checked (real, finite, (..., M, S) with
    ``S`` the largest ``state_dim`` of ``kinematics``), its first two entries set to
    ``sensors`` (the positions are the problem's; a ``ValueError`` naming the field)."""
    if kinematics is None:
        raise ValueError("sensor_states needs kinematics (a tuple of one per sensor)")
    s = max(int(k.state_dim) for k in kinematics)
    try:
        arr = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"sensor_states must be real numbers, got {value!r}") from None
    m = sensors.shape[-2]
    if arr.ndim < 2 or arr.shape[-2:] != (m, s) or not np.all(np.isfinite(arr)):
        raise ValueError(
            f"sensor_states must be finite with shape (..., {m}, {s}) (one state per sensor, "
            f"the largest state_dim of its kinematics), got shape {arr.shape}"
        )
    arr = np.array(np.broadcast_to(arr, np.broadcast_shapes(arr.shape, sensors.shape[:-1] + (s,))))
    arr[..., :2] = sensors
    return arr
