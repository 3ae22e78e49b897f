"""Geodesic distances among occluders: how far a sensor must travel, around the buildings, to
reach a point (issue 36: a sensor that has lost the target goes around a block, not into it;
GSR's approach, and the agents' route readings, :func:`route_readings`).

The free plane is the plane minus the occluded region ``U`` (the union of the polygons'
open interiors, :mod:`activetrack.models.occluders`). A shortest path in it between two
points is a polyline that bends only at convex corners of the polygons (the classic
visibility-graph property), so the geodesic distance is a shortest path in the graph whose
nodes are those corners and whose edges are the unblocked segments between them
(:func:`activetrack.models.occluders.blocked`, the world's own segment test). The nodes are
the corners moved :data:`CLEARANCE` out along their mitre (the corner of the polygon grown
by ``CLEARANCE``), so that a path keeps off the walls it turns around, and a node that
falls inside another polygon is dropped. The distance is thus the geodesic of the plane
minus the polygons grown by ``CLEARANCE`` at the corners (exact for the original polygons
as ``CLEARANCE -> 0``; a corner cut costs at most ``2 CLEARANCE``).

:class:`Roadmap` builds one layout's graph and its all-pairs node distances once
(:func:`scipy.sparse.csgraph.shortest_path`); :meth:`Roadmap.distances` then answers a goal
and many points with two batches of segment tests: the goal's legs to the nodes, and the
points' legs to the nodes and the goal. A goal inside a polygon (a target in a tunnel) is
reached through that polygon: the legs to the goal ignore the polygons that contain it
(the sensor is led to the wall nearest the goal, where the target comes out).
"""

from __future__ import annotations

import numpy as np

from activetrack.models.occluders import Occluders, blocked, inside
from activetrack.validation import FloatArray

#: The nodes' distance (m) off the corners they stand for.
CLEARANCE = 0.25


def _convex_corners(poly: FloatArray, clearance: float) -> FloatArray:
    """Return the convex corners of the simple polygon ``poly`` (n, 2) moved ``clearance``
    out along their mitre (the corners of the polygon grown by ``clearance``), (c, 2)."""
    p = np.asarray(poly, np.float64)
    prev, nxt = np.roll(p, 1, axis=0), np.roll(p, -1, axis=0)
    area2 = np.sum(p[:, 0] * nxt[:, 1] - nxt[:, 0] * p[:, 1])  # > 0: counter-clockwise
    sign = 1.0 if area2 > 0.0 else -1.0
    e1, e2 = p - prev, nxt - p
    cross = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    convex = sign * cross > 0.0
    # Outward normals of the two edges (right of the edge for a counter-clockwise polygon).
    n1 = sign * np.stack([e1[:, 1], -e1[:, 0]], -1) / np.hypot(e1[:, 0], e1[:, 1])[:, None]
    n2 = sign * np.stack([e2[:, 1], -e2[:, 0]], -1) / np.hypot(e2[:, 0], e2[:, 1])[:, None]
    # The mitre: the point at distance `clearance` from both edges' lines.
    mitre = (n1 + n2) / (1.0 + np.sum(n1 * n2, -1))[:, None]
    return (p + clearance * mitre)[convex]


