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
  clipped, projected out of a ``rho`` disk or asked as an absolute position; among
  occluders, a move whose path (the arc, the parabola) meets one goes to another point
  the sensor reaches, by the rule of :mod:`activetrack.kinematics.path_rule` (its state
  that of the command reaching it);
- **readers**: :meth:`MotionState.sensor_states` (positions and ``motion`` together), the
  planning problem's ``sensor_states``, and the agents' observations and the global state,
  which end with each sensor's :meth:`~activetrack.Kinematics.features` (the heading as
  ``(cos, sin)``, the velocity over the top speed; :mod:`activetrack.world.observation`).

With a minimum separation (``d_sep > 0``) the moves then go through the team rule: the
disks' closed form (:class:`activetrack.kinematics.separation.Separation`) with known
positions and no occluders, else the same rule along each sensor's actual path, on the
TRUE positions (:class:`activetrack.kinematics.path_rule.PathRule`: any kinematics,
occluders, ``pose_cov``); the world keeps per copy the
step's ``collisions`` (pairs of wanted points closer than their distance, before the
rule), their episode count ``n_collisions``, the sensors the rule kept in place for want
of a feasible point (``n_stuck``) and the smallest pairwise distance after the step
``min_separation`` (:meth:`MotionState.separation_info`, in the environments' infos).

A world whose sensors all have ``state_dim = 2`` (the paper's disks, any kinematics of
the position alone) has no ``motion`` field and runs exactly as before.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.kinematics.separation import min_separation, separated_starts
from activetrack.validation import FloatArray


def rule_of(sc: Any, team: Any, sep: Any, occ: Any, pose: bool) -> Any:
    """Return the world's :class:`activetrack.kinematics.path_rule.PathRule`, or None when
    the moves need none: no separation and no occluders, the disks' own rules (known
    positions, no occluders: :class:`~activetrack.kinematics.separation.Separation`;
    occluders alone: straight moves), or another kinematics without either."""
    disks = team is None
    if sep is None and (disks or occ is None):
        return None
    if sep is not None and disks and occ is None and not pose:
        return None
    from activetrack.kinematics.path_rule import PathRule  # noqa: PLC0415

    return PathRule(sc.kinematics_models, None if sep is None else sep.d)


#: The state fields of the team rule of a minimum separation.
SEPARATION_FIELDS = ("collisions", "n_collisions", "n_stuck", "min_separation")


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
        self._sep_next: tuple | None = None
        self._rule = rule_of(self.scenario, self._team, self._sep, self._occ, self._pose)
        if self._sep is not None:
            state.update(collisions=0, n_collisions=0, n_stuck=0, min_separation=np.inf)

    def _motion_start(self, new: dict[str, Any], sensors: FloatArray) -> None:
        """Put the reset copies' initial ``motion`` into ``new``, from the true start
        positions ``sensors`` (..., M, 2)."""
        if self._n_motion:
            toward = np.mean([x[:2] for x in self._x0_hats], axis=0)
            new["motion"] = self._team.initial(sensors, toward)[..., 2:]
        if self._sep is not None:
            low = min_separation(sensors)
            new.update(collisions=0, n_collisions=0, n_stuck=0,
                       min_separation=float(low) if np.ndim(low) == 0 else low)  # fmt: skip

    def _separated_starts(self, sensors: FloatArray, rows: np.ndarray, one: bool) -> FloatArray:
        """Return the start positions ``sensors`` ((M, 2) for ``one`` copy, else (R, M, 2)
        of the copies ``rows``) with each sensor too close to an earlier one drawn again
        from its copy's generator (:func:`activetrack.kinematics.separation.separated_starts`),
        outside the occluders."""
        out = np.array(sensors)
        for j, i in enumerate(rows.tolist()):
            rng = self.rng(i)
            row = out if one else out[j]
            occ = self._occ
            if occ is not None and not one and occ.batched:
                occ = occ[i]

            def redraw(rng=rng, occ=occ):
                return self._free_start(rng, occ)

            row[...] = separated_starts(row, self._sep.d, redraw)
        return out

    def _free_start(self, rng: np.random.Generator, occ: Any) -> FloatArray:
        """Return a fresh start (2,) drawn from ``rng``, outside the occluders ``occ``."""
        for _ in range(1000):
            pt = self._start_positions(rng.random(2))
            if occ is None:
                return pt
            from activetrack.models import occluders  # noqa: PLC0415

            if not occluders.inside(pt, occ):
                return pt
        raise ValueError("occluders cover the sensors' start disk: no start outside them found")

    def _move_sensors(
        self, move: Any, moves: FloatArray, sensors: FloatArray, fixes: FloatArray,
        where: FloatArray, calc: Any,
    ) -> tuple[FloatArray, np.ndarray]:  # fmt: skip
        """Return ``(moved, projected)``: the sensors' next believed positions from the
        proposed ``moves`` (the disk's compiled ``move``, or the team's), then kept out of
        the occluders and apart (the team rules); the next ``motion`` of the copies
        ``calc`` is kept for :meth:`_motion_store`."""
        p = self.params
        nxt = states = None
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
        if self._occ is not None and self._team is None:  # disks: straight moves, exact
            moved, projected = self._around_occluders(sensors, fixes, moved, projected)
        if self._rule is not None:  # along the actual paths (path_rule)
            moved, projected, nxt = self._by_path_rule(
                moved, projected, sensors, fixes, states, nxt, where
            )
        elif self._sep is not None:  # the disks' rule, sensor after sensor (known poses)
            moved, collisions, stuck = self._sep.resolve(fixes, moved, where, p.r, p.rho)
            self._sep_next = (collisions, np.count_nonzero(stuck, -1), min_separation(moved))
        if self._n_motion:
            self._motion_next = nxt[..., 2:]
        return moved, projected

    def _by_path_rule(
        self, moved: FloatArray, projected: np.ndarray, sensors: FloatArray,
        fixes: FloatArray, states: FloatArray | None, nxt: FloatArray | None,
        where: FloatArray,
    ) -> tuple[FloatArray, np.ndarray, FloatArray | None]:  # fmt: skip
        """Return ``(moved, projected, next states)`` after
        :class:`activetrack.kinematics.path_rule.PathRule` (the TRUE positions
        ``sensors`` apart and out of the occluders; the fixes' errors carried along)."""
        one = moved.ndim == 2
        lift = (lambda a: a[None]) if one else (lambda a: a)  # noqa: E731
        shift = lift(fixes - sensors) if self._pose else None
        want = lift(moved) if shift is None else lift(moved) - shift
        true = lift(np.array(sensors, np.float64))
        if states is None:
            st, nx = true, want.copy()
        else:
            st = lift(np.array(states))
            st[..., :2] = true
            nx = lift(nxt)
        tg = lift(where[..., None, :] if where.ndim == moved.ndim - 1 else where)
        new, nx, coll, stuck, changed = self._rule.resolve(
            true, want, st, nx, tg, self.params.rho, shift, self._occ
        )
        if self._sep is not None:
            low = min_separation(new)
            self._sep_next = tuple(
                v[0] if one else v for v in (coll, np.count_nonzero(stuck, -1), low)
            )
        out = new
        if one:
            out, changed, nx = out[0], changed[0], nx[0]
        if self._pose:  # back to the believed frame (the fix plus the displacement)
            out = fixes + (out - sensors)
        return out, projected | changed, None if states is None else nx

    def _motion_store(self, new: dict[str, Any], sel: Any, partial: bool) -> None:
        """Put the stepped copies' next ``motion`` into the step's results ``new``."""
        if self._n_motion:
            nxt = self._motion_next
            new["motion"] = nxt[sel] if partial else nxt
        if self._sep is not None:
            coll, stuck, low = (v[sel] if partial else v for v in self._sep_next)
            st = self._s
            n_coll, n_stuck = (st["n_collisions"], st["n_stuck"]) if self._one else (
                st["n_collisions"][sel], st["n_stuck"][sel])  # fmt: skip
            if self._one:
                coll, stuck, low = int(coll), int(stuck), float(low)
            new.update(collisions=coll, n_collisions=n_coll + coll, n_stuck=n_stuck + stuck,
                       min_separation=low)  # fmt: skip

    def separation_info(self, index: int) -> dict[str, Any]:
        """Return copy ``index``'s :data:`SEPARATION_FIELDS` as Python numbers (an empty
        dict without ``d_sep``): what an environment's infos add."""
        if self._sep is None:
            return {}
        get = self._s.__getitem__ if self._one else (lambda key: self._s[key][index])
        return {key: get(key).item() if hasattr(get(key), "item") else get(key)
                for key in SEPARATION_FIELDS}  # fmt: skip

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
