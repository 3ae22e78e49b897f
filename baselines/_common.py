"""Helpers shared by the baseline planners: per-sensor modes and random test problems.

Every planner treats two kinds of sensor as *fixed* (not optimized):

- ``r_i = 0``: the sensor cannot move and stays where it is;
- ``||c_i|| + r_i < rho_i``: no reachable point keeps the minimum distance of eq. (16);
  the sensor goes to :func:`activetrack.geometry.unreachable_fallback`, the reachable
  point farthest from the target (the least violation of eq. 16).

All other sensors are *free*: their next position is searched on the curve ADB of
Lemma 3 (:func:`activetrack.geometry.facing_boundary`). The modes are computed here once,
batched over the copies of a batched problem, for every planner.

With K > 1 predicted targets (``problem.multi_target``) sensor ``i`` must keep ``rho_i``
from every one: its feasible set is ``F_i = D(p_S_i, r_i) minus the union of the K open
disks D(t_k, rho_i)``. Its boundary is a union of circular arcs (:func:`feasible_arcs`):
pieces of the reach circle outside every ``rho`` disk, and pieces of each ``rho`` circle
inside the reach disk and outside the other ``rho`` disks; each piece is a circle minus a
union of open angular intervals, computed in closed form (law of cosines). A sensor is
fixed when ``r_i = 0`` (it stays) or when ``F_i`` is empty (its boundary has zero length);
it then goes to :func:`multi_target_fallback`, the point of a fine fixed set of reachable
points maximizing ``min_k (||x - t_k|| - rho_i)`` (the least violation of eq. 16 by the
nearest target). For K = 1 every function is today's (bit-identical).
"""

from __future__ import annotations

import math

import numpy as np

from activetrack import geometry
from activetrack.problem import PlanningProblem
from activetrack.validation import FloatArray


def sensor_modes(problem: PlanningProblem) -> tuple[np.ndarray, FloatArray]:
    """Return ``(free, fixed_rel)``: which sensors are optimized, and the others' positions.

    Batched over the problem's batch axes: ``free`` (..., M) bool; ``fixed_rel`` (..., M, 2)
    holds, relative to the predicted target (with K targets: the first one,
    ``problem.targets[..., 0, :]``), the next position of every fixed sensor (rows of free
    sensors hold their current position relative to it).

    Raises:
        ValueError: a free sensor with ``rho = 0`` can reach a predicted target (the
            objective has no minimum there), or a fixed sensor sits exactly on one.
    """
    targets = problem.targets
    if targets.shape[-2] == 1:
        c = problem.sensors - targets[..., 0, None, :]
        return sensor_modes_of(c, problem.r, problem.rho)
    free, fixed = sensor_modes_multi(problem.sensors, targets, problem.r, problem.rho)
    return free, fixed - targets[..., 0, None, :]


def sensor_modes_multi(
    sensors: FloatArray, targets: FloatArray, r: FloatArray, rho: FloatArray
) -> tuple[np.ndarray, FloatArray]:
    """Return ``(free, fixed)`` for K targets, in absolute coordinates.

    ``sensors`` (..., M, 2), ``targets`` (..., K, 2), ``r`` and ``rho`` (..., M). ``free``
    (..., M): ``r > 0`` and the feasible set is not empty; ``fixed`` (..., M, 2): the
    current position of free sensors and of those with ``r = 0``, and
    :func:`multi_target_fallback` for the sensors whose feasible set is empty.

    Raises:
        ValueError: as :func:`sensor_modes`.
    """
    free, fixed, _ = modes_and_arcs(sensors, targets, r, rho)
    return free, fixed


def modes_and_arcs(
    sensors: FloatArray, targets: FloatArray, r: FloatArray, rho: FloatArray
) -> tuple[np.ndarray, FloatArray, dict[tuple[int, ...], list[geometry.Arc]]]:
    """Return :func:`sensor_modes_multi` and the free sensors' :func:`feasible_arcs`.

    The arcs are keyed by the sensor's index ``batch index + (i,)``.
    """
    sensors = np.asarray(sensors, dtype=np.float64)
    r = np.broadcast_to(r, sensors.shape[:-1])
    rho = np.broadcast_to(rho, sensors.shape[:-1])
    free = np.zeros(sensors.shape[:-1], dtype=bool)
    fixed = sensors.copy()
    reach = np.zeros(sensors.shape[:-1], dtype=bool)  # some target within reach
    arcs_of = {}
    for idx in np.ndindex(sensors.shape[:-1]):
        s, ri, rhoi = sensors[idx], float(r[idx]), float(rho[idx])
        t = targets[idx[:-1]]
        if ri <= 0.0:
            continue
        reach[idx] = bool(np.any(np.hypot(*(t - s).T) <= ri))
        arcs = feasible_arcs(s, ri, t, rhoi)
        if sum(a.length for a in arcs) > 0.0:
            free[idx] = True
            arcs_of[idx] = arcs
        else:
            fixed[idx] = multi_target_fallback(s, ri, t, rhoi)
    degenerate = free & (rho <= 0.0) & reach
    if np.any(degenerate):
        raise ValueError(
            f"rho must be > 0 for sensors {_where(degenerate)}: a predicted "
            "target is within their reach and the information grows without bound near it"
        )
    gap = np.hypot(*np.moveaxis(fixed[..., None, :, :] - targets[..., :, None, :], -1, 0))
    on_target = ~free & np.any(gap == 0.0, axis=-2)
    if np.any(on_target):
        raise ValueError(
            f"sensors {_where(on_target)} cannot move (r = 0) and sit exactly "
            "on a predicted target, where the bearing is undefined"
        )
    return free, fixed, arcs_of


