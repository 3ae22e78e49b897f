"""The numerical single-sensor solver's local refinement: trust-region steps on finite
difference models, along the boundary circles (the angle) and in the plane.

From each start (a candidate of :mod:`activetrack.solvers.numeric`), the objective is
modelled by central differences at ``FD_STEP`` of the local length scale and minimized
within a trust radius (a 1-D step on a circle's angle, a 2-D step in the plane, the best
of the model's Newton step and its boundary minima); a step is accepted if it lowers the
objective inside the feasible set. A start stops when its step falls below ``CONVERGED``
of the local scale, after an accepted step shorter than ``SETTLED`` of it (smooth
objectives), or after ``MAX_MISSES`` steps leaving the feasible set. All starts of all
rows step together, one batched evaluation of every stencil per iteration.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from activetrack.validation import FloatArray

if TYPE_CHECKING:
    from activetrack.solvers.numeric import _Problem

#: Finite-difference step in units of the local length scale.
FD_STEP = 1e-4


#: A refinement step shorter than this fraction of the local length scale ends it.
CONVERGED = 1e-7


#: An accepted step shorter than this fraction of the local scale ends a start (smooth
#: objectives: Newton's next step would be of the order of its square).
SETTLED = 1e-4


#: Infeasible steps after which a start stops.
MAX_MISSES = 1


#: Batches of at least this many rows drop their converged rows during refinement.
COMPACT_ROWS = 64


_TINY = 1e-300


def _finite(x: FloatArray) -> FloatArray:
    """Return ``x`` with non-finite entries (a difference quotient at a target) set to 0."""
    return np.where(np.isfinite(x), x, 0.0)


def _circle_points(o: FloatArray, rad: FloatArray, th: FloatArray) -> FloatArray:
    """Return ``o + rad (cos th, sin th)`` for matching leading shapes, (..., 2)."""
    out = np.empty(th.shape + (2,))
    out[..., 0] = np.cos(th)
    out[..., 1] = np.sin(th)
    out *= rad[..., None]
    out += o
    return out


def _model_max(f: FloatArray, g: FloatArray, H: FloatArray, d: FloatArray) -> FloatArray:
    """Return ``max_k q_k(d)`` for 1-D piece models ``q_k = f_k + g_k d + H_k d^2 / 2``.

    ``f, g, H`` (..., P); steps ``d`` (..., S); returns (..., S).
    """
    dd = d[..., :, None]
    return np.max(f[..., None, :] + dd * (g[..., None, :] + 0.5 * H[..., None, :] * dd), axis=-1)


def _step_1d(f: FloatArray, g: FloatArray, H: FloatArray, delta: FloatArray) -> FloatArray:
    """Return the step in ``[-delta, delta]`` minimizing the model ``max_k q_k`` (..., ).

    Candidates: both ends, each piece's vertex, every root of ``q_i - q_j`` (the kinks);
    for one piece this is the trust-region Newton step.
    """
    n = f.shape[-1]
    if n == 1:  # a smooth objective: the trust-region Newton step
        g, H = g[..., 0], H[..., 0]
        step = np.where(H > 0, -g / np.where(H > 0, H, 1.0), -np.sign(g) * delta)
        return np.clip(step, -delta, delta)
    cands = [-delta[..., None], delta[..., None]]
    with np.errstate(divide="ignore", invalid="ignore"):
        cands.append(np.where(H > 0, -g / np.where(H > 0, H, 1.0), 0.0))
        if n > 1:
            i, j = np.triu_indices(n, k=1)
            a = 0.5 * (H[..., i] - H[..., j])
            b = g[..., i] - g[..., j]
            c = f[..., i] - f[..., j]
            disc = b * b - 4.0 * a * c
            sq = np.sqrt(np.maximum(disc, 0.0))
            q = -0.5 * (b + np.where(b >= 0, sq, -sq))
            r1 = np.where(a != 0, q / np.where(a != 0, a, 1.0), np.inf)
            r2 = np.where(q != 0, c / np.where(q != 0, q, 1.0), np.inf)
            lin = np.where(b != 0, -c / np.where(b != 0, b, 1.0), np.inf)
            tiny = np.abs(a) * np.maximum(delta[..., None], _TINY) <= 1e-12 * np.abs(b)
            r1 = np.where(tiny, lin, np.where(disc >= 0, r1, np.inf))
            r2 = np.where(tiny, lin, np.where(disc >= 0, r2, np.inf))
            cands += [r1, r2]
    d = np.concatenate(cands, axis=-1)
    d = np.where(np.isfinite(d), np.clip(d, -delta[..., None], delta[..., None]), delta[..., None])
    model = _model_max(f, g, H, d)
    best = np.argmin(model, axis=-1)
    return np.take_along_axis(d, best[..., None], axis=-1)[..., 0]


def _quad(f: FloatArray, g: FloatArray, H: FloatArray, d: FloatArray) -> FloatArray:
    """Return 2-D piece models at steps: f (..., P), g (..., P, 2), H (..., P, 3), d (..., S, 2)."""
    x, y = d[..., :, None, 0], d[..., :, None, 1]
    h11, h12, h22 = H[..., None, :, 0], H[..., None, :, 1], H[..., None, :, 2]
    lin = g[..., None, :, 0] * x + g[..., None, :, 1] * y
    return f[..., None, :] + lin + 0.5 * (h11 * x * x + 2.0 * h12 * x * y + h22 * y * y)


def _clip_norm(d: FloatArray, delta: FloatArray) -> FloatArray:
    """Return steps ``d`` (..., S, 2) scaled into the disk of radius ``delta`` (...)."""
    norm = np.hypot(d[..., 0], d[..., 1])
    lim = delta[..., None]
    scale = np.where(norm > lim, lim / np.maximum(norm, _TINY), 1.0)
    return np.where(np.isfinite(d), d * scale[..., None], 0.0)


def _newton_2d(g: FloatArray, H: FloatArray, delta: FloatArray) -> FloatArray:
    """Return each piece's trust-region Newton step (gradient step if ``H`` not PD), (..., P, 2)."""
    h11, h12, h22 = H[..., 0], H[..., 1], H[..., 2]
    det = h11 * h22 - h12 * h12
    pd = (h11 > 0) & (det > 0)
    sdet = np.where(pd, det, 1.0)
    nx = -(h22 * g[..., 0] - h12 * g[..., 1]) / sdet
    ny = -(-h12 * g[..., 0] + h11 * g[..., 1]) / sdet
    gn = np.maximum(np.hypot(g[..., 0], g[..., 1]), _TINY)
    lim = delta[..., None]
    sx = np.where(pd, nx, -g[..., 0] * lim / gn)
    sy = np.where(pd, ny, -g[..., 1] * lim / gn)
    return _clip_norm(np.stack([sx, sy], -1), delta)


