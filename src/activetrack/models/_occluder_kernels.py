"""Compiled geometry of polygonal occluders, one point, segment or ray at a time.

The kernels behind :mod:`activetrack.models.occluders` (its module docstring states the
definitions, the tolerances and why :func:`project_point`'s candidates contain the nearest
reachable point). Each ``*_rows`` kernel loops its per-row kernel over a flat batch in
compiled code, so one call serves one sensor or thousands of copies alike.

Geometry arguments (``Occluders._kernel_args``), for ``L`` layouts of ``P`` polygons and
``E`` edges each: ``ea``, ``eb`` (L, E, 2) the edges' ends, ``starts``, ``ends`` (P,) each
polygon's block of edges, ``bbox`` (L, P, 4) ``(xmin, ymin, xmax, ymax)``, ``cross``
(L, X, 2) the crossings of different polygons' edges (NaN rows pad), ``eps`` and ``scale``
(L,); ``lay`` (M,) is the layout of each row (all 0 for one shared layout).
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import kernel

#: Relative tolerance of boundary membership (times ``occ.scale``: ``occ.eps``).
TOL = 1e-10
#: Relative tolerance of the reach disk in :func:`project_point`.
REACH_TOL = 1e-10
#: Margin of the cuts of :func:`blocked_segment` (edge parameter; vertex offset from the line).
CUT = 1e-9
#: Margin of the shadow rays' first hits in :func:`project_point` (edge and ray parameters).
SHADOW_TOL = 1e-9


@kernel
def edge_dist2(px, py, ax, ay, bx, by):
    """Return the squared distance from point (px, py) to the segment [(ax, ay), (bx, by)]."""
    dx, dy = bx - ax, by - ay
    qx, qy = px - ax, py - ay
    t = (qx * dx + qy * dy) / (dx * dx + dy * dy)
    t = min(max(t, 0.0), 1.0)
    ex, ey = qx - t * dx, qy - t * dy
    return ex * ex + ey * ey


@kernel
def line_parameters(px, py, dx, dy, cx, cy, fx, fy):
    """Return ``(ok, t, s)`` with ``p + t d = c + s f`` where the lines cross (``ok``:
    they are not parallel; else ``t = s = 0``)."""
    den = dx * fy - dy * fx
    if den == 0.0:
        return False, 0.0, 0.0
    wx, wy = cx - px, cy - py
    return True, (wx * fy - wy * fx) / den, (wx * dy - wy * dx) / den


@kernel
def inside_point(px, py, lay, ea, eb, starts, ends, bbox, eps):
    """Return whether (px, py) lies in the open interior of a polygon of layout ``lay``,
    farther than its ``eps`` from that polygon's boundary (even-odd crossing rule)."""
    e2 = eps[lay] * eps[lay]
    for p in range(starts.shape[0]):
        if not (
            px > bbox[lay, p, 0] and px < bbox[lay, p, 2]
            and py > bbox[lay, p, 1] and py < bbox[lay, p, 3]
        ):  # fmt: skip
            continue  # outside its box: outside the polygon, or within eps of its boundary
        odd = False
        for j in range(starts[p], ends[p]):
            ax, ay, bx, by = ea[lay, j, 0], ea[lay, j, 1], eb[lay, j, 0], eb[lay, j, 1]
            if (ay > py) != (by > py):  # the edge spans the point's height: dy != 0
                if px < ax + (py - ay) * ((bx - ax) / (by - ay)):
                    odd = not odd
        if odd:
            on_boundary = False
            for j in range(starts[p], ends[p]):
                d2 = edge_dist2(px, py, ea[lay, j, 0], ea[lay, j, 1], eb[lay, j, 0], eb[lay, j, 1])
                if d2 <= e2:
                    on_boundary = True
                    break
            if not on_boundary:
                return True
    return False


@kernel
def _beside(ax, ay, dx, dy, x0, y0, x1, y1, margin):
    """Return whether the box ``[x0, x1] x [y0, y1]`` lies on one side of the line through
    ``a`` along ``d``, each corner farther than ``margin / |d|`` from it."""
    c0 = (x0 - ax) * dy - (y0 - ay) * dx
    c1 = (x1 - ax) * dy - (y0 - ay) * dx
    c2 = (x1 - ax) * dy - (y1 - ay) * dx
    c3 = (x0 - ax) * dy - (y1 - ay) * dx
    return min(c0, c1, c2, c3) > margin or max(c0, c1, c2, c3) < -margin


