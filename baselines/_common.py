"""Helpers shared by the baseline planners: per-sensor modes and random test problems.

Every planner treats two kinds of sensor as *fixed* (not optimized):

- ``r_i = 0``: the sensor cannot move and stays where it is;
- ``||c_i|| + r_i < rho_i``: no reachable point keeps the minimum distance of eq. (16);
  the sensor goes to :func:`activetrack.kinematics.geometry.unreachable_fallback`, the reachable
  point farthest from the target (the least violation of eq. 16).

All other sensors are *free*: their next position is searched on the curve ADB of
Lemma 3 (:func:`activetrack.kinematics.geometry.facing_boundary`). The modes are computed here once,
batched over the copies of a batched problem, for every planner.

With K > 1 predicted targets (``problem.multi_target``) sensor ``i`` must keep ``rho_i``
from every one: its feasible set is ``F_i = D(p_S_i, r_i) minus the union of the K open
disks D(t_k, rho_i)``. Its boundary is a union of circular arcs
(:func:`activetrack.kinematics.feasible_set.boundary_arcs`): pieces of the reach circle outside
every
``rho`` disk, and pieces of each ``rho`` circle inside the reach disk and outside the other
``rho`` disks. A sensor is fixed when ``r_i = 0`` (it stays) or when ``F_i`` is empty (its
boundary has zero length); it then goes to :func:`activetrack.kinematics.feasible_set.fallback`, the
reachable point maximizing ``min_k (||x - t_k|| - rho_i)`` (the least violation of eq. 16
by the nearest target). For K = 1 every function is today's (bit-identical).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack._jit import as_rows
from activetrack.baselines import gsr_kernel as gk
from activetrack.kinematics import feasible_set, geometry
from activetrack.kinematics.team import all_disks
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem


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
    :func:`activetrack.kinematics.feasible_set.fallback` for the sensors whose feasible set is
    empty.

    Raises:
        ValueError: as :func:`sensor_modes`.
    """
    free, fixed, _ = modes_and_arcs(sensors, targets, r, rho)
    return free, fixed


