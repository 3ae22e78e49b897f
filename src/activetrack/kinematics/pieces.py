"""Reach sets bounded by a few smooth curves: the nearest points, exactly, for any of them.

:class:`PiecewiseReach` is a :class:`~activetrack.kinematics.base.Kinematics` whose reach
set ``R`` (of a sensor's whole state) is bounded by ``n_pieces`` smooth curves
``t in [0, 1] -> piece(k, t, state)`` (arcs of circles, the endpoints of a unicycle's arcs
at top speed, straight segments). From them it gives:

- :meth:`PiecewiseReach.nearest_on_boundary`: the point of the boundary of ``R`` nearest a
  point, vectorized: every piece sampled at :data:`SAMPLES` parameters, the :data:`KEEP`
  best discrete local minima of the distance on each piece refined by golden-section
  search (:data:`ROUNDS` rounds: the bracket shrinks by ``0.618^32 ~ 2e-7``), the nearest
  of the refined ones. A subclass's :meth:`clip` is ``wanted`` when reachable, else this.
- :meth:`PiecewiseReach.project`: the point of ``F = R minus the rho disks`` nearest a
  wanted point ``q``. The nearest point of a closed set to a point outside it lies on its
  boundary, at a local minimum of the distance along a smooth piece of that boundary or
  at a corner of it; so the candidates are: every local minimum of the distance along each
  piece of ``R``'s boundary (dense samples, every discrete local minimum refined), the
  radial projection of ``q`` onto each ``rho`` circle (the one local minimum on a circle),
  the pieces' ends (the corners of ``R``), every crossing of a piece with a ``rho``
  circle (sign changes of ``|piece - t_k| - rho`` on the samples, refined by bisection)
  and every crossing of two ``rho`` circles (closed form); the nearest feasible one.
  Exact up to the refinements (a crossing or a minimum closer than the samples' spacing
  to another of the same kind, or a tangency, could be missed: a piece is sampled at
  :data:`PROJECT_SAMPLES` parameters). With ``F`` empty: the point of ``R``'s boundary
  that violates eq. (16) least (the base's rule).
- :meth:`PiecewiseReach.reach_boundary`: each piece sampled at about ``spacing``.
"""

from __future__ import annotations

from abc import abstractmethod

import numpy as np

from activetrack.kinematics.base import TOL, Kinematics, outside_disks
from activetrack.validation import FloatArray

#: Parameters sampled per piece by :meth:`PiecewiseReach.nearest_on_boundary`.
SAMPLES = 129
#: Parameters sampled per piece by :meth:`PiecewiseReach.project` (one query).
PROJECT_SAMPLES = 2049
#: Golden-section rounds (a bracket of ``1 / 64`` of a piece ends below ``1e-8`` of it:
#: the distance, stationary there, is off by its square) and bisection rounds.
ROUNDS = 32
BISECTIONS = 48
#: Discrete local minima refined per piece by :meth:`PiecewiseReach.nearest_on_boundary`.
KEEP = 2
_GOLD = 0.5 * (np.sqrt(5.0) - 1.0)


def real_parameter(name: str, value: object, low: float, high: float = np.inf, *,
                   open_low: bool = False) -> float:  # fmt: skip
    """Return ``value`` as a float in ``[low, high]`` (``(low, high]`` if ``open_low``), or
    raise ValueError naming ``name`` and the range."""
    rng = f"{'(' if open_low else '['}{low:g}, {high:g}]"
    if isinstance(value, (bool, np.bool_)) or not isinstance(
        value, (int, float, np.integer, np.floating)
    ):
        raise ValueError(f"{name} must be a real number in {rng}, got {value!r}")
    v = float(value)
    if not (low < v if open_low else low <= v) or not v <= high or not np.isfinite(v):
        raise ValueError(f"{name} must be a real number in {rng}, got {value!r}")
    return v


def golden(f, a: FloatArray, b: FloatArray, rounds: int = ROUNDS) -> FloatArray:
    """Return the minimizers of the unimodal ``f`` on the brackets ``[a, b]`` (arrays of one
    shape; ``f`` maps such an array of parameters to values), by golden-section search."""
    a, b = np.array(a, dtype=np.float64), np.array(b, dtype=np.float64)
    c, d = b - _GOLD * (b - a), a + _GOLD * (b - a)
    fc, fd = f(c), f(d)
    for _ in range(rounds):
        left = fc < fd  # the minimum is in [a, d]: drop (d, b]; else drop [a, c)
        a, b = np.where(left, a, c), np.where(left, d, b)
        c, d = np.where(left, b - _GOLD * (b - a), d), np.where(left, c, a + _GOLD * (b - a))
        fn = f(np.where(left, c, d))  # the one new point
        fc, fd = np.where(left, fn, fd), np.where(left, fc, fn)
    ends = np.stack([a, b, c, d])
    vals = np.stack([f(a), f(b), fc, fd])
    return np.take_along_axis(ends, np.argmin(vals, axis=0)[None], 0)[0]


