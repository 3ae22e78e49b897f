"""The search map: where a target not yet detected may be, on a grid over the region.

With targets that appear (:class:`activetrack.models.births.BirthProcess`) the team must
look for those it has not detected. The map holds, per cell of a ``G x G`` grid over the
birth process's region, ``q_c``, the probability that a target present and not yet
detected is in the cell (``sum q_c`` is the expected number of them, capped at 1 per
cell). Each step (:func:`step`):

1. **spread**: undetected targets move; a fraction ``a = min(1, hi dt / h)`` of each
   cell's mass (``hi`` the birth process's top speed, ``h`` the smaller cell side) goes
   to its four neighbours in equal parts (a neighbour off the grid keeps its share);
2. **arrivals**: ``+ rate`` times each cell's share of the entry distribution
   (:func:`inflow`: the cell's length of the region's edge, or its area of the spawn areas);
3. **look**: each cell whose centre is within sensor ``i``'s ``max_range`` is searched by
   it with probability ``p_detect_i``; ``q_c <- q_c prod_i (1 - p_detect_i [in range])``
   (occluders are not accounted: a cell behind one counts as searched);
4. ``q_c <- min(q_c, 1)``.

It starts at ``1 / G^2`` per cell (one target, anywhere). The world's score adds
``search_weight * sum q_c`` (the expected number of targets missed) and each slot without
a track shows the planners a search point (:func:`search_points`): the centres of the cells
of highest ``q``, greedily, each at least ``spacing`` from those taken before.
"""

from __future__ import annotations

import numpy as np

from activetrack.validation import FloatArray


def centers(region: tuple[float, float, float, float], g: int) -> FloatArray:
    """Return the grid's cell centres (g, g, 2): ``[i, j]`` is column i (x), row j (y)."""
    x0, y0, x1, y1 = region
    xs = x0 + (np.arange(g) + 0.5) * (x1 - x0) / g
    ys = y0 + (np.arange(g) + 0.5) * (y1 - y0) / g
    return np.stack(np.meshgrid(xs, ys, indexing="ij"), -1)


def inflow(births) -> FloatArray:  # births: BirthProcess
    """Return each cell's expected arrivals per step (g, g): ``rate`` times the cell's
    share of the entry distribution (of the region's edge by length, or of the spawn areas
    by area)."""
    g, (x0, y0, x1, y1) = births.search_cells, births.region
    w, h = (x1 - x0) / g, (y1 - y0) / g
    share = np.zeros((g, g))
    if births.spawn_areas is None:
        per = 2.0 * ((x1 - x0) + (y1 - y0))
        share[:, 0] += w / per
        share[:, -1] += w / per
        share[0, :] += h / per
        share[-1, :] += h / per
    else:
        xe = x0 + np.arange(g + 1) * w
        ye = y0 + np.arange(g + 1) * h
        total = 0.0
        for a, b, c, d in births.spawn_areas:
            ox = np.clip(np.minimum(xe[1:], c) - np.maximum(xe[:-1], a), 0.0, None)
            oy = np.clip(np.minimum(ye[1:], d) - np.maximum(ye[:-1], b), 0.0, None)
            share += ox[:, None] * oy[None, :]
            total += (c - a) * (d - b)
        share /= total
    return births.rate * share


def spread_fraction(births, dt: float) -> float:
    """Return ``a``, the fraction of a cell's mass that moves to its neighbours per step."""
    g, (x0, y0, x1, y1) = births.search_cells, births.region
    h = min((x1 - x0) / g, (y1 - y0) / g)
    return min(1.0, births.speed[1] * dt / h)


def step(
    q: FloatArray,
    arrivals: FloatArray,
    a: float,
    cells: FloatArray,
    sensors: FloatArray,
    max_range: FloatArray | None,
    p_detect: FloatArray | None,
) -> FloatArray:
    """Return the map after one step (see the module docstring) from ``q`` (..., g, g),
    the arrivals per cell (g, g), the spread fraction ``a``, the cell centres (g, g, 2)
    and the sensors' true positions (..., M, 2) with their ``max_range`` and
    ``p_detect`` (M,) (None: unlimited, 1)."""
    pad = np.concatenate([q[..., :1, :], q, q[..., -1:, :]], -2)
    pad = np.concatenate([pad[..., :, :1], pad, pad[..., :, -1:]], -1)
    nbr = pad[..., :-2, 1:-1] + pad[..., 2:, 1:-1] + pad[..., 1:-1, :-2] + pad[..., 1:-1, 2:]
    q = (1.0 - a) * q + 0.25 * a * nbr + arrivals
    m = sensors.shape[-2]
    rel = cells[..., None, :] - sensors[..., None, None, :, :]  # (..., g, g, M, 2)
    near = np.ones(rel.shape[:-1], dtype=bool)
    if max_range is not None:
        near = np.sum(rel * rel, axis=-1) <= np.asarray(max_range) ** 2
    pd = np.ones(m) if p_detect is None else np.asarray(p_detect)
    q = q * np.prod(1.0 - pd * near, axis=-1)
    return np.minimum(q, 1.0)


def search_points(q: FloatArray, cells: FloatArray, n: int, spacing: float) -> FloatArray:
    """Return ``n`` search points (n, 2) of one map ``q`` (g, g): the centres of the cells
    of highest ``q`` (ties: the lower flat index), each at least ``spacing`` from those
    taken before while such a cell remains (else the next highest)."""
    flat, pts = q.ravel(), cells.reshape(-1, 2)
    order = np.argsort(-flat, kind="stable")
    out: list[FloatArray] = []
    for c in order:
        if len(out) == n:
            break
        if all(np.hypot(*(pts[c] - o)) >= spacing for o in out):
            out.append(pts[c])
    for c in order:  # fewer cells far enough apart than slots: the next highest
        if len(out) == n:
            break
        out.append(pts[c])
    return np.array(out).reshape(n, 2)