@kernel
def blocked_segment(ax, ay, bx, by, lay, ea, eb, starts, ends, bbox, eps, scale, cuts):
    """Return whether a sub-interval of positive length of [a, b] lies in an occluder.

    The parameters where [a, b] crosses an edge (a margin :data:`CUT` in the edge's
    parameter) and those of vertices on its line (within ``CUT * scale``) cut [0, 1];
    the segment is blocked iff the midpoint of a piece is :func:`inside_point`. ``cuts``
    is scratch space of at least ``2E`` floats.

    A polygon whose box is clear of the segment's line (farther than the cuts' margins:
    the vertex offset, and ``CUT`` times an edge's length, which its box's half-perimeter
    bounds) gives no cut and holds no midpoint: it is skipped.
    """
    e = eps[lay]
    lox, hix, loy, hiy = min(ax, bx), max(ax, bx), min(ay, by), max(ay, by)
    dx, dy = bx - ax, by - ay
    dd = dx * dx + dy * dy
    sdd = dd if dd > 0.0 else 1.0
    off_max = CUT * scale[lay] * math.sqrt(dd)
    near = False
    n = 0
    for p in range(starts.shape[0]):
        x0, y0, x1, y1 = bbox[lay, p, 0], bbox[lay, p, 1], bbox[lay, p, 2], bbox[lay, p, 3]
        if not (hix > x0 + e and lox < x1 - e and hiy > y0 + e and loy < y1 - e):
            continue  # the segment stays out of this polygon (farther in than eps)
        if _beside(ax, ay, dx, dy, x0, y0, x1, y1, off_max + CUT * math.sqrt(dd) * (
            (x1 - x0) + (y1 - y0)
        )):  # fmt: skip
            continue  # its box lies on one side of the segment's line: no cuts, no inside
        near = True
        for j in range(starts[p], ends[p]):
            cx, cy = ea[lay, j, 0], ea[lay, j, 1]
            fx, fy = eb[lay, j, 0] - cx, eb[lay, j, 1] - cy
            ok, t, s = line_parameters(ax, ay, dx, dy, cx, cy, fx, fy)
            if ok and s >= -CUT and s <= 1.0 + CUT and t > 0.0 and t < 1.0:
                cuts[n] = t
                n += 1
            wx, wy = cx - ax, cy - ay
            tv = (wx * dx + wy * dy) / sdd
            if abs(wx * dy - wy * dx) <= off_max and tv > 0.0 and tv < 1.0:
                cuts[n] = tv
                n += 1
    if not near:
        return False
    for i in range(1, n):  # insertion sort: a few cuts
        v = cuts[i]
        k = i - 1
        while k >= 0 and cuts[k] > v:
            cuts[k + 1] = cuts[k]
            k -= 1
        cuts[k + 1] = v
    prev = 0.0
    for i in range(n + 1):
        nxt = cuts[i] if i < n else 1.0
        mid = 0.5 * (nxt + prev)
        if inside_point(ax + mid * dx, ay + mid * dy, lay, ea, eb, starts, ends, bbox, eps):
            return True
        prev = nxt
    return False


@kernel
def inside_rows(points, lay, ea, eb, starts, ends, bbox, eps, out):
    """Fill ``out`` (M,) with :func:`inside_point` of each row of ``points`` (M, 2)."""
    for i in range(points.shape[0]):
        out[i] = inside_point(points[i, 0], points[i, 1], lay[i], ea, eb, starts, ends, bbox, eps)


@kernel
def blocked_rows(a, b, lay, ea, eb, starts, ends, bbox, eps, scale, out):
    """Fill ``out`` (M,) with :func:`blocked_segment` of the rows of ``a``, ``b`` (M, 2)."""
    cuts = np.empty(2 * ea.shape[1])
    for i in range(a.shape[0]):
        out[i] = blocked_segment(
            a[i, 0], a[i, 1], b[i, 0], b[i, 1], lay[i], ea, eb, starts, ends, bbox, eps, scale,
            cuts,
        )  # fmt: skip


