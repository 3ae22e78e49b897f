"""The world's team rules along the paths sensors actually travel: :class:`PathRule`.

The paper's disks, with known positions and no occluders, keep the separation ``d_sep`` by
:class:`activetrack.kinematics.separation.Separation` (straight moves, closed forms). Every
other team goes through this rule, the same rule along each sensor's own path
(:mod:`activetrack.kinematics.paths`: a unicycle's arc, a double integrator's parabola, a
disk's segment): any :class:`~activetrack.Kinematics`, with occluders, with uncertain
position fixes (``pose_cov``), and with occluders alone (``d_sep = 0``) for a kinematics
whose moves are not straight.

**The rule (sequential moves in agent order, along the actual paths).** After the usual
move (each sensor's kinematics clips its wanted point and moves it out of the ``rho``
disks) gives each sensor a wanted end point ``w_i`` (reachable, so with a command and a
path), the sensors move one after the other, 0 to M-1. When sensor i moves, sensors
0..i-1 stand at their new positions and i+1..M-1 at their old ones. A reachable point
``p`` is *feasible* for i when the path i travels to it (:func:`~activetrack.kinematics.
paths.path`, checked between its samples too: :func:`~activetrack.kinematics.paths.slack`,
:func:`~activetrack.kinematics.paths.hull_segments`):

- keeps ``d_ij`` from every other sensor where it stands (so no two sensors are closer
  than ``d_ij`` after the step, and none passes through another within it);
- neither enters nor crosses an occluder (:func:`activetrack.models.occluders.blocked` of
  the path's pieces);
- ends at least ``rho`` from every predicted target.

- **the same instant**: keeps ``d_ij`` from every earlier sensor j < i along both
  executed paths at every instant of the step (the robots move together): the relative
  path ``p_i(t) - p_j(t)``, sampled at the same instants, keeps ``d_ij`` from the origin,
  between the samples too (its deviation from the straight pieces is at most the sum of
  the two paths' :func:`~activetrack.kinematics.paths.slack`); a sensor held where it is
  has the constant path. (For a later sensor, still where it stands, this is the first
  condition.)

Sensor i goes to ``w_i`` (with the state of its own move) when it is feasible; else to
the feasible candidate nearest to ``w_i`` (the first in this order on ties) among: its
position when the kinematics can stay (a disk, a unicycle with ``v_min = 0``), the points
``o_i + f (w_i - o_i)`` for ``f = 1/16 .. 15/16`` clipped to the reach set (for a
unicycle: the same turn at a lower speed), the end points of a 9 x 9 grid of the agent's
action box (:meth:`~activetrack.Kinematics.apply`), and those of 32 points on each ``rho``
circle the sensor reaches. Every candidate is a point the kinematics reaches; the sensor's
state after the step is :meth:`~activetrack.Kinematics.advance` of the
:meth:`~activetrack.Kinematics.command` reaching it (its position exactly the point), so
heading and velocity stay those of a move the robot can make; a unicycle whose pick is
its own position turns in place as its wanted move turns (a turn moves no point of it,
so it keeps every rule; a robot facing a wall comes to face a way out). When no candidate is
feasible it takes the candidate that keeps the separation and the occluders and lies
deepest out of the ``rho`` disks, and counts as ``stuck``.

**Staying is always safe.** Every sensor's path was checked against the old positions of
the sensors after it, at every instant, and a team starts separated, outside the
occluders; so standing still keeps every rule but ``rho``. A kinematics that can stay
has its position among the candidates. **A robot that cannot stop** (a unicycle with
``v_min > 0``, a fixed wing; a double integrator moving faster than it can brake in one
step), with no candidate that keeps the separation and the occluders, is *held* where it
is: its position does not change (an emergency stop beyond its limits, for a fixed wing
a loiter too tight to matter at this scale: the one move that always keeps the team
safe); a unicycle's heading turns as its wanted move turns (so a robot facing a wall or
a neighbour can come to face a way out), a double integrator's velocity is set to zero,
any other state beyond the position is kept; it counts as ``stuck``. Every step is thus
deterministic.

**Uncertain positions (``pose_cov``).** The separation and the occluders are physical:
the rule acts on the TRUE positions. The agent's move is a displacement from where it
believes it is (its fix); the true sensor makes the same displacement (the same path,
shifted), and the rule checks that true path against the other sensors' true positions
and the occluders. The ``rho`` disks are about the predicted targets, in the frame the
sensor plans in: the end point's believed position (true plus the fix's error) keeps
``rho``. A move the rule changes changes the believed position by the same displacement.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.kinematics.base import TOL
from activetrack.kinematics.double_integrator import DoubleIntegrator
from activetrack.kinematics.paths import N_PATH, hull_of, path, point_distances, slack
from activetrack.kinematics.unicycle import Unicycle
from activetrack.validation import FloatArray

#: The fallback candidates: fractions of the wanted move, the action grid per axis, and
#: the points per ``rho`` circle.
N_FRACTIONS = 16
N_GRID = 9
N_RING = 32
_RING_OUT = 1e-9  # the rho circles' points aim this (relative) outside
_END_MARGIN = 1e-9  # (relative) an end point this much within d_ij fails without its path


def restate(kin: Any, points: FloatArray, state: FloatArray) -> FloatArray:
    """Return the state (..., ``state_dim``) after ``kin`` moves from ``state`` to the
    reachable ``points`` (..., 2): ``advance(command(points))``, the position exactly
    ``points``."""
    st = np.asarray(state, np.float64)
    q = np.asarray(points, np.float64)
    out = np.array(np.broadcast_to(st, np.broadcast_shapes(st.shape, q.shape[:-1] + st.shape[-1:])))
    if kin.state_dim > 2:
        out[...] = kin.advance(kin.command(q, st), st)
    out[..., :2] = q
    return out


def held(kin: Any, state: FloatArray, wanted: FloatArray) -> FloatArray:
    """Return the state of a sensor held where it is (module docstring): ``state`` with a
    double integrator's velocity zero, and a unicycle's heading that of its ``wanted``
    move's state (it turns as asked, so it can come to face a way out)."""
    out = np.array(state, np.float64)
    if isinstance(kin, DoubleIntegrator):
        out[..., 2:4] = 0.0
    elif isinstance(kin, Unicycle):
        out[..., 2] = np.asarray(wanted, np.float64)[..., 2]
    return out


