"""One sensor's feasible set with K targets: membership, projection, boundary arcs.

Sensor ``i`` at ``p_i`` with reach ``r_i`` (eq. 13/15) and minimum distance ``rho_i`` to each
of the K predicted target positions ``t_k`` (eq. 14/16, one ``rho_i`` for all targets) may
move to

    F = { s : |s - p_i| <= r_i }  minus  the union over k of { s : |s - t_k| < rho_i }.

For K = 1 this is the set of :mod:`activetrack.kinematics.geometry` (there written relative to the
target). The boundary of ``F`` is a union of arcs of the K + 1 circles ("the reach circle"
around ``p_i`` and the ``rho`` circles around the targets) whose ends are pairwise circle
intersections; so the point of ``F`` nearest to any ``q`` is ``q`` itself, the radial
projection of ``q`` onto one of the circles, or one of those intersections
(:func:`project`).

``F`` may be empty (the reach disk covered by the ``rho`` disks); :func:`project` then
returns the *fallback point*: among the reach disk's centre, the points of the reach circle
farthest from each target (``p_i + r_i (p_i - t_k) / |p_i - t_k|``, the x axis for
``p_i = t_k``), the intersections of the reach circle with the ``rho`` circles and the points
of the reach circle equidistant from two targets, the one maximizing
``min_k |s - t_k| - rho_i`` (the first such in that order): the least violation of eq. (16)
on the reach circle, exactly (for K <= 2 also over the disk; for K >= 3 a Voronoi vertex
inside the disk could do better). For K = 1 this is
:func:`activetrack.kinematics.geometry.unreachable_fallback`.

Membership carries the relative tolerance of :data:`activetrack.kinematics.sensor_motion.TOL`:
``|s - p_i| <= r_i (1 + tol)`` and ``|s - t_k| >= rho_i (1 - tol)``, so that exact boundary
points (up to rounding) count as feasible.

Kernels are unchecked and broadcast over leading axes: ``center`` (..., 2), ``r`` and ``rho``
(...), ``targets`` (..., K, 2), points (..., 2); float64 throughout.
"""

from __future__ import annotations

import functools

import numpy as np

from activetrack.kinematics.geometry import Arc, sample_uniform
from activetrack.validation import FloatArray

#: Relative tolerance of the membership tests (as :data:`activetrack.kinematics.sensor_motion.TOL`).
TOL = 1e-12


def _unit(v: FloatArray, default: FloatArray | None = None) -> FloatArray:
    """Return ``v / |v|`` (..., 2); ``default`` (or the x axis) where ``v`` is zero."""
    n = np.hypot(v[..., 0], v[..., 1])[..., None]
    if default is None:
        default = np.array([1.0, 0.0])
    return np.where(n > 0, v / np.where(n > 0, n, 1.0), default)


def contains(
    s: FloatArray,
    center: FloatArray,
    r: FloatArray,
    targets: FloatArray,
    rho: FloatArray,
    tol: float = TOL,
) -> np.ndarray:
    """Return whether points ``s`` (..., 2) lie in ``F`` (with the relative tolerance ``tol``)."""
    r, rho = np.asarray(r, dtype=np.float64), np.asarray(rho, dtype=np.float64)
    d = s - center
    reach = d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] <= (r * (1.0 + tol)) ** 2
    e = s[..., None, :] - targets
    far = e[..., 0] * e[..., 0] + e[..., 1] * e[..., 1] >= ((rho * (1.0 - tol)) ** 2)[..., None]
    return reach & np.all(far, axis=-1)