@kernel
def sight_rows(sensors, targets, lay, ea, eb, starts, ends, bbox, eps, scale, where, out):
    """Fill ``out`` (B, K, M) with whether sensor ``m`` sees target ``k`` in row ``b``
    (``sensors`` (B, M, 2), ``targets`` (B, K, 2)): the segment from the sensor to the
    target not :func:`blocked_segment`; only where ``where`` (B', K, M) holds (B' = 1: the
    same for every row), False elsewhere."""
    cuts = np.empty(2 * ea.shape[1])
    for b in range(sensors.shape[0]):
        wb = where[b if where.shape[0] > 1 else 0]
        for k in range(targets.shape[1]):
            for m in range(sensors.shape[1]):
                out[b, k, m] = wb[k, m] and not blocked_segment(
                    sensors[b, m, 0], sensors[b, m, 1], targets[b, k, 0], targets[b, k, 1],
                    lay[b], ea, eb, starts, ends, bbox, eps, scale, cuts,
                )  # fmt: skip


@kernel
def _put(cand, k, x, y):
    """Store candidate ``k``."""
    cand[k, 0] = x
    cand[k, 1] = y


@kernel
def _far(ox, oy, bbox, lay, p, reach2):
    """Return whether polygon ``p``'s box is farther than ``sqrt(reach2)`` from (ox, oy)."""
    gx = max(bbox[lay, p, 0] - ox, 0.0, ox - bbox[lay, p, 2])
    gy = max(bbox[lay, p, 1] - oy, 0.0, oy - bbox[lay, p, 3])
    return gx * gx + gy * gy > reach2


