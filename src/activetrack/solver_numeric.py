"""A global numerical single-sensor solver: any measurement model, pose uncertainty, K targets.

The subproblem of Gauss-Seidel relaxation for sensor ``i`` with the other sensors folded
in (``docs/sensor-models-design.md``, section 4; the paper's eq. 22-24 generalized):

    minimize over s in F:  f(s) = objective.of_targets(a0 + ai(s), b0 + bi(s), c0 + ci(s))

where ``(a0, b0, c0)`` (..., K) are the entries of each target's information without
sensor ``i`` (prior plus the other sensors, eq. 12), ``(ai, bi, ci)(s)`` is sensor ``i``'s
information about each target (:func:`activetrack.sensor_models.information_entries`,
eq. 17 with the model's weights and the effective noise of an uncertain pose) and ``F``
is the feasible set of :mod:`activetrack.feasible_set` (eq. 15-16 with K targets).

Method (deterministic, batched over leading axes without Python loops over the batch):

1. Candidates. On each of the K + 1 boundary circles (reach circle, ``rho`` circles) a
   uniform grid of ``n_boundary`` angles plus, around the direction from the circle's
   centre to each target, angles at offsets ``+-sigma {1/8, ..., 4}`` and 0, where
   ``sigma`` is the angular width of the target's well on that circle
   (``max(| |t - o| - R |, rho) / R``: the bearing information grows as the inverse
   squared distance, so on the reach circle passing near a target ``f`` varies on that
   scale). Every pairwise circle intersection (the arcs' ends, where constrained optima
   sit). A square grid of ``n_interior x n_interior`` points over the reach disk: with
   K >= 2 the optimum need not lie on the boundary (Lemma 3 holds per target only).
   Infeasible candidates get the value ``+inf`` (ragged arc sets become masks).
2. Refinement. From the best ``N_LOCAL_ARC`` local minima (along the sorted angles) of each
   circle, Newton on the angle; from the best ``N_LOCAL_PLANE`` local minima of the
   interior grid, Newton in the plane. Derivatives are central differences with a step
   ``1e-4`` of the local length scale (the distance to the nearest target, capped by the
   radius), steps are limited by a trust radius that starts at the grid spacing and
   shrinks by 4 after a rejected step. A step is accepted only when its point is
   feasible and strictly better.
3. The answer is the best point evaluated (grid, intersections, accepted steps), so it is
   never worse than any candidate. When no candidate is feasible (``F`` empty), the
   answer is :func:`activetrack.feasible_set.fallback` and its value.

Special cases: ``r = 0`` returns the sensor's position (its only reachable point, feasible
or the fallback); a point at zero distance from a target gets no information about it
(the rule of :mod:`activetrack.sensor_models`); with ``rho = 0`` and a target within reach
an infimum that is not attained (the bearing information unbounded) is approached only
to the resolution of the candidates.

Computation is relative to the sensor's position (rounding scales with the reach, not
with the absolute coordinates); the returned positions are absolute.
"""

from __future__ import annotations

import numpy as np

from activetrack import feasible_set
from activetrack.objective import TRACE, TraceObjective
from activetrack.sensor_models import information_entries
from activetrack.validation import FloatArray

#: Multipliers of a target's angular well width at which extra angles are placed.
WELL_OFFSETS = np.array(
    [0.0, 0.125, -0.125, 0.25, -0.25, 0.5, -0.5, 1.0, -1.0, 2.0, -2.0, 4.0, -4.0]
)
#: Local minima refined per circle and in the interior.
N_LOCAL_ARC = 2
N_LOCAL_PLANE = 3
#: Finite-difference step in units of the local length scale.
FD_STEP = 1e-4
_TINY = 1e-300


