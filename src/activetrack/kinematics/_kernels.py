"""Compiled sensor moves, eq. (13)-(16), one sensor at a time.

The kernels behind :mod:`activetrack.kinematics.sensor_motion` and
:func:`activetrack.kinematics.geometry.project_feasible` (their docstrings state the rules):
:func:`moves_rows` turns actions (in units of the reach) or absolute positions into
positions within reach, :func:`keep_rows` pushes the moves that end inside a ``rho`` disk
to the nearest feasible point (:func:`project_feasible_point`). Arrays are C-contiguous
float64 rows: positions (B, M, 2), the predicted target (B, 2), per-sensor values (B', M)
with B' = 1 (shared) or B.
"""

from __future__ import annotations

import math

from activetrack._jit import kernel

#: Relative tolerance of the unit-disk and minimum-distance tests.
TOL = 1e-12
#: Longer than the unit disk / the reach, and inside a ``rho`` disk, beyond rounding.
LONG = 1.0 + TOL
INSIDE = 1.0 - TOL


@kernel
def fallback_point(cx, cy, r):
    """Return ``c + r c / ||c||`` (x axis where ``c`` is zero): the reachable point
    farthest from the target, for a sensor that cannot leave the ``rho`` disk."""
    nc = math.hypot(cx, cy)
    if nc > 0.0:
        return cx + r * (cx / nc), cy + r * (cy / nc)
    return cx + r * 1.0, cy + r * 0.0


@kernel
def project_feasible_point(qx, qy, cx, cy, r, rho):
    """Return the feasible point nearest to ``q`` (all relative to the target).

    ``q`` must lie in the speed disk around ``c``. A ``q`` inside the ``rho`` disk goes
    radially onto the ``rho`` circle; if that leaves the speed disk, to the nearer of the
    two circle intersections; if the circles do not meet, to :func:`fallback_point`.
    """
    nq = math.hypot(qx, qy)
    if not nq < rho:
        return qx, qy
    nc = math.hypot(cx, cy)
    ux, uy = (cx / nc, cy / nc) if nc > 0.0 else (1.0, 0.0)
    dx, dy = (qx / nq, qy / nq) if nq > 0.0 else (ux, uy)
    radx, rady = rho * dx, rho * dy
    if math.hypot(radx - cx, rady - cy) <= r * (1.0 + 1e-12):
        return radx, rady
    # The intersections of ||s - c|| = r and ||s|| = rho (angle g from c's direction).
    cos_g = (rho * rho + nc * nc - r * r) / (2.0 * rho * nc)
    if not abs(cos_g) <= 1.0:  # the circles do not meet (or c = 0)
        return fallback_point(cx, cy, r)
    sin_g = math.sqrt(1.0 - cos_g * cos_g)
    bx, by = (rho * cos_g) * ux, (rho * cos_g) * uy
    ox, oy = (rho * sin_g) * -uy, (rho * sin_g) * ux
    ax, ay, qbx, qby = bx + ox, by + oy, bx - ox, by - oy
    if math.hypot(ax - qx, ay - qy) <= math.hypot(qbx - qx, qby - qy):
        return ax, ay
    return qbx, qby


@kernel
def unit_disk(ax, ay):
    """Return ``(ax, ay)`` scaled to length 1 if longer than ``1 + TOL`` (no overflow)."""
    norm = math.hypot(ax, ay)
    if not norm > LONG:
        return ax, ay
    if math.isinf(norm):  # |a| overflowed: divide by the larger component first
        big = max(abs(ax), abs(ay))
        ax, ay = ax / big, ay / big
        norm = math.hypot(ax, ay)
    return ax / norm, ay / norm


@kernel
def move_point(x, y, sx, sy, r, absolute):
    """Return one sensor's position within reach ``r`` of ``(sx, sy)``: ``s + r a`` for
    the action ``(x, y)`` (``a`` on the unit disk), or for the absolute position ``(x, y)``
    (``absolute``) itself, scaled onto the speed circle if farther than ``r (1 + TOL)``."""
    if not absolute:
        ax, ay = unit_disk(x, y)
        return sx + ax * r, sy + ay * r
    dx, dy = x - sx, y - sy
    if math.hypot(dx, dy) > r * LONG:
        safe = r if r > 0.0 else 1.0
        ax, ay = unit_disk(dx / safe, dy / safe)
        return sx + ax * r, sy + ay * r
    return x, y


@kernel
def keep_point(nx, ny, sx, sy, tx, ty, r, rho):
    """Return ``(x, y, inside)``: the move ``(nx, ny)`` from ``(sx, sy)``, projected to the
    nearest feasible point if it ends inside the ``rho`` disk around the predicted target
    ``(tx, ty)`` (by more than ``TOL``, relative); ``inside`` marks that. A sensor with
    ``r = 0`` stays, even inside."""
    qx, qy = nx - tx, ny - ty
    if math.hypot(qx, qy) < rho * INSIDE and r > 0.0:
        px, py = project_feasible_point(qx, qy, sx - tx, sy - ty, r, rho)
        return px + tx, py + ty, True
    return nx, ny, False


@kernel
def moves_rows(x, sensors, r, absolute, out):
    """Write positions within reach into ``out`` (B, M, 2): :func:`move_point` of the
    actions or absolute positions ``x`` (B, M, 2) from ``sensors``."""
    for b in range(x.shape[0]):
        rb = r[b if r.shape[0] > 1 else 0]
        for m in range(x.shape[1]):
            out[b, m, 0], out[b, m, 1] = move_point(
                x[b, m, 0], x[b, m, 1], sensors[b, m, 0], sensors[b, m, 1], rb[m], absolute
            )


@kernel
def keep_rows(new, sensors, target, r, rho, out, inside):
    """Write ``new`` (B, M, 2) with the moves that end inside their ``rho`` disk around the
    predicted ``target`` (B, 2) projected (:func:`keep_point`) into ``out``; mark them in
    ``inside`` (B, M)."""
    for b in range(new.shape[0]):
        rb, hb = r[b if r.shape[0] > 1 else 0], rho[b if rho.shape[0] > 1 else 0]
        tx, ty = target[b, 0], target[b, 1]
        for m in range(new.shape[1]):
            out[b, m, 0], out[b, m, 1], inside[b, m] = keep_point(
                new[b, m, 0], new[b, m, 1], sensors[b, m, 0], sensors[b, m, 1], tx, ty,
                rb[m], hb[m],
            )  # fmt: skip


@kernel
def project_feasible_rows(q, c, r, rho, out):
    """Write :func:`project_feasible_point` of rows ``q``, ``c`` (B, 2), ``r``, ``rho``
    (B,) into ``out`` (B, 2)."""
    for b in range(q.shape[0]):
        out[b, 0], out[b, 1] = project_feasible_point(
            q[b, 0], q[b, 1], c[b, 0], c[b, 1], r[b], rho[b]
        )


@kernel
def fallback_rows(c, r, out):
    """Write :func:`fallback_point` of rows ``c`` (B, 2), ``r`` (B,) into ``out`` (B, 2)."""
    for b in range(c.shape[0]):
        out[b, 0], out[b, 1] = fallback_point(c[b, 0], c[b, 1], r[b])
