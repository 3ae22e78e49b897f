"""The lost sensors' approach among occluders and under the team rule (issue 36).

A sensor that sees no target from anywhere it can reach has a flat subproblem (its expected
information is 0 there), so relaxation leaves it where it stands; closing in is GSR's
tie-break (:func:`activetrack.baselines.gsr_numeric.relax`). Among buildings a straight
move to the predicted target stalls against the wall between them, and with the team rule
``d_sep`` a move must keep the pair conditions with the others' plans. :func:`approach`
moves each lost sensor, one sensor at a time (Gauss-Seidel, as the relaxation), toward the
nearest predicted target by the *geodesic* distance around the occluders
(:mod:`activetrack.models.roadmap`). Its candidates are the points that keep

- its kinematics: the end points of a grid of its action box, :data:`GRID` commands per
  axis and the :data:`FINE` ones (:meth:`~activetrack.Kinematics.apply`; the paper's disks are
  :class:`~activetrack.baselines.gsr_separation.RadiusDisk`);
- every target's ``rho`` disk (:func:`activetrack.baselines.gsr_command._outside`);
- the team rule with every other sensor's current plan, the same pair conditions GSR's
  subproblems keep (:func:`activetrack.baselines.gsr_separation.constraints`,
  :func:`activetrack.baselines.gsr_command.keeps`);
- the occluders: the end point is outside them and the path the sensor's kinematics
  travels meets none (the world's test, :func:`activetrack.kinematics.paths.hull_segments`;
  checked on the best candidates, :data:`TRIES` at a time, until one is clear).

A candidate's score looks one step further: the geodesic distance from the end point is
``|p - w| + rest`` (``w`` the first corner, or the target, its shortest path heads for),
and the score is ``min |q - w| + rest`` over ``p`` itself and the end points ``q`` of a
:data:`GRID_NEXT` x :data:`GRID_NEXT` grid of commands from the state after the move. The
next step ignores the occluders (``w`` is in sight of ``p``; what the score measures is
how well the state after the move is set to head for it): of two moves that shorten the
distance alike, a unicycle takes the one that leaves it facing its way out. The sensor
takes the best candidate (by score, then distance) if that beats its plan's (a lower
score, or the same and a shorter distance); otherwise it keeps its plan, which GSR found
feasible. Each move keeps the rule with the plans of the sensors before it (already moved)
and after it, so the team's plan keeps every pair condition.
"""

from __future__ import annotations

import numpy as np

from activetrack.baselines import gsr_command, gsr_separation
from activetrack.kinematics.path_rule import restate
from activetrack.kinematics.paths import hull_segments
from activetrack.models.occluders import Occluders, blocked, inside
from activetrack.models.roadmap import ROADMAPS
from activetrack.validation import FloatArray

#: Commands per axis of the grid of candidates over the action box.
GRID = 13
#: More commands per axis (fractions of the box), near its ends and its middle: the small
#: moves (a unicycle's slowest speeds, a disk's shortest steps) by which a sensor close to
#: a wall turns along it.
FINE = (1e-3, 1e-2, 0.49, 0.499, 0.501, 0.51, 0.99, 0.999)
#: Commands per axis of the next step's grid (the look-ahead of the score).
GRID_NEXT = 7
#: The paths of the candidates are checked for occluders this many at a time (best first).
TRIES = 8


