"""Polygon checks of :class:`activetrack.models.occluders.Occluders`: simplicity, size.

What :meth:`~activetrack.models.occluders.Occluders.from_polygons` validates before it
builds a set: each polygon's shape and values, the number of vertices in all
(:data:`MAX_VERTICES`), and each polygon's simplicity (no two edges meet other than
consecutive edges at their common vertex; non-zero area), tested pair by pair of edges in
bounded chunks, with the occluders' tolerance (:data:`activetrack.models.occluders.TOL`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from activetrack.models._occluder_kernels import TOL
from activetrack.validation import real_array

#: Most vertices (= edges) of one layout, fixed and random polygons together. Building a
#: layout tests every pair of its edges for crossings (the compiled table holds up to
#: E (E - 1) / 2 of them, 134 MB at this bound) and every line-of-sight test walks all
#: E edges, so the bound keeps both within a second and well within memory.
MAX_VERTICES = 4096

#: Pairs of edges tested at once by the simplicity check (its memory: a few hundred bytes a pair).
_PAIRS_PER_CHUNK = 1 << 18


def _check_simple(name: str, p: np.ndarray, eps: float) -> None:
    """Raise ``ValueError`` unless ``p`` is a simple polygon of non-zero area.

    Every pair of edges is tested (in chunks of rows of the pair table, so memory stays
    bounded); the first bad pair in the order of ``np.triu_indices`` is the one named.
    """
    q = np.roll(p, -1, axis=0)
    if np.any(np.all(p == q, axis=-1)):
        raise ValueError(f"{name} has a repeated consecutive vertex (zero-length edge)")
    span = float(np.max(np.ptp(p, axis=0)))
    n = len(p)
    rows = max(1, _PAIRS_PER_CHUNK // n)
    for start in range(0, n - 1, rows):
        i, j = _pairs(n, start, min(n - 1, start + rows))
        adjacent = (j == i + 1) | ((i == 0) & (j == n - 1))
        meet = _segments_meet(p[i], q[i], p[j], q[j], eps)
        # Consecutive edges share a vertex; they must meet only there (no fold-back).
        nxt = np.where(j == i + 1, j, i)  # the edge that starts at the shared vertex
        prv = np.where(j == i + 1, i, j)
        d_prev = p[prv] - q[prv]  # from the shared vertex back along the previous edge
        d_next = q[nxt] - p[nxt]
        fold = (np.abs(_cross(d_prev, d_next)) <= eps * span * span) & (
            np.sum(d_prev * d_next, -1) > 0
        )
        bad = np.where(adjacent, fold, meet)
        if np.any(bad):
            k = int(np.argmax(bad))
            raise ValueError(f"{name} must not self-intersect: edges {i[k]} and {j[k]} meet")
    area = 0.5 * float(np.sum(_cross(p, q)))
    if abs(area) <= eps * span:
        raise ValueError(f"{name} must have non-zero area, got area {area!r}")


def _pairs(n: int, lo: int, hi: int) -> tuple[np.ndarray, np.ndarray]:
    """Return the rows ``lo <= i < hi`` of ``np.triu_indices(n, k=1)``, in its order."""
    rows = np.arange(lo, hi)
    counts = n - 1 - rows  # row i pairs edge i with edges i + 1 .. n - 1
    i = np.repeat(rows, counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)  # where each row starts
    return i, np.arange(len(i)) - first + i + 1


def checked_polygons(polygons: Sequence[object]) -> list[np.ndarray]:
    """Return ``polygons`` (a sequence of (n_i, 2) vertex arrays) as float64 arrays, each
    checked simple (:meth:`activetrack.models.occluders.Occluders.from_polygons` names the
    errors)."""
    if isinstance(polygons, np.ndarray) and polygons.ndim == 2:
        raise ValueError("polygons must be a sequence of (n_i, 2) vertex arrays, got one array")
    polys: list[np.ndarray] = []
    total = 0
    for i, raw in enumerate(polygons):
        name = f"polygons[{i}]"
        arr = real_array(name, raw, finite=False)
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < 3:
            raise ValueError(f"{name} must have shape (n, 2) with n >= 3, got {arr.shape}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{name} must be finite (no NaN or inf)")
        polys.append(arr)
        total += len(arr)
        if total > MAX_VERTICES:  # before any pair of edges is tested
            raise ValueError(
                f"polygons must have at most {MAX_VERTICES} vertices in all, got "
                f"{total} in polygons[0..{i}]"
            )
    eps = TOL * _scale(polys)
    for i, p in enumerate(polys):
        _check_simple(f"polygons[{i}]", p, eps)
    return polys


def _scale(polys: list[np.ndarray]) -> float:
    """Return ``max(1, max |vertex coordinate|)``: the scale of the tolerances."""
    return max([1.0] + [float(np.max(np.abs(p))) for p in polys])


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def _segments_meet(p1, p2, q1, q2, eps: float) -> np.ndarray:
    """Return whether closed segments ``[p1, p2]`` and ``[q1, q2]`` share a point (batched)."""
    d1, d2 = p2 - p1, q2 - q1
    o1 = _cross(d1, q1 - p1)
    o2 = _cross(d1, q2 - p1)
    o3 = _cross(d2, p1 - q1)
    o4 = _cross(d2, p2 - q1)
    s = eps * (np.hypot(d1[..., 0], d1[..., 1]) + np.hypot(d2[..., 0], d2[..., 1]))
    proper = (o1 * o2 < 0) & (o3 * o4 < 0) & (np.abs(o1) > s) & (np.abs(o2) > s)
    proper &= (np.abs(o3) > s) & (np.abs(o4) > s)

    def on(a, b, p, o):  # p on segment [a, b] (collinear up to s)
        lo, hi = np.minimum(a, b) - eps, np.maximum(a, b) + eps
        box = np.all((p >= lo) & (p <= hi), axis=-1)
        return (np.abs(o) <= s) & box

    return (
        proper | on(p1, p2, q1, o1) | on(p1, p2, q2, o2) | on(q1, q2, p1, o3) | on(q1, q2, p2, o4)
    )