class Roadmap:
    """The visibility graph of one layout of occluders (module docstring).

    Attributes: ``nodes`` (N, 2) the moved corners, ``between`` (N, N) their geodesic
    distances (inf between parts the occluders cut apart).
    """

    def __init__(self, occ: Occluders, clearance: float = CLEARANCE) -> None:
        if occ.batched:
            raise ValueError("Roadmap takes one layout (occ[i] of a batched set)")
        if not np.isfinite(clearance) or clearance < 0.0:
            raise ValueError(f"clearance must be finite and >= 0, got {clearance}")
        self.occ = occ
        self.polygons = [np.asarray(p, np.float64) for p in occ.polygons]
        self.single = [Occluders.from_polygons([p]) for p in self.polygons]
        corners = [_convex_corners(p, clearance) for p in self.polygons]
        nodes = np.concatenate(corners) if corners else np.empty((0, 2))
        self.nodes = nodes[~inside(nodes, occ)] if len(nodes) else nodes
        n = len(self.nodes)
        self._without: dict[tuple[int, ...], Occluders] = {(): occ}
        if n == 0:
            self.between = np.zeros((0, 0))
            return
        from scipy.sparse import csr_matrix  # noqa: PLC0415 (occluded worlds only)
        from scipy.sparse.csgraph import shortest_path  # noqa: PLC0415

        seen = ~blocked(self.nodes[:, None, :], self.nodes[None, :, :], occ)
        length = np.hypot(*np.moveaxis(self.nodes[:, None, :] - self.nodes[None, :, :], -1, 0))
        # Edges of zero length (two corners that coincide) join their nodes at no cost.
        w = np.where(seen, np.maximum(length, 1e-300), 0.0)
        np.fill_diagonal(w, 0.0)
        self.between = shortest_path(csr_matrix(w), method="D", directed=False)

    def _layout_without(self, key: tuple[int, ...]) -> Occluders:
        """Return the layout less the polygons ``key`` (indices)."""
        if key not in self._without:
            rest = [p for k, p in enumerate(self.polygons) if k not in key]
            self._without[key] = Occluders.from_polygons(rest)
        return self._without[key]

    def distances(self, points: FloatArray, goals: FloatArray) -> FloatArray:
        """Return the geodesic distances (S, P) from ``points`` (S, P, 2) to ``goals``
        (S, 2), row by row: the shortest path in the free plane through the nodes (module
        docstring); inf for a point inside a polygon or cut off from its goal."""
        return self.paths(points, goals)[0]

    def paths(self, points: FloatArray, goals: FloatArray) -> tuple[FloatArray, ...]:
        """Return ``(distances (S, P), waypoints (S, P, 2), rest (S, P))``: the geodesic
        distances of :meth:`distances`, the first point each shortest path heads for (a
        node or the goal) and the path's length beyond it (``distances = |point -
        waypoint| + rest``; the waypoint is the point itself where the distance is inf)."""
        p = np.asarray(points, np.float64)
        g = np.asarray(goals, np.float64)
        out = np.empty(p.shape[:2])
        way = np.array(p)
        rest = np.zeros(p.shape[:2])
        # Rows whose goals lie in the same polygons share the layout of their last legs.
        holds = np.stack([inside(g, one) for one in self.single], -1) if self.single else None
        keys = np.zeros((len(g), 0), bool) if holds is None else holds
        groups, which = np.unique(keys, axis=0, return_inverse=True)
        n = len(self.nodes)
        if n:
            seen = ~blocked(p[:, :, None, :], self.nodes, self.occ)  # (S, P, N)
            e = p[:, :, None, :] - self.nodes
            reach = np.where(seen, np.hypot(e[..., 0], e[..., 1]), np.inf)
        for k, key in enumerate(groups):
            rows = np.flatnonzero(np.reshape(which, -1) == k)
            last = self._layout_without(tuple(np.flatnonzero(key).tolist()))
            pr, gr = p[rows], g[rows, None, :]  # (R, P, 2), (R, 1, 2)
            far = np.hypot(pr[..., 0] - gr[..., 0], pr[..., 1] - gr[..., 1])
            best = np.where(blocked(pr, gr, last), np.inf, far)
            wr = np.where(np.isfinite(best)[..., None], gr, pr)
            rr = np.zeros(best.shape)
            if n:
                leg = np.hypot(self.nodes[:, 0] - gr[..., 0], self.nodes[:, 1] - gr[..., 1])
                leg = np.where(blocked(self.nodes, gr, last), np.inf, leg)  # (R, N)
                via = np.min(self.between[None] + leg[:, None, :], axis=-1)  # (R, N)
                total = reach[rows] + via[:, None, :]  # (R, P, N)
                j = np.argmin(total, axis=-1)
                tj = np.take_along_axis(total, j[..., None], -1)[..., 0]
                use = tj < best
                best = np.where(use, tj, best)
                wr = np.where(use[..., None], self.nodes[j], wr)
                rr = np.where(use, np.take_along_axis(via, j, -1), rr)
            out[rows], way[rows], rest[rows] = best, wr, rr
        return out, way, rest