def modes_and_arcs(
    sensors: FloatArray, targets: FloatArray, r: FloatArray, rho: FloatArray
) -> tuple[np.ndarray, FloatArray, dict[tuple[int, ...], list[geometry.Arc]]]:
    """Return :func:`sensor_modes_multi` and the free sensors' boundary arcs.

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
        arcs = feasible_set.boundary_arcs(s, ri, t, rhoi)
        if sum(a.length for a in arcs) > 0.0:
            free[idx] = True
            arcs_of[idx] = arcs
        else:
            fixed[idx] = feasible_set.fallback(s, np.float64(ri), t, np.float64(rhoi))
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


def sensor_modes_of(c: FloatArray, r: FloatArray, rho: FloatArray) -> tuple[np.ndarray, FloatArray]:
    """Return :func:`sensor_modes` for arrays ``c`` (..., M, 2) and ``r``, ``rho`` (..., M)
    (:func:`activetrack.baselines.gsr_kernel.modes_row`)."""
    c = np.asarray(c, np.float64)
    batch, m = c.shape[:-2], c.shape[-2]
    free, fixed = np.empty(batch + (m,), bool), np.empty(batch + (m, 2))
    status = np.empty(batch + (m,), np.int64)
    gk.modes_rows(
        as_rows(c, batch, (m, 2)), as_rows(r, batch, (m,)), as_rows(rho, batch, (m,)),
        free.reshape(-1, m), fixed.reshape(-1, m, 2), status.reshape(-1, m),
    )  # fmt: skip
    raise_for_status(status)
    return free, fixed


def raise_for_status(status: np.ndarray) -> None:
    """Raise the ValueError of the sensors flagged by
    :func:`activetrack.baselines.gsr_kernel.modes_row` (``status`` (..., M)), if any."""
    degenerate = status == gk.DEGENERATE
    if degenerate.any():
        raise ValueError(
            f"rho must be > 0 for sensors {_where(degenerate)}: the predicted "
            "target is within their reach and the information grows without bound near it"
        )
    on_target = status == gk.ON_TARGET
    if on_target.any():
        raise ValueError(
            f"sensors {_where(on_target)} cannot move (r = 0) and sit exactly "
            "on the predicted target, where the bearing is undefined"
        )


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


#: The most boundary points a grid of one sensor's feasible set may hold (a kinematics of
#: its own, :func:`kinematic_boundaries`): 4M points, 64 MB.
MAX_BOUNDARY_POINTS = 1 << 22


def own_kinematics(problem: PlanningProblem) -> bool:
    """Return whether some sensor of ``problem`` moves by a kinematics that is not a
    built-in :class:`activetrack.Disk` (the planners then ask its kinematics)."""
    kin = problem.kinematics
    return kin is not None and not all_disks(kin)


def kinematic_boundaries(
    problem: PlanningProblem, spacing: float | None = None
) -> tuple[np.ndarray, FloatArray, dict[tuple[int, ...], FloatArray]]:
    """Return ``(free, fixed, boundary_of)`` of a problem whose sensors move by their own
    kinematics (``problem.kinematics``), in absolute coordinates, batched.

    ``free`` (..., M): the radius is > 0 and the boundary of the feasible set ``F`` (reach
    set minus the K ``rho`` disks) has points; ``fixed`` (..., M, 2): the current position
    of free sensors and of those with radius 0 (they stay), and for the sensors whose
    ``F`` is empty their kinematics' :meth:`~activetrack.Kinematics.project` of their
    position (its least violation of eq. 16, the world's rule); ``boundary_of`` maps a free
    sensor's index ``batch index + (i,)`` to :meth:`~activetrack.Kinematics.boundary` at
    ``spacing`` (None: ``radius / 1024``), exact repeats dropped, in the kinematics' order.

    Raises:
        ValueError: ``spacing`` would give a sensor more than :data:`MAX_BOUNDARY_POINTS`
            (estimated from its radius and the ``rho`` circles before any is built); or
            as :func:`sensor_modes` (a free sensor with ``rho = 0`` can reach a target).
    """
    sensors, targets = problem.sensors, problem.targets
    states = sensors if problem.sensor_states is None else problem.sensor_states
    team = problem.kinematics
    rho_all = np.broadcast_to(problem.rho, sensors.shape[:-1])
    free = np.zeros(sensors.shape[:-1], dtype=bool)
    fixed = np.array(sensors, dtype=np.float64)
    boundary_of = {}
    for idx in np.ndindex(sensors.shape[:-1]):
        kin, t = team[idx[-1]], targets[idx[:-1]]
        s = states[idx][: kin.state_dim]  # its state (a heading, a velocity: beyond it)
        r, rho = float(kin.radius), float(rho_all[idx])
        if not r > 0.0:
            continue
        pts = boundary_grid(kin, s, t, rho, spacing)
        if len(pts) == 0:
            fixed[idx] = kin.project(sensors[idx], s, t, rho)
            continue
        if rho <= 0.0 and bool(np.any(kin.reaches(t, s))):
            raise ValueError(
                f"rho must be > 0 for sensors {_where(_flag(free.shape, idx))}: a predicted "
                "target is within their reach and the information grows without bound near it"
            )
        free[idx] = True
        boundary_of[idx] = pts
    return free, fixed, boundary_of


def boundary_grid(
    kin: Any, position: FloatArray, targets: FloatArray, rho: float, spacing: float | None
) -> FloatArray:
    """Return ``kin``'s :meth:`~activetrack.Kinematics.boundary` of the feasible set of one
    sensor at ``position`` (targets (K, 2)) at ``spacing`` (None: ``radius / 1024``), exact
    repeats dropped, in the kinematics' order, (P, 2).

    Raises:
        ValueError: ``spacing`` would give more than :data:`MAX_BOUNDARY_POINTS`
            (estimated from the radius and the ``rho`` circles before any is built).
    """
    r = float(kin.radius)
    step = r / 1024 if spacing is None else float(spacing)
    # The perimeter of a convex reach set is at most 2 pi radius; each rho circle adds
    # at most 2 pi rho: refuse before building a grid beyond the memory bound.
    length = 2.0 * np.pi * (r + len(targets) * rho)
    est = length / step
    if est > MAX_BOUNDARY_POINTS:
        raise ValueError(
            f"spacing must be at least {length / MAX_BOUNDARY_POINTS:.3g} m for the boundary "
            f"grid of kinematics {kin.name!r} (about {est:.3g} points, more than "
            f"{MAX_BOUNDARY_POINTS}), got {step!r}"
        )
    pts = np.asarray(kin.boundary(position, targets, rho, step), dtype=np.float64)
    pts = pts.reshape(-1, 2)
    _, first = np.unique(pts, axis=0, return_index=True)
    return pts[np.sort(first)]


def _flag(shape: tuple[int, ...], idx: tuple[int, ...]) -> np.ndarray:
    """Return a boolean array of ``shape`` that is True at ``idx`` only."""
    out = np.zeros(shape, dtype=bool)
    out[idx] = True
    return out
