"""How one sensor moves in one step: the public base :class:`Kinematics`.

A kinematics says, for one sensor at ``position``, which points it can reach in one step
(its *reach set* ``R``, eq. 13/15 for the paper's disk), and the planners' and the
world's questions about the *feasible set* ``F = R minus the rho disks`` around the K
predicted targets (eq. 14/16):

- :meth:`Kinematics.reaches` (membership of ``R``) and :meth:`Kinematics.feasible`
  (membership of ``F``), both with the relative tolerance :data:`TOL`;
- :meth:`Kinematics.clip`: the point of ``R`` nearest a wanted one;
- :meth:`Kinematics.project`: the point of ``F`` nearest a wanted one (the world's move
  when a clipped move ends inside a ``rho`` disk);
- :meth:`Kinematics.boundary` and :meth:`Kinematics.sample`: points on the boundary of
  ``F`` and uniform in ``F``, the candidates of the planners;
- :meth:`Kinematics.apply` and :meth:`Kinematics.command`: an agent's action to the point
  it asks for, and back (``command`` is what
  :func:`activetrack.kinematics.sensor_motion.actions_to_reach` does for the disk);
  :attr:`Kinematics.action_low` / :attr:`Kinematics.action_high` bound the agent's
  action space (the environments' ``Box``).

A new kinematics subclasses :class:`Kinematics` and gives ``name``, :attr:`radius`,
:meth:`reaches`, :meth:`clip` and :meth:`reach_boundary`; the rest have defaults that
work for any reach set that contains ``position`` and is star-shaped from it (every
segment from ``position`` to a point of ``R`` lies in ``R``): :meth:`project` searches the
candidates that can be nearest (the clipped point, the radial projections onto the
``rho`` circles, dense points of the boundary of ``F``), so it is exact where one of the
first two is feasible and otherwise within the boundary's spacing ``radius / 4096``.
The built-in kinematics: :class:`activetrack.kinematics.disk.Disk`, the paper's disk of
radius ``vmax dt``, whose methods are the compiled functions of this package; and, on
:class:`activetrack.kinematics.pieces.PiecewiseReach` (exact nearest points on a reach set
bounded by smooth pieces, star-shaped or not), the robots below.

Shapes: ``position`` (2,), ``targets`` (K, 2) and ``rho`` a float for one sensor;
:meth:`reaches`, :meth:`clip`, :meth:`apply` and :meth:`command` also broadcast over
leading axes (``position`` (..., 2)). Positions are absolute (not relative to a target).

**A state beyond the position.** A kinematics may move more than a point: a heading (a
unicycle, :class:`activetrack.kinematics.unicycle.Unicycle`), a velocity (a double
integrator, :class:`activetrack.kinematics.double_integrator.DoubleIntegrator`). It then
sets :attr:`Kinematics.state_dim` > 2, and every method's ``position`` argument is the
sensor's whole *state* (..., ``state_dim``): the position ``(x, y)`` first, then the rest;
the reach set, and every answer, depend on all of it (returned points stay (..., 2)). Such
a kinematics also gives :meth:`Kinematics.initial_state` (the state at a reset),
:meth:`Kinematics.advance` (the state after a step, from the agent's action) and
:meth:`Kinematics.features` (what of it the agent observes, :attr:`n_features` numbers in
[-1, 1]); one that needs the step's duration ``dt`` gives :meth:`Kinematics.bind` (the
scenario binds its ``dt`` once). With ``state_dim = 2`` (the :class:`Disk`, any
kinematics written before) the state is the position and nothing changes. The world keeps
each sensor's state beyond the position (``World.get("motion")``, ``World.sensor_states``;
:mod:`activetrack.world._motion_state`), the planners see it as
``PlanningProblem.sensor_states``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from activetrack.validation import ComparedByValue, FloatArray

#: Relative tolerance of the membership tests (as the disk's,
#: :data:`activetrack.kinematics.sensor_motion.TOL`).
TOL = 1e-12
#: The boundary spacing of the default :meth:`Kinematics.project`, in units of the radius.
PROJECT_SPACING = 1.0 / 4096


def _f64(x: FloatArray) -> FloatArray:
    return np.asarray(x, dtype=np.float64)


def outside_disks(points: FloatArray, targets: FloatArray, rho: float, tol: float = TOL):
    """Return whether ``points`` (..., 2) keep ``rho`` (less the tolerance) from every one
    of ``targets`` (K, 2)."""
    e = _f64(points)[..., None, :] - _f64(targets).reshape(-1, 2)
    return np.all(np.hypot(e[..., 0], e[..., 1]) >= rho * (1.0 - tol), axis=-1)


class Kinematics(ComparedByValue, ABC):
    """How one sensor moves in one step (module docstring); subclass it for a new one.

    Subclasses set ``name`` (a non-empty string, recorded in ``Scenario.to_dict``) and
    implement :attr:`radius`, :meth:`reaches`, :meth:`clip` and :meth:`reach_boundary`.
    """

    #: A name for records (``Scenario.to_dict``); a new kinematics sets its own.
    name: str = ""
    #: Bounds of one agent's action (the environments' ``Box(action_low, action_high)``).
    action_low: tuple[float, ...] = (-1.0, -1.0)
    action_high: tuple[float, ...] = (1.0, 1.0)
    #: The numbers of one sensor's state: its position (x, y), then what the kinematics
    #: carries beyond it (module docstring); 2: the position alone.
    state_dim: int = 2
    #: The entries of :meth:`features` (the agent's observation of its state), in [-1, 1].
    n_features: int = 0

    # What a subclass gives --------------------------------------------------------------
    @property
    @abstractmethod
    def radius(self) -> float:
        """Return the farthest a step can go, ``max |s - position|`` over ``R`` (>= 0): the
        reach ``r`` the observation and the planners' scales use."""

    @abstractmethod
    def reaches(self, points: FloatArray, position: FloatArray) -> np.ndarray:
        """Return whether ``points`` (..., 2) lie in the reach set of ``position`` (with the
        relative tolerance :data:`TOL`)."""

    @abstractmethod
    def clip(self, wanted: FloatArray, position: FloatArray) -> FloatArray:
        """Return the point of the reach set nearest to ``wanted`` (..., 2); ``wanted``
        itself when it is reachable."""

    @abstractmethod
    def reach_boundary(self, position: FloatArray, spacing: float) -> FloatArray:
        """Return points on the boundary of the reach set, at most ``spacing`` apart, (P, 2)
        (empty when ``radius`` is 0)."""

    # The state beyond the position (defaults: the state is the position) ------------------
    def bind(self, dt: float) -> Kinematics:
        """Return this kinematics for steps of ``dt`` seconds (the scenario's; called once at
        validation): itself, unless its motion depends on ``dt``."""
        return self

    def initial_state(self, positions: FloatArray, toward: FloatArray) -> FloatArray:
        """Return the state (..., ``state_dim``) of sensors starting at ``positions``
        (..., 2), facing the point ``toward`` (..., 2) (the targets' prior mean). Default:
        the position."""
        return np.array(np.broadcast_to(_f64(positions), np.shape(positions)), dtype=np.float64)

    def advance(self, actions: FloatArray, state: FloatArray) -> FloatArray:
        """Return the state (..., ``state_dim``) after the step an agent's ``actions``
        (..., 2) ask for from ``state``; its position is :meth:`apply`'s (up to rounding).
        Default: :meth:`apply`."""
        return self.apply(actions, state)

    def features(self, state: FloatArray) -> FloatArray:
        """Return what the agent observes of its ``state`` beyond the position, (...,
        :attr:`n_features`), in [-1, 1]. Default: nothing."""
        return np.zeros(np.shape(state)[:-1] + (0,))

    # Defaults ---------------------------------------------------------------------------
    def apply(self, actions: FloatArray, position: FloatArray) -> FloatArray:
        """Return the point an agent's ``actions`` (..., 2) ask for, inside the reach set.

        Default: the action is the displacement in units of :attr:`radius`, each component
        clipped to ``[action_low, action_high]``, then :meth:`clip`.
        """
        a = np.clip(_f64(actions), self.action_low, self.action_high)
        return self.clip(_f64(position)[..., :2] + self.radius * a, position)

    def command(self, points: FloatArray, position: FloatArray) -> FloatArray:
        """Return the actions that :meth:`apply` turns into ``points`` (reachable), (..., 2).

        Default: the inverse of the default :meth:`apply`, ``(points - position) / radius``
        (zero when the radius is 0), exact up to rounding.
        """
        r = float(self.radius)
        d = _f64(points) - _f64(position)[..., :2]
        return d / r if r > 0.0 else np.zeros_like(d)

    def feasible(
        self, points: FloatArray, position: FloatArray, targets: FloatArray, rho: float
    ) -> np.ndarray:
        """Return whether ``points`` (..., 2) lie in ``F``: reachable, and at least ``rho``
        from every one of ``targets`` (K, 2) (both tests with the tolerance)."""
        return self.reaches(points, position) & outside_disks(points, targets, rho)

    def boundary(
        self, position: FloatArray, targets: FloatArray, rho: float, spacing: float
    ) -> FloatArray:
        """Return points on the boundary of ``F``, at most about ``spacing`` apart, (P, 2):
        the reach set's boundary outside every ``rho`` disk, and each ``rho`` circle's points
        inside the reach set and outside the other disks (empty when ``F`` is)."""
        state, targets = _f64(position), _f64(targets).reshape(-1, 2)
        position = state[:2]
        r = float(self.radius)
        if not r > 0.0:
            return np.empty((0, 2))
        edge = self.reach_boundary(state, spacing).reshape(-1, 2)
        pts = [edge[outside_disks(edge, targets, rho)]]
        for tk in targets if rho > 0.0 else ():
            # Only the arc within the radius of ``position`` can be reached: angles about
            # the direction to ``position`` whose cosine is at least ``cos_w``.
            v = position - tk
            d = float(np.hypot(v[0], v[1]))
            cos_w = (rho * rho + d * d - r * r) / (2.0 * rho * d) if d > 0.0 else -1.0
            if cos_w > 1.0 + TOL:
                continue
            half = float(np.arccos(np.clip(cos_w, -1.0, 1.0)))
            n = max(8, int(np.ceil(2.0 * half * rho / spacing)) + 1)
            t = float(np.arctan2(v[1], v[0])) + np.linspace(-half, half, n)
            circ = tk + rho * np.stack([np.cos(t), np.sin(t)], -1)
            pts.append(circ[self.feasible(circ, state, targets, rho)])
        return np.concatenate(pts)

    def sample(
        self,
        position: FloatArray,
        targets: FloatArray,
        rho: float,
        rng: np.random.Generator,
        n: int,
    ) -> FloatArray:
        """Return ``n`` points (n, 2) uniform in ``F`` (rejection from the disk of
        :attr:`radius`, at most 64 rounds); missing points (``F`` of no area) are drawn from
        :meth:`boundary`, or are :meth:`project` of ``position`` when that is empty too."""
        state, targets = _f64(position), _f64(targets).reshape(-1, 2)
        position = state[:2]
        r = float(self.radius)
        got: list[FloatArray] = []
        count = 0
        for _ in range(64 if r > 0.0 else 0):
            if count >= n:
                break
            u = rng.random((max(4 * n, 64), 2))
            rad, ang = r * np.sqrt(u[:, 0]), 2.0 * np.pi * u[:, 1]
            pts = position + rad[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
            pts = pts[self.feasible(pts, state, targets, rho)]
            got.append(pts)
            count += len(pts)
        pts = np.concatenate(got)[:n] if got else np.empty((0, 2))
        if len(pts) < n:
            edge = self.boundary(state, targets, rho, max(r, 1e-300) / 256)
            if len(edge):
                extra = edge[rng.integers(len(edge), size=n - len(pts))]
            else:
                extra = np.tile(self.project(position, state, targets, rho), (n - len(pts), 1))
            pts = np.concatenate([pts, extra])
        return pts

    def project(
        self, wanted: FloatArray, position: FloatArray, targets: FloatArray, rho: float
    ) -> FloatArray:
        """Return the point of ``F`` nearest to ``wanted`` (2,); ``wanted`` when feasible.

        Candidates: ``wanted``, its :meth:`clip`, its radial projection onto each ``rho``
        circle (clipped), and :meth:`boundary` at spacing ``radius / 4096``; the nearest
        feasible one. With ``F`` empty: the candidate among ``position`` and the reach
        set's boundary that violates eq. (16) least (largest ``min_k |s - t_k| - rho``).
        A sensor that cannot move (``radius`` 0) stays.
        """
        q, state = _f64(wanted).reshape(2), _f64(position).reshape(-1)
        position = state[:2]
        targets = _f64(targets).reshape(-1, 2)
        r = float(self.radius)
        if not r > 0.0:
            return position.copy()
        e = q - targets
        d = np.hypot(e[:, 0], e[:, 1])
        toward = np.where(d[:, None] > 0, e / np.where(d > 0, d, 1.0)[:, None], [1.0, 0.0])
        radial = targets + rho * toward
        # Exact answers first: q itself; the nearest point of R when feasible (no point of F
        # is nearer); q in R inside disk k: the nearest point outside disk k when feasible.
        quick = np.concatenate([q[None], self.clip(q, state)[None]])
        if self.reaches(q, state):
            quick = np.concatenate([quick, radial[d < rho]])
        ok = self.feasible(quick, state, targets, rho)
        if np.any(ok):
            return quick[int(np.argmax(ok))].copy()
        radial = self.clip(radial, state)
        spacing = r * PROJECT_SPACING
        cand = np.concatenate(
            [q[None], self.clip(q, state)[None], radial,
             self.boundary(state, targets, rho, spacing)]
        )  # fmt: skip
        ok = self.feasible(cand, state, targets, rho)
        if np.any(ok):
            cand = cand[ok]
            return cand[int(np.argmin(np.hypot(*(cand - q).T)))].copy()
        rim = np.concatenate([position[None], self.reach_boundary(state, spacing)])
        g = rim[:, None, :] - targets
        margin = np.min(np.hypot(g[..., 0], g[..., 1]), axis=-1) - rho
        return rim[int(np.argmax(margin))].copy()

    def __repr__(self) -> str:
        return f"{type(self).__name__}(radius={self.radius!r})"
