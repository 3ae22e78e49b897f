"""Feasible-set geometry of one sensor's next position, eq. (15)-(16) and Lemma 3.

Relative to the predicted target, sensor ``i`` may move to ``s`` with ``||s - c|| <= r``
(speed limit, eq. 15) and ``||s|| >= rho`` (minimum distance, eq. 16). By Lemma 3 the
optimum lies on the part of the feasible boundary facing the target, the curve ADB of
Fig. 3, which is a union of circular arcs:

- the arc of the speed circle centred on the direction ``-c`` with half-angle
  ``alpha = arccos(r / ||c||)`` (the points whose outward normal faces the target),
  minus what lies inside the ``rho`` disk (two pieces in Case III, none in Case II);
- the arc of the ``rho`` circle inside the speed disk (Cases II, III and 4).

Case 4 (``||c|| <= r``, the target within reach) is this library's extension of the
paper, which caps ``r`` at ``||c||``: the boundary is then the ``rho`` arc alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from activetrack.validation import FloatArray


@dataclass(frozen=True)
class Arc:
    """A counter-clockwise arc ``center + radius (cos t, sin t)`` for ``t in [t0, t1]``."""

    center: tuple[float, float]
    radius: float
    t0: float
    t1: float

    @property
    def length(self) -> float:
        """Return the arc length."""
        return self.radius * (self.t1 - self.t0)

    def points(self, t: FloatArray) -> FloatArray:
        """Return the points at parameters ``t`` (shape (K,)), shape (K, 2)."""
        return np.stack(
            [self.center[0] + self.radius * np.cos(t), self.center[1] + self.radius * np.sin(t)], -1
        )


def case_of(c: FloatArray, r: float, rho: float) -> int:
    """Return the geometric case of Fig. 3 (1, 2, 3) or 4 when ``||c|| <= r``."""
    return case_from_norm(float(np.hypot(c[0], c[1])), r, rho)


def case_from_norm(nc: float, r: float, rho: float) -> int:
    """Return the geometric case of Fig. 3 from ``||c||``, ``r`` and ``rho``."""
    if nc <= r:
        return 4
    if rho <= nc - r:
        return 1
    if rho * rho >= nc * nc - r * r:
        return 2
    return 3


def facing_boundary(c: FloatArray, r: float, rho: float) -> list[Arc]:
    """Return the arcs of the curve ADB (Lemma 3) for one sensor; empty if infeasible or r = 0."""
    c = np.asarray(c, dtype=np.float64)
    nc = float(np.hypot(c[0], c[1]))
    if r <= 0.0:
        return []
    arcs: list[Arc] = []
    tc = float(np.arctan2(c[1], c[0]))
    if nc > r:
        alpha = float(np.arccos(r / nc))
        kappa = (nc * nc + r * r - rho * rho) / (2.0 * r * nc)
        beta = 0.0 if kappa >= 1.0 else float(np.arccos(max(kappa, -1.0)))
        centre = (float(c[0]), float(c[1]))
        if beta == 0.0:
            arcs.append(Arc(centre, r, tc + np.pi - alpha, tc + np.pi + alpha))
        elif beta < alpha:
            arcs.append(Arc(centre, r, tc + np.pi - alpha, tc + np.pi - beta))
            arcs.append(Arc(centre, r, tc + np.pi + beta, tc + np.pi + alpha))
    if rho > 0.0 and (nc > 0.0 or rho <= r):
        if nc == 0.0:
            eta = -np.inf
        else:
            eta = (rho * rho + nc * nc - r * r) / (2.0 * rho * nc)
        if eta <= -1.0:
            arcs.append(Arc((0.0, 0.0), rho, tc - np.pi, tc + np.pi))
        elif eta <= 1.0 and not (nc > r and rho <= nc - r):
            gamma = float(np.arccos(eta))
            arcs.append(Arc((0.0, 0.0), rho, tc - gamma, tc + gamma))
    return arcs


def discretize(arcs: list[Arc], spacing: float) -> FloatArray:
    """Return points along ``arcs`` at most ``spacing`` apart, endpoints included, (K, 2)."""
    pts = []
    for arc in arcs:
        n = max(1, int(np.ceil(arc.length / spacing)))
        pts.append(arc.points(np.linspace(arc.t0, arc.t1, n + 1)))
    return np.concatenate(pts) if pts else np.empty((0, 2))


def sample_uniform(arcs: list[Arc], rng: np.random.Generator) -> FloatArray:
    """Return one point drawn uniformly by arc length from ``arcs``, shape (2,)."""
    lengths = np.array([a.length for a in arcs])
    u = rng.random() * lengths.sum()
    k = min(int(np.searchsorted(np.cumsum(lengths), u, side="right")), len(arcs) - 1)
    arc = arcs[k]
    frac = (u - (lengths[:k].sum())) / max(arc.length, 1e-300)
    return arc.points(np.array([arc.t0 + min(max(frac, 0.0), 1.0) * (arc.t1 - arc.t0)]))[0]


def unreachable_fallback(c: FloatArray, r: FloatArray) -> FloatArray:
    """Return ``c + r c / ||c||``: the reachable point farthest from the target (batched)."""
    nc = np.hypot(c[..., 0], c[..., 1])[..., None]
    safe = np.where(nc > 0.0, nc, 1.0)
    direction = np.where(nc > 0.0, c / safe, np.array([1.0, 0.0]))
    return c + np.asarray(r)[..., None] * direction


def project_feasible(q: FloatArray, c: FloatArray, r: FloatArray, rho: FloatArray) -> FloatArray:
    """Return the feasible point nearest to ``q`` (all relative to the target), batched.

    ``q`` must already lie in the speed disk around ``c``. A ``q`` inside the ``rho`` disk
    goes radially onto the ``rho`` circle; if that leaves the speed disk, to the nearer of
    the two circle intersections A, B; if the circles do not meet (``||c|| + r < rho``), to
    :func:`unreachable_fallback`.
    """
    q, c = np.asarray(q, float), np.asarray(c, float)
    r, rho = np.broadcast_to(r, q.shape[:-1]), np.broadcast_to(rho, q.shape[:-1])
    nq = np.hypot(q[..., 0], q[..., 1])
    inside = nq < rho
    if not np.any(inside):
        return q
    out = q.copy()
    dirq = np.where(nq[..., None] > 0, q / np.where(nq > 0, nq, 1.0)[..., None], unit(c))
    radial = rho[..., None] * dirq
    ok = np.hypot(*np.moveaxis(radial - c, -1, 0)) <= r * (1 + 1e-12)
    A, B, meet = circle_intersections(c, r, rho)
    dA = np.hypot(*np.moveaxis(A - q, -1, 0))
    dB = np.hypot(*np.moveaxis(B - q, -1, 0))
    nearest = np.where((dA <= dB)[..., None], A, B)
    fallback = unreachable_fallback(c, r)
    proj = np.where(ok[..., None], radial, np.where(meet[..., None], nearest, fallback))
    out[inside] = proj[inside]
    return out


def unit(c: FloatArray) -> FloatArray:
    """Return ``c / ||c||`` (x axis where ``c`` is zero), batched."""
    n = np.hypot(c[..., 0], c[..., 1])[..., None]
    return np.where(n > 0, c / np.where(n > 0, n, 1.0), np.array([1.0, 0.0]))


def circle_intersections(
    c: FloatArray, r: FloatArray, rho: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return ``(A, B, meet)``: intersections of ``||s - c|| = r`` and ``||s|| = rho`` (batched).

    Where the circles do not meet, ``A`` and ``B`` are the point of the ``rho`` circle
    nearest to the speed circle and ``meet`` is False.
    """
    c = np.asarray(c, float)
    nc = np.hypot(c[..., 0], c[..., 1])
    u = unit(c)
    perp = np.stack([-u[..., 1], u[..., 0]], -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cos_g = (rho**2 + nc**2 - r**2) / (2.0 * rho * nc)
    meet = np.abs(cos_g) <= 1.0
    cos_g = np.clip(np.nan_to_num(cos_g, nan=1.0), -1.0, 1.0)
    sin_g = np.sqrt(1.0 - cos_g**2)
    base = (rho * cos_g)[..., None] * u
    off = (rho * sin_g)[..., None] * perp
    return base + off, base - off, meet