def _step_2d(f: FloatArray, g: FloatArray, H: FloatArray, delta: FloatArray) -> FloatArray:
    """Return the step in the disk ``|d| <= delta`` minimizing the model ``max_k q_k``, (..., 2).

    Candidates: each piece's Newton step; for each pair, the minimum of their model
    along the line where their linear models agree (a kink curve), weighted by the SQP
    multipliers (the least-norm convex combination of their gradients); for each triple, the
    point where the three linear models agree. One piece: the trust-region Newton step.
    """
    n = f.shape[-1]
    if n == 1:  # a smooth objective: the trust-region Newton step
        return _newton_2d(g, H, delta)[..., 0, :]
    cands = [_newton_2d(g, H, delta)]
    with np.errstate(divide="ignore", invalid="ignore"):
        if n > 1:
            i, j = np.triu_indices(n, k=1)
            nv = g[..., i, :] - g[..., j, :]
            n2 = np.maximum(nv[..., 0] ** 2 + nv[..., 1] ** 2, _TINY)
            d0 = nv * ((f[..., j] - f[..., i]) / n2)[..., None]
            e = np.stack([-nv[..., 1], nv[..., 0]], -1) / np.sqrt(n2)[..., None]
            # Lagrangian weights: the convex combination of the two gradients of least norm
            # (zero at a kink minimum), as in SQP for minimax.
            lam = np.clip(-np.sum(g[..., j, :] * nv, -1) / n2, 0.0, 1.0)[..., None]
            Hm = lam * H[..., i, :] + (1.0 - lam) * H[..., j, :]
            gm = lam * g[..., i, :] + (1.0 - lam) * g[..., j, :]
            hd = np.stack(
                [
                    Hm[..., 0] * d0[..., 0] + Hm[..., 1] * d0[..., 1],
                    Hm[..., 1] * d0[..., 0] + Hm[..., 2] * d0[..., 1],
                ],
                -1,
            )
            slope = np.sum((gm + hd) * e, -1)
            curv = Hm[..., 0] * e[..., 0] ** 2 + 2 * Hm[..., 1] * e[..., 0] * e[..., 1]
            curv = curv + Hm[..., 2] * e[..., 1] ** 2
            t = np.where(
                curv > 0, -slope / np.where(curv > 0, curv, 1.0), -np.sign(slope) * delta[..., None]
            )
            cands.append(_clip_norm(d0 + t[..., None] * e, delta))
        if n > 2:
            i, j, k = (np.array(x) for x in zip(*_triples(n), strict=True))
            u, v = g[..., i, :] - g[..., j, :], g[..., i, :] - g[..., k, :]
            ru, rv = f[..., j] - f[..., i], f[..., k] - f[..., i]
            det = u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]
            sdet = np.where(det != 0, det, 1.0)
            x = (ru * v[..., 1] - rv * u[..., 1]) / sdet
            y = (u[..., 0] * rv - v[..., 0] * ru) / sdet
            cands.append(
                _clip_norm(
                    np.stack([np.where(det != 0, x, 0.0), np.where(det != 0, y, 0.0)], -1), delta
                )
            )
    d = np.concatenate(cands, axis=-2)
    model = np.max(_quad(f, g, H, d), axis=-1)
    best = np.argmin(np.where(np.isfinite(model), model, np.inf), axis=-1)
    return np.take_along_axis(d, best[..., None, None], axis=-2)[..., 0, :]


