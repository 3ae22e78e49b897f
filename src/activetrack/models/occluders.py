"""Polygonal occluders: point membership, line of sight, projected straight moves, rays.

The geometric kernel of occluders (issue 13, beyond the paper: its closing sentence names
visibility and motion constraints from obstacles as future work). An :class:`Occluders` is
a fixed set of simple polygons (either orientation, convex or not, possibly touching or
overlapping each other). The *occluded region* ``U`` is the union of the polygons' open
interiors. Every function broadcasts over leading axes and is float64; the computation is
compiled, one point, segment or ray at a time (:mod:`activetrack.models._occluder_kernels`,
numba), so one sensor and a batch of thousands cost the same per point; with no polygons
each returns the trivial answer.

Tolerance. All tests use one absolute tolerance ``occ.eps = TOL * occ.scale``, with
``scale = max(1, max |vertex coordinate|)``: a point within ``eps`` of a polygon's boundary
counts as *on* it, never inside. So points computed on an edge (up to rounding) are
classified consistently, and sub-``eps`` dents into ``U`` are ignored.

Definitions.

- :func:`inside` ``(p)``: ``p`` lies in the open interior of some polygon (even-odd
  crossing rule per polygon), farther than ``eps`` from that polygon's boundary. Points on
  a boundary are not inside. Caveat of the union-of-interiors convention: two polygons that
  share an edge exactly leave that seam open (a segment running along it is not blocked);
  make solid walls from overlapping (not merely abutting) polygons.
- :func:`blocked` ``(a, b)``: some sub-interval of positive length of the closed segment
  ``[a, b]`` lies in ``U``. A segment that touches a boundary at a point, runs along an edge
  or through a vertex, or ends on an edge is not blocked (a sensor on a wall sees along it);
  one with an endpoint in ``U`` is. Computed from the definition: the parameters ``t``
  where ``[a, b]`` crosses an edge, together with the projections of the vertices lying on
  its line (they delimit the pieces of edges collinear with it), cut ``[0, 1]`` into
  sub-intervals on each of which membership in ``U`` is constant; the segment is blocked
  iff the midpoint of one of them is :func:`inside`. Cuts are taken with a margin
  (``1e-9`` in the edge parameter, ``1e-9 * scale`` off the line): a surplus cut only
  splits an interval, a missing one could merge an inside and an outside piece.
- :func:`project_move` ``(start, desired, r)``: ``desired`` itself if ``[start, desired]``
  is not blocked and ``desired`` is within reach, else the point nearest to ``desired`` of
  the *reachable set*
  ``R = {p : |p - start| <= r, [start, p] not blocked}`` (start's visibility region cut by
  its reach disk, with the tolerances ``|p - start| <= r (1 + REACH_TOL)`` and ``eps``).

Why the candidates of :func:`project_move` contain the nearest point. ``R`` is closed (if
``[start, p]`` met the open set ``U`` so would ``[start, p_n]`` for ``p_n -> p``), so a
nearest point ``p*`` to ``q = desired`` exists, and it lies on the boundary of ``R``
since ``q`` is not in ``R``. That boundary is made of three kinds of pieces: arcs of the
reach circle, pieces of occluder edges, and pieces of *shadow rays* (the ray from
``start`` through a vertex ``v``, beyond ``v``; visibility changes only across such rays).
On a straight piece the distance to ``q`` is smallest at the foot of the perpendicular
from ``q`` (the projection of ``q`` onto the edge, or onto the shadow ray) or at an end of
the piece; on an arc, at the radial projection of ``q`` or at an end. The ends of pieces
are the corners of ``R``: occluder vertices, edge-edge crossings (overlapping polygons),
reach circle with an edge or a shadow ray, the first point where a shadow ray meets an
edge beyond its vertex (a shadow ray that grazes a further vertex ``u`` continues as ``u``'s
shadow ray, whose first hit is a candidate of its own), and ``start`` itself. All of these
are candidates; each is kept if it lies in ``R`` (the same :func:`blocked` test), and the
nearest kept one is ``p*``. Candidates are tested lazily in order of distance to ``q`` (the
first reachable one is the answer), so typically only a few :func:`blocked` calls run.
A ``start`` inside ``U`` (excluded by the world) reaches nothing: it stays, projected.
With ``desired`` inside the reach disk (the world's case) the reach-circle candidates are
never the answer: ``R`` is star-shaped about ``start``, so for ``p`` on the circle the
segment ``[start, p]`` lies in ``R``, and when ``|q - start| <= r`` its point nearest to
``q`` is not ``p`` (unless ``q = p``). They make the projection exact for a ``desired``
beyond the reach too.

Batched layouts (one layout per copy of an episode). :meth:`Occluders.stack` makes one
set of ``N`` layouts with the same number of polygons and vertices per polygon; every
kernel then reads the first axis of its points (of their broadcast shape, without the
coordinate axis) as the layout axis, of length ``N``: point ``[i, ...]`` is tested against
layout ``i`` with layout ``i``'s own ``eps`` and ``scale``, bit for bit as the unbatched
kernel on ``occ[i]`` and the points ``[i]``. The kernels take each row's layout index (all
0 for a shared layout), so both cases run the same code.

Only :meth:`Occluders.from_polygons`, :meth:`Occluders.stack`, :meth:`Occluders.replaced`
and :func:`random_layout` validate their input; the kernels are unchecked (finite float
arrays, as the world passes them) except for the layout axis of a batched set. The polygon
checks are :mod:`activetrack.models._polygons`, the random layouts
:mod:`activetrack.models.occluder_layouts`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from activetrack._jit import as_rows
from activetrack.models import _occluder_kernels as ok
from activetrack.models._occluder_kernels import REACH_TOL, TOL
from activetrack.models._polygons import MAX_VERTICES, checked_polygons
from activetrack.models.occluder_layouts import random_layout
from activetrack.validation import FloatArray

__all__ = [
    "MAX_VERTICES", "REACH_TOL", "TOL", "Occluders", "blocked", "inside", "line_of_sight",
    "project_move", "random_layout", "ray_distances",
]  # fmt: skip


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class Occluders:
    """An immutable set of simple polygons; build it with :meth:`from_polygons` (one layout)
    or :meth:`stack` (a batch of ``N`` layouts, one per copy).

    Attributes (read-only float64/int arrays) of one layout: ``polygons`` (tuple of (n_i, 2)
    vertex arrays), ``edges_a``, ``edges_b`` (E, 2) the edges' ends (polygon ``i``'s edges
    are the contiguous block ``starts[i]:starts[i] + n_i``, edge ``j`` runs from vertex
    ``j`` to ``j + 1`` cyclically), ``edge_polygon`` (E,) the polygon of each edge,
    ``starts`` (P,), ``bbox`` (P, 4) each polygon's ``(xmin, ymin, xmax, ymax)``,
    ``crossings`` (X, 2) the points where edges of different polygons meet, ``scale`` and
    ``eps`` floats (module docstring).

    A batched set (``batched`` True, ``n_layouts`` = N) shares ``edge_polygon`` and
    ``starts``; its other arrays get a leading layout axis: ``edges_a``, ``edges_b``
    (N, E, 2), ``bbox`` (N, P, 4), ``crossings`` (N, X, 2) with X the most of any layout,
    each layout's rows first and NaN rows after them (no crossing), ``scale`` and ``eps``
    (N,) arrays; ``polygons`` is the tuple of the layouts' ``polygons`` tuples.
    ``n_polygons`` and ``n_edges`` count one layout's.
    """

    polygons: tuple
    edges_a: np.ndarray
    edges_b: np.ndarray
    edge_polygon: np.ndarray
    starts: np.ndarray
    bbox: np.ndarray
    crossings: np.ndarray
    scale: float | np.ndarray
    eps: float | np.ndarray

    # Not iterable (an unbatched set would index itself forever): index layouts instead.
    __iter__ = None

    def __post_init__(self) -> None:
        # The compiled kernels' view (activetrack.models._occluder_kernels), built once: every
        # array with a leading layout axis (1 for one shared layout), C-contiguous and
        # writable (one numba signature for every set).
        lead = (lambda a: a) if self.edges_a.ndim == 3 else (lambda a: np.asarray(a)[None])
        n = len(self.starts)
        ends = np.append(self.starts[1:], self.edges_a.shape[-2]) if n else self.starts
        arrays = (
            np.array(lead(self.edges_a), np.float64),
            np.array(lead(self.edges_b), np.float64),
            np.array(self.starts, np.intp),
            np.array(ends, np.intp),
            np.array(lead(self.bbox), np.float64),
            np.array(lead(self.crossings), np.float64),
            np.array(np.reshape(self.eps, -1), np.float64),
            np.array(np.reshape(self.scale, -1), np.float64),
        )
        object.__setattr__(self, "_kernel_args", arrays)

    @property
    def batched(self) -> bool:
        """Return whether this is a batch of layouts (:meth:`stack`), one per copy."""
        return self.edges_a.ndim == 3

    @property
    def n_layouts(self) -> int | None:
        """Return the number N of layouts of a batched set, None for one (shared) layout."""
        return int(self.edges_a.shape[0]) if self.edges_a.ndim == 3 else None

    @property
    def n_polygons(self) -> int:
        """Return the number of polygons (of each layout)."""
        return int(self.starts.shape[0])

    @property
    def n_edges(self) -> int:
        """Return the total number of edges (= vertices; of each layout)."""
        return int(self.edges_a.shape[-2])

    def __getitem__(self, index: object) -> Occluders:
        """Return layout ``index`` (an int: unbatched, the arrays of the one stacked) or the
        batched subset of layouts ``index`` (a slice, int array or bool mask). An unbatched
        set is shared by every copy: ``occ[anything]`` is ``occ`` itself."""
        if not self.batched:
            return self
        n = self.n_layouts
        if isinstance(index, (int, np.integer)) and not isinstance(index, (bool, np.bool_)):
            i = int(index)
            if not -n <= i < n:
                raise IndexError(f"layout index {i} out of range for {n} layouts")
            cr = self.crossings[i]
            return Occluders(
                polygons=self.polygons[i],
                edges_a=_frozen(self.edges_a[i]),
                edges_b=_frozen(self.edges_b[i]),
                edge_polygon=self.edge_polygon,
                starts=self.starts,
                bbox=_frozen(self.bbox[i]),
                crossings=_frozen(cr[: int(np.sum(~np.isnan(cr[:, 0])))]),
                scale=float(self.scale[i]),
                eps=float(self.eps[i]),
            )
        sel = np.arange(n)[index]
        if sel.ndim != 1:
            raise IndexError(f"layouts index must select along one axis, got shape {sel.shape}")
        return self._subset(sel, self.crossings[sel])

    def _subset(self, sel: np.ndarray, crossings: np.ndarray) -> Occluders:
        """Return the batched set of the layouts ``sel`` with ``crossings`` (NaN padded)."""
        return Occluders(
            polygons=tuple(self.polygons[j] for j in sel),
            edges_a=_frozen(self.edges_a[sel]),
            edges_b=_frozen(self.edges_b[sel]),
            edge_polygon=self.edge_polygon,
            starts=self.starts,
            bbox=_frozen(self.bbox[sel]),
            crossings=_frozen(_trimmed(crossings)),
            scale=_frozen(self.scale[sel]),
            eps=_frozen(self.eps[sel]),
        )

    @classmethod
    def stack(cls, layouts: Sequence[Occluders]) -> Occluders:
        """Return the batched set of ``layouts`` (N >= 1 unbatched sets), layout ``i`` first.

        Raises ``TypeError`` naming ``layouts[i]`` if it is not an :class:`Occluders`, and
        ``ValueError`` for no layouts, a batched ``layouts[i]``, or one whose number of
        polygons or vertices per polygon differs from ``layouts[0]``'s.
        """
        if isinstance(layouts, Occluders):
            raise TypeError("layouts must be a sequence of Occluders, got one Occluders")
        layouts = list(layouts)
        if not layouts:
            raise ValueError("layouts must hold at least 1 Occluders, got none")
        for i, occ in enumerate(layouts):
            if not isinstance(occ, Occluders):
                raise TypeError(f"layouts[{i}] must be an Occluders, got {type(occ).__name__}")
            if occ.batched:
                raise ValueError(
                    f"layouts[{i}] must be one layout, got a batched set of {occ.n_layouts}"
                )
        first = layouts[0]
        counts = first._vertex_counts()
        for i, occ in enumerate(layouts):
            if occ.n_polygons != first.n_polygons:
                raise ValueError(
                    f"layouts[{i}] has {occ.n_polygons} polygons, layouts[0] has "
                    f"{first.n_polygons}: stacked layouts need the same number"
                )
            if not np.array_equal(occ._vertex_counts(), counts):
                raise ValueError(
                    f"layouts[{i}] has polygons of {occ._vertex_counts().tolist()} vertices, "
                    f"layouts[0] of {counts.tolist()}: stacked layouts need the same counts"
                )
        x = max(len(occ.crossings) for occ in layouts)
        crossings = np.full((len(layouts), x, 2), np.nan)
        for i, occ in enumerate(layouts):
            crossings[i, : len(occ.crossings)] = occ.crossings
        return cls(
            polygons=tuple(occ.polygons for occ in layouts),
            edges_a=_frozen(np.stack([occ.edges_a for occ in layouts])),
            edges_b=_frozen(np.stack([occ.edges_b for occ in layouts])),
            edge_polygon=first.edge_polygon,
            starts=first.starts,
            bbox=_frozen(np.stack([occ.bbox for occ in layouts])),
            crossings=_frozen(crossings),
            scale=_frozen(np.array([occ.scale for occ in layouts], np.float64)),
            eps=_frozen(np.array([occ.eps for occ in layouts], np.float64)),
        )

    def _vertex_counts(self) -> np.ndarray:
        """Return the number of vertices of each polygon (P,) (of each layout)."""
        return np.diff(np.append(self.starts, self.n_edges))

    def replaced(self, rows: object, layouts: Sequence[Occluders] | Occluders) -> Occluders:
        """Return a new batched set with layout ``rows[j]`` replaced by ``layouts[j]``.

        ``rows`` distinct ints in ``[0, N)``, ``layouts`` as many unbatched sets of this
        set's polygon and vertex counts, or one batched set of as many layouts
        (``ValueError`` naming ``rows`` or ``layouts[j]`` otherwise). The other layouts'
        arrays are copied unchanged.
        """
        if not self.batched:
            raise ValueError("replaced needs a batched set (Occluders.stack), got one layout")
        n = self.n_layouts
        idx = np.asarray(rows)
        if idx.ndim != 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
            raise ValueError(f"rows must be a 1-D array of ints, got {rows!r}")
        idx = idx.astype(np.intp)
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise ValueError(f"rows must lie in [0, {n}), got {idx.tolist()}")
        if len(np.unique(idx)) != len(idx):
            raise ValueError(f"rows must be distinct, got {idx.tolist()}")
        batch = isinstance(layouts, Occluders) and layouts.batched
        count = layouts.n_layouts if batch else len(layouts := list(layouts))
        if count != len(idx):
            raise ValueError(f"layouts must hold one layout per row ({len(idx)}), got {count}")
        if not count:
            return self
        new = layouts if batch else Occluders.stack(layouts)
        if new.n_polygons != self.n_polygons or not np.array_equal(
            new._vertex_counts(), self._vertex_counts()
        ):
            raise ValueError(
                f"layouts[0] has polygons of {new._vertex_counts().tolist()} vertices, the set "
                f"of {self._vertex_counts().tolist()}: replacements need the same counts"
            )
        x = max(self.crossings.shape[1], new.crossings.shape[1])
        crossings = np.full((n, x, 2), np.nan)
        crossings[:, : self.crossings.shape[1]] = self.crossings
        crossings[idx] = np.nan
        crossings[idx, : new.crossings.shape[1]] = new.crossings
        polygons = list(self.polygons)
        for j, i in enumerate(idx.tolist()):
            polygons[i] = new.polygons[j]
        arrays = {}
        for name in ("edges_a", "edges_b", "bbox", "scale", "eps"):
            arr = getattr(self, name).copy()
            arr[idx] = getattr(new, name)
            arrays[name] = _frozen(arr)
        return Occluders(
            polygons=tuple(polygons),
            edge_polygon=self.edge_polygon,
            starts=self.starts,
            crossings=_frozen(_trimmed(crossings)),
            **arrays,
        )

    @classmethod
    def empty(cls) -> Occluders:
        """Return the empty set (no occlusion anywhere)."""
        return cls.from_polygons([])

    @classmethod
    def from_polygons(cls, polygons: Sequence[object]) -> Occluders:
        """Return the occluders of ``polygons`` (a sequence of (n_i, 2) vertex arrays).

        Raises ``ValueError`` naming ``polygons[i]`` for fewer than 3 vertices, a wrong
        shape, non-finite or non-real values, a repeated consecutive vertex, zero area, or
        edges that meet other than consecutive edges at their common vertex, and naming
        ``polygons`` for more than :data:`MAX_VERTICES` vertices in all.
        """
        return cls._of_simple(checked_polygons(polygons))

    @classmethod
    def _of_simple(cls, polys: list[np.ndarray]) -> Occluders:
        """Return the occluders of float64 polygons known to be simple (not checked)."""
        if not polys:
            empty = np.empty((0, 2))
            return cls(
                polygons=(), edges_a=_frozen(empty), edges_b=_frozen(empty),
                edge_polygon=_frozen(np.empty(0, np.intp)), starts=_frozen(np.empty(0, np.intp)),
                bbox=_frozen(np.empty((0, 4))), crossings=_frozen(empty), scale=1.0, eps=TOL,
            )  # fmt: skip
        counts = np.array([len(p) for p in polys], dtype=np.intp)
        return cls._stack_simple(np.concatenate(polys)[None], counts)[0]

    @classmethod
    def _stack_simple(cls, vertices: np.ndarray, counts: np.ndarray) -> Occluders:
        """Return the batched set of N layouts of simple polygons (not checked) with the same
        vertex counts ``counts`` (P,): ``vertices`` (N, E, 2), each polygon's in order."""
        vertices = np.ascontiguousarray(vertices, np.float64)
        N, E = vertices.shape[:2]
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.intp)
        nxt = np.arange(1, E + 1)
        nxt[starts + counts - 1] = starts  # each polygon's last vertex closes on its first
        b = np.ascontiguousarray(vertices[:, nxt])
        ep = np.repeat(np.arange(len(counts)), counts)
        bbox = np.concatenate(
            [np.minimum.reduceat(vertices, starts, axis=1),
             np.maximum.reduceat(vertices, starts, axis=1)], axis=-1,
        )  # fmt: skip
        scale = np.maximum(1.0, np.max(np.abs(vertices), axis=(1, 2)))
        # Twice: their number first (a layout's scratch only), then the padded table.
        scratch, found = np.empty((E * (E - 1) // 2, 2)), np.empty(N, np.intp)
        ok.crossings_rows(vertices, b, ep, scratch, found, np.empty((N, 0, 2)))
        x = int(found.max(initial=0))
        crossings = np.empty((N, x, 2))
        if x:
            ok.crossings_rows(vertices, b, ep, scratch, found, crossings)
        polygons = tuple(
            tuple(_frozen(v[s : s + n]) for s, n in zip(starts.tolist(), counts.tolist(),
                                                        strict=True))
            for v in vertices
        )  # fmt: skip
        return cls(
            polygons=polygons,
            edges_a=_frozen(vertices),
            edges_b=_frozen(b),
            edge_polygon=_frozen(ep),
            starts=_frozen(starts),
            bbox=_frozen(bbox),
            crossings=_frozen(crossings),
            scale=_frozen(scale),
            eps=_frozen(TOL * scale),
        )


def _trimmed(crossings: np.ndarray) -> np.ndarray:
    """Return batched ``crossings`` (N, X, 2) without the NaN columns no layout needs."""
    x = int(np.max(np.sum(~np.isnan(crossings[..., 0]), axis=-1), initial=0))
    return crossings[:, :x]


def _layouts(occ: Occluders, shape: tuple[int, ...], name: str) -> np.ndarray:
    """Return the layout of each of the points of broadcast ``shape`` (without the
    coordinate axis), flattened: all 0 for one shared layout; for a batched set,
    ``shape[0]`` must be its number of layouts (the leading axis is the layout axis)."""
    size = math.prod(shape)
    if not occ.batched:
        return np.zeros(size, np.intp)
    n = occ.n_layouts
    if len(shape) == 0 or shape[0] != n:
        raise ValueError(
            f"{name}: a batched Occluders of {n} layouts needs the points' leading axis to "
            f"be the layout axis, of length {n}, got points of shape {shape}"
        )
    return np.repeat(np.arange(n, dtype=np.intp), size // n)


def _flat(a: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Return points ``a`` broadcast to ``shape + (2,)`` as kernel rows (size, 2)."""
    return as_rows(a, shape, (2,))


def inside(points: FloatArray, occ: Occluders) -> np.ndarray:
    """Return whether each point (..., 2) lies in ``U`` (module docstring), bool (...).

    Even-odd crossing rule per polygon; a point within ``occ.eps`` of a polygon's boundary
    is not inside that polygon.
    """
    p = np.asarray(points, np.float64)
    shape = p.shape[:-1]
    lay = _layouts(occ, shape, "inside")
    out = np.zeros(math.prod(shape), bool)
    if occ.n_edges:
        ea, eb, starts, ends, bbox, _, eps, _ = occ._kernel_args
        ok.inside_rows(_flat(p, shape), lay, ea, eb, starts, ends, bbox, eps, out)
    return out.reshape(shape)


def blocked(a: FloatArray, b: FloatArray, occ: Occluders) -> np.ndarray:
    """Return whether the closed segments ``[a, b]`` (..., 2) are blocked, bool (...).

    Blocked: a sub-interval of positive length lies in ``U`` (module docstring); touching
    a boundary, running along an edge or ending on one does not block; an endpoint in ``U``
    does. The line-of-sight test (sensor to target) and the motion test (a straight move).
    With a batched ``occ`` the broadcast shape's first axis is the layout axis.
    """
    return _blocked(a, b, occ, "blocked")


def path_blocked(a: FloatArray, b: FloatArray, occ: Occluders) -> np.ndarray:
    """Return whether any of the segments ``[a, b]`` (..., S, 2) of each path (a path's
    pieces) is :func:`blocked`, bool (...). A path whose box (of all its segments) meets
    no polygon's box (shrunk by the layout's ``eps``, the kernel's own first test) is
    clear without testing its segments. With a batched ``occ`` the first axis is the
    layout axis."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    shape = np.broadcast_shapes(a.shape, b.shape)[:-2]
    a, b = np.broadcast_to(a, shape + a.shape[-2:]), np.broadcast_to(b, shape + b.shape[-2:])
    out = np.zeros(shape, bool)
    if not occ.n_edges or not out.size:
        return out
    # (per coordinate: a reduction along the middle axis is many times slower in NumPy)
    lo = np.stack([np.minimum(a[..., k].min(-1), b[..., k].min(-1)) for k in (0, 1)], -1)
    hi = np.stack([np.maximum(a[..., k].max(-1), b[..., k].max(-1)) for k in (0, 1)], -1)
    _, _, _, _, bbox, _, eps, _ = occ._kernel_args  # (L, P, 4), (L,)
    lay = _layouts(occ, shape, "path_blocked").reshape(shape)
    box, e = bbox[lay], eps[lay][..., None]  # (..., P, 4), (..., 1)
    near = np.any(
        (hi[..., None, 0] > box[..., 0] + e) & (lo[..., None, 0] < box[..., 2] - e)
        & (hi[..., None, 1] > box[..., 1] + e) & (lo[..., None, 1] < box[..., 3] - e),
        axis=-1,
    )  # fmt: skip
    if np.any(near):
        sub = occ[np.nonzero(near)[0]] if occ.batched else occ
        out[near] = np.any(blocked(a[near], b[near], sub), axis=-1)
    return out


def _blocked(a: FloatArray, b: FloatArray, occ: Occluders, name: str) -> np.ndarray:
    """Return :func:`blocked` (``name`` the public function, for the layout-axis error)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    shape = np.broadcast_shapes(a.shape, b.shape)[:-1]
    lay = _layouts(occ, shape, name)
    out = np.zeros(math.prod(shape), bool)
    if occ.n_edges:
        ea, eb, starts, ends, bbox, _, eps, scale = occ._kernel_args
        a, b = _flat(a, shape), _flat(b, shape)
        ok.blocked_rows(a, b, lay, ea, eb, starts, ends, bbox, eps, scale, out)
    return out.reshape(shape)


def project_move(
    start: FloatArray, desired: FloatArray, occ: Occluders, r: FloatArray
) -> tuple[FloatArray, np.ndarray]:
    """Return ``(positions (..., 2), projected bool (...))`` of straight moves (module docstring).

    ``start`` (..., 2) the sensors, ``desired`` (..., 2) their intended positions, ``r``
    (...) their reach. A ``desired`` within ``r (1 + REACH_TOL)`` of ``start`` whose segment
    is not blocked is returned bit for bit (``projected`` False); any other (blocked, or
    beyond the reach) goes to the nearest reachable point (``projected`` True). A ``start``
    inside ``U`` stays where it is (projected). With no occluders this is the radial
    projection onto the reach disk (identity inside it). With a batched ``occ`` the first
    axis of the broadcast shape of ``start``, ``desired`` and ``r`` is the layout axis.
    """
    o, q = np.asarray(start, np.float64), np.asarray(desired, np.float64)
    r = np.asarray(r, np.float64)
    shape = o.shape[:-1]  # the world's case: start and desired alike (no broadcast)
    if q.shape != o.shape or r.shape != shape[len(shape) - r.ndim :]:
        shape = np.broadcast_shapes(o.shape[:-1], q.shape[:-1], r.shape)
    lay = _layouts(occ, shape, "project_move")
    rf = r if r.shape == shape else np.broadcast_to(r, shape)
    rf = rf.reshape(-1)
    if not (rf.flags.c_contiguous and rf.flags.writeable):
        rf = rf.copy()
    out = np.empty(shape + (2,))
    projected = np.empty(shape, bool)
    ok.project_rows(
        _flat(o, shape), _flat(q, shape), rf, lay, *occ._kernel_args,
        out.reshape(-1, 2), projected.reshape(-1),
    )  # fmt: skip
    return out, projected


def line_of_sight(
    sensors: FloatArray, targets: FloatArray, occ: Occluders, where: np.ndarray | None = None
) -> np.ndarray:
    """Return whether each sensor (..., M, 2) sees each target (..., K, 2): (..., K, M),
    the segment between them not :func:`blocked` (batched ``occ``: the first of the
    leading axes ``...`` is the layout axis). ``where`` (bool, broadcastable to (..., K, M)):
    only those pairs are tested, the others are False (what a detection needs: no segment
    tested for a sensor out of range)."""
    s, t = np.asarray(sensors, np.float64), np.asarray(targets, np.float64)
    lead = s.shape[:-2]
    if t.shape[:-2] != lead:
        lead = np.broadcast_shapes(lead, t.shape[:-2])
    m, k = s.shape[-2], t.shape[-2]
    lay = _layouts(occ, lead + (k, m), "line_of_sight")[:: max(k * m, 1)]  # each row's
    if not (occ.n_edges and math.prod(lead + (k, m))):
        out = np.ones(lead + (k, m), bool)
        return out if where is None else out & where
    out = np.empty(lead + (k, m), bool)
    if where is None:
        w = np.ones((1, k, m), bool)
    else:
        w = np.asarray(where)
        if w.dtype != np.bool_ or w.ndim > len(lead) + 2:
            raise ValueError(f"where must be a bool array broadcastable to {lead + (k, m)}")
        try:
            w = as_rows(w, lead if w.ndim > 2 else (), (k, m), np.bool_)
        except ValueError:
            raise ValueError(
                f"where must be a bool array broadcastable to {lead + (k, m)}, got {w.shape}"
            ) from None
    ea, eb, starts, ends, bbox, _, eps, scale = occ._kernel_args
    ok.sight_rows(_flat(s, lead + (m,)).reshape(-1, m, 2),
                  _flat(t, lead + (k,)).reshape(-1, k, 2), lay, ea, eb, starts, ends, bbox,
                  eps, scale, w, out.reshape(-1, k, m))  # fmt: skip
    return out


def ray_distances(
    origins: FloatArray, directions: FloatArray, occ: Occluders, max_distance: float
) -> FloatArray:
    """Return the distance (..., R) along each ray to the first occluder edge, capped.

    ``origins`` (..., 2), ``directions`` (R, 2) unit vectors: for each origin and direction
    the smallest ``s > occ.eps`` with ``origin + s direction`` on an edge, or
    ``max_distance`` if none is nearer (a range finder; an origin on an edge does not see
    the edge it stands on). With a batched ``occ`` the first axis of ``origins`` (N, ..., 2)
    is the layout axis.
    """
    o = np.asarray(origins, np.float64)
    out = np.empty(o.shape[:-1] + (len(directions),))
    return _rays_into(o, directions, occ, max_distance, 1.0, out)


def _rays_into(
    origins: FloatArray, directions: FloatArray, occ: Occluders, max_distance: float,
    divisor: float, out: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """Write :func:`ray_distances` divided by ``divisor`` into ``out`` (..., R) (float64 or
    float32, a view whose leading axes merge into rows); return ``out``."""
    o = np.asarray(origins, np.float64)
    dirs = _flat(np.asarray(directions, np.float64), (len(directions),))
    shape = o.shape[:-1]
    lay = _layouts(occ, shape, "ray_distances")
    rows = out.reshape(math.prod(shape), len(dirs))  # a view (checked below)
    ea, eb, starts, ends, bbox, _, eps, _ = occ._kernel_args
    ok.ray_rows(_flat(o, shape), dirs, lay, ea, eb, starts, ends, bbox, eps,
                float(max_distance), float(divisor), rows)  # fmt: skip
    if not np.may_share_memory(rows, out):  # out's layout forced a copy: write it back
        out[...] = rows.reshape(out.shape)
    return out