@kernel
def candidates(ox, oy, qx, qy, r, lay, ea, eb, starts, ends, bbox, cross, cand):
    """Fill ``cand`` (7E + X + 2, 2) with the candidates of the nearest reachable point to
    ``q`` from ``o`` (NaN where one does not exist), in this order: ``q`` projected onto
    each edge, the vertices, ``q`` projected onto each vertex's shadow ray, the reach
    circle on each shadow ray, each shadow ray's first edge hit, the reach circle on each
    edge (two roots), the crossings, ``q``'s radial projection onto the circle, ``o``.

    A polygon whose box is out of reach (with a margin far above rounding) gives NaN for
    all its candidates without computing them: each lies on its edges or beyond its
    vertices as seen from ``o``, so out of reach, never the answer.
    """
    nan = math.nan
    E = ea.shape[1]
    X = cross.shape[1]
    reach2 = (r * (1.0 + REACH_TOL) * (1.0 + 1e-9)) ** 2
    far = np.empty(starts.shape[0], np.bool_)  # each polygon's box out of reach, once
    for p in range(starts.shape[0]):
        far[p] = _far(ox, oy, bbox, lay, p, reach2)
    for p in range(starts.shape[0]):
        for j in range(starts[p], ends[p]):
            if far[p]:
                for k in range(7):
                    _put(cand, k * E + j, nan, nan)
                continue
            cx, cy = ea[lay, j, 0], ea[lay, j, 1]
            fx, fy = eb[lay, j, 0] - cx, eb[lay, j, 1] - cy
            ff = fx * fx + fy * fy
            u = min(max(((qx - cx) * fx + (qy - cy) * fy) / ff, 0.0), 1.0)
            _put(cand, j, cx + u * fx, cy + u * fy)
            _put(cand, E + j, cx, cy)
            # The shadow ray o + s g, s >= 1, through this vertex.
            gx, gy = cx - ox, cy - oy
            gg = gx * gx + gy * gy
            has = gg > 0.0
            s = max(1.0, ((qx - ox) * gx + (qy - oy) * gy) / (gg if has else 1.0))
            _put(cand, 2 * E + j, ox + s * gx, oy + s * gy)
            glen = math.sqrt(gg)
            if has and glen <= r:
                _put(cand, 3 * E + j, ox + (r / glen) * gx, oy + (r / glen) * gy)
            else:
                _put(cand, 3 * E + j, nan, nan)
            # The first edge the shadow ray hits beyond the vertex (s > 1): out of reach
            # when the vertex is, and a hit on an out-of-reach polygon is out of reach too
            # (any nearer hit is found among the others), so those are not computed.
            smin = math.inf
            if has and glen <= r * (1.0 + REACH_TOL):
                for q in range(starts.shape[0]):
                    if far[q]:
                        continue
                    for h in range(starts[q], ends[q]):
                        hx, hy = ea[lay, h, 0], ea[lay, h, 1]
                        kx, ky = eb[lay, h, 0] - hx, eb[lay, h, 1] - hy
                        ok, sh, uh = line_parameters(ox, oy, gx, gy, hx, hy, kx, ky)
                        if ok and uh >= -SHADOW_TOL and uh <= 1.0 + SHADOW_TOL:
                            if sh > 1.0 + SHADOW_TOL:
                                smin = min(smin, sh)
            if smin < math.inf:
                _put(cand, 4 * E + j, ox + smin * gx, oy + smin * gy)
            else:
                _put(cand, 4 * E + j, nan, nan)
            # The reach circle |c - o + u f| = r on this edge.
            cox, coy = cx - ox, cy - oy
            bq = cox * fx + coy * fy
            cq = (cox * cox + coy * coy) - r * r
            disc = bq * bq - ff * cq
            sq = math.sqrt(max(disc, 0.0))
            lo, hi = (-bq - sq) / ff, (-bq + sq) / ff
            if disc >= 0.0 and lo >= 0.0 and lo <= 1.0:
                _put(cand, 5 * E + j, cx + lo * fx, cy + lo * fy)
            else:
                _put(cand, 5 * E + j, nan, nan)
            if disc >= 0.0 and hi >= 0.0 and hi <= 1.0:
                _put(cand, 6 * E + j, cx + hi * fx, cy + hi * fy)
            else:
                _put(cand, 6 * E + j, nan, nan)
    for j in range(X):
        _put(cand, 7 * E + j, cross[lay, j, 0], cross[lay, j, 1])
    dqx, dqy = qx - ox, qy - oy
    nq = math.hypot(dqx, dqy)
    if nq > 0.0:
        _put(cand, 7 * E + X, ox + (r / nq) * dqx, oy + (r / nq) * dqy)
    else:
        _put(cand, 7 * E + X, nan, nan)
    _put(cand, 7 * E + X + 1, ox, oy)


@kernel
def within_reach(ox, oy, qx, qy, r):
    """Return whether ``q`` is within reach ``r`` of ``o`` (to :data:`REACH_TOL`)."""
    dx, dy = qx - ox, qy - oy
    lim = r * (1.0 + REACH_TOL)
    return dx * dx + dy * dy <= lim * lim


@kernel
def project_point(ox, oy, qx, qy, r, lay, ea, eb, starts, ends, bbox, cross, eps, scale, work):
    """Return ``(x, y, projected)``: ``q`` if its straight move from ``o`` is
    :func:`within_reach` and not blocked, else the nearest point of the reachable set
    (``o`` if it is empty). ``work`` (7E + X + 2 + 2E, 3) is scratch space."""
    reach = within_reach(ox, oy, qx, qy, r)
    E = ea.shape[1]
    if E == 0:
        if not reach:  # the reach disk only
            dx, dy = qx - ox, qy - oy
            n = math.hypot(dx, dy)
            return ox + (r / n) * dx, oy + (r / n) * dy, True
        return qx, qy, False
    C = 7 * E + cross.shape[1] + 2
    cuts = work[C:, 0]
    if reach and not blocked_segment(
        ox, oy, qx, qy, lay, ea, eb, starts, ends, bbox, eps, scale, cuts
    ):
        return qx, qy, False
    lim = r * (1.0 + REACH_TOL)
    cand = work[:C, :2]
    dist = work[:C, 2]
    candidates(ox, oy, qx, qy, r, lay, ea, eb, starts, ends, bbox, cross, cand)
    for k in range(C):
        ex, ey = cand[k, 0] - ox, cand[k, 1] - oy
        if ex * ex + ey * ey <= lim * lim:  # False for NaN
            ex, ey = cand[k, 0] - qx, cand[k, 1] - qy
            dist[k] = ex * ex + ey * ey
        else:
            dist[k] = math.inf
    # In order of distance (ties: the candidates' order), the first unblocked one; by
    # selection, since the first or second is the answer almost always.
    for _ in range(C):
        best = -1
        best_d = math.inf
        for k in range(C):
            if dist[k] < best_d:
                best, best_d = k, dist[k]
        if best < 0:
            break
        px, py = cand[best, 0], cand[best, 1]
        if not blocked_segment(ox, oy, px, py, lay, ea, eb, starts, ends, bbox, eps, scale, cuts):
            return px, py, True
        dist[best] = math.inf
    return ox, oy, True