def circles(
    center: FloatArray, r: FloatArray, targets: FloatArray, rho: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Return the K + 1 boundary circles ``(origins (..., K+1, 2), radii (..., K+1))``.

    Circle 0 is the reach circle, circle ``k + 1`` the ``rho`` circle of target ``k``.
    """
    center, targets = np.asarray(center, np.float64), np.asarray(targets, np.float64)
    shape = np.broadcast_shapes(center.shape[:-1], targets.shape[:-2], np.shape(r), np.shape(rho))
    k = targets.shape[-2]
    origins = np.concatenate(
        [
            np.broadcast_to(center[..., None, :], shape + (1, 2)),
            np.broadcast_to(targets, shape + (k, 2)),
        ],
        axis=-2,
    )
    radii = np.concatenate(
        [
            np.broadcast_to(np.asarray(r, np.float64)[..., None], shape + (1,)),
            np.broadcast_to(np.asarray(rho, np.float64)[..., None], shape + (k,)),
        ],
        axis=-1,
    )
    return origins, radii


@functools.lru_cache(maxsize=16)
def pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the index pairs ``(i, j)``, ``i < j < n``, of the circles (fixed order)."""
    i, j = np.triu_indices(n, k=1)
    i.flags.writeable = j.flags.writeable = False
    return i, j


def intersections(
    o1: FloatArray, r1: FloatArray, o2: FloatArray, r2: FloatArray
) -> tuple[FloatArray, FloatArray, np.ndarray]:
    """Return ``(P, Q, meet)``: the intersections of circles ``(o1, r1)`` and ``(o2, r2)``.

    ``P`` lies on the side ``+perp(o1 - o2)`` of the line of centres (``perp`` turns by +90
    degrees), ``Q`` on the other; both are computed on the smaller circle as its centre plus
    its radius times a unit vector, so each is on that circle to rounding. ``meet`` is False
    (and ``P``, ``Q`` finite but meaningless) for disjoint, nested or concentric circles or a
    zero radius. Batched over leading axes.
    """
    swap = r2 < r1
    os = np.where(swap[..., None], o2, o1)  # the smaller circle
    ol = np.where(swap[..., None], o1, o2)
    rs, rl = np.where(swap, r2, r1), np.where(swap, r1, r2)
    v = ol - os
    d = np.hypot(v[..., 0], v[..., 1])
    ok = (d > 0) & (rs > 0)
    dd = np.where(ok, d, 1.0)
    e = v / dd[..., None]
    # cos of the angle at the small circle's centre, law of cosines with (d - rl)(d + rl).
    cos_p = ((d - rl) * (d + rl) + rs * rs) / (2.0 * dd * np.where(ok, rs, 1.0))
    meet = ok & (np.abs(cos_p) <= 1.0)
    cos_p = np.clip(cos_p, -1.0, 1.0)
    sin_p = np.sqrt(1.0 - cos_p * cos_p)
    perp = np.stack([-e[..., 1], e[..., 0]], -1)
    # +perp(o1 - o2): equals +perp(e) when the small circle is circle 2, -perp(e) otherwise.
    sgn = np.where(swap, 1.0, -1.0)[..., None]
    base = os + (rs * cos_p)[..., None] * e
    off = (rs * sin_p)[..., None] * perp * sgn
    return base + off, base - off, meet


def pair_points(origins: FloatArray, radii: FloatArray) -> tuple[FloatArray, np.ndarray]:
    """Return all pairwise intersection points (..., 2 P, 2) and whether they exist (..., 2 P)."""
    i, j = pairs(radii.shape[-1])
    P, Q, meet = intersections(origins[..., i, :], radii[..., i], origins[..., j, :], radii[..., j])
    pts = np.stack([P, Q], axis=-2).reshape(P.shape[:-2] + (2 * len(i), 2))
    ok = np.repeat(meet, 2, axis=-1)
    return pts, ok


def fallback(center: FloatArray, r: FloatArray, targets: FloatArray, rho: FloatArray) -> FloatArray:
    """Return the fallback point of an empty ``F`` (module docstring), (..., 2).

    Defined (and finite) whether or not ``F`` is empty.
    """
    center, targets = np.asarray(center, np.float64), np.asarray(targets, np.float64)
    r, rho = np.asarray(r, np.float64), np.asarray(rho, np.float64)
    far = center[..., None, :] + r[..., None, None] * _unit(center[..., None, :] - targets)
    origins, radii = circles(center, r, targets, rho)
    k = targets.shape[-2]
    P, Q, meet = intersections(
        origins[..., :1, :], radii[..., :1], origins[..., 1:, :], radii[..., 1:]
    )
    # Points of the reach circle equidistant from two targets (where the nearest target
    # changes): with the farthest points, the maximum of min_k |s - t_k| on the circle.
    ia, ib = pairs(k)
    n = targets[..., ib, :] - targets[..., ia, :]
    norm = np.hypot(n[..., 0], n[..., 1])
    h = 0.5 * (np.sum(targets[..., ib, :] ** 2, -1) - np.sum(targets[..., ia, :] ** 2, -1))
    safe_r = np.where(r > 0.0, r, 1.0)[..., None]
    cos_d = (h - np.sum(n * center[..., None, :], -1)) / (safe_r * np.where(norm > 0, norm, 1.0))
    split = (norm > 0) & (np.abs(cos_d) <= 1.0) & (r[..., None] > 0.0)
    phi = np.arctan2(n[..., 1], n[..., 0])
    delta = np.arccos(np.clip(cos_d, -1.0, 1.0))
    bis = [
        center[..., None, :] + r[..., None, None] * np.stack([np.cos(a), np.sin(a)], -1)
        for a in (phi + delta, phi - delta)
    ]
    cand = np.concatenate(
        [far, np.broadcast_to(center[..., None, :], far.shape[:-2] + (1, 2)), P, Q, *bis],
        axis=-2,
    )
    valid = np.concatenate(
        [np.ones(meet.shape[:-1] + (k + 1,), bool), meet, meet, split, split], axis=-1
    )
    e = cand[..., :, None, :] - targets[..., None, :, :]
    margin = np.min(np.hypot(e[..., 0], e[..., 1]), axis=-1) - rho[..., None]
    best = np.argmax(np.where(valid, margin, -np.inf), axis=-1)
    return np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]