class _Problem:
    """The flattened batch (B rows), relative to each sensor's position, and ``f``."""

    def __init__(self, base, center, r, targets, rho, w_d, w_theta, pose_cov, objective):
        a0, b0, c0 = (np.asarray(x, dtype=np.float64) for x in base)
        center = np.asarray(center, dtype=np.float64)
        targets = np.asarray(targets, dtype=np.float64)
        r, rho = np.asarray(r, dtype=np.float64), np.asarray(rho, dtype=np.float64)
        w_d, w_theta = np.asarray(w_d, dtype=np.float64), np.asarray(w_theta, dtype=np.float64)
        k = targets.shape[-2]
        shapes = [
            a0.shape[:-1], b0.shape[:-1], c0.shape[:-1], center.shape[:-1],
            targets.shape[:-2], r.shape, rho.shape, w_d.shape, w_theta.shape,
        ]  # fmt: skip
        if pose_cov is not None:
            pose_cov = np.asarray(pose_cov, dtype=np.float64)
            shapes.append(pose_cov.shape[:-2])
        self.shape = np.broadcast_shapes(*shapes)
        n = int(np.prod(self.shape))
        self.k = k

        def flat(x, tail=()):
            return np.broadcast_to(x, self.shape + tail).reshape((n,) + tail)

        self.center = flat(center, (2,))
        self.a0, self.b0, self.c0 = flat(a0, (k,)), flat(b0, (k,)), flat(c0, (k,))
        self.t = flat(targets, (k, 2)) - self.center[:, None, :]
        self.r, self.rho = flat(r), flat(rho)
        self.wd = flat(w_d)[:, None, None]
        self.wt = flat(w_theta)[:, None, None]
        self.pc = None if pose_cov is None else flat(pose_cov, (2, 2))[:, None, None]
        self.objective = objective
        self.zero = np.zeros((n, 2))

    def f(self, pts: FloatArray) -> FloatArray:
        """Return the objective at points (B, C, 2) relative to the sensor, (B, C)."""
        rel = pts[:, :, None, :] - self.t[:, None, :, :]
        a, b, c = information_entries(rel, self.wd, self.wt, self.pc)
        a0, b0, c0 = self.a0[:, None], self.b0[:, None], self.c0[:, None]
        return self.objective.of_targets(a0 + a, b0 + b, c0 + c)

    def feasible(self, pts: FloatArray) -> np.ndarray:
        """Return whether points (B, C, 2) lie in F (with the tolerance), (B, C)."""
        return feasible_set.contains(
            pts, self.zero[:, None], self.r[:, None], self.t[:, None], self.rho[:, None]
        )

    def masked(self, pts: FloatArray) -> FloatArray:
        """Return ``f`` at points (B, C, 2), ``+inf`` where infeasible."""
        return np.where(self.feasible(pts), self.f(pts), np.inf)

    def scale(self, pts: FloatArray) -> FloatArray:
        """Return the distance from points (B, C, 2) to the nearest target, (B, C)."""
        e = pts[:, :, None, :] - self.t[:, None, :, :]
        return np.min(np.hypot(e[..., 0], e[..., 1]), axis=-1)


def _circle_points(o: FloatArray, rad: FloatArray, th: FloatArray) -> FloatArray:
    """Return ``o + rad (cos th, sin th)`` for matching leading shapes, (..., 2)."""
    return o + rad[..., None] * np.stack([np.cos(th), np.sin(th)], -1)


def _arc_candidates(p: _Problem, n_boundary: int) -> tuple[FloatArray, ...]:
    """Return ``(origins, radii, angles, values)``: (B, n, 2), (B, n), (B, n, M), (B, n, M).

    Angles are sorted along the last axis; ``values`` are ``+inf`` where infeasible.
    """
    origins, radii = feasible_set.circles(p.zero, p.r, p.t, p.rho)
    b, n = radii.shape
    uniform = np.broadcast_to(
        np.linspace(-np.pi, np.pi, n_boundary, endpoint=False), (b, n, n_boundary)
    )
    v = p.t[:, None, :, :] - origins[:, :, None, :]  # circle -> target, (B, n, K, 2)
    dist = np.hypot(v[..., 0], v[..., 1])
    phi = np.arctan2(v[..., 1], v[..., 0])
    width = np.maximum(np.abs(dist - radii[..., None]), p.rho[:, None, None])
    # Wider wells are resolved by the uniform grid (spacing 2 pi / n_boundary).
    sigma = np.minimum(width / np.maximum(radii[..., None], _TINY), 0.25)
    well = phi[..., None] + sigma[..., None] * WELL_OFFSETS  # (B, n, K, W)
    th = np.concatenate([uniform, well.reshape(b, n, -1)], axis=-1)
    th = np.sort(np.mod(th + np.pi, 2.0 * np.pi) - np.pi, axis=-1)
    pts = _circle_points(origins[:, :, None, :], np.broadcast_to(radii[..., None], th.shape), th)
    vals = p.masked(pts.reshape(b, -1, 2)).reshape(th.shape)
    return origins, radii, th, vals