def _triples(n: int) -> list[tuple[int, int, int]]:
    """Return the index triples ``i < j < k < n``."""
    return [(i, j, k) for i in range(n) for j in range(i + 1, n) for k in range(j + 1, n)]


_ARC_STENCIL = np.array([0.0, 1.0, -1.0])


_PLANE_STENCIL = np.array(
    [[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [1.0, 1.0]]
)


#: Difference quotients of the arc stencil (values at 0, +h, -h): h g and h^2 H.
_ARC_DIFF = np.array([[0.0, 0.5, -0.5], [-2.0, 1.0, 1.0]])


#: Difference quotients of the plane stencil (values at _PLANE_STENCIL): h g_x, h g_y,
#: h^2 H_xx, h^2 H_xy, h^2 H_yy.
_PLANE_DIFF = np.array(
    [
        [0.0, 0.5, -0.5, 0.0, 0.0, 0.0],
        [0.0, 0.0, 0.0, 0.5, -0.5, 0.0],
        [-2.0, 1.0, 1.0, 0.0, 0.0, 0.0],
        [1.0, -1.0, 0.0, -1.0, 0.0, 1.0],
        [-2.0, 0.0, 0.0, 1.0, 1.0, 0.0],
    ]
)


_ARC_POWERS = np.array([[1.0], [2.0]])


_PLANE_POWERS = np.array([[1.0], [1.0], [2.0], [2.0], [2.0]])


def _stencils(p: _Problem, o: FloatArray, rad: FloatArray, th: FloatArray, x: FloatArray) -> dict:
    """Return values, pieces and difference-quotient derivatives at arc angles and points.

    ``o, rad, th`` (B, ma, ...) arc starts (circle origin, radius, angle), ``x`` (B, mp, 2)
    plane points; all stencils are evaluated in one call of the objective.
    """
    b, ma = th.shape
    mp = x.shape[1]
    pa = _circle_points(o, rad, th)
    centres = np.concatenate([pa, x], axis=1)
    scale = p.scale(centres)
    feas = p.feasible(centres)
    ha = FD_STEP * np.minimum(scale[:, :ma] / np.maximum(rad, _TINY), 1.0)
    tha = th[..., None] + ha[..., None] * _ARC_STENCIL
    pts = [_circle_points(o[:, :, None], rad[..., None], tha).reshape(b, -1, 2)]
    if mp:
        hp = FD_STEP * np.minimum(scale[:, ma:], p.r[:, None])
        pts.append((x[:, :, None, :] + hp[..., None, None] * _PLANE_STENCIL).reshape(b, -1, 2))
    vals = p.pieces(np.concatenate(pts, axis=1) if mp else pts[0])
    npc = vals.shape[-1]
    va = vals[:, : 3 * ma].reshape(b, ma, 3, npc)
    da = _finite((_ARC_DIFF @ va) / ha[..., None, None] ** _ARC_POWERS)
    out = {
        "fa": np.where(feas[:, :ma], p.combine(va[..., 0, :]), np.inf),
        "pa": va[..., 0, :],
        "ga": da[..., 0, :],
        "Ha": da[..., 1, :],
        "ha": ha,
    }
    if mp:
        vp = vals[:, 3 * ma :].reshape(b, mp, 6, npc)
        dp = _finite((_PLANE_DIFF @ vp) / hp[..., None, None] ** _PLANE_POWERS).swapaxes(-1, -2)
        out.update(
            fp=np.where(feas[:, ma:], p.combine(vp[..., 0, :]), np.inf),
            pp=vp[..., 0, :],
            gp=dp[..., :2],
            Hp=dp[..., 2:],
            hp=hp,
        )
    return out


_ARC_KEYS = ("th", "fa", "pa", "ga", "Ha", "ha", "da", "active_a", "o", "rad", "miss_a")


_PLANE_KEYS = ("x", "fp", "pp", "gp", "Hp", "hp", "dp", "active_p", "miss")


def _iterate(p: _Problem, st: dict) -> None:
    """Take one trust-region step for every active start of ``st`` (updated in place)."""
    sa = np.where(st["active_a"], _step_1d(st["pa"], st["ga"], st["Ha"], st["da"]), 0.0)
    # Converged: a step below CONVERGED of the local scale changes f by its square.
    st["active_a"] &= np.abs(sa) > (CONVERGED / FD_STEP) * st["ha"]
    plane = st["x"].shape[1] > 0
    if plane:
        sp = _step_2d(st["pp"], st["gp"], st["Hp"], st["dp"])
        sp = np.where(st["active_p"][..., None], sp, 0.0)
        norm = np.hypot(sp[..., 0], sp[..., 1])
        st["active_p"] &= norm > (CONVERGED / FD_STEP) * st["hp"]
    if not (st["active_a"].any() or (plane and st["active_p"].any())):
        return  # every start has converged: nothing to evaluate
    # A smooth objective converges quadratically under Newton's steps: after an accepted
    # step shorter than SETTLED of the local scale the next would change f by less than
    # the rounding of the difference quotients, so the start ends there.
    settle = 0.0 if p.minimax else SETTLED / FD_STEP
    settled_a = np.abs(sa) <= settle * st["ha"]
    if plane:
        settled_p = norm <= settle * st["hp"]
        new = _stencils(p, st["o"], st["rad"], st["th"] + sa, st["x"] + sp)
        new["x"] = st["x"] + sp
    else:
        new = _stencils(p, st["o"], st["rad"], st["th"] + sa, st["x"])
    new["th"] = st["th"] + sa
    acc_a = st["active_a"] & (new["fa"] < st["fa"])
    # An arc step leaving F ends the arc at another circle: that end (a circle
    # intersection) is a candidate itself, so MAX_MISSES such steps stop the start.
    st["miss_a"] = st["miss_a"] + (st["active_a"] & ~np.isfinite(new["fa"]))
    st["active_a"] &= (st["miss_a"] < MAX_MISSES) & ~(acc_a & settled_a)
    for key in ("th", "fa", "pa", "ga", "Ha", "ha"):
        mask = acc_a.reshape(acc_a.shape + (1,) * (new[key].ndim - acc_a.ndim))
        st[key] = np.where(mask, new[key], st[key])
    st["da"] = np.where(acc_a, np.maximum(st["da"], 2.0 * np.abs(sa)), 0.25 * np.abs(sa))
    if not plane:
        return
    acc_p = st["active_p"] & (new["fp"] < st["fp"])
    # Plane steps leaving F MAX_MISSES times (each shrinking the trust radius): the
    # optimum nearby lies on the boundary, which the arc refinement covers; stop.
    st["miss"] = st["miss"] + ~np.isfinite(new["fp"])
    st["active_p"] &= (st["miss"] < MAX_MISSES) & ~(acc_p & settled_p)
    for key in _PLANE_KEYS[:6]:
        mask = acc_p.reshape(acc_p.shape + (1,) * (new[key].ndim - acc_p.ndim))
        st[key] = np.where(mask, new[key], st[key])
    st["dp"] = np.where(acc_p, np.maximum(st["dp"], 2.0 * norm), 0.25 * norm)


def _refine(
    p: _Problem,
    arcs: tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray],
    plane: tuple[FloatArray, FloatArray, FloatArray],
    n_iter: int,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Return the refined points (B, m, 2) and values (B, m) (``+inf`` where none started),
    and the final angles (B, ma) and plane points (B, mp, 2).

    ``arcs = (origin (B, ma, 2), radius (B, ma), theta (B, ma), value (B, ma), delta)``,
    ``plane = (x (B, mp, 2), value (B, mp), delta (B, mp))``; a start with value ``+inf``
    does not start (otherwise the value is recomputed at the start). One evaluation of all
    stencils per iteration. Models are per piece (:meth:`_Problem.pieces`). Rows whose
    starts have all converged drop out of the batch (when they are at least half of it).
    """
    o, rad, th, fa, da = arcs
    x, fp, dp = plane
    st = {"pp": fp[..., None], "gp": x[..., None, :], "Hp": np.zeros(fp.shape + (1, 3))}
    st.update(hp=fp, fp=fp)
    st.update(_stencils(p, o, rad, th, x))
    st.update(th=th, x=x, o=o, rad=rad, da=da, dp=dp)
    st["fa"] = np.where(np.isfinite(fa), st["fa"], np.inf)
    st["fp"] = np.where(np.isfinite(fp), st["fp"], np.inf)
    st["active_a"], st["active_p"] = np.isfinite(st["fa"]), np.isfinite(st["fp"])
    st["miss"] = np.zeros(fp.shape, dtype=np.int64)
    st["miss_a"] = np.zeros(fa.shape, dtype=np.int64)
    if len(p.r) < COMPACT_ROWS:  # small batches: no compaction, stop when all converged
        for _ in range(n_iter):
            _iterate(p, st)
            if not (st["active_a"].any() or st["active_p"].any()):
                break
        pts = np.concatenate([_circle_points(o, rad, st["th"]), st["x"]], axis=1)
        return pts, np.concatenate([st["fa"], st["fp"]], axis=1), st["th"], st["x"]
    full = {key: st[key].copy() for key in _ARC_KEYS + _PLANE_KEYS}
    rows = np.arange(len(p.r))
    sub = p
    for _ in range(n_iter):
        _iterate(sub, st)
        busy = st["active_a"].any(axis=1) | st["active_p"].any(axis=1)
        if not busy.all() and 2 * np.count_nonzero(busy) <= len(busy):
            for key in full:
                full[key][rows] = st[key]
            rows = rows[busy]
            st = {key: full[key][rows] for key in full}
            if len(rows) == 0:
                break
            sub = p.take(rows)
    for key in full:
        full[key][rows] = st[key]
    pts = np.concatenate([_circle_points(o, rad, full["th"]), full["x"]], axis=1)
    return pts, np.concatenate([full["fa"], full["fp"]], axis=1), full["th"], full["x"]