def project(
    q: FloatArray, center: FloatArray, r: FloatArray, targets: FloatArray, rho: FloatArray
) -> FloatArray:
    """Return the point of ``F`` nearest to ``q`` (..., 2); ``q`` itself when feasible.

    Candidates: ``q``; its radial projection onto each of the K + 1 circles (a ``q`` at a
    circle's centre goes towards the sensor's position ``center``, or along the x axis);
    every pairwise circle intersection. The feasible candidate (with the tolerance) nearest
    to ``q`` is exact. With ``F`` empty: :func:`fallback`. With K = 1 and ``q`` in the reach
    disk this is :func:`activetrack.kinematics.geometry.project_feasible` (shifted by the target).
    """
    q, center = np.asarray(q, np.float64), np.asarray(center, np.float64)
    targets = np.asarray(targets, np.float64)
    r, rho = np.asarray(r, np.float64), np.asarray(rho, np.float64)
    origins, radii = circles(center, r, targets, rho)
    shape = np.broadcast_shapes(q.shape[:-1], radii.shape[:-1])
    q = np.broadcast_to(q, shape + (2,))
    toward = _unit(center[..., None, :] - origins)  # the default direction at a centre
    radial = origins + radii[..., None] * _unit(q[..., None, :] - origins, toward)
    inter, inter_ok = pair_points(origins, radii)
    cand = np.concatenate(
        [q[..., None, :], radial, np.broadcast_to(inter, shape + inter.shape[-2:])], -2
    )
    ok = contains(
        cand, center[..., None, :], r[..., None], targets[..., None, :, :], rho[..., None]
    )
    ok[..., 1 + radii.shape[-1] :] &= inter_ok
    d = cand - q[..., None, :]
    dist = np.where(ok, np.hypot(d[..., 0], d[..., 1]), np.inf)
    best = np.argmin(dist, axis=-1)
    out = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    empty = ~np.any(ok, axis=-1)
    if np.any(empty):  # the fallback of the empty sets only (it is elementwise)
        k = targets.shape[-2]
        out[empty] = fallback(
            np.broadcast_to(center, shape + (2,))[empty],
            np.broadcast_to(r, shape)[empty],
            np.broadcast_to(targets, shape + (k, 2))[empty],
            np.broadcast_to(rho, shape)[empty],
        )
    return out


def is_empty(center: FloatArray, r: FloatArray, targets: FloatArray, rho: FloatArray) -> np.ndarray:
    """Return whether ``F`` is empty (...): no candidate of :func:`project` is feasible."""
    center = np.asarray(center, np.float64)
    q = fallback(center, r, targets, rho)
    return ~contains(project(q, center, r, targets, rho), center, r, targets, rho)


