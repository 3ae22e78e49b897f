"""Compiled kernel of GSR's command-space step (:mod:`activetrack.baselines.gsr_command`) for
the built-in kinematics, the built-in sensor models and the trace objective.

The same solve as :class:`activetrack.baselines.gsr_command.Prepared` (grid, the previous
solution, the adaptive pattern search; the same constants), one copy after the other, with
the kinematics' :meth:`~activetrack.Kinematics.apply` written out:

- ``DISK`` (params ``radius``): ``position + radius a``, an action longer than 1 scaled onto
  the unit circle (:meth:`activetrack.kinematics.disk.Disk.apply`);
- ``RADIUS_DISK`` (no params): the same with the radius in the state ``(x, y, r)``
  (:class:`activetrack.baselines.gsr_separation.RadiusDisk`);
- ``DOUBLE_INTEGRATOR`` (params ``a_max, v_max, dt``): the acceleration ``a_max u / max(1,
  |u|)`` then the nearest point of the two disks' intersection
  (:meth:`activetrack.kinematics.double_integrator.DoubleIntegrator.apply`, its ``clip``
  with the same tolerance; the query lies in the acceleration disk);
- ``UNICYCLE`` (params ``v_min, v_max, w_max, dt``): the exact arc of
  :meth:`activetrack.kinematics.unicycle.Unicycle.advance`.

A command whose point falls inside a ``rho`` disk (or a capsule, below) stands for that
point moved radially onto the disk's edge, when that is reachable: the search then moves
along the constraints' boundaries, where optima often lie, instead of stalling at a
curved edge in command space.

The information is ``J0`` of eq. (17) with the weights ``(w_d, w_theta)`` (any built-in
model: a component a model does not measure has weight 0), the objective the sum over the
K targets of ``tr(Y^{-1})``. Constraints beyond the ``rho`` disks (the team rule ``d_sep``,
:mod:`activetrack.baselines.gsr_separation`) are given as *capsules* ``(ax, ay, bx, by,
r)``: a point must keep ``r`` from the segment ``a -> b`` (a disk when ``a = b``), and
*sweeps* ``(cx, cy, vx, vy, r)``: the segment from the sensor's position to the point less
``v`` must keep ``r`` from ``c`` (``v = 0``: the sensor's own segment; else the relative
motion against a sensor moving from ``c`` by ``v`` over the same step).
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import kernel

DISK = 0
UNICYCLE = 1
RADIUS_DISK = 2
DOUBLE_INTEGRATOR = 3
#: A point moved out of a disk lands this much (relative) outside it (rounding).
_EDGE = 1e-14


@kernel
def point(code, prm, st, u0, u1):
    """Return the point ``(x, y)`` the command ``(u0, u1)`` (clipped to [-1, 1]^2) reaches
    from the state ``st``."""
    a0 = min(max(u0, -1.0), 1.0)
    a1 = min(max(u1, -1.0), 1.0)
    if code == DISK or code == RADIUS_DISK:
        n = math.hypot(a0, a1)
        if n > 1.0:
            a0 /= n
            a1 /= n
        r = prm[0] if code == DISK else st[2]
        return st[0] + r * a0, st[1] + r * a1
    if code == DOUBLE_INTEGRATOR:
        return _double_integrator(prm, st, a0, a1)
    v = prm[0] + 0.5 * (a0 + 1.0) * (prm[1] - prm[0])
    phi = 0.5 * a1 * prm[2] * prm[3]
    s = 1.0 if phi == 0.0 else math.sin(phi) / phi
    chord = v * prm[3] * s
    ang = st[2] + phi
    return st[0] + chord * math.cos(ang), st[1] + chord * math.sin(ang)


@kernel
def _double_integrator(prm, st, a0, a1):
    """Return :meth:`DoubleIntegrator.apply` of ``(a0, a1)`` from ``st`` (x, y, vx, vy)."""
    dt = prm[2]
    n = max(1.0, math.hypot(a0, a1))
    ra, rv = 0.5 * prm[0] * dt * dt, 0.5 * prm[1] * dt
    cax, cay = st[0] + st[2] * dt, st[1] + st[3] * dt
    cvx, cvy = st[0] + 0.5 * dt * st[2], st[1] + 0.5 * dt * st[3]
    qx, qy = cax + ra * a0 / n, cay + ra * a1 / n
    tol = 4e-12 * (prm[1] * dt + max(abs(st[0]), abs(st[1])))
    dv = math.hypot(qx - cvx, qy - cvy)
    if dv <= rv + tol:
        return qx, qy
    ox, oy = cvx + (qx - cvx) * (rv / dv), cvy + (qy - cvy) * (rv / dv)
    if math.hypot(ox - cax, oy - cay) <= ra + tol:
        return ox, oy
    ex, ey = cvx - cax, cvy - cay
    d = math.hypot(ex, ey)
    ux, uy = (ex / d, ey / d) if d > 0.0 else (1.0, 0.0)
    x = (d * d + ra * ra - rv * rv) / (2.0 * (d if d > 0.0 else 1.0))
    h = math.sqrt(max(ra * ra - x * x, 0.0))
    mx, my = cax + x * ux, cay + x * uy
    k1x, k1y, k2x, k2y = mx - h * uy, my + h * ux, mx + h * uy, my - h * ux
    if math.hypot(k1x - qx, k1y - qy) <= math.hypot(k2x - qx, k2y - qy):
        return k1x, k1y
    return k2x, k2y


@kernel
def seg_dist(ax, ay, bx, by, cx, cy):
    """Return the distance from ``c`` to the segment ``a -> b``."""
    ux, uy = bx - ax, by - ay
    den = ux * ux + uy * uy
    t = 0.0
    if den > 0.0:
        t = min(max(((cx - ax) * ux + (cy - ay) * uy) / den, 0.0), 1.0)
    return math.hypot(cx - ax - t * ux, cy - ay - t * uy)


@kernel
def reaches(code, prm, st, px, py):
    """Return whether ``(px, py)`` lies in the reach set of state ``st`` (no tolerance: a
    point on the rounding's wrong side of the boundary is left out)."""
    dx, dy = px - st[0], py - st[1]
    d = math.hypot(dx, dy)
    if code == DISK:
        return d <= prm[0]
    if code == RADIUS_DISK:
        return d <= st[2]
    if code == DOUBLE_INTEGRATOR:
        dt = prm[2]
        ea = math.hypot(px - st[0] - st[2] * dt, py - st[1] - st[3] * dt)
        ev = math.hypot(px - st[0] - 0.5 * dt * st[2], py - st[1] - 0.5 * dt * st[3])
        return ea <= 0.5 * prm[0] * dt * dt and ev <= 0.5 * prm[1] * dt
    dt = prm[3]
    if d == 0.0:
        return prm[0] == 0.0
    phi = math.atan2(dy, dx) - st[2]
    phi = math.atan2(math.sin(phi), math.cos(phi))
    if abs(phi) > 0.5 * prm[2] * dt:
        return False
    s = 1.0 if phi == 0.0 else math.sin(phi) / phi
    return prm[0] * dt * s <= d <= prm[1] * dt * s


@kernel
def locate(code, prm, st, u0, u1, tg, rho, caps, sweeps):
    """Return ``(feasible, x, y)``: the point of command ``(u0, u1)``, moved radially out of
    a ``rho`` disk or a capsule it falls in (onto its edge: the search then reaches the
    constraints' boundaries, where optima lie), and whether that point is feasible."""
    x, y = point(code, prm, st, u0, u1)
    moved = False
    for k in range(tg.shape[0]):
        ex, ey = x - tg[k, 0], y - tg[k, 1]
        d = math.hypot(ex, ey)
        if d < rho and d > 0.0:
            f = rho * (1.0 + _EDGE) / d
            x, y = tg[k, 0] + f * ex, tg[k, 1] + f * ey
            moved = True
    for j in range(caps.shape[0]):
        ax, ay, bx, by, r = caps[j, 0], caps[j, 1], caps[j, 2], caps[j, 3], caps[j, 4]
        ux, uy = bx - ax, by - ay
        den = ux * ux + uy * uy
        t = 0.0
        if den > 0.0:
            t = min(max(((x - ax) * ux + (y - ay) * uy) / den, 0.0), 1.0)
        cx, cy = ax + t * ux, ay + t * uy
        d = math.hypot(x - cx, y - cy)
        if d < r and d > 0.0:
            f = r * (1.0 + _EDGE) / d
            x, y = cx + f * (x - cx), cy + f * (y - cy)
            moved = True
    for k in range(tg.shape[0]):
        if math.hypot(x - tg[k, 0], y - tg[k, 1]) < rho:
            return False, x, y
    for j in range(caps.shape[0]):
        if seg_dist(caps[j, 0], caps[j, 1], caps[j, 2], caps[j, 3], x, y) < caps[j, 4]:
            return False, x, y
    for j in range(sweeps.shape[0]):
        ex, ey = x - sweeps[j, 2], y - sweeps[j, 3]
        if seg_dist(st[0], st[1], ex, ey, sweeps[j, 0], sweeps[j, 1]) < sweeps[j, 4]:
            return False, x, y
    if moved and not reaches(code, prm, st, x, y):
        return False, x, y
    return True, x, y


@kernel
def value(px, py, tg, wd, wt, base):
    """Return the objective (the sum over the targets of ``tr(Y^{-1})``) with the sensor at
    ``(px, py)``; ``inf`` where it is not finite."""
    total = 0.0
    for k in range(tg.shape[0]):
        rx, ry = px - tg[k, 0], py - tg[k, 1]
        n2 = rx * rx + ry * ry
        a, b, c = base[k, 0], base[k, 1], base[k, 2]
        if n2 > 0.0:
            n = math.sqrt(n2)
            ux, uy = rx / n, ry / n
            wv = wt / n2
            a += wd * ux * ux + wv * uy * uy
            b += (wd - wv) * ux * uy
            c += wd * uy * uy + wv * ux * ux
        det = a * c - b * b
        if not det > 0.0:
            return np.inf
        total += (a + c) / det
    if not math.isfinite(total):
        return np.inf
    return total


@kernel
def evaluate(code, prm, st, u0, u1, tg, rho, wd, wt, base, caps, sweeps):
    """Return ``(value, x, y)`` of command ``(u0, u1)`` (:func:`locate`, :func:`value`;
    ``inf`` when infeasible)."""
    ok, x, y = locate(code, prm, st, u0, u1, tg, rho, caps, sweeps)
    if not ok:
        return np.inf, x, y
    return value(x, y, tg, wd, wt, base), x, y


@kernel
def solve_rows(
    code, prm, states, tg, rho, wd, wt, base, caps, sweeps, prev, grid, n, stop, rounds,
    out_u, out_p, out_v,
):  # fmt: skip
    """Solve each copy's subproblem (rows of ``states`` (S, sd), ``tg`` (S, K, 2), ``rho``,
    ``wd``, ``wt`` (S,), ``base`` (S, K, 3), ``caps`` (S, J, 5), ``sweeps`` (S, J2, 3), the
    previous commands ``prev`` (S, 2), NaN: none) into ``out_u``, ``out_p`` (S, 2) and
    ``out_v`` (S,) (``inf``: nothing feasible)."""
    for s in range(states.shape[0]):
        st = states[s]
        bu0, bu1, bp0, bp1, bv = 0.0, 0.0, st[0], st[1], np.inf
        for i0 in range(grid):
            for i1 in range(grid):
                u0 = -1.0 + 2.0 * i0 / (grid - 1)
                u1 = -1.0 + 2.0 * i1 / (grid - 1)
                v, x, y = evaluate(
                    code, prm, st, u0, u1, tg[s], rho[s], wd[s], wt[s], base[s], caps[s], sweeps[s]
                )
                if v < bv:
                    bu0, bu1, bp0, bp1, bv = u0, u1, x, y, v
        if math.isfinite(prev[s, 0]):
            v, x, y = evaluate(
                code, prm, st, prev[s, 0], prev[s, 1], tg[s], rho[s], wd[s], wt[s], base[s],
                caps[s], sweeps[s],
            )  # fmt: skip
            if v < bv:
                bu0, bu1, bp0, bp1, bv = prev[s, 0], prev[s, 1], x, y, v
        h = 2.0 / (grid - 1)
        if math.isfinite(bv):
            for _ in range(rounds):
                if h < stop:
                    break
                c0, c1 = bu0, bu1
                moved, edge = False, False
                for k0 in range(-n, n + 1):
                    for k1 in range(-n, n + 1):
                        if k0 == 0 and k1 == 0:
                            continue
                        u0 = min(max(c0 + h * k0, -1.0), 1.0)
                        u1 = min(max(c1 + h * k1, -1.0), 1.0)
                        v, x, y = evaluate(
                            code, prm, st, u0, u1, tg[s], rho[s], wd[s], wt[s], base[s],
                            caps[s], sweeps[s],
                        )  # fmt: skip
                        if v < bv:
                            bu0, bu1, bp0, bp1, bv = u0, u1, x, y, v
                            moved = True
                            edge = max(abs(k0), abs(k1)) == n
                if moved and edge:
                    h = min(2.0 * h, 2.0)
                else:
                    h = h / (n + 1)
        out_u[s, 0], out_u[s, 1] = bu0, bu1
        out_p[s, 0], out_p[s, 1] = bp0, bp1
        out_v[s] = bv