@kernel
def project_rows(o, q, r, lay, ea, eb, starts, ends, bbox, cross, eps, scale, out, projected):
    """Fill ``out`` (M, 2) and ``projected`` (M,) with :func:`project_point` of each row."""
    E = ea.shape[1]
    work = np.empty((9 * E + cross.shape[1] + 2, 3))
    cuts = work[7 * E + cross.shape[1] + 2 :, 0]
    for i in range(o.shape[0]):
        ox, oy, qx, qy = o[i, 0], o[i, 1], q[i, 0], q[i, 1]
        # The common free move here: project_point is too large to be inlined, and a
        # call costs about twice the test (its many array arguments).
        if (
            E > 0
            and within_reach(ox, oy, qx, qy, r[i])
            and not blocked_segment(
                ox, oy, qx, qy, lay[i], ea, eb, starts, ends, bbox, eps, scale, cuts
            )
        ):
            out[i, 0] = qx
            out[i, 1] = qy
            projected[i] = False
            continue
        x, y, hit = project_point(
            o[i, 0], o[i, 1], q[i, 0], q[i, 1], r[i], lay[i], ea, eb, starts, ends, bbox,
            cross, eps, scale, work,
        )  # fmt: skip
        out[i, 0] = x
        out[i, 1] = y
        projected[i] = hit


@kernel
def ray_rows(origins, directions, lay, ea, eb, starts, ends, bbox, eps, max_distance, divisor, out):
    """Fill ``out`` (M, R) with the distance along each ray from each origin to the first
    edge (the smallest ``s > eps``), or ``max_distance`` if none is nearer, divided by
    ``divisor`` (1: distances; ``out`` may be a float32 view, then each quotient is rounded
    once, as a float64 array cast to float32 would be).

    Polygons whose bounding box is farther than ``max_distance`` from the origin are
    skipped (no hit of theirs could be nearer), and so are the back faces of a polygon
    whose box is farther than ``2 eps |d|`` away (|d| the longest direction): from outside
    a polygon, a ray's first hit on it is where it enters, through an edge whose outer side
    holds the origin, at ``s`` beyond ``eps``; an edge with the origin on its inner side or
    line is only ever left through. Both cullings change no result in exact arithmetic.
    """
    R = directions.shape[0]
    reach2 = (max_distance * (1.0 + 1e-9)) ** 2
    inv = np.empty((ea.shape[1], R))  # 1 / (g x f) of each edge and direction (0: parallel)
    side = np.empty(starts.shape[0])  # each polygon's orientation: 1 counter-clockwise, else -1
    dxs, dys = directions[:, 0].copy(), directions[:, 1].copy()
    dmax2 = 0.0
    for k in range(R):
        dmax2 = max(dmax2, dxs[k] * dxs[k] + dys[k] * dys[k])
    best = np.empty(R)
    made = np.full(ea.shape[1], -1)  # the layout whose row of ``inv`` each edge holds
    current = -1
    for i in range(origins.shape[0]):
        ox, oy, la = origins[i, 0], origins[i, 1], lay[i]
        if la != current:  # rows of a layout come together: its orientations once
            current = la
            for p in range(starts.shape[0]):
                area = 0.0
                for j in range(starts[p], ends[p]):
                    area += ea[la, j, 0] * eb[la, j, 1] - eb[la, j, 0] * ea[la, j, 1]
                side[p] = 1.0 if area > 0.0 else -1.0
        e = eps[la]
        clear2 = 4.0 * e * e * dmax2
        best[:] = math.inf
        for p in range(starts.shape[0]):
            if _far(ox, oy, bbox, la, p, reach2):
                continue
            front = _far(ox, oy, bbox, la, p, clear2)  # the origin is well outside it
            for j in range(starts[p], ends[p]):
                cx, cy = ea[la, j, 0], ea[la, j, 1]
                fx, fy = eb[la, j, 0] - cx, eb[la, j, 1] - cy
                wx, wy = cx - ox, cy - oy
                cwf = wx * fy - wy * fx
                if front and cwf * side[p] >= 0.0:
                    continue  # a back face: the origin on its inner side (or its line)
                if made[j] != la:  # the edge's row of the table, once per layout
                    made[j] = la
                    for k in range(R):
                        den = directions[k, 0] * fy - directions[k, 1] * fx
                        inv[j, k] = 1.0 / den if den != 0.0 else 0.0
                for k in range(R):  # branch-free, so that it vectorizes over the rays
                    s = cwf * inv[j, k]  # 0 for a parallel edge: never a hit (s > eps)
                    u = (wx * dys[k] - wy * dxs[k]) * inv[j, k]
                    hit = (u >= 0.0) & (u <= 1.0) & (s > e)
                    best[k] = min(best[k], s if hit else math.inf)
        for k in range(R):
            out[i, k] = min(max_distance, best[k]) / divisor


