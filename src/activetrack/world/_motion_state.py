"""The sensors' states beyond their positions, kept by the world (a mixin of
:class:`activetrack.world.World`).

A kinematics whose ``state_dim`` exceeds 2 (a heading, a velocity: module docstring of
:mod:`activetrack.kinematics.base`) moves more than a point. The world then keeps, per copy
and per sensor, the state beyond the position in the field ``motion`` (N, M, S - 2)
(``World.get("motion")``; ``S`` the team's largest ``state_dim``, a sensor with fewer
entries zero-padded), and:

- **reset**: each sensor's :meth:`~activetrack.Kinematics.initial_state` at its start
  position, facing the centroid of the targets' prior means ``x0_hat`` (a unicycle's
  heading points at it, a double integrator's velocity is zero);
- **step**: the team's move (:meth:`activetrack.kinematics.team.TeamMotion.move`) from the
  states made of the position fixes and ``motion``: the new state is
  :meth:`~activetrack.Kinematics.advance` of the agent's action, or of the
  :meth:`~activetrack.Kinematics.command` of the point the sensor went to when the move was
  clipped, projected out of a ``rho`` disk or asked as an absolute position; a move an
  occluder stopped short keeps the occluder rule's position, and its state beyond the
  position is that of the command reaching the nearest reachable point to it;
- **readers**: :meth:`MotionState.sensor_states` (positions and ``motion`` together), the
  planning problem's ``sensor_states``, and the agents' observations and the global state,
  which end with each sensor's :meth:`~activetrack.Kinematics.features` (the heading as
  ``(cos, sin)``, the velocity over the top speed; :mod:`activetrack.world.observation`).

A world whose sensors all have ``state_dim = 2`` (the paper's disks, any kinematics of
the position alone) has no ``motion`` field and runs exactly as before.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.validation import FloatArray


class MotionState:
    """The world's bookkeeping of the sensors' states beyond their positions."""

    def _motion_setup(self, state: dict[str, Any]) -> None:
        """Add the ``motion`` field (M, S - 2) to one copy's initial ``state`` if the team
        carries a state beyond the position; remember its size."""
        team = self._team
        self._n_motion = 0 if team is None else team.state_dim - 2
        self._motion_next: FloatArray | None = None
        if self._n_motion:
            state["motion"] = np.zeros((self.n_sensors, self._n_motion))

    def _motion_start(self, new: dict[str, Any], sensors: FloatArray) -> None:
        """Put the reset copies' initial ``motion`` into ``new``, from the true start
        positions ``sensors`` (..., M, 2)."""
        if self._n_motion:
            toward = np.mean([x[:2] for x in self._x0_hats], axis=0)
            new["motion"] = self._team.initial(sensors, toward)[..., 2:]

    def _move_sensors(
        self, move: Any, moves: FloatArray, sensors: FloatArray, fixes: FloatArray,
        where: FloatArray, calc: Any,
    ) -> tuple[FloatArray, np.ndarray]:  # fmt: skip
        """Return ``(moved, projected)``: the sensors' next believed positions from the
        proposed ``moves`` (the disk's compiled ``move``, or the team's), then kept out of
        the occluders; the next ``motion`` of the copies ``calc`` is kept for
        :meth:`_motion_store`."""
        p = self.params
        if self._team is None:
            moved, projected = move(moves, fixes, where, p.r, p.rho)
        elif not self._n_motion:
            moved, projected = self._team.of(move)(moves, fixes, where, p.r, p.rho)
        else:
            from activetrack.kinematics import sensor_motion  # noqa: PLC0415

            states = self._team.states(fixes, self._s["motion"][calc])
            moved, projected, nxt = self._team.move(
                move is sensor_motion.move_to, moves, states, where, p.rho
            )
        if self._occ is not None:  # no move ends in or passes through an occluder
            free = moved
            moved, projected = self._around_occluders(sensors, fixes, moved, projected)
            if self._n_motion:
                stopped = np.any(moved != free, axis=-1)
                if np.any(stopped):  # the state of the nearest reachable point
                    near = moved.copy()
                    for idx in zip(*np.nonzero(stopped), strict=True):
                        kin = self._team.team[idx[-1]]
                        st = states[idx][: kin.state_dim]
                        near[idx] = kin.clip(moved[idx], st)
                    redo = self._team.restate(near, states)
                    nxt[stopped] = redo[stopped]
                    nxt[..., :2] = moved
        if self._n_motion:
            self._motion_next = nxt[..., 2:]
        return moved, projected

    def _motion_store(self, new: dict[str, Any], sel: Any, partial: bool) -> None:
        """Put the stepped copies' next ``motion`` into the step's results ``new``."""
        if self._n_motion:
            nxt = self._motion_next
            new["motion"] = nxt[sel] if partial else nxt

    def sensor_states(self, index: int | None = None) -> FloatArray:
        """Return the sensors' states (N, M, S), or (M, S) for copy ``index``: the position
        fixes, then ``motion`` (S = 2, the fixes alone, when no sensor carries more)."""
        fixes = self.get("fixes", index)
        if not self._n_motion:
            return np.array(fixes)
        return self._team.states(fixes, self.get("motion", index))

    def _motion_features(self, index: int | None) -> FloatArray | None:
        """Return every sensor's observed features (..., M, F), or None (no features)."""
        if self._team is None or not self._team.n_features:
            return None
        return self._team.features(self.sensor_states(index))
