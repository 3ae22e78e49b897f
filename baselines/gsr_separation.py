"""The team rule ``d_sep`` inside the planners (issue 36): what a plan must keep so that the
world executes it as planned.

The world (:class:`activetrack.kinematics.separation.Separation`) moves the sensors in agent
order along straight segments, sensor ``b`` after ``a < b``: ``a``'s segment ``o_a -> p_a``
must keep ``d_ab`` from ``o_b`` (``b`` has not moved yet), ``b``'s segment ``o_b -> p_b``
from ``p_a`` (``a`` has), and the two moving together keep it at every same instant (their
relative position, the segment ``(o_b - o_a) -> (p_b - p_a)``, keeps ``d_ab`` from the
origin; equivalently ``b``'s segment shifted by ``a``'s move, ``o_b -> p_b - (p_a - o_a)``,
keeps it from ``o_a``). A plan whose every pair meets the three (:func:`keeps_rule`; it
implies ``|p_a - p_b| >= d_ab``) passes the rule untouched. Each pair condition involves the two
sensors' plans only, so it fits Gauss-Seidel exactly: sensor ``i``'s subproblem, the others
at their current plans, has the feasible set of its kinematics minus

- for ``j > i``: the *capsule* of radius ``d_ij`` about ``j``'s segment ``o_j -> p_j``, and
  ``o_j`` as a *sweep* point (``i``'s segment keeps ``d_ij`` from it);
- for ``j < i``: ``p_j`` as a sweep point;
- for every ``j``: ``o_j`` as a *moving* sweep point of velocity ``p_j - o_j`` (``i``'s
  segment shifted by ``j``'s move, ``o_i -> p - (p_j - o_j)``, keeps ``d_ij`` from it: the
  same instant).

(:func:`constraints`, the form :mod:`activetrack.baselines.gsr_command` takes). Every pair
keeps a relative :data:`MARGIN` more than ``d_ij``, so that the world's own test (``>=``,
in its own arithmetic) passes. A team that starts separated keeps every condition at its
current positions, so GSR's warm start is feasible and every kept update stays so.
"""

from __future__ import annotations

import numpy as np

from activetrack.kinematics.separation import pair_distances, segment_distance, together
from activetrack.validation import FloatArray

#: The planners keep this much (relative) more than ``d_ij``.
MARGIN = 1e-9


def pair_matrix(problem) -> FloatArray | None:
    """Return the (M, M) distances the problem's ``d_sep`` asks each pair to keep, or None
    when it asks none (no ``d_sep``, all zero, or one sensor)."""
    d_sep = getattr(problem, "d_sep", None)
    m = problem.n_sensors
    if d_sep is None or m < 2:
        return None
    d = pair_distances(d_sep, m)
    return d if np.any(d > 0.0) else None


def constraints(d: FloatArray, old: FloatArray, plan: FloatArray):
    """Return ``of(sub, i) -> (caps (S, J, 5), sweeps (S, J2, 5))``: sensor ``i``'s
    constraints in copies ``sub`` (module docstring) from the pair distances ``d`` (M, M),
    the old positions ``old`` (B, M, 2) and the plans ``plan`` (B, M, 2), read at each call
    (GSR updates it in place)."""
    m = len(d)
    dm = d * (1.0 + MARGIN)

    def of(sub: np.ndarray, i: int) -> tuple[FloatArray, FloatArray]:
        later = [j for j in range(i + 1, m) if d[i, j] > 0.0]
        earlier = [j for j in range(i) if d[i, j] > 0.0]
        S = len(sub)
        caps = np.empty((S, len(later), 5))
        caps[:, :, 0:2] = old[sub][:, later]
        caps[:, :, 2:4] = plan[sub][:, later]
        caps[:, :, 4] = dm[i, later]
        nl, ne = len(later), len(earlier)
        both = later + earlier
        # (cx, cy, vx, vy, r): the static ones (v = 0), then the moving ones (same instant).
        sweeps = np.zeros((S, 2 * (nl + ne), 5))
        sweeps[:, :nl, 0:2] = old[sub][:, later]
        sweeps[:, nl : nl + ne, 0:2] = plan[sub][:, earlier]
        sweeps[:, nl + ne :, 0:2] = old[sub][:, both]
        sweeps[:, nl + ne :, 2:4] = plan[sub][:, both] - old[sub][:, both]
        sweeps[:, :, 4] = np.tile(dm[i, both], 2)
        return caps, sweeps

    return of