def boundary_arcs(center: FloatArray, r: float, targets: FloatArray, rho: float) -> list[Arc]:
    """Return the arcs forming the boundary of one sensor's ``F`` (unbatched).

    Pieces of the reach circle outside every ``rho`` disk, then for each target the pieces of
    its ``rho`` circle inside the reach disk and outside the other ``rho`` disks (a target
    repeated at the same position counts once). Each arc runs counter-clockwise between
    consecutive intersection angles of its circle (or is the whole circle,
    ``t0 = -pi``, ``t1 = pi``). Empty when ``F`` is empty or ``r = 0``; ``rho = 0`` circles
    are points and contribute nothing.
    """
    center = np.asarray(center, np.float64).reshape(2)
    targets = np.asarray(targets, np.float64).reshape(-1, 2)
    r, rho = float(r), float(rho)
    if r <= 0.0:
        return []
    origins, radii = circles(center, r, targets, rho)
    n = radii.shape[0]
    arcs: list[Arc] = []
    for a in range(n):
        if radii[a] <= 0.0 or (
            a > 0 and any(np.array_equal(targets[a - 1], t) for t in targets[: a - 1])
        ):
            continue
        angles = []
        for b in range(n):
            if b == a:
                continue
            P, Q, meet = intersections(origins[a], radii[a], origins[b], radii[b])
            if meet:
                for p in (P, Q):
                    angles.append(float(np.arctan2(p[1] - origins[a][1], p[0] - origins[a][0])))
        if angles:
            ts = np.sort(np.array(angles))
            bounds = list(zip(ts, np.append(ts[1:], ts[0] + 2 * np.pi), strict=True))
        else:
            bounds = [(-np.pi, np.pi)]
        for t0, t1 in bounds:
            if t1 - t0 <= 0.0:
                continue
            arc = Arc(
                (float(origins[a][0]), float(origins[a][1])), float(radii[a]), float(t0), float(t1)
            )
            mid = arc.points(np.array([0.5 * (t0 + t1)]))[0]
            if _on_boundary_piece(mid, a, center, r, targets, rho):
                arcs.append(arc)
    return arcs


def _on_boundary_piece(
    mid: FloatArray, a: int, center: FloatArray, r: float, targets: FloatArray, rho: float
) -> bool:
    """Return whether the point ``mid`` of circle ``a`` lies on the boundary of ``F``."""
    d_reach = float(np.hypot(*(mid - center)))
    d_t = np.hypot(*(mid - targets).T)
    others = np.ones(len(targets), bool)
    if a > 0:
        others[np.all(targets == targets[a - 1], axis=-1)] = False
    outside = bool(np.all(d_t[others] >= rho * (1.0 - TOL)))
    inside = d_reach <= r * (1.0 + TOL)
    return outside and inside


def sample_interior(
    center: FloatArray,
    r: float,
    targets: FloatArray,
    rho: float,
    rng: np.random.Generator,
    n: int,
) -> FloatArray:
    """Return ``n`` points (n, 2) drawn uniformly from ``F`` of one sensor (rejection).

    Draws uniformly in the reach disk, in rounds of ``max(4 n, 64)`` draws (at most 64
    rounds), and keeps the feasible ones in order. Fallbacks (deterministic given ``rng``):
    when ``F`` has no area (``r = 0``, empty, or too thin to hit) the missing points are
    drawn uniformly by length from :func:`boundary_arcs`; when those are empty too, they
    are :func:`project` of the centre (the centre itself if feasible, else the fallback).
    """
    center = np.asarray(center, np.float64).reshape(2)
    targets = np.asarray(targets, np.float64).reshape(-1, 2)
    out: list[FloatArray] = []
    got = 0
    batch = max(4 * n, 64)
    for _ in range(64 if r > 0.0 else 0):
        if got >= n:
            break
        u = rng.random((batch, 2))
        rad = r * np.sqrt(u[:, 0])
        ang = 2.0 * np.pi * u[:, 1]
        pts = center + rad[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
        pts = pts[contains(pts, center, r, targets, rho)]
        out.append(pts)
        got += len(pts)
    pts = np.concatenate(out)[:n] if out else np.empty((0, 2))
    if len(pts) < n:
        arcs = boundary_arcs(center, r, targets, rho)
        if arcs:
            extra = np.array([sample_uniform(arcs, rng) for _ in range(n - len(pts))])
        else:
            extra = np.tile(project(center, center, r, targets, rho), (n - len(pts), 1))
        pts = np.concatenate([pts, extra.reshape(-1, 2)])
    return pts