#: Reach-circle points :func:`multi_target_fallback` compares (a fixed set: deterministic).
FALLBACK_POINTS = 4096


def multi_target_fallback(
    sensor: FloatArray, r: float, targets: FloatArray, rho: float
) -> FloatArray:
    """Return the reachable point maximizing ``min_k (||x - t_k|| - rho)``, approximately.

    For a sensor whose feasible set is empty (every reachable point violates eq. 16 for
    some target). Compared points: :data:`FALLBACK_POINTS` equally spaced points of the
    reach circle (angle 0 first) and, per target, the reachable point farthest from it
    (:func:`activetrack.geometry.unreachable_fallback`); the first maximum wins. ``sensor``
    (2,), ``targets`` (K, 2); absolute coordinates, shape (2,).
    """
    sensor = np.asarray(sensor, dtype=np.float64)
    t = np.linspace(0.0, 2.0 * np.pi, FALLBACK_POINTS, endpoint=False)
    ring = sensor + r * np.stack([np.cos(t), np.sin(t)], -1)
    far = targets + geometry.unreachable_fallback(sensor - targets, np.full(len(targets), r))
    pts = np.concatenate([ring, far])
    gap = np.hypot(*np.moveaxis(pts[:, None, :] - targets[None, :, :], -1, 0)).min(axis=1)
    return pts[int(np.argmax(gap - rho))]


def feasible_arcs(
    sensor: FloatArray, r: float, targets: FloatArray, rho: float
) -> list[geometry.Arc]:
    """Return the arcs of the boundary of ``F = D(sensor, r) minus the open D(t_k, rho)``.

    Absolute coordinates; ``sensor`` (2,), ``targets`` (K, 2). The reach circle's pieces
    outside every ``rho`` disk come first (counter-clockwise), then each ``rho`` circle's
    pieces inside the reach disk and outside the other ``rho`` disks (targets in order; a
    target equal to an earlier one adds nothing). Arcs of zero length are dropped, so the
    list is empty when ``F`` is empty (or a single point) or ``r = 0``. Every arc is a
    closed piece: its end points are circle-circle intersections.
    """
    sensor = np.asarray(sensor, dtype=np.float64)
    targets = np.asarray(targets, dtype=np.float64)
    if r <= 0.0:
        return []
    arcs: list[geometry.Arc] = []
    centre = (float(sensor[0]), float(sensor[1]))
    cut = [_inside(sensor, r, t, rho) for t in targets] if rho > 0.0 else []
    phi0 = math.atan2(*(targets[0] - sensor)[::-1]) if len(targets) else 0.0
    for lo, hi in _allowed(cut, phi0):
        arcs.append(geometry.Arc(centre, r, lo, hi))
    if rho <= 0.0:
        return arcs
    for k, tk in enumerate(targets):
        if any(np.array_equal(tk, targets[j]) for j in range(k)):
            continue  # the same circle as an earlier target's
        cut = [_outside(tk, rho, sensor, r)]
        cut += [_inside(tk, rho, tj, rho) for j, tj in enumerate(targets) if j != k]
        phi0 = math.atan2(*(sensor - tk)[::-1])
        centre = (float(tk[0]), float(tk[1]))
        for lo, hi in _allowed(cut, phi0 + math.pi):
            arcs.append(geometry.Arc(centre, rho, lo, hi))
    return arcs


#: An angular cut: None (nothing), "all" (the whole circle), or an open interval (lo, hi).
_Cut = tuple[float, float] | str | None


def _inside(o: FloatArray, radius: float, q: FloatArray, rad_q: float) -> _Cut:
    """Return the angles of circle ``(o, radius)`` strictly inside the disk ``(q, rad_q)``.

    ``||o + R e(t) - q||^2 < rad_q^2`` iff ``cos(t - phi) > kappa`` with ``d = ||q - o||``,
    ``phi`` the angle of ``q - o`` and ``kappa = (R^2 + d^2 - rad_q^2) / (2 R d)``.
    """
    d = math.hypot(q[0] - o[0], q[1] - o[1])
    if d == 0.0:
        return "all" if radius < rad_q else None
    kappa = (radius * radius + d * d - rad_q * rad_q) / (2.0 * radius * d)
    if kappa >= 1.0:
        return None
    if kappa < -1.0:
        return "all"
    phi = math.atan2(q[1] - o[1], q[0] - o[0])
    half = math.acos(kappa)
    return (phi - half, phi + half)