@kernel
def edge_dist2_rows(points, ea, eb, out):
    """Fill ``out`` (M, E) with the squared distance of each point to each edge of
    one layout (``ea``, ``eb`` (E, 2))."""
    for i in range(points.shape[0]):
        for j in range(ea.shape[0]):
            out[i, j] = edge_dist2(
                points[i, 0], points[i, 1], ea[j, 0], ea[j, 1], eb[j, 0], eb[j, 1]
            )


@kernel
def crossings_into(a, b, polygon, out):
    """Fill the first rows of ``out`` with the points where edges [a, b] (E, 2) of
    different polygons (``polygon`` (E,) each edge's) cross or touch; return their count."""
    n = 0
    E = a.shape[0]
    for i in range(E):
        d1x, d1y = b[i, 0] - a[i, 0], b[i, 1] - a[i, 1]
        for j in range(i + 1, E):
            if polygon[i] == polygon[j]:
                continue
            d2x, d2y = b[j, 0] - a[j, 0], b[j, 1] - a[j, 1]
            ok, t, s = line_parameters(a[i, 0], a[i, 1], d1x, d1y, a[j, 0], a[j, 1], d2x, d2y)
            if ok and t >= 0.0 and t <= 1.0 and s >= 0.0 and s <= 1.0:
                out[n, 0] = a[i, 0] + t * d1x
                out[n, 1] = a[i, 1] + t * d1y
                n += 1
    return n


@kernel
def rectangle_into(cx, cy, w, h, c, s, out):
    """Write the 4 vertices (counter-clockwise) of the ``w`` x ``h`` rectangle centred at
    (cx, cy) and turned by the angle of cosine ``c`` and sine ``s`` into ``out`` (4, 2)."""
    for k in range(4):
        x = 0.5 * (w if k == 1 or k == 2 else -w)
        y = 0.5 * (h if k >= 2 else -h)
        out[k, 0] = cx + (x * c - y * s)
        out[k, 1] = cy + (x * s + y * c)


