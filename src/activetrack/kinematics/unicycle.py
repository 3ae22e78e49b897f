"""A ground robot with a heading and a turning limit: :class:`Unicycle`.

State ``(x, y, theta)`` (``state_dim`` 3). Over one step of ``dt`` seconds the robot holds a
command: a forward speed ``v in [v_min, v_max]`` and a turn rate ``w in [-w_max, w_max]``
(``v_min`` may be 0, a robot that can stop and turn in place, or positive, a fixed-wing or
Dubins-like vehicle that cannot stop). The motion ``x' = v cos(theta)``, ``y' = v
sin(theta)``, ``theta' = w`` integrates exactly to an arc, written as its chord::

    phi = w dt / 2,   S(phi) = sin(phi) / phi   (S(0) = 1; a quotient: no cancellation)
    (x, y)(t + dt) = (x, y) + v dt S(phi) (cos(theta + phi), sin(theta + phi))
    theta(t + dt) = theta + w dt                (wrapped to (-pi, pi])

so the straight limit ``w -> 0`` is the same formula. **Reach set**: with ``Phi = w_max dt
/ 2 < pi`` (required: ``w_max dt < 2 pi``) the map from commands to endpoints is, in polar
coordinates about the position relative to the heading, ``(v, w) -> (rho, phi) = (v dt
S(phi), w dt / 2)``, one to one. The reach set is ``{phi in [-Phi, Phi], v_min dt S(phi)
<= rho <= v_max dt S(phi)}``: its boundary is the images of the command box's edges, the
curve of endpoints at ``v_max`` (all turn rates), the one at ``v_min`` (the position
itself when ``v_min`` is 0) and two straight segments at ``w = +-w_max`` (all speeds).
Membership is that polar test; :meth:`Unicycle.command` inverts it (``w = 2 phi / dt``,
``v = rho / (dt S(phi))``; a robot that stays, ``rho = 0``, gets ``v = w = 0``);
:meth:`Unicycle.clip` and :meth:`Unicycle.project` are
:class:`~activetrack.kinematics.pieces.PiecewiseReach`'s nearest points on those four
pieces. :attr:`Unicycle.radius` is ``v_max dt`` (the chord at ``w = 0``).

**Action**: a normalized ``Box([-1, 1]^2)``: ``v = v_min + (a_0 + 1) (v_max - v_min) / 2``,
``w = a_1 w_max`` (each component clipped to [-1, 1]). **Observation**: the heading as
``(cos theta, sin theta)``. **Reset**: the heading points at the targets' prior mean.
``dt`` comes from the scenario (:meth:`Unicycle.bind`); a standalone object takes ``dt=``.
"""

from __future__ import annotations

import numpy as np

from activetrack.kinematics._unicycle_kernels import team_step_rows
from activetrack.kinematics.base import TOL
from activetrack.kinematics.pieces import PiecewiseReach, real_parameter
from activetrack.validation import FloatArray

#: The largest speed accepted (m/s), as the scenario's ``vmax``.
SPEED_MAX = 1e9