def together(samples: FloatArray, paths: FloatArray, slacks: FloatArray, d: FloatArray):
    """Return whether the paths through ``samples`` (B, C, n + 1, 2) keep the distances
    ``d`` (J,) from the paths through ``paths`` (B, J, n + 1, 2) (sampled at the same
    instants; ``slacks`` (B, J) their :func:`~activetrack.kinematics.paths.slack`) at
    every same instant, between the samples too (module docstring), (B, C)."""
    rel = samples[:, :, None] - paths[:, None]  # (B, C, J, n + 1, 2)
    a, u = rel[..., :-1, :], rel[..., 1:, :] - rel[..., :-1, :]
    den = np.sum(u * u, -1)
    t = np.clip(-np.sum(a * u, -1) / np.where(den > 0.0, den, 1.0), 0.0, 1.0)
    e = a + t[..., None] * u  # each piece's point nearest the origin
    low = np.sqrt(np.min(np.sum(e * e, -1), axis=-1))
    low = low - slack(samples)[:, :, None] - slacks[:, None]
    return np.all(low >= d, axis=-1)


class PathRule:
    """The world's rule (module docstring) for a team of kinematics ``team`` (M) and pair
    distances ``d`` (M, M) (zeros: the occluders alone)."""

    def __init__(self, team: tuple[Any, ...], d: FloatArray, n: int = N_PATH) -> None:
        self.team = tuple(team)
        m = len(self.team)
        self.d = np.zeros((m, m)) if d is None else np.asarray(d, np.float64)
        self.n = n
        self._others = [np.array([j for j in range(m) if j != i], dtype=np.int64) for i in range(m)]
        self._frac = np.arange(1, N_FRACTIONS)[:, None] / N_FRACTIONS
        ang = 2.0 * np.pi * np.arange(N_RING) / N_RING
        self._dirs = np.stack([np.cos(ang), np.sin(ang)], -1)
        self._grids = []
        for kin in self.team:
            lo, hi = np.asarray(kin.action_low, float), np.asarray(kin.action_high, float)
            axes = (np.linspace(lo[k], hi[k], N_GRID) for k in range(2))
            g0, g1 = np.meshgrid(*axes)
            self._grids.append(np.stack([g0.ravel(), g1.ravel()], -1))

    def resolve(
        self, old: FloatArray, want: FloatArray, states: FloatArray, nxt: FloatArray,
        targets: FloatArray, rho: FloatArray, shift: FloatArray | None = None, occ: Any = None,
    ) -> tuple[FloatArray, FloatArray, FloatArray, np.ndarray, np.ndarray]:  # fmt: skip
        """Return ``(new, next_states, collisions, stuck, changed)`` of copies (B) of the
        team: from the TRUE positions ``old`` (B, M, 2) and states ``states`` (B, M, S),
        the wanted reachable end points ``want`` (B, M, 2) (true frame) and the states
        ``nxt`` (B, M, S) after them, the predicted targets ``targets`` (B, K, 2) (believed
        frame), ``rho`` (M,), the fixes' errors ``shift`` (B, M, 2) (believed minus true;
        None: known positions) and the occluders ``occ`` (None: none; batched: one layout
        per copy): the positions (true frame) and states after the rule, the pairs of
        ``want`` closer than ``d`` (B,), the sensors that found no feasible point (B, M)
        and those the rule moved elsewhere than ``want`` (B, M)."""
        from activetrack.kinematics.separation import violations  # noqa: PLC0415

        old, want = np.asarray(old, np.float64), np.asarray(want, np.float64)
        states = np.asarray(states, np.float64)
        targets = np.asarray(targets, np.float64)
        b_n, m = want.shape[:2]
        collisions = violations(want, self.d)
        new, nxt = old.copy(), np.array(nxt, np.float64)
        stuck = np.zeros((b_n, m), bool)
        changed = np.zeros((b_n, m), bool)
        rho = np.broadcast_to(np.asarray(rho, np.float64), (m,))
        # The executed paths (B, M, n + 1, 2) and their slacks (B, M), sensor after sensor.
        ex = np.zeros((b_n, m, self.n + 1, 2))
        ex_slack = np.zeros((b_n, m))
        for i, kin in enumerate(self.team):
            js = self._others[i]
            st = states[:, i, : kin.state_dim]
            obst = np.where((js < i)[None, :, None], new[:, js], old[:, js])
            tg = targets if shift is None else targets - shift[:, i, None, :]
            early = np.flatnonzero(self.d[i, :i] > 0.0)
            moving = (ex[:, early], ex_slack[:, early], self.d[i, early]) if early.size else None
            sep, clear_occ, clear = self._check(
                kin, st, want[:, i, None], obst, self.d[i, js], tg, float(rho[i]), occ, moving
            )
            ok = (sep & clear_occ & (clear >= 0.0))[:, 0]
            new[ok, i] = want[ok, i]
            bad = np.flatnonzero(~ok)  # (the few moves that break a rule)
            if bad.size:
                occ_b = occ[bad] if occ is not None and occ.batched else occ
                mv = None if moving is None else tuple(v[bad] for v in moving[:2]) + moving[2:]
                pt, state, stuck[bad, i], hold = self._fallback(
                    kin, i, st[bad], want[bad, i], obst[bad], self.d[i, js], tg[bad],
                    float(rho[i]), occ_b, nxt[bad, i, : kin.state_dim], mv,
                )  # fmt: skip
                new[bad, i] = pt
                nxt[bad, i, : kin.state_dim] = state
                changed[bad, i] = True
            if np.any(self.d[i, i + 1 :] > 0.0):  # a later sensor checks against this path
                ex[:, i] = path(kin, new[:, i], st, self.n)
                if bad.size:  # held: the constant path
                    ex[bad[hold], i] = st[bad[hold], None, :2]
                ex_slack[:, i] = slack(ex[:, i])
        return new, nxt, collisions, stuck, changed

    def _check(
        self, kin: Any, st: FloatArray, pts: FloatArray, obst: FloatArray, dij: FloatArray,
        tg: FloatArray, rho: float, occ: Any, moving: Any = None,
    ) -> tuple[np.ndarray, np.ndarray, FloatArray]:  # fmt: skip
        """Return ``(separated, clear of occluders (where separated), rho clearance)``
        (B, C) of the moves of a sensor of states ``st`` (B, S) to the reachable ``pts``
        (B, C, 2): its path keeps ``dij`` (J,) from ``obst`` (B, J, 2); meets no occluder;
        and, given ``moving = (paths (B, J2, n + 1, 2), slacks (B, J2), distances (J2,))``
        of the earlier sensors, keeps those distances from their paths at the same
        instants; and the end point's distance to the nearest of ``tg`` (B, K, 2) less
        ``rho`` (with the tolerance; inf without ``rho``)."""
        keep = dij > 0.0
        shape = pts.shape[:-1]
        clear = np.full(shape, np.inf)
        if rho > 0.0:
            e = pts[:, :, None, :] - tg[:, None, :, :]
            clear = np.min(np.hypot(e[..., 0], e[..., 1]), axis=-1) - rho * (1.0 - TOL)
        if not np.any(keep) and occ is None:
            return np.ones(shape, bool), np.ones(shape, bool), clear
        sep = np.ones(shape, bool)
        if np.any(keep):  # an end point within d_ij: the path is not farther (a margin
            # for the rounding of the path's last piece), no path needed
            e = pts[:, :, None, :] - obst[:, None, keep]
            sep = np.all(np.hypot(e[..., 0], e[..., 1]) >= dij[keep] * (1.0 - _END_MARGIN), -1)
        rows, cols = np.nonzero(sep)  # the paths are sampled for these candidates alone
        fine = path(kin, pts[rows, cols], st[rows], 2 * self.n)  # (L, 2n + 1, 2)
        live = np.ones(len(rows), bool)
        if np.any(keep):
            dist = point_distances(fine[:, ::2, :], obst[rows][:, keep])  # (L, J')
            live = np.all(dist >= dij[keep], axis=-1)
        if moving is not None and np.any(live):  # (the candidates still separated alone)
            paths_m, slacks_m, d_m = moving
            at = np.flatnonzero(live)
            live[at] = together(fine[at, None, ::2, :], paths_m[rows[at]], slacks_m[rows[at]],
                                d_m)[:, 0]  # fmt: skip
        sep[rows, cols] = live
        clear_occ = np.ones(shape, bool)  # (decides nothing where not separated)
        if occ is not None and np.any(live):
            from activetrack.models import occluders  # noqa: PLC0415

            at = np.flatnonzero(live)
            a, b = hull_of(fine[at])  # (L', 3n, 2)
            clear_occ[rows[at], cols[at]] = ~occluders.path_blocked(
                a, b, occ[rows[at]] if occ.batched else occ
            )
        return sep, clear_occ, clear

    def _fallback(
        self, kin: Any, i: int, st: FloatArray, w: FloatArray, obst: FloatArray,
        dij: FloatArray, tg: FloatArray, rho: float, occ: Any, wanted: FloatArray,
        moving: Any = None,
    ) -> tuple[FloatArray, FloatArray, np.ndarray, np.ndarray]:  # fmt: skip
        """Return ``(points, states, stuck, held)`` (F, 2), (F, S), (F,), (F,) of sensor
        ``i`` in the copies (F) of states ``st`` (F, S) wanting ``w`` (F, 2) (the wanted
        move's state ``wanted``; the earlier sensors' paths ``moving``, see
        :meth:`_check`): the feasible candidate nearest ``w``; else the safe one deepest
        out of the ``rho`` disks; else held (module docstring)."""
        f_n, sd = st.shape
        o = st[:, :2]
        frac = o[:, None] + self._frac * (w - o)[:, None]  # (F, 15, 2)
        grid = self._grids[i]
        parts = [
            o[:, None],
            frac,
            kin.apply(grid, np.broadcast_to(st[:, None], (f_n, len(grid), sd))),
        ]
        if rho > 0.0:
            ring = (tg[:, :, None, :] + rho * (1.0 + _RING_OUT) * self._dirs).reshape(f_n, -1, 2)
            parts.append(ring)
        c = np.concatenate(parts, 1)  # (F, C, 2)
        full = np.broadcast_to(st[:, None], c.shape[:-1] + (sd,))
        reach = kin.reaches(c, full)
        n_frac = frac.shape[1]
        far = ~reach[:, 1 : 1 + n_frac]  # the fractions beyond the reach: clipped
        if np.any(far):
            fr = c[:, 1 : 1 + n_frac]
            fr[far] = kin.clip(fr[far], full[:, 1 : 1 + n_frac][far])
            c[:, 1 : 1 + n_frac] = fr
        # Valid: the position when the kinematics can stay, the fractions and the grid
        # (points it reaches by construction), the rho circles' points it reaches.
        valid = np.ones(c.shape[:-1], bool)
        valid[:, 0] = reach[:, 0]
        if rho > 0.0:
            valid[:, 1 + n_frac + len(grid) :] = reach[:, 1 + n_frac + len(grid) :]
        valid &= np.all(np.isfinite(c), axis=-1)
        c = np.where(valid[..., None], c, o[:, None])  # (placeholders, never chosen)
        sep, clear_occ, clear = self._check(kin, st, c, obst, dij, tg, rho, occ, moving)
        safe = valid & sep & clear_occ
        feasible = safe & (clear >= 0.0)
        far_w = np.where(feasible, np.hypot(*np.moveaxis(c - w[:, None], -1, 0)), np.inf)
        best = np.argmin(far_w, axis=1)  # (the first on ties: the order above)
        deep = np.argmax(np.where(safe, clear, -np.inf), axis=1)
        found, any_safe = np.any(feasible, axis=1), np.any(safe, axis=1)
        pick = np.where(found, best, deep)
        rows = np.arange(f_n)
        pts = np.where((found | any_safe)[:, None], c[rows, pick], o)
        states = restate(kin, pts, st)
        hold = ~(found | any_safe)
        # A unicycle that stays (its own position the pick) turns in place as its wanted
        # move turns: a turn moves no point of it, so it keeps every rule, and a robot
        # facing a wall comes to face a way out instead of freezing.
        turn = hold | (pick == 0) if isinstance(kin, Unicycle) else hold
        if np.any(turn):
            states[turn] = held(kin, st[turn], wanted[turn])
        return pts, states, ~found, hold
