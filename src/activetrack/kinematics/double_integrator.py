"""A vehicle with inertia: :class:`DoubleIntegrator`, bounded acceleration and speed.

State ``(x, y, vx, vy)`` (``state_dim`` 4). Over one step of ``dt`` seconds the vehicle holds
an acceleration ``a`` with ``|a| <= a_max``; the motion ``p'' = a`` integrates exactly to::

    p(t + dt) = p + v dt + a dt^2 / 2,        v(t + dt) = v + a dt.

**Speed bound**: the commands are restricted so that the new speed is at most ``v_max``,
``|v + a dt| <= v_max`` (the speed at the end of the step, hence, the velocity being
linear in time and the norm convex, at every instant of it, given ``|v| <= v_max`` at
its start, which a reset with ``v = 0`` and every step keep). In terms of the new position
``p'`` (``a = 2 (p' - p - v dt) / dt^2``, ``v + a dt = 2 (p' - p) / dt - v``) the two
constraints are two disks, and the **reach set** is their intersection::

    |p' - (p + v dt)|     <= a_max dt^2 / 2      (the acceleration)
    |p' - (p + v dt / 2)| <= v_max dt / 2        (the speed)

never empty (it holds ``p + v dt``, the coasting point, since ``|v| <= v_max``). Its
boundary is an arc of each circle (the part inside the other disk); :meth:`clip` is the
closed-form nearest point of an intersection of two disks (the projection onto one circle
when it lies in the other disk, else the nearer crossing of the circles) and
:meth:`project` is :class:`~activetrack.kinematics.pieces.PiecewiseReach`'s on the two
arcs. :attr:`radius` is ``v_max dt``, the farthest any state reaches in a step (the speed
disk's far side, ``|v| dt / 2 + v_max dt / 2``).

**Action**: a normalized ``Box([-1, 1]^2)``: the acceleration ``a_max u / max(1, |u|)`` of
the action ``u``, then restricted to the speed bound: the nearest allowed acceleration
(the same two-disk geometry, scaled by ``dt^2 / 2``). So :meth:`apply` is :meth:`clip` of
``p + v dt + a_max u dt^2 / (2 max(1, |u|))`` and :meth:`command` of a reachable point is
``2 (p' - p - v dt) / (a_max dt^2)``. **Observation**: the velocity over ``v_max``
(components in [-1, 1]). **Reset**: at rest (``v = 0``). ``dt`` comes from the scenario
(:meth:`DoubleIntegrator.bind`); a standalone object takes ``dt=``.
"""

from __future__ import annotations

import numpy as np

from activetrack.kinematics.pieces import PiecewiseReach, real_parameter
from activetrack.kinematics.unicycle import SPEED_MAX
from activetrack.validation import FloatArray


def _norm(d: FloatArray) -> FloatArray:
    return np.hypot(d[..., 0], d[..., 1])