def _wrap(a: FloatArray) -> FloatArray:
    """Return angles ``a`` wrapped to (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(a, np.float64), 2.0 * np.pi)


def _sinc(phi: FloatArray) -> FloatArray:
    """Return ``sin(phi) / phi`` (1 at 0; no cancellation: a quotient, not a difference)."""
    phi = np.asarray(phi, np.float64)
    zero = phi == 0.0
    if not zero.any():  # (the usual case: no np.where, which costs microseconds)
        return np.sin(phi) / phi
    return np.where(zero, 1.0, np.sin(phi) / np.where(zero, 1.0, phi))


def _last(*columns: FloatArray) -> FloatArray:
    """Return ``columns`` (broadcast together) stacked on a new last axis (np.stack's
    values, without its per-call cost)."""
    out = np.empty(np.broadcast(*columns).shape + (len(columns),))
    for j, c in enumerate(columns):
        out[..., j] = c
    return out


class Unicycle(PiecewiseReach):
    """A unicycle: forward speed in ``[v_min, v_max]``, turn rate in ``[-w_max, w_max]``,
    held over each step and integrated exactly (module docstring).

    Args:
        v_min: the least forward speed (m/s), >= 0 (positive: the robot cannot stop).
        v_max: the top speed (m/s), > 0 and >= ``v_min``.
        w_max: the largest turn rate (rad/s), >= 0, with ``w_max dt < 2 pi``.
        dt: the step (s); None until a scenario binds its own (:meth:`bind`).
    """

    name = "unicycle"
    state_dim = 3
    n_features = 2
    n_pieces = 4

    def __init__(self, v_min: float, v_max: float, w_max: float, dt: float | None = None):
        self.v_min = real_parameter("v_min", v_min, 0.0, SPEED_MAX)
        self.v_max = real_parameter("v_max", v_max, 0.0, SPEED_MAX, open_low=True)
        if self.v_min > self.v_max:
            raise ValueError(f"v_min must be at most v_max ({self.v_max!r}), got {v_min!r}")
        self.w_max = real_parameter("w_max", w_max, 0.0, SPEED_MAX)
        self.dt = None if dt is None else real_parameter("dt", dt, 0.0, open_low=True)
        if self.dt is not None and not self.w_max * self.dt < 2.0 * np.pi:
            raise ValueError(
                f"w_max must be below 2 pi / dt = {2.0 * np.pi / self.dt:g} rad/s (a step turns "
                f"less than a full circle), got {w_max!r}"
            )

    def bind(self, dt: float) -> Unicycle:
        """Return this unicycle with steps of ``dt`` seconds."""
        return Unicycle(self.v_min, self.v_max, self.w_max, dt)

    def _dt(self) -> float:
        if self.dt is None:
            raise ValueError(
                "Unicycle: dt is not set: give it to a scenario (which binds its dt) or "
                "pass dt= (seconds)"
            )
        return self.dt

    @property
    def radius(self) -> float:
        """Return ``v_max dt``, the longest chord of a step."""
        return self.v_max * self._dt()

    @property
    def half_turn(self) -> float:
        """Return ``Phi = w_max dt / 2``, the largest angle between a step's chord and the
        heading."""
        return 0.5 * self.w_max * self._dt()

    # Commands and states ---------------------------------------------------------------
    def commands(self, actions: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``(v, w)`` (...) of normalized ``actions`` (..., 2) (clipped to [-1, 1])."""
        a = np.minimum(np.maximum(np.asarray(actions, np.float64), -1.0), 1.0)  # (np.clip)
        v = self.v_min + 0.5 * (a[..., 0] + 1.0) * (self.v_max - self.v_min)
        return v, a[..., 1] * self.w_max

    def integrate(self, v: FloatArray, w: FloatArray, state: FloatArray) -> FloatArray:
        """Return the state (..., 3) after holding ``(v, w)`` for ``dt`` from ``state``."""
        state = np.asarray(state, np.float64)
        dt = self._dt()
        phi = 0.5 * np.asarray(w, np.float64) * dt
        chord = np.asarray(v, np.float64) * dt * _sinc(phi)
        ang = state[..., 2] + phi
        x = state[..., 0] + chord * np.cos(ang)
        y = state[..., 1] + chord * np.sin(ang)
        return _last(x, y, _wrap(state[..., 2] + 2.0 * phi))

    def advance(self, actions: FloatArray, state: FloatArray) -> FloatArray:
        """Return the state (..., 3) after the step ``actions`` ask for."""
        return self.integrate(*self.commands(actions), state)

    def team_step(
        self, actions: FloatArray, states: FloatArray, targets: FloatArray, rho_inside: FloatArray
    ) -> tuple[FloatArray, np.ndarray]:
        """Return ``(next_states, inside)``: :meth:`advance` of a team's ``actions`` (...,
        M, 2) from its ``states`` (..., M, 3), bit for bit, and whether each new position
        is closer than ``rho_inside`` (..., M) to one of ``targets`` (..., K, 2); one
        compiled call (:func:`activetrack.kinematics._unicycle_kernels.team_step_rows`)."""

        a, s = np.asarray(actions, np.float64), np.asarray(states, np.float64)
        targets = np.asarray(targets, np.float64)
        if type(self) is not Unicycle:  # a subclass may move otherwise: its own methods
            nxt = self.advance(a, s)
            e = nxt[..., None, :2] - targets[..., None, :, :]
            dist = np.hypot(e[..., 0], e[..., 1])
            return nxt, (dist < np.asarray(rho_inside)[..., None]).any(-1)
        lead, m = a.shape[:-2], a.shape[-2]
        rows = a.reshape(-1, m, 2)
        n = rows.shape[0]
        out, inside = np.empty((n, m, 3)), np.empty((n, m), dtype=bool)
        rho_inside = np.asarray(rho_inside, np.float64)
        if targets.shape[:-2] != lead:  # (broadcasting costs microseconds: only if needed)
            targets = np.broadcast_to(targets, lead + targets.shape[-2:])
        if rho_inside.shape != lead + (m,):
            rho_inside = np.broadcast_to(rho_inside, lead + (m,))
        team_step_rows(
            np.ascontiguousarray(rows), np.ascontiguousarray(s.reshape(n, m, 3)),
            self.v_min, self.v_max, self.w_max, self._dt(),
            np.ascontiguousarray(targets).reshape(n, -1, 2),
            np.ascontiguousarray(rho_inside).reshape(n, m), out, inside,
        )  # fmt: skip
        return out.reshape(lead + (m, 3)), inside.reshape(lead + (m,))

    def team_step_one(
        self, actions: FloatArray, states: FloatArray, where: FloatArray, rho: FloatArray
    ) -> tuple[FloatArray, np.ndarray, FloatArray] | None:
        """Return ``(positions (M, 2), projected (M,), next_states (M, 3))`` of
        :meth:`~activetrack.kinematics.team.TeamMotion.move` of one copy's ``actions``
        (M, 2) from its ``states`` (M, 3) about the target(s) ``where`` (2,) or (K, 2)
        (``rho`` (M,) or a number) when no new position is inside a ``rho`` disk and all
        are finite (then nothing is projected: the positions are the step's), else None
        (the caller's general rule). The numbers of :meth:`team_step`, one compiled call."""
        m = actions.shape[0]
        if type(self) is not Unicycle or states.shape != (m, 3):
            return None
        out, inside = np.empty((1, m, 3)), np.empty((1, m), dtype=bool)
        rho_inside = np.empty((1, m))
        rho_inside[0] = rho
        rho_inside *= 1.0 - TOL  # (TeamMotion's test: closer than rho (1 - TOL))
        team_step_rows(
            np.ascontiguousarray(actions).reshape(1, m, 2),
            np.ascontiguousarray(states).reshape(1, m, 3),
            self.v_min, self.v_max, self.w_max, self._dt(),
            np.ascontiguousarray(where, np.float64).reshape(1, -1, 2), rho_inside, out, inside,
        )  # fmt: skip
        nxt = out[0]
        if inside.any() or not np.isfinite(nxt).all():
            return None
        return nxt[:, :2].copy(), inside[0], nxt

    def apply(self, actions: FloatArray, position: FloatArray) -> FloatArray:
        """Return the position (..., 2) the step ``actions`` ask for reaches."""
        return self.advance(actions, position)[..., :2]

    def _polar(self, points: FloatArray, state: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``(rho, phi)``: the distance and the angle from the heading of ``points``
        about the position of ``state``."""
        state = np.asarray(state, np.float64)
        d = np.asarray(points, np.float64) - state[..., :2]
        return np.hypot(d[..., 0], d[..., 1]), _wrap(
            np.arctan2(d[..., 1], d[..., 0]) - state[..., 2]
        )

    def command(self, points: FloatArray, position: FloatArray) -> FloatArray:
        """Return the normalized actions (..., 2) whose step reaches ``points`` (reachable)
        from the state ``position`` (the arc's inverse; ``(v, w) = (0, 0)`` for the
        position itself)."""
        rho, phi = self._polar(points, position)
        dt = self._dt()
        phi = np.clip(phi, -self.half_turn, self.half_turn)
        v = np.where(rho > 0.0, rho / (dt * _sinc(phi)), 0.0)
        w = np.where(rho > 0.0, 2.0 * phi / dt, 0.0)
        span = self.v_max - self.v_min
        a0 = 2.0 * (v - self.v_min) / span - 1.0 if span > 0.0 else np.zeros_like(v)
        a1 = w / self.w_max if self.w_max > 0.0 else np.zeros_like(w)
        return np.clip(np.stack([a0, a1], -1), -1.0, 1.0)

    def initial_state(self, positions: FloatArray, toward: FloatArray) -> FloatArray:
        """Return ``(x, y, theta)`` with the heading toward ``toward`` (0 if there)."""
        p = np.asarray(positions, np.float64)
        d = np.asarray(toward, np.float64) - p
        theta = np.where(
            np.hypot(d[..., 0], d[..., 1]) > 0.0, np.arctan2(d[..., 1], d[..., 0]), 0.0
        )
        return np.concatenate([p, theta[..., None]], -1)

    def features(self, state: FloatArray) -> FloatArray:
        """Return the heading as ``(cos theta, sin theta)`` (..., 2)."""
        # (a contiguous copy: NumPy's cosine runs faster on it, the same numbers)
        theta = np.ascontiguousarray(np.asarray(state, np.float64)[..., 2])
        return _last(np.cos(theta), np.sin(theta))

    # The reach set ---------------------------------------------------------------------
    def reaches(self, points: FloatArray, position: FloatArray) -> np.ndarray:
        """Return whether ``points`` (..., 2) are step endpoints from the state ``position``
        (the polar test of the module docstring, with an absolute tolerance of
        ``4e-12 (radius + |position|)``)."""
        rho, phi = self._polar(points, position)
        big = self.half_turn
        near = np.clip(phi, -big, big)
        off = np.abs(phi - near)
        gap = np.where(off < 0.5 * np.pi, rho * np.sin(off), rho)  # to the nearest side
        s = _sinc(near)
        dt, tol = self._dt(), self._tol(position)
        return (
            (gap <= tol) & (rho <= self.v_max * dt * s + tol) & (rho >= self.v_min * dt * s - tol)
        )

    def clip(self, wanted: FloatArray, position: FloatArray) -> FloatArray:
        """Return ``wanted`` where reachable, else the nearest point of the reach set's
        boundary (:meth:`~activetrack.kinematics.pieces.PiecewiseReach.nearest_on_boundary`)."""
        q, state = np.asarray(wanted, np.float64), np.asarray(position, np.float64)
        inside = self.reaches(q, state)
        if np.all(inside):
            return np.array(np.broadcast_to(q, np.broadcast_shapes(q.shape, state[..., :2].shape)))
        near = self.nearest_on_boundary(q, state)
        return np.where(inside[..., None], q, near)

    def point_pieces(self) -> tuple[int, ...]:
        """Return ``(1,)`` when ``v_min`` is 0 (the arc at ``v_min`` is the position: a
        chord of ``0 dt sinc(phi)``, exactly 0), else ``()``."""
        return (1,) if self.v_min == 0.0 else ()

    def piece(self, k: np.ndarray, t: FloatArray, state: FloatArray) -> FloatArray:
        """Return pieces ``k`` of the reach set's boundary at ``t`` in [0, 1]: 0 the
        endpoints at ``v_max`` and 1 at ``v_min`` (turn rate ``-w_max .. w_max``), 2 and 3
        the segments at ``w = w_max`` and ``-w_max`` (speed ``v_min .. v_max``)."""
        state, t, k = np.asarray(state, np.float64), np.asarray(t, np.float64), np.asarray(k)
        big = self.half_turn
        curve = k < 2
        phi = np.where(curve, -big + 2.0 * big * t, np.where(k == 2, big, -big))
        ramp = self.v_min + (self.v_max - self.v_min) * t
        v = np.where(curve, np.where(k == 0, self.v_max, self.v_min), ramp)
        chord = v * self._dt() * _sinc(phi)
        ang = state[..., 2] + phi
        return _last(state[..., 0] + chord * np.cos(ang), state[..., 1] + chord * np.sin(ang))

    def __repr__(self) -> str:
        dt = "" if self.dt is None else f", dt={self.dt!r}"
        return f"Unicycle(v_min={self.v_min!r}, v_max={self.v_max!r}, w_max={self.w_max!r}{dt})"