class Roadmaps:
    """:class:`Roadmap` per layout, built on first use and kept (a bounded cache keyed by
    the layout's vertices: a batched set's copies share their layouts' graphs)."""

    #: At most this many layouts are kept.
    SIZE = 512

    def __init__(self, clearance: float = CLEARANCE) -> None:
        self.clearance = clearance
        self._maps: dict[bytes, Roadmap] = {}

    def of(self, occ: Occluders) -> Roadmap:
        """Return the roadmap of the one layout ``occ``."""
        key = np.ascontiguousarray(occ.edges_a).tobytes() + np.asarray(occ.starts).tobytes()
        found = self._maps.get(key)
        if found is None:
            if len(self._maps) >= self.SIZE:
                self._maps.pop(next(iter(self._maps)))
            found = self._maps[key] = Roadmap(occ, self.clearance)
        return found


#: The planners' and the observation's shared cache.
ROADMAPS = Roadmaps()

#: Route readings per sensor and goal (:func:`route_readings`): the first leg's direction
#: (x, y) and the detour ratio.
ROUTE_DIM = 3


def route_bounds(n_targets: int) -> tuple[np.ndarray, np.ndarray]:
    """Return float32 ``(low, high)`` of one agent's route readings (3K): the directions in
    [-1, 1], the detour ratios in [0, 1]."""
    low = np.tile(np.float32([-1.0, -1.0, 0.0]), n_targets)
    return low, np.ones(ROUTE_DIM * n_targets, dtype=np.float32)


def route_readings(positions: FloatArray, goals: FloatArray, occ: object) -> FloatArray:
    """Return each sensor's route readings to each goal, float64 (..., M, 3K), from the
    sensors' ``positions`` (..., M, 2) and the goals (..., K, 2) (the targets'
    predictions), among the occluders ``occ`` (None: an open plane; batched over the
    copies or one layout for all).

    The route is the shortest path around the occluders
    (:class:`activetrack.models.roadmap.Roadmap`, the geodesic GSR's lost sensors follow).
    Per target: the unit direction (world frame) of its first leg, toward the first corner
    it turns around or the goal itself, and the detour ratio ``|goal - position| /
    geodesic distance`` in (0, 1], 1 on a clear straight line. A goal cut off from the
    sensor (or reached: zero distance) reads direction (0, 0), ratio 0 (or 1).
    """
    p = np.asarray(positions, np.float64)
    g = np.asarray(goals, np.float64)
    batch, m, kk = p.shape[:-2], p.shape[-2], g.shape[-2]
    p, g = p.reshape(-1, m, 2), g.reshape(-1, kk, 2)
    s = p.shape[0]
    dist, way = np.empty((s, m, kk)), np.empty((s, m, kk, 2))
    for k in range(kk):
        if occ is None:  # the straight line
            way[:, :, k] = g[:, None, k]
            dist[:, :, k] = np.hypot(*np.moveaxis(g[:, None, k] - p, -1, 0))
        elif occ.batched:  # each copy's layout
            for c in range(s):
                d, w, _ = ROADMAPS.of(occ[c]).paths(p[c : c + 1], g[c : c + 1, k])
                dist[c, :, k], way[c, :, k] = d[0], w[0]
        else:
            dist[:, :, k], way[:, :, k] = ROADMAPS.of(occ).paths(p, g[:, k])[:2]
    leg = way - p[:, :, None, :]
    n = np.hypot(leg[..., 0], leg[..., 1])
    ok = np.isfinite(dist) & (n > 0.0)
    out = np.zeros((s, m, kk, ROUTE_DIM))
    out[..., :2] = np.where(ok[..., None], leg / np.where(ok, n, 1.0)[..., None], 0.0)
    straight = np.hypot(*np.moveaxis(g[:, None, :, :] - p[:, :, None, :], -1, 0))
    ratio = np.where(dist > 0.0, straight / np.where(dist > 0.0, dist, 1.0), 1.0)
    out[..., 2] = np.clip(np.where(np.isfinite(dist), ratio, 0.0), 0.0, 1.0)
    return out.reshape(batch + (m, ROUTE_DIM * kk))
