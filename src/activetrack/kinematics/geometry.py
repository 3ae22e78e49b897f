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

from activetrack._jit import as_rows
from activetrack.kinematics import _kernels as mk
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
    """Return ``c + r c / ||c||``: the reachable point farthest from the target (batched;
    the x axis where ``c`` is zero)."""
    c = np.asarray(c, np.float64)
    shape = np.broadcast_shapes(c.shape[:-1], np.shape(r))
    out = np.empty(shape + (2,))
    mk.fallback_rows(as_rows(c, shape, (2,)), as_rows(r, shape), out.reshape(-1, 2))
    return out


def project_feasible(q: FloatArray, c: FloatArray, r: FloatArray, rho: FloatArray) -> FloatArray:
    """Return the feasible point nearest to ``q`` (all relative to the target), batched.

    ``q`` must already lie in the speed disk around ``c``. A ``q`` inside the ``rho`` disk
    goes radially onto the ``rho`` circle; if that leaves the speed disk, to the nearer of
    the two circle intersections A, B; if the circles do not meet (``||c|| + r < rho``), to
    :func:`unreachable_fallback` (:func:`activetrack.kinematics._kernels.project_feasible_point`).
    """
    q, c = np.asarray(q, np.float64), np.asarray(c, np.float64)
    shape = np.broadcast_shapes(q.shape[:-1], c.shape[:-1], np.shape(r), np.shape(rho))
    out = np.empty(shape + (2,))
    mk.project_feasible_rows(
        as_rows(q, shape, (2,)), as_rows(c, shape, (2,)), as_rows(r, shape),
        as_rows(rho, shape), out.reshape(-1, 2),
    )  # fmt: skip
    return out