@kernel
def too_close(points, poly, clearance):
    """Return whether a point (k, 2) is inside the polygon ``poly`` (n, 2) (farther in than
    its ``eps``, :func:`inside_point`) or nearer to it than ``clearance``."""
    n = poly.shape[0]
    ea, eb = np.empty((1, n, 2)), np.empty((1, n, 2))
    bbox = np.empty((1, 1, 4))
    scale = 1.0
    for j in range(n):
        for d in range(2):
            ea[0, j, d] = poly[j, d]
            eb[0, j, d] = poly[(j + 1) % n, d]
            scale = max(scale, abs(poly[j, d]))
    bbox[0, 0, 0], bbox[0, 0, 1] = poly[:, 0].min(), poly[:, 1].min()
    bbox[0, 0, 2], bbox[0, 0, 3] = poly[:, 0].max(), poly[:, 1].max()
    eps = np.full(1, TOL * scale)
    starts, ends = np.zeros(1, np.intp), np.full(1, n, np.intp)
    c2 = clearance * clearance
    for i in range(points.shape[0]):
        px, py = points[i, 0], points[i, 1]
        if inside_point(px, py, 0, ea, eb, starts, ends, bbox, eps):
            return True
    for i in range(points.shape[0]):
        for j in range(n):
            if edge_dist2(points[i, 0], points[i, 1], ea[0, j, 0], ea[0, j, 1], eb[0, j, 0],
                          eb[0, j, 1]) < c2:  # fmt: skip
                return True
    return False


@kernel
def rectangles_into(rng, bounds, sizes, clear, clearance, rotate, max_tries, out):
    """Draw ``len(out)`` rectangles into ``out`` (n, 4, 2) from the generator ``rng``; return
    the index of the first that found no place in ``max_tries`` draws, or -1.

    Each draw: the sides uniform in ``sizes`` (lo, hi), the angle uniform in [0, pi) (0
    without ``rotate``), the centre uniform among the positions keeping the rectangle in
    ``bounds`` (xmin, ymin, xmax, ymax); drawn again while a ``clear`` point (k, 2) is
    :func:`too_close`.
    """
    for k in range(out.shape[0]):
        placed = False
        for _ in range(max_tries):
            w = rng.uniform(sizes[0], sizes[1])
            h = rng.uniform(sizes[0], sizes[1])
            ang = rng.uniform(0.0, np.pi) if rotate else 0.0
            c, s = math.cos(ang), math.sin(ang)
            hx = (0.5 * abs(c)) * w + (0.5 * abs(s)) * h  # the half extents
            hy = (0.5 * abs(s)) * w + (0.5 * abs(c)) * h
            lox, loy, hix, hiy = bounds[0] + hx, bounds[1] + hy, bounds[2] - hx, bounds[3] - hy
            if lox > hix or loy > hiy:
                continue
            cx = rng.uniform(lox, hix)
            cy = rng.uniform(loy, hiy)
            rectangle_into(cx, cy, w, h, c, s, out[k])
            if clear.shape[0] and too_close(clear, out[k], clearance):
                continue
            placed = True
            break
        if not placed:
            return k
    return -1


@kernel
def unique_points(points, n):
    """Sort the first ``n`` rows of ``points`` (n, 2) by x, then y, and drop exact
    repeats in place (as ``np.unique(points[:n], axis=0)``); return how many remain."""
    for i in range(1, n):  # insertion sort: a few points
        x, y = points[i, 0], points[i, 1]
        k = i - 1
        while k >= 0 and (points[k, 0] > x or (points[k, 0] == x and points[k, 1] > y)):
            points[k + 1, 0], points[k + 1, 1] = points[k, 0], points[k, 1]
            k -= 1
        points[k + 1, 0], points[k + 1, 1] = x, y
    m = 0
    for i in range(n):
        if m == 0 or points[i, 0] != points[m - 1, 0] or points[i, 1] != points[m - 1, 1]:
            points[m, 0], points[m, 1] = points[i, 0], points[i, 1]
            m += 1
    return m


@kernel
def crossings_rows(a, b, polygon, scratch, counts, out):
    """For each layout ``i`` (edges ``a[i]``, ``b[i]`` (E, 2)): its distinct crossings
    (:func:`crossings_into`, then :func:`unique_points`, in ``scratch`` (E(E-1)/2, 2)),
    their number into ``counts[i]`` and, if ``out`` (N, X, 2) has room (X >= every count),
    the crossings to the front of ``out[i]`` with NaN rows after them."""
    for i in range(a.shape[0]):
        n = unique_points(scratch, crossings_into(a[i], b[i], polygon, scratch))
        counts[i] = n
        if out.shape[1] < n:
            continue
        out[i, :n] = scratch[:n]
        out[i, n:] = np.nan