def geodesic_to_targets(
    occ: Occluders | None, rows: np.ndarray, pts: FloatArray, targets: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return ``(distances, waypoints, rest)`` (R, P), (R, P, 2), (R, P): the geodesic
    distance from ``pts`` (R, P, 2) of copies ``rows`` to the nearest of their targets
    ``targets`` (R, K, 2) around ``occ`` (None: straight lines; batched: copy ``rows[j]``'s
    layout ``occ[rows[j]]``), the first point its shortest path heads for and the length
    beyond it (:meth:`activetrack.models.roadmap.Roadmap.paths`)."""
    out = np.full(pts.shape[:2], np.inf)
    way, rest = np.array(pts, np.float64), np.zeros(pts.shape[:2])
    K = targets.shape[1]
    if occ is None:
        for k in range(K):
            e = pts - targets[:, k, None, :]
            d = np.hypot(e[..., 0], e[..., 1])
            nearer = d < out
            out = np.where(nearer, d, out)
            way = np.where(nearer[..., None], targets[:, k, None, :], way)
        return out, way, rest
    groups = (
        [np.arange(len(rows))] if not occ.batched else [np.array([j]) for j in range(len(rows))]
    )
    for g in groups:
        roadmap = ROADMAPS.of(occ if not occ.batched else occ[int(rows[g[0]])])
        for k in range(K):
            d, w, r = roadmap.paths(pts[g], targets[g, k])
            nearer = d < out[g]
            out[g] = np.where(nearer, d, out[g])
            way[g] = np.where(nearer[..., None], w, way[g])
            rest[g] = np.where(nearer, r, rest[g])
    return out, way, rest


def next_states(kin, pts: FloatArray, state: FloatArray) -> FloatArray:
    """Return the states (..., S) after ``kin`` moves from ``state`` to the reachable
    ``pts`` (..., 2) (:func:`activetrack.kinematics.path_rule.restate`, the world's); a
    :class:`~activetrack.baselines.gsr_separation.RadiusDisk` keeps its radius."""
    pts = np.asarray(pts, np.float64)
    if isinstance(kin, gsr_separation.RadiusDisk):
        st = np.broadcast_to(state, pts.shape[:-1] + state.shape[-1:])
        return np.concatenate([pts, st[..., 2:]], -1)
    return restate(kin, pts, state)


def approach(
    kinematics, states: FloatArray, s: FloatArray, current: FloatArray, lost: np.ndarray,
    targets: FloatArray, rho: FloatArray, occ: Occluders | None, sep: FloatArray | None,
) -> FloatArray:  # fmt: skip
    """Return the plans (B, M, 2) with every ``lost`` (B, M) sensor moved (module
    docstring), the others' plans ``s`` (B, M, 2) unchanged.

    ``kinematics``: the M sensors' command-space kinematics, ``states`` (B, M, S) their
    states, ``current`` (B, M, 2) their positions, ``targets`` (B, K, 2) the predicted
    targets, ``rho`` (B, M), ``occ`` the occluders (one layout, or one per copy; None),
    ``sep`` the pair distances (M, M) of the team rule (None: no rule).
    """
    moved = np.array(s, np.float64)
    rule = None if sep is None else gsr_separation.constraints(sep, current, moved)
    t = np.union1d(np.linspace(0.0, 1.0, GRID), FINE)
    unit = np.stack(np.meshgrid(t, t, indexing="ij"), -1).reshape(-1, 2)
    t2 = np.linspace(0.0, 1.0, GRID_NEXT)
    unit2 = np.stack(np.meshgrid(t2, t2, indexing="ij"), -1).reshape(-1, 2)
    for i, kin in enumerate(kinematics):
        rows = np.flatnonzero(lost[:, i])
        if rows.size == 0:
            continue
        lo = np.asarray(kin.action_low, np.float64)
        hi = np.asarray(kin.action_high, np.float64)
        st = states[rows, i, : kin.state_dim][:, None, :]
        grid = np.asarray(kin.apply(lo + (hi - lo) * unit, st), np.float64)[..., :2]
        pts = np.concatenate([moved[rows, i, None, :], grid], 1)  # (R, 1 + P, 2): plan first
        ok = gsr_command._outside(pts, targets[rows], rho[rows, i])
        if rule is not None:
            caps, sweeps = rule(rows, i)
            ok &= gsr_command.keeps(pts, current[rows, i], caps, sweeps)
        lay = None if occ is None else (occ[rows] if occ.batched else occ)
        if lay is not None:
            ok &= ~inside(pts, lay)
        dist, way, rest = geodesic_to_targets(occ, rows, pts, targets[rows])
        # The next step's estimate: from the state after each candidate, the nearest its
        # kinematics then reaches to the candidate's waypoint. The state is the one the
        # world gives a sensor that moves to the point (a plan is a point: a turn in place
        # is none, the world keeps the heading of a sensor that stays).
        after = next_states(kin, pts, st)  # (R, 1 + P, S)
        far = np.asarray(kin.apply(lo + (hi - lo) * unit2, after[:, :, None, :]), np.float64)
        far = far[..., :2]  # (R, 1 + P, P2, 2)
        e = far - way[:, :, None, :]
        ahead = np.hypot(e[..., 0], e[..., 1])  # (the occluders ignored: a heading's worth)
        score = np.minimum(np.min(ahead, axis=-1), dist - rest) + rest
        score = np.where(np.isfinite(dist), score, np.inf)
        now, now_d = score[:, 0].copy(), dist[:, 0].copy()
        score = np.where(ok, score, np.inf)
        score[:, 0] = np.inf  # the plan is the fallback, not a candidate
        order = np.lexsort((dist, score), axis=1)  # (R, 1 + P): by score, then distance
        r_idx = np.arange(rows.size)[:, None]
        cand, c_s, c_d = pts[r_idx, order], score[r_idx, order], dist[r_idx, order]
        good = np.isfinite(c_s) & (
            (c_s < now[:, None]) | ((c_s == now[:, None]) & (c_d < now_d[:, None]))
        )
        # The paths of the best TRIES at a time, for the rows with none clear yet (sorted
        # by score, then distance, the good candidates come first in each row).
        clear = np.zeros(good.shape, bool)
        if lay is None:
            clear = good
        for lo_k in range(0, good.shape[1], TRIES):
            k = slice(lo_k, lo_k + TRIES)
            todo = np.flatnonzero(~clear.any(axis=1) & good[:, k].any(axis=1))
            if lay is None or todo.size == 0:
                break
            a, b = hull_segments(kin, cand[todo, k], st[todo])  # (R', T, 3n, 2)
            lay_t = lay[todo] if occ.batched else lay
            clear[todo, k] = good[todo, k] & ~np.any(blocked(a, b, lay_t), axis=-1)
        first = np.argmax(clear, axis=1)  # the best clear candidate
        take = clear[np.arange(rows.size), first]
        moved[rows[take], i] = cand[np.flatnonzero(take), first[take]]
    return moved