def _vertex_candidates(p: _Problem) -> tuple[FloatArray, FloatArray]:
    """Return the pairwise circle intersections (B, V, 2) and their values (``+inf`` if none)."""
    origins, radii = feasible_set.circles(p.zero, p.r, p.t, p.rho)
    pts, ok = feasible_set._pair_points(origins, radii)
    return pts, np.where(ok, p.masked(pts), np.inf)


def _interior_candidates(p: _Problem, n_interior: int) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return the square grid over the reach disk (B, n, n, 2), values (B, n, n), spacing (B,)."""
    u = np.linspace(-1.0, 1.0, n_interior)
    grid = np.stack(np.meshgrid(u, u, indexing="ij"), -1)  # (n, n, 2)
    pts = p.r[:, None, None, None] * grid
    vals = p.masked(pts.reshape(len(p.r), -1, 2)).reshape(pts.shape[:-1])
    spacing = p.r * (2.0 / max(n_interior - 1, 1))
    return pts, vals, spacing


def _best_local(vals: FloatArray, local: np.ndarray, m: int) -> tuple[np.ndarray, FloatArray]:
    """Return the indices (B, m) of the ``m`` smallest local minima of ``vals`` (B, C), values."""
    masked = np.where(local & np.isfinite(vals), vals, np.inf)
    m = min(m, masked.shape[-1])
    idx = np.argsort(masked, axis=-1, kind="stable")[:, :m]
    return idx, np.take_along_axis(masked, idx, axis=-1)


def _newton_1d(g: FloatArray, h: FloatArray, delta: FloatArray) -> FloatArray:
    """Return the trust-region-limited Newton step (gradient step where ``h <= 0``)."""
    newton = -g / np.where(h > 0, h, 1.0)
    step = np.where(h > 0, newton, -np.sign(g) * delta)
    return np.clip(step, -delta, delta)


def _newton_2d(g: FloatArray, H: FloatArray, delta: FloatArray) -> FloatArray:
    """Return the 2-D trust-region-limited Newton step (gradient step if ``H`` not PD)."""
    h11, h12, h22 = H[..., 0], H[..., 1], H[..., 2]
    det = h11 * h22 - h12 * h12
    pd = (h11 > 0) & (det > 0)
    sdet = np.where(pd, det, 1.0)
    nx = -(h22 * g[..., 0] - h12 * g[..., 1]) / sdet
    ny = -(-h12 * g[..., 0] + h11 * g[..., 1]) / sdet
    gn = np.hypot(g[..., 0], g[..., 1])
    sx = np.where(pd, nx, -g[..., 0] * delta / np.maximum(gn, _TINY))
    sy = np.where(pd, ny, -g[..., 1] * delta / np.maximum(gn, _TINY))
    norm = np.hypot(sx, sy)
    shrink = np.where(norm > delta, delta / np.maximum(norm, _TINY), 1.0)
    return np.stack([sx * shrink, sy * shrink], -1)


_ARC_STENCIL = np.array([0.0, 1.0, -1.0])
_PLANE_STENCIL = np.array(
    [[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [1.0, 1.0]]
)


def _refine(
    p: _Problem,
    arcs: tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray],
    plane: tuple[FloatArray, FloatArray, FloatArray],
    n_iter: int,
) -> tuple[FloatArray, FloatArray]:
    """Return the refined points (B, m, 2) and values (B, m) (``+inf`` where none started).

    ``arcs = (origin (B, ma, 2), radius (B, ma), theta (B, ma), value (B, ma), delta)``,
    ``plane = (x (B, mp, 2), value (B, mp), delta (B, mp))``; one evaluation of all stencils
    per iteration.
    """
    o, rad, th, fa, da = arcs
    x, fp, dp = plane
    b, ma = th.shape
    mp = x.shape[1]
    active_a, active_p = np.isfinite(fa), np.isfinite(fp)
    rs = np.maximum(rad, _TINY)

    def stencils(th_c: FloatArray, x_c: FloatArray) -> tuple[FloatArray, ...]:
        pa = _circle_points(o, rad, th_c)
        ha = FD_STEP * np.minimum(p.scale(pa) / rs, 1.0)
        tha = th_c[..., None] + ha[..., None] * _ARC_STENCIL
        pts_a = _circle_points(o[:, :, None], np.broadcast_to(rad[..., None], tha.shape), tha)
        hp = FD_STEP * np.minimum(p.scale(x_c), p.r[:, None])
        pts_p = x_c[:, :, None, :] + hp[..., None, None] * _PLANE_STENCIL
        pts = np.concatenate([pts_a.reshape(b, -1, 2), pts_p.reshape(b, -1, 2)], axis=1)
        vals = p.f(pts)
        va = vals[:, : 3 * ma].reshape(b, ma, 3)
        vp = vals[:, 3 * ma :].reshape(b, mp, 6)
        with np.errstate(divide="ignore", invalid="ignore"):
            ga = (va[..., 1] - va[..., 2]) / (2.0 * ha)
            Ha = (va[..., 1] - 2.0 * va[..., 0] + va[..., 2]) / (ha * ha)
            gp = np.stack([vp[..., 1] - vp[..., 2], vp[..., 3] - vp[..., 4]], -1) / (
                2.0 * hp[..., None]
            )
            h2 = hp * hp
            Hp = np.stack(
                [
                    (vp[..., 1] - 2.0 * vp[..., 0] + vp[..., 2]) / h2,
                    (vp[..., 5] - vp[..., 1] - vp[..., 3] + vp[..., 0]) / h2,
                    (vp[..., 3] - 2.0 * vp[..., 0] + vp[..., 4]) / h2,
                ],
                -1,
            )
        ok_a = np.isfinite(ga) & np.isfinite(Ha)
        ok_p = np.all(np.isfinite(gp), -1) & np.all(np.isfinite(Hp), -1)
        ga, Ha = np.where(ok_a, ga, 0.0), np.where(ok_a, Ha, 0.0)
        gp, Hp = np.where(ok_p[..., None], gp, 0.0), np.where(ok_p[..., None], Hp, 0.0)
        feas = p.feasible(np.concatenate([pa, x_c], axis=1))
        fa_c = np.where(feas[:, :ma], va[..., 0], np.inf)
        fp_c = np.where(feas[:, ma:], vp[..., 0], np.inf)
        return fa_c, ga, Ha, fp_c, gp, Hp

    _, ga, Ha, _, gp, Hp = stencils(th, x)
    for _ in range(n_iter):
        sa = np.where(active_a, _newton_1d(ga, Ha, da), 0.0)
        sp = np.where(active_p[..., None], _newton_2d(gp, Hp, dp), 0.0)
        th_n, x_n = th + sa, x + sp
        fa_n, ga_n, Ha_n, fp_n, gp_n, Hp_n = stencils(th_n, x_n)
        acc_a = active_a & (fa_n < fa)
        acc_p = active_p & (fp_n < fp)
        th, fa = np.where(acc_a, th_n, th), np.where(acc_a, fa_n, fa)
        ga, Ha = np.where(acc_a, ga_n, ga), np.where(acc_a, Ha_n, Ha)
        da = np.where(acc_a, np.maximum(da, 2.0 * np.abs(sa)), 0.25 * np.abs(sa))
        x, fp = np.where(acc_p[..., None], x_n, x), np.where(acc_p, fp_n, fp)
        gp, Hp = np.where(acc_p[..., None], gp_n, gp), np.where(acc_p[..., None], Hp_n, Hp)
        dp = np.where(
            acc_p,
            np.maximum(dp, 2.0 * np.hypot(sp[..., 0], sp[..., 1])),
            0.25 * np.hypot(sp[..., 0], sp[..., 1]),
        )
    pts = np.concatenate([_circle_points(o, rad, th), x], axis=1)
    return pts, np.concatenate([fa, fp], axis=1)


def solve_sensor(
    base: tuple[FloatArray, FloatArray, FloatArray],
    center: FloatArray,
    r: FloatArray | float,
    targets: FloatArray,
    rho: FloatArray | float,
    w_d: FloatArray | float,
    w_theta: FloatArray | float,
    pose_cov: FloatArray | None = None,
    objective: TraceObjective = TRACE,
    *,
    n_boundary: int = 64,
    n_interior: int = 16,
    n_iter: int = 8,
) -> tuple[FloatArray, FloatArray]:
    """Return ``(positions (..., 2), values (...))``: the best next position of one sensor.

    Unchecked kernel (callers pass validated arrays), batched over leading axes ``...``.

    Args:
        base: ``(a0, b0, c0)``, each (..., K): every target's information entries without
            this sensor (SPD: prior plus the other sensors).
        center: the sensor's current position (..., 2).
        r: its reach (...), >= 0.
        targets: the K predicted target positions (..., K, 2).
        rho: its minimum distance to every target (...), >= 0.
        w_d, w_theta: its measurement weights (...) (:func:`activetrack.sensor_models.weights`).
        pose_cov: its pose covariance (..., 2, 2) PSD, or None.
        objective: a K-target objective of :mod:`activetrack.objective`.
        n_boundary: uniform angles per boundary circle.
        n_interior: points per side of the square interior grid.
        n_iter: refinement iterations (one batched evaluation each).

    Returns ``values = f(positions)``; positions lie in ``F`` (to the tolerance of
    :func:`activetrack.feasible_set.contains`) unless ``F`` is empty (then the fallback).
    """
    p = _Problem(base, center, r, targets, rho, w_d, w_theta, pose_cov, objective)
    b = len(p.r)
    origins, radii, th, va = _arc_candidates(p, n_boundary)
    n, m = th.shape[1], th.shape[2]
    local = (va <= np.roll(va, 1, axis=-1)) & (va <= np.roll(va, -1, axis=-1))
    gap = np.diff(th, axis=-1, append=th[..., :1] + 2.0 * np.pi)  # to the next angle
    # Trust radius: the larger gap to a neighbouring angle, at least the uniform spacing in
    # units of the local scale (repeated angles have gap 0).
    pts_arc = _circle_points(
        origins[:, :, None, :], np.broadcast_to(radii[..., None], th.shape), th
    )
    local_scale = p.scale(pts_arc.reshape(b, -1, 2)).reshape(th.shape) / np.maximum(
        radii[..., None], _TINY
    )
    floor = (2.0 * np.pi / n_boundary) * np.minimum(local_scale, 1.0)
    reach = np.maximum(np.maximum(gap, np.roll(gap, 1, axis=-1)), floor)
    idx, fa = _best_local(va.reshape(b * n, m), local.reshape(b * n, m), N_LOCAL_ARC)
    th0 = np.take_along_axis(th.reshape(b * n, m), idx, -1).reshape(b, -1)
    da0 = np.take_along_axis(reach.reshape(b * n, m), idx, -1).reshape(b, -1)
    ka = idx.shape[-1]
    o_a = np.repeat(origins, ka, axis=1)
    r_a = np.repeat(radii, ka, axis=1)
    fa = fa.reshape(b, -1)

    grid, vg, spacing = _interior_candidates(p, n_interior)
    pad = np.pad(vg, ((0, 0), (1, 1), (1, 1)), constant_values=np.inf)
    local_g = (
        (vg <= pad[:, :-2, 1:-1])
        & (vg <= pad[:, 2:, 1:-1])
        & (vg <= pad[:, 1:-1, :-2])
        & (vg <= pad[:, 1:-1, 2:])
    )
    flat_g = grid.reshape(b, -1, 2)
    ip, fp = _best_local(vg.reshape(b, -1), local_g.reshape(b, -1), N_LOCAL_PLANE)
    x0 = np.take_along_axis(flat_g, ip[..., None], axis=1)
    dp0 = np.broadcast_to(spacing[:, None], fp.shape).copy()

    pts_r, vals_r = _refine(p, (o_a, r_a, th0, fa, da0), (x0, fp, dp0), n_iter)
    pts_v, vals_v = _vertex_candidates(p)
    all_pts = np.concatenate([pts_r, pts_v, pts_arc.reshape(b, -1, 2), flat_g], axis=1)
    all_vals = np.concatenate([vals_r, vals_v, va.reshape(b, -1), vg.reshape(b, -1)], axis=1)
    best = np.argmin(all_vals, axis=1)
    s = np.take_along_axis(all_pts, best[:, None, None], axis=1)[:, 0]
    value = np.take_along_axis(all_vals, best[:, None], axis=1)[:, 0]
    empty = ~np.isfinite(value)
    if np.any(empty):
        fb = feasible_set.fallback(p.zero, p.r, p.t, p.rho)
        s = np.where(empty[:, None], fb, s)
        value = np.where(empty, p.f(s[:, None])[:, 0], value)
    positions = (s + p.center).reshape(p.shape + (2,))
    return positions, value.reshape(p.shape)