def _outside(o: FloatArray, radius: float, q: FloatArray, rad_q: float) -> _Cut:
    """Return the angles of circle ``(o, radius)`` strictly outside the disk ``(q, rad_q)``."""
    d = math.hypot(q[0] - o[0], q[1] - o[1])
    if d == 0.0:
        return "all" if radius > rad_q else None
    kappa = (radius * radius + d * d - rad_q * rad_q) / (2.0 * radius * d)
    if kappa > 1.0:
        return "all"
    if kappa <= -1.0:
        return None
    phi = math.atan2(q[1] - o[1], q[0] - o[0])
    half = math.acos(kappa)
    return (phi + half, phi + 2.0 * math.pi - half)


def _allowed(cuts: list[_Cut], start: float) -> list[tuple[float, float]]:
    """Return the closed angular intervals ``[lo, hi]`` (hi > lo) left by open ``cuts``.

    A circle without cuts is one interval starting at ``start``. Intervals are in
    counter-clockwise order and each lies within one turn.
    """
    two_pi = 2.0 * math.pi
    if any(cut == "all" for cut in cuts):
        return []
    ivs = sorted(
        (lo % two_pi, lo % two_pi + (hi - lo)) for lo, hi in (c for c in cuts if c is not None)
    )
    if not ivs:
        return [(start, start + two_pi)]
    merged = [list(ivs[0])]
    for lo, hi in ivs[1:]:
        if lo < merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], hi)
        else:
            merged.append([lo, hi])
    # The last interval may wrap past 2 pi and cover the first ones.
    while len(merged) > 1 and merged[0][0] + two_pi < merged[-1][1]:
        first = merged.pop(0)
        merged[-1][1] = max(merged[-1][1], first[1] + two_pi)
    out = [(merged[j][1], merged[j + 1][0]) for j in range(len(merged) - 1)]
    out.append((merged[-1][1], merged[0][0] + two_pi))
    return [(lo, hi) for lo, hi in out if hi > lo]


def sensor_modes_of(c: FloatArray, r: FloatArray, rho: FloatArray) -> tuple[np.ndarray, FloatArray]:
    """Return :func:`sensor_modes` for arrays ``c`` (..., M, 2) and ``r``, ``rho`` (..., M)."""
    nc = np.hypot(c[..., 0], c[..., 1])
    stay = r <= 0.0
    unreachable = ~stay & (nc + r < rho)
    free = ~stay & ~unreachable
    degenerate = free & (rho <= 0.0) & (nc <= r)
    if np.any(degenerate):
        raise ValueError(
            f"rho must be > 0 for sensors {_where(degenerate)}: the predicted "
            "target is within their reach and the information grows without bound near it"
        )
    fixed_rel = np.where(unreachable[..., None], geometry.unreachable_fallback(c, r), c)
    on_target = ~free & (np.hypot(fixed_rel[..., 0], fixed_rel[..., 1]) == 0.0)
    if np.any(on_target):
        raise ValueError(
            f"sensors {_where(on_target)} cannot move (r = 0) and sit exactly "
            "on the predicted target, where the bearing is undefined"
        )
    return free, fixed_rel


def _where(mask: np.ndarray, limit: int = 10) -> str:
    """Return the sensors flagged in ``mask`` (..., M): indices, or (copy..., sensor) tuples."""
    if mask.ndim == 1:
        return str(np.flatnonzero(mask).tolist())
    hits = [tuple(int(k) for k in row) for row in np.argwhere(mask)[:limit]]
    more = " ..." if np.count_nonzero(mask) > limit else ""
    return f"(copy, sensor) {hits}{more}"


def random_problem(
    rng: np.random.Generator,
    n_sensors: int = 3,
    *,
    distance: tuple[float, float] = (1.0, 4.0),
    r: float = 1.0,
    rho: float = 2.0,
) -> PlanningProblem:
    """Return a random one-step planning problem in which ``rho`` is often active.

    The predicted target is at the origin; the prior covariance has eigenvalues drawn
    log-uniformly in [0.05, 20] and a random orientation; sensors lie at distances drawn
    uniformly in ``distance`` (with r = 1, rho = 2 and the default range every sensor can
    keep the minimum distance, and for two thirds of them (``||c|| < r + rho``) it is active
    in Cases II, III or 4 of Fig. 3), with range variances in [0.5, 5] m^2 and bearing
    variances in [0.05, 1] rad^2.
    """
    eig = np.exp(rng.uniform(np.log(0.05), np.log(20.0), 2))
    phi = rng.uniform(0.0, np.pi)
    rot = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    prior_cov = rot @ np.diag(eig) @ rot.T
    dist = rng.uniform(*distance, n_sensors)
    ang = rng.uniform(0.0, 2.0 * np.pi, n_sensors)
    sensors = dist[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    return PlanningProblem(
        prior_cov=0.5 * (prior_cov + prior_cov.T),
        target=np.zeros(2),
        sensors=sensors,
        r=r,
        rho=rho,
        sigma_d2=rng.uniform(0.5, 5.0, n_sensors),
        sigma_theta2=rng.uniform(0.05, 1.0, n_sensors),
    )