class DoubleIntegrator(PiecewiseReach):
    """A point mass: acceleration at most ``a_max``, speed at most ``v_max`` (module
    docstring).

    Args:
        a_max: the largest acceleration (m/s^2), > 0.
        v_max: the top speed (m/s), > 0.
        dt: the step (s); None until a scenario binds its own (:meth:`bind`).
    """

    name = "double_integrator"
    state_dim = 4
    n_features = 2
    n_pieces = 2

    def __init__(self, a_max: float, v_max: float, dt: float | None = None) -> None:
        self.a_max = real_parameter("a_max", a_max, 0.0, SPEED_MAX, open_low=True)
        self.v_max = real_parameter("v_max", v_max, 0.0, SPEED_MAX, open_low=True)
        self.dt = None if dt is None else real_parameter("dt", dt, 0.0, open_low=True)

    def bind(self, dt: float) -> DoubleIntegrator:
        """Return this double integrator with steps of ``dt`` seconds."""
        return DoubleIntegrator(self.a_max, self.v_max, dt)

    def _dt(self) -> float:
        if self.dt is None:
            raise ValueError(
                "DoubleIntegrator: dt is not set: give it to a scenario (which binds its dt) "
                "or pass dt= (seconds)"
            )
        return self.dt

    @property
    def radius(self) -> float:
        """Return ``v_max dt``, the farthest a step goes from any state."""
        return self.v_max * self._dt()

    def disks(self, state: FloatArray) -> tuple[FloatArray, float, FloatArray, float]:
        """Return ``(c_a, r_a, c_v, r_v)``: the acceleration disk and the speed disk whose
        intersection is the reach set of ``state`` (..., 4) (module docstring)."""
        state = np.asarray(state, np.float64)
        dt = self._dt()
        p, v = state[..., :2], state[..., 2:4]
        return p + v * dt, 0.5 * self.a_max * dt * dt, p + 0.5 * dt * v, 0.5 * self.v_max * dt

    # Commands and states ---------------------------------------------------------------
    def apply(self, actions: FloatArray, position: FloatArray) -> FloatArray:
        """Return the position (..., 2) the acceleration ``actions`` ask for reaches (the
        acceleration scaled onto ``a_max``, then restricted to the speed bound)."""
        u = np.asarray(actions, np.float64)
        u = u / np.maximum(1.0, _norm(u))[..., None]
        c_a, r_a, _, _ = self.disks(position)
        return self.clip(c_a + r_a * u, position)

    def advance(self, actions: FloatArray, state: FloatArray) -> FloatArray:
        """Return the state (..., 4) after the step ``actions`` ask for: the position of
        :meth:`apply` and the velocity ``2 (p' - p) / dt - v`` (``v + a dt``), scaled back
        onto ``v_max`` if rounding put it a hair beyond."""
        state = np.asarray(state, np.float64)
        new = self.apply(actions, state)
        return self.restate(new, state)

    def restate(self, points: FloatArray, state: FloatArray) -> FloatArray:
        """Return the state (..., 4) after a step from ``state`` to the reachable
        ``points``."""
        state = np.asarray(state, np.float64)
        p, v = state[..., :2], state[..., 2:4]
        vel = 2.0 * (np.asarray(points, np.float64) - p) / self._dt() - v
        speed = _norm(vel)
        vel = vel * np.minimum(1.0, self.v_max / np.where(speed > 0.0, speed, 1.0))[..., None]
        pts = np.broadcast_to(points, vel.shape)
        return np.concatenate([pts, vel], -1)

    def command(self, points: FloatArray, position: FloatArray) -> FloatArray:
        """Return the normalized acceleration (..., 2) whose step reaches ``points``
        (reachable): ``(p' - p - v dt) / r_a``."""
        c_a, r_a, _, _ = self.disks(position)
        return (np.asarray(points, np.float64) - c_a) / r_a

    def initial_state(self, positions: FloatArray, toward: FloatArray) -> FloatArray:
        """Return ``(x, y, 0, 0)``: at rest."""
        p = np.asarray(positions, np.float64)
        return np.concatenate([p, np.zeros_like(p)], -1)

    def features(self, state: FloatArray) -> FloatArray:
        """Return the velocity over ``v_max`` (..., 2)."""
        return np.asarray(state, np.float64)[..., 2:4] / self.v_max

    # The reach set ---------------------------------------------------------------------
    def reaches(self, points: FloatArray, position: FloatArray) -> np.ndarray:
        """Return whether ``points`` (..., 2) lie in both disks (absolute tolerance
        ``4e-12 (radius + |position|)``)."""
        c_a, r_a, c_v, r_v = self.disks(position)
        q, tol = np.asarray(points, np.float64), self._tol(position)
        return (_norm(q - c_a) <= r_a + tol) & (_norm(q - c_v) <= r_v + tol)

    def clip(self, wanted: FloatArray, position: FloatArray) -> FloatArray:
        """Return the nearest point of the intersection of the two disks to ``wanted``
        (closed form: module docstring)."""
        c_a, r_a, c_v, r_v = self.disks(position)
        q = np.asarray(wanted, np.float64)
        shape = np.broadcast_shapes(q.shape, c_a.shape)
        q, c_a, c_v = (np.broadcast_to(x, shape) for x in (q, c_a, c_v))
        tol = self._tol(position)
        da, dv = _norm(q - c_a), _norm(q - c_v)
        on_a = c_a + (q - c_a) * (r_a / np.where(da > 0.0, da, 1.0))[..., None]
        on_v = c_v + (q - c_v) * (r_v / np.where(dv > 0.0, dv, 1.0))[..., None]
        in_a, in_v = da <= r_a + tol, dv <= r_v + tol
        ok_a = _norm(on_a - c_v) <= r_v + tol  # the projection onto circle a, in disk v
        ok_v = _norm(on_v - c_a) <= r_a + tol
        # The circles' crossings (the corners), the nearer one to q.
        e = c_v - c_a
        d = _norm(e)
        u = e / np.where(d > 0.0, d, 1.0)[..., None]
        x = (d * d + r_a * r_a - r_v * r_v) / (2.0 * np.where(d > 0.0, d, 1.0))
        h = np.sqrt(np.maximum(r_a * r_a - x * x, 0.0))
        perp = np.stack([-u[..., 1], u[..., 0]], -1)
        mid = c_a + x[..., None] * u
        k1, k2 = mid + h[..., None] * perp, mid - h[..., None] * perp
        corner = np.where((_norm(k1 - q) <= _norm(k2 - q))[..., None], k1, k2)
        out = np.where((~in_v & ok_v)[..., None], on_v, corner)
        out = np.where((~in_a & ok_a)[..., None], on_a, out)
        return np.where((in_a & in_v)[..., None], q, out)

    def piece(self, k: np.ndarray, t: FloatArray, state: FloatArray) -> FloatArray:
        """Return pieces ``k`` of the reach set's boundary at ``t`` in [0, 1]: 0 the arc of
        the acceleration circle inside the speed disk, 1 the arc of the speed circle inside
        the acceleration disk (the arcs meet at the circles' crossings; an empty arc is one
        point outside the set, which membership filters out)."""
        c_a, r_a, c_v, r_v = self.disks(state)
        t, k = np.asarray(t, np.float64), np.asarray(k)
        e = c_v - c_a
        d = _norm(e)
        toward = np.arctan2(e[..., 1], e[..., 0])
        safe = np.where(d > 0.0, d, 1.0)
        cos_a = np.where(d > 0.0, (d * d + r_a * r_a - r_v * r_v) / (2.0 * safe * r_a),
                         -1.0 if r_a <= r_v else 1.0)  # fmt: skip
        cos_v = np.where(d > 0.0, (d * d + r_v * r_v - r_a * r_a) / (2.0 * safe * r_v),
                         -1.0 if r_v < r_a else 1.0)  # fmt: skip
        first = k == 0
        half = np.arccos(np.clip(np.where(first, cos_a, cos_v), -1.0, 1.0))
        mid = np.where(first, toward, toward + np.pi)
        ang = mid - half + 2.0 * half * t
        r = np.where(first, r_a, r_v)
        cx = np.where(first, c_a[..., 0], c_v[..., 0])
        cy = np.where(first, c_a[..., 1], c_v[..., 1])
        return np.stack([cx + r * np.cos(ang), cy + r * np.sin(ang)], -1)

    def __repr__(self) -> str:
        dt = "" if self.dt is None else f", dt={self.dt!r}"
        return f"DoubleIntegrator(a_max={self.a_max!r}, v_max={self.v_max!r}{dt})"
