"""The team rule of a minimum separation ``d_sep`` between any two sensors.

The scenario field ``d_sep`` (0: none, the paper) is a distance every pair keeps (one
number), or one radius per sensor (a tuple of M: sensors i and j keep ``d_i + d_j``).
:func:`converted` checks it, :func:`pair_distances` gives the (M, M) distances, and
:class:`Separation` is the world's rule that enforces it:

**The rule (sequential moves in agent order).** After the usual move (reach, ``rho``
disks) gives each sensor a wanted point ``w_i``, the sensors move one after the other,
0 to M-1. When sensor i moves, sensors 0..i-1 stand at their new positions and
i+1..M-1 at their old ones; i's *obstacles* are the disks of radius ``d_ij`` about them.
A point ``p`` is *feasible* for i when it lies within i's reach of its old position
``o_i``, outside every ``rho`` disk, the segment ``o_i -> p`` never comes within
``d_ij`` of an obstacle, and (**the same instant**) it keeps ``d_ij`` from every earlier
sensor j < i along both moves at every instant of the step: the robots move together,
each along its segment at constant speed, so the relative position
``(o_i - o_j) + t ((p - o_i) - (n_j - o_j))``, t in [0, 1], a segment, never comes within
``d_ij`` of the origin (a closed form; for a later sensor, still at ``o_j``, this is the
segment's own condition). So the sensors never pass through one another within the step,
neither in the sequential reading nor moving simultaneously. Sensor i goes to ``w_i`` when
it is feasible; else to the feasible candidate nearest to ``w_i`` (the first in a fixed
order on ties) among: the point where the segment ``o_i -> w_i`` first touches an
obstacle; the fractions ``o_i + k/32 (w_i - o_i)``, k = 31 .. 1 (the move cut short: the
largest fraction on this grid that keeps every condition, when one does); a polar grid of
its reach disk (:data:`N_RADII` radii x :data:`N_ANGLES` angles); and :data:`N_ANGLES`
points on each ``rho`` circle within reach. The old position ``o_i`` always keeps the
separation (a team that starts separated stays separated; every earlier sensor's segment
was checked against ``o_i`` at every instant), so the rule never fails it. When no candidate is
feasible (a sensor boxed in between a ``rho`` disk and its neighbours) it takes the
candidate that keeps the separation and lies deepest out of the ``rho`` disks (its old
position is one), and counts as ``stuck``. Every step is thus deterministic, and after it
no two sensors are closer than their ``d_ij``; a sensor inside a ``rho`` disk after a
step is one the world reports stuck.

This closed form is the rule of the paper's disks with known positions and no occluders.
Every other team (a unicycle, a double integrator, any kinematics; occluders; position
fixes with noise) keeps the same rule along each sensor's actual path, on the true
positions: :mod:`activetrack.kinematics.path_rule`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.validation import FloatArray, real_array

#: The polar grid of the fallback candidates: radii (fractions of the reach, 0 the old
#: position) and angles.
N_RADII = 8
N_ANGLES = 64
#: The fractions of the wanted move among the fallback candidates: k / N_FRACTIONS.
N_FRACTIONS = 32
#: Largest accepted ratio of the team's separation disks' area (radius ``d_ij / 2`` each)
#: to the start disk's (``sensor_radius`` plus that radius): random starts drawn one by
#: one find room well below random sequential packing's jamming density (about 0.55).
START_DENSITY_MAX = 0.25
#: Draws per sensor at a reset before it is declared impossible.
START_TRIES = 1000
_LENGTH_MAX = 1e9
_CONTACT = 1e-9  # the stop-short point aims this (relative) outside the contact


def converted(value: object, m: int) -> float | tuple[float, ...]:
    """Return the scenario field ``d_sep`` checked: a distance in [0, 1e9] for every pair,
    or a tuple of ``m`` radii in [0, 1e9] (a ``ValueError`` naming the field)."""
    arr = real_array("d_sep", value)
    if arr.ndim == 0:
        out: Any = float(arr)
    elif arr.shape == (m,):
        out = tuple(float(v) for v in arr)
    else:
        raise ValueError(
            f"d_sep must be one distance for every pair or {m} radii (one per sensor: a pair "
            f"keeps d_i + d_j), got shape {arr.shape}"
        )
    if not np.all((arr >= 0.0) & (arr <= _LENGTH_MAX)):
        raise ValueError(f"d_sep must lie in [0, {_LENGTH_MAX:g}], got {arr.tolist()!r}")
    return out


def pair_distances(d_sep: Any, m: int) -> FloatArray:
    """Return the (M, M) distances each pair keeps (zero diagonal)."""
    arr = np.asarray(d_sep, np.float64)
    d = np.full((m, m), float(arr)) if arr.ndim == 0 else arr[:, None] + arr[None, :]
    np.fill_diagonal(d, 0.0)
    return d


def check_scenario(sc: Any) -> None:
    """Raise ValueError naming ``d_sep`` when scenario ``sc`` cannot enforce its ``d_sep``:
    the team's start disk (radius ``sensor_radius``) too small for it
    (:data:`START_DENSITY_MAX`). Every kinematics, occluders and position fixes with
    noise are covered (:mod:`activetrack.kinematics.path_rule`)."""
    d_sep, m, sensor_radius = sc.d_sep, sc.n_sensors, sc.sensor_radius
    if m < 2 or not np.any(pair_distances(d_sep, m)):
        return
    d = pair_distances(d_sep, m)
    half = np.max(d, axis=1) / 2.0  # each sensor's own disk: half its largest distance
    density = float(np.sum(half**2) / (sensor_radius + np.max(half)) ** 2)
    if not density <= START_DENSITY_MAX:
        raise ValueError(
            f"d_sep={d_sep!r} does not fit the team's start: {m} sensors start in a disk of "
            f"sensor_radius={sensor_radius:g} (their separation disks would cover "
            f"{density:.3g} of it; at most {START_DENSITY_MAX:g}); lower d_sep or raise "
            "sensor_radius"
        )


def separated_starts(starts: FloatArray, d: FloatArray, redraw: Any) -> FloatArray:
    """Return start positions (M, 2) that keep the pair distances ``d``: ``starts`` with
    each sensor, in agent order, drawn again (``redraw()``: a fresh start) while it is
    closer than ``d_ij`` to a sensor j < i (a ``ValueError`` naming ``d_sep`` after
    :data:`START_TRIES` draws)."""
    out = np.array(starts, np.float64)
    for i in range(1, len(out)):
        for _ in range(START_TRIES):
            e = out[:i] - out[i]
            if np.all(np.hypot(e[:, 0], e[:, 1]) >= d[i, :i]):
                break
            out[i] = redraw()
        else:
            raise ValueError(f"d_sep: no start of sensor {i} kept it in {START_TRIES} draws")
    return out


def segment_distance(a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
    """Return the distance (...) from points ``c`` to the segments ``a -> b`` (..., 2)."""
    ab, ac = b - a, c - a
    den = np.sum(ab * ab, -1)
    t = np.clip(np.sum(ac * ab, -1) / np.where(den > 0.0, den, 1.0), 0.0, 1.0)
    e = ac - t[..., None] * ab
    return np.hypot(e[..., 0], e[..., 1])


def together(o: FloatArray, p: FloatArray, oj: FloatArray, pj: FloatArray) -> FloatArray:
    """Return the smallest distance (...) between two sensors moving at the same time,
    each straight at constant speed over the step, one from ``o`` to ``p``, the other from
    ``oj`` to ``pj`` (..., 2): the distance from the origin to the segment of their
    relative position ``(o - oj) -> (p - pj)``."""
    a = np.asarray(o, np.float64) - oj
    b = np.asarray(p, np.float64) - pj
    return segment_distance(a, b, np.zeros(np.broadcast_shapes(a.shape, b.shape)))


def min_separation(positions: FloatArray) -> FloatArray:
    """Return the smallest pairwise distance (...) of ``positions`` (..., M, 2) (inf: M=1)."""
    e = positions[..., :, None, :] - positions[..., None, :, :]
    dist = np.hypot(e[..., 0], e[..., 1])
    m = positions.shape[-2]
    dist[..., np.arange(m), np.arange(m)] = np.inf
    return np.min(dist, axis=(-2, -1))


def violations(positions: FloatArray, d: FloatArray) -> FloatArray:
    """Return the number (...) of pairs of ``positions`` (..., M, 2) closer than ``d``."""
    e = positions[..., :, None, :] - positions[..., None, :, :]
    close = np.hypot(e[..., 0], e[..., 1]) < d
    return np.count_nonzero(np.triu(close, 1), axis=(-2, -1))


class Separation:
    """The world's rule (module docstring) for pair distances ``d`` (M, M)."""

    def __init__(self, d: FloatArray) -> None:
        self.d = np.asarray(d, np.float64)
        m = len(self.d)
        ang = 2.0 * np.pi * np.arange(N_ANGLES) / N_ANGLES
        self._dirs = np.stack([np.cos(ang), np.sin(ang)], -1)  # (A, 2)
        fr = np.arange(N_RADII + 1) / N_RADII  # 0 (stay) .. 1 (the reach)
        self._grid = (fr[:, None, None] * self._dirs[None]).reshape(-1, 2)
        self._others = [np.array([j for j in range(m) if j != i]) for i in range(m)]
        self._frac = np.arange(N_FRACTIONS - 1, 0, -1)[:, None] / N_FRACTIONS

    def resolve(
        self, old: FloatArray, want: FloatArray, targets: FloatArray, r: FloatArray,
        rho: FloatArray,
    ) -> tuple[FloatArray, FloatArray, FloatArray]:  # fmt: skip
        """Return ``(new, collisions, stuck)``: the positions (..., M, 2) after the rule
        from the old ones and the wanted ``want`` (reachable, outside the ``rho`` disks of
        ``targets`` (..., K, 2) or (..., 2)); the pairs of ``want`` closer than ``d``
        (...); the sensors that found no feasible point (..., M) (boxed in)."""
        old, want = np.asarray(old, np.float64), np.asarray(want, np.float64)
        targets = np.asarray(targets, np.float64)
        if targets.ndim == want.ndim - 1:
            targets = targets[..., None, :]
        collisions = violations(want, self.d)
        m, batch = want.shape[-2], want.shape[:-2]
        o = old.reshape(-1, m, 2)
        w = want.reshape(-1, m, 2)
        tg = np.broadcast_to(targets, batch + targets.shape[-2:]).reshape(-1, *targets.shape[-2:])
        new = o.copy()
        stuck = np.zeros(w.shape[:-1], bool)
        for i in range(m):
            js = self._others[i]
            dij = self.d[i, js]
            ok = np.all(segment_distance(o[:, i, None], w[:, i, None], new[:, js]) >= dij, -1)
            ok &= np.all(together(o[:, i, None], w[:, i, None], o[:, js], new[:, js]) >= dij, -1)
            new[ok, i] = w[ok, i]
            for b in np.flatnonzero(~ok):  # (the few moves that would come too close)
                new[b, i], stuck[b, i] = self._fallback(
                    o[b, i], w[b, i], new[b, js], dij, tg[b], float(r[i]), float(rho[i]),
                    o[b, js],
                )  # fmt: skip
        return new.reshape(want.shape), collisions, stuck.reshape(want.shape[:-1])

    def _fallback(
        self, o: FloatArray, w: FloatArray, obst: FloatArray, dij: FloatArray,
        targets: FloatArray, r: float, rho: float, start: FloatArray | None = None,
    ) -> tuple[FloatArray, bool]:  # fmt: skip
        """Return sensor i's feasible candidate nearest to ``w`` and False; or, when none
        is feasible (boxed in), the candidate that keeps the separation and lies deepest
        out of the ``rho`` disks, and True (module docstring)."""
        c, ok, clear = self.candidates(o, w, obst, dij, targets, r, rho, start)
        g = c - w
        far = np.hypot(g[:, 0], g[:, 1])
        inside = ok & (clear >= 0.0)
        if np.any(inside):
            return c[inside][int(np.argmin(far[inside]))], False
        # Boxed in: the candidate keeping the separation deepest out of the rho disks.
        best = np.flatnonzero(ok)
        if not best.size:
            return o.copy(), True
        return c[best[int(np.argmax(clear[best]))]], True

    def candidates(
        self, o: FloatArray, w: FloatArray, obst: FloatArray, dij: FloatArray,
        targets: FloatArray, r: float, rho: float, start: FloatArray | None = None,
    ) -> tuple[FloatArray, np.ndarray, FloatArray]:  # fmt: skip
        """Return the rule's candidates (C, 2) for a sensor at ``o`` wanting ``w`` (module
        docstring), whether each is within the reach ``r`` with a path clear of the
        ``obst``acles (J, 2) by ``dij`` (J,) (and, given the obstacles' positions at the
        step's ``start`` (J, 2), clear of them moving straight to ``obst`` at the same
        instants), and each one's clearance of the ``rho`` disks of ``targets`` (K, 2)
        (inf when ``rho`` is 0; feasible: also >= 0)."""
        fr = o + self._frac * (w - o)
        cands = [self._contact(o, w, obst, dij)[None], fr, o + r * self._grid]
        if rho > 0.0:
            ring = (targets[:, None, :] + rho * (1.0 + _CONTACT) * self._dirs).reshape(-1, 2)
            cands.append(ring)
        c = np.concatenate(cands)
        e = c - o
        ok = np.hypot(e[:, 0], e[:, 1]) <= r
        seg = segment_distance(o, c[:, None, :], obst[None])  # (C, J)
        ok &= np.all(seg >= dij, axis=-1)
        if start is not None:
            ok &= np.all(together(o, c[:, None, :], start[None], obst[None]) >= dij, axis=-1)
        clear = np.full(len(c), np.inf)
        if rho > 0.0:
            f = c[:, None, :] - targets[None]
            clear = np.min(np.hypot(f[..., 0], f[..., 1]), axis=-1) - rho
        return c, ok, clear

    @staticmethod
    def _contact(o: FloatArray, w: FloatArray, obst: FloatArray, dij: FloatArray) -> FloatArray:
        """Return the point where the segment ``o -> w`` first comes within (slightly more
        than) ``dij`` of an obstacle (``o`` when it starts there)."""
        u = w - o
        a = float(u @ u)
        if a == 0.0:
            return o.copy()
        f = o - obst  # (J, 2)
        rad = dij * (1.0 + _CONTACT)
        bq = f @ u
        cq = np.sum(f * f, -1) - rad**2
        disc = bq**2 - a * cq
        t_in = np.where(disc >= 0.0, (-bq - np.sqrt(np.maximum(disc, 0.0))) / a, np.inf)
        t_in = np.where(t_in >= 0.0, t_in, np.where(cq <= 0.0, 0.0, np.inf))
        return o + min(1.0, float(np.min(t_in))) * u