def bisect(g, a: FloatArray, b: FloatArray, rounds: int = BISECTIONS) -> FloatArray:
    """Return roots of ``g`` in the brackets ``[a, b]`` where ``g(a)`` and ``g(b)`` differ in
    sign (arrays of one shape), by bisection."""
    a, b = np.array(a, dtype=np.float64), np.array(b, dtype=np.float64)
    ga = g(a)
    for _ in range(rounds):
        m = 0.5 * (a + b)
        gm = g(m)
        same = np.sign(gm) == np.sign(ga)
        a, ga = np.where(same, m, a), np.where(same, gm, ga)
        b = np.where(same, b, m)
    return 0.5 * (a + b)


class PiecewiseReach(Kinematics):
    """A kinematics whose reach set is bounded by ``n_pieces`` smooth curves (module
    docstring); a subclass gives :meth:`piece` and :meth:`reaches` (and ``clip``, usually
    :meth:`nearest_on_boundary` of the points it does not reach)."""

    #: The number of smooth pieces of the reach set's boundary.
    n_pieces: int = 0

    @abstractmethod
    def piece(self, k: np.ndarray, t: FloatArray, state: FloatArray) -> FloatArray:
        """Return the points (..., 2) of pieces ``k`` (integers) of the boundary of the
        reach set of ``state`` (..., S) at the parameters ``t`` in [0, 1] (``k``, ``t`` and
        ``state``'s leading axes broadcast)."""

    def point_pieces(self) -> tuple[int, ...]:
        """Return the pieces ``k`` that are one point for every ``t`` and state (e.g. the
        arc at a speed of zero), bit for bit: ``piece(k, t, state)`` the same at every
        ``t``. None by default; :meth:`project` takes such a piece's point once."""
        return ()

    def _tol(self, state: FloatArray) -> FloatArray:
        """Return the membership tests' absolute tolerance at ``state`` (...,): relative
        :data:`TOL` of the radius plus the position's size (the rounding of coordinates)."""
        p = np.asarray(state, np.float64)[..., :2]
        return 4.0 * TOL * (self.radius + np.max(np.abs(p), axis=-1))

    def _samples(self, state: FloatArray, n: int) -> tuple[FloatArray, np.ndarray, FloatArray]:
        """Return ``(t (n,), k (P, 1), points (..., P, n, 2))``: every piece at ``n`` even
        parameters."""
        t = np.linspace(0.0, 1.0, n)
        k = np.arange(self.n_pieces)[:, None]
        return t, k, self.piece(k, t, np.asarray(state, np.float64)[..., None, None, :])

    def nearest_on_boundary(self, q: FloatArray, state: FloatArray) -> FloatArray:
        """Return the point of the boundary of the reach set of ``state`` (..., S) nearest
        each of ``q`` (..., 2) (broadcast), (..., 2) (module docstring)."""
        q, state = np.asarray(q, np.float64), np.asarray(state, np.float64)
        lead = np.broadcast_shapes(q.shape[:-1], state.shape[:-1])
        q = np.broadcast_to(q, lead + (2,))
        state = np.broadcast_to(state, lead + state.shape[-1:])
        t, k, pts = self._samples(state, SAMPLES)
        d = np.sum((pts - q[..., None, None, :]) ** 2, axis=-1)  # (..., P, T)
        big = d.max(axis=-1, keepdims=True) + 1.0
        pad = np.concatenate([big, d, big], -1)
        local = (d <= pad[..., :-2]) & (d <= pad[..., 2:])
        j = np.argsort(np.where(local, d, np.inf), axis=-1)[..., :KEEP]  # (..., P, KEEP)
        lo, hi = t[np.maximum(j - 1, 0)], t[np.minimum(j + 1, len(t) - 1)]
        qq, ss = q[..., None, None, :], state[..., None, None, :]

        def dist(s):
            return np.sum((self.piece(k, s, ss) - qq) ** 2, axis=-1)

        best = golden(dist, lo, hi)  # (..., P, KEEP)
        pt = self.piece(k, best, ss).reshape(lead + (-1, 2))
        dd = np.sum((pt - q[..., None, :]) ** 2, axis=-1)
        return np.take_along_axis(pt, np.argmin(dd, axis=-1)[..., None, None], -2)[..., 0, :]

    def reach_boundary(self, position: FloatArray, spacing: float) -> FloatArray:
        """Return points of every piece at most about ``spacing`` apart, (P, 2), in order."""
        state = np.asarray(position, np.float64).reshape(-1)
        if not self.radius > 0.0:
            return np.empty((0, 2))
        _, _, rough = self._samples(state, 65)
        length = np.sum(np.hypot(*np.moveaxis(np.diff(rough, axis=-2), -1, 0)), axis=-1)
        out = []
        for k in range(self.n_pieces):
            n = max(2, int(np.ceil(1.05 * float(length[k]) / max(spacing, 1e-300))) + 1)
            t = np.linspace(0.0, 1.0, min(n, 1 << 22))
            out.append(self.piece(np.array(k), t, state))
        pts = np.concatenate(out)
        return pts[self.reaches(pts, state)]

    def project(
        self, wanted: FloatArray, position: FloatArray, targets: FloatArray, rho: float
    ) -> FloatArray:
        """Return the point of ``F`` nearest to ``wanted`` (2,), ``wanted`` when feasible,
        from the candidates of the module docstring; with ``F`` empty the point of the
        reach set's boundary farthest (by ``min_k |s - t_k| - rho``) into eq. (16)."""
        q, state = np.asarray(wanted, np.float64).reshape(2), np.asarray(position, np.float64)
        state = state.reshape(-1)
        targets = np.asarray(targets, np.float64).reshape(-1, 2)
        if not self.radius > 0.0:
            return state[:2].copy()
        c = self.clip(q, state)
        quick = [q[None], c[None]]
        e = q - targets
        d = np.hypot(e[:, 0], e[:, 1])
        toward = np.where(d[:, None] > 0, e / np.where(d > 0, d, 1.0)[:, None], [1.0, 0.0])
        radial = targets + rho * toward
        if self.reaches(q, state):
            quick.append(radial[d < rho])
        quick = np.concatenate(quick)
        ok = self.feasible(quick, state, targets, rho)
        if np.any(ok):
            return quick[int(np.argmax(ok))].copy()
        t, k, pts = self._samples(state, PROJECT_SAMPLES)  # (P, T, 2)
        cand = [radial, c[None], pts[:, [0, -1]].reshape(-1, 2), _circle_crossings(targets, rho)]
        dq = np.sum((pts - q) ** 2, axis=-1)  # (P, T)
        big = dq.max(axis=-1, keepdims=True) + 1.0
        pad = np.concatenate([big, dq, big], -1)
        local = (dq <= pad[:, :-2]) & (dq <= pad[:, 2:])  # every local minimum
        dots = self.point_pieces()
        # (a piece that is one point is a local minimum at every sample: its point once,
        # not thousands of golden searches that all return it)
        single = [k for k in dots if local[k].any()]
        local[list(dots)] = False
        kk, j = np.nonzero(local)

        def dist(s):
            return np.sum((self.piece(kk, s, state) - q) ** 2, axis=-1)

        s = golden(dist, t[np.maximum(j - 1, 0)], t[np.minimum(j + 1, len(t) - 1)])
        found = self.piece(kk, s, state)
        if single:  # in the order of the pieces, as if searched (ties: the first nearest)
            found = np.concatenate(
                [found[kk < k] for k in single[:1]]
                + [
                    np.concatenate([pts[k, :1], found[(kk > k) & (kk < nxt)]])
                    for k, nxt in zip(single, single[1:] + [self.n_pieces], strict=True)
                ]
            )
        cand.append(found)
        for tk in targets if rho > 0.0 else ():  # the crossings of the pieces and circle k
            g = np.hypot(*np.moveaxis(pts - tk, -1, 0)) - rho  # (P, T)
            kc, jc = np.nonzero(np.sign(g[:, :-1]) != np.sign(g[:, 1:]))
            if len(kc):

                def gap(s, kc=kc, tk=tk):
                    p = self.piece(kc, s, state)
                    return np.hypot(p[..., 0] - tk[0], p[..., 1] - tk[1]) - rho

                cand.append(self.piece(kc, bisect(gap, t[jc], t[jc + 1]), state))
        cand = np.concatenate(cand)
        ok = self.feasible(cand, state, targets, rho)
        if np.any(ok):
            cand = cand[ok]
            return cand[int(np.argmin(np.hypot(*(cand - q).T)))].copy()
        rim = self.reach_boundary(state, self.radius / 4096)
        if len(rim) == 0:
            return c
        g = rim[:, None, :] - targets
        margin = np.min(np.hypot(g[..., 0], g[..., 1]), axis=-1) - rho
        return rim[int(np.argmax(margin))].copy()


def _circle_crossings(targets: FloatArray, rho: float) -> FloatArray:
    """Return the crossing points of every pair of the ``rho`` circles about ``targets``
    (K, 2), (P, 2)."""
    out = [np.empty((0, 2))]
    for a in range(len(targets)):
        for b in range(a + 1, len(targets)):
            e = targets[b] - targets[a]
            dd = float(np.hypot(*e))
            if not 0.0 < dd <= 2.0 * rho:
                continue
            u = e / dd
            h = np.sqrt(max(rho * rho - 0.25 * dd * dd, 0.0))
            mid = targets[a] + 0.5 * dd * u
            perp = np.array([-u[1], u[0]])
            out.append(np.stack([mid + h * perp, mid - h * perp]))
    return np.concatenate(out)


__all__ = ["PiecewiseReach", "bisect", "golden", "outside_disks", "real_parameter"]