def keeps_rule(old: FloatArray, plan: FloatArray, d: FloatArray) -> np.ndarray:
    """Return whether every pair ``a < b`` of ``plan`` (..., M, 2) from ``old`` meets the
    rule's three conditions (module docstring) with the distances ``d`` (M, M), (...)."""
    old, plan = np.asarray(old, np.float64), np.asarray(plan, np.float64)
    m = plan.shape[-2]
    ok = np.ones(plan.shape[:-2], bool)
    for a in range(m):
        for b in range(a + 1, m):
            if d[a, b] > 0.0:
                ok &= segment_distance(old[..., a, :], plan[..., a, :], old[..., b, :]) >= d[a, b]
                ok &= segment_distance(old[..., b, :], plan[..., b, :], plan[..., a, :]) >= d[a, b]
                ok &= (
                    together(old[..., b, :], plan[..., b, :], old[..., a, :], plan[..., a, :])
                    >= d[a, b]
                )
    return ok


def pair_masks(d: FloatArray, old: FloatArray, cands: list[FloatArray]) -> list[tuple]:
    """Return ``[(a, b, ok)]`` for every pair ``a < b`` with ``d_ab > 0``: ``ok[ka, kb]``
    whether sensor ``a`` at candidate ``cands[a][ka]`` and ``b`` at ``cands[b][kb]``
    (absolute, (K_i, 2)) from ``old`` (M, 2) meet the rule's three conditions (module
    docstring; GBES filters its combinations with them)."""
    out = []
    for a in range(len(cands)):
        for b in range(a + 1, len(cands)):
            if not d[a, b] > 0.0:
                continue
            first = segment_distance(old[a], cands[a], old[b]) >= d[a, b]  # (K_a,)
            second = (
                segment_distance(old[b], cands[b][None, :, :], cands[a][:, None, :]) >= d[a, b]
            )  # (K_a, K_b)
            second &= (
                together(old[b], cands[b][None, :, :], old[a], cands[a][:, None, :]) >= d[a, b]
            )
            out.append((a, b, first[:, None] & second))
    return out


class RadiusDisk:
    """The paper's disk as a command-space kinematics whose radius is in the state, ``(x, y,
    r)``: ``apply`` is :meth:`activetrack.kinematics.disk.Disk.apply` with each copy's own
    ``r`` (a batched problem's ``r`` may differ between copies)."""

    name = "radius_disk"
    state_dim = 3
    action_low = (-1.0, -1.0)
    action_high = (1.0, 1.0)

    def apply(self, actions: FloatArray, state: FloatArray) -> FloatArray:
        """Return ``position + r a`` (..., 2), an action longer than 1 scaled onto the unit
        circle."""
        a = np.clip(np.asarray(actions, np.float64), -1.0, 1.0)
        n = np.hypot(a[..., 0], a[..., 1])[..., None]
        a = np.where(n > 1.0, a / np.where(n > 1.0, n, 1.0), a)
        st = np.asarray(state, np.float64)
        return st[..., :2] + st[..., 2:3] * a

    def reaches(self, points: FloatArray, state: FloatArray) -> np.ndarray:
        """Return whether ``points`` (..., 2) are within ``r`` (no tolerance)."""
        st = np.asarray(state, np.float64)
        e = np.asarray(points, np.float64) - st[..., :2]
        return np.hypot(e[..., 0], e[..., 1]) <= st[..., 2]
