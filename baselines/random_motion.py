"""Random motion (RM), the naive baseline of Section V.

Every sensor moves to a point drawn uniformly, by arc length, from its curve ADB
(Lemma 3, Fig. 3 (a)-(c)): a random heading "towards the target" that respects the
speed limit (eq. 15) and the minimum distance (eq. 16). Sensors that cannot move
(``r = 0``) stay; sensors that cannot keep the minimum distance go to
:func:`activetrack.kinematics.geometry.unreachable_fallback`.

With K > 1 predicted targets there is no single direction "towards the target": every
free sensor moves to a point drawn uniformly by arc length from the whole boundary of its
feasible set (the reach disk minus the K ``rho`` disks,
:func:`activetrack.kinematics.feasible_set.boundary_arcs`: reach-circle pieces outside the
``rho`` disks and ``rho``-circle pieces inside the reach disk); sensors whose feasible set
is empty go to :func:`activetrack.kinematics.feasible_set.fallback`. With one target
(any sensor model or pose covariance) the curve ADB as above.

A sensor that moves by a kinematics of its own (``problem.kinematics``, not a built-in
:class:`activetrack.Disk`) has no curve ADB: it moves to a point drawn uniformly by arc
length from the whole boundary of its feasible set (reach set minus the K ``rho`` disks),
as the disk's sensors do with K > 1 targets: its kinematics'
:meth:`~activetrack.Kinematics.boundary` at ``radius / 1024``, each point weighted by the
arc it stands for (:func:`arc_weights`). Its sensors whose feasible set is empty go to
their kinematics' :meth:`~activetrack.Kinematics.project` (the world's rule).

With the team rule ``d_sep`` (``problem.d_sep``) the draws are filtered, sensor by
sensor in agent order (:func:`separate_draws`): a drawn point whose straight path would
come within ``d_ij`` of another sensor (the ones before it at their drawn points, the
ones after it where they stand), or within ``d_ij`` of an earlier sensor's straight path
at the same instant (the world's rule, :mod:`activetrack.baselines.gsr_separation`) is
drawn again, with one more uniform, among the points of the boundary of its feasible set
whose paths keep the rule (:data:`SEP_POINTS` per circle); with none, the sensor stays.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from activetrack.baselines import gsr_separation
from activetrack.baselines._common import (
    kinematic_boundaries,
    modes_and_arcs,
    own_kinematics,
    sensor_modes,
)
from activetrack.kinematics import geometry
from activetrack.kinematics.separation import segment_distance, together
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem

#: Points per circle of the candidates a redraw under ``d_sep`` picks from.
SEP_POINTS = 256


def separate_draws(
    problem: PlanningProblem, plan: FloatArray, d: FloatArray, rng: np.random.Generator
) -> FloatArray:
    """Return ``plan`` (``batch + (M, 2)``) with the draws that break the team rule drawn
    again (module docstring), for the pair distances ``d`` (M, M)."""
    out = np.array(plan, np.float64)
    dm = d * (1.0 + gsr_separation.MARGIN)
    sensors = np.asarray(problem.sensors, np.float64)
    states = sensors if problem.sensor_states is None else problem.sensor_states
    rho_all = np.broadcast_to(problem.rho, sensors.shape[:-1])
    r_all = np.broadcast_to(problem.r, sensors.shape[:-1])
    ang = 2.0 * np.pi * np.arange(SEP_POINTS) / SEP_POINTS
    ring = np.stack([np.cos(ang), np.sin(ang)], -1)
    m = sensors.shape[-2]
    for b in np.ndindex(sensors.shape[:-2]):
        old, targets = sensors[b], problem.targets[b]
        for i in range(m):
            js = np.array([j for j in range(m) if j != i and d[i, j] > 0.0], dtype=np.int64)
            obst = np.where((js < i)[:, None], out[b][js], old[js])
            early = js[js < i]
            if np.all(segment_distance(old[i], out[b + (i,)], obst) >= dm[i, js]) and np.all(
                together(old[i], out[b + (i,)], old[early], out[b][early]) >= dm[i, early]
            ):
                continue
            rho = float(rho_all[b + (i,)])
            if problem.kinematics is not None:
                kin = problem.kinematics[i]
                st = states[b + (i,)][: kin.state_dim]
                cand = kin.boundary(st, targets, rho, max(float(kin.radius), 1e-300) / SEP_POINTS)
                cand = cand[kin.feasible(cand, st, targets, rho)]
            else:
                r = float(r_all[b + (i,)])
                cand = [old[i] + r * ring] + [t + rho * (1.0 + 1e-12) * ring for t in targets]
                cand = np.concatenate(cand)
                e = cand - old[i]
                cand = cand[np.hypot(e[:, 0], e[:, 1]) <= r]
                f = cand[:, None, :] - targets[None]
                cand = cand[np.all(np.hypot(f[..., 0], f[..., 1]) >= rho, axis=-1)]
            seg = segment_distance(old[i], cand[:, None, :], obst[None])  # (C, J)
            same = together(old[i], cand[:, None, :], old[early], out[b][early])  # (C, J')
            cand = cand[np.all(seg >= dm[i, js], axis=-1) & np.all(same >= dm[i, early], -1)]
            out[b + (i,)] = cand[rng.integers(len(cand))] if len(cand) else old[i]
    return out


class RandomMotion:
    """Each sensor to a uniformly random point of its curve ADB (Section V, "RM").

    With K > 1 targets, or a kinematics of its own: of the boundary of its feasible set
    (see the module docstring).
    """

    #: Keeps the team rule ``d_sep`` itself (:mod:`activetrack.baselines.gsr_separation`).
    keeps_d_sep = True

    def plan(self, problem: PlanningProblem, rng: np.random.Generator) -> FloatArray:
        """Return random feasible next absolute positions, ``batch_shape + (M, 2)``.

        Draws exactly one uniform per free sensor from ``rng``, in copy order (row-major
        over the batch axes), then sensor order (with ``d_sep``, then one more per redraw).
        """
        plan = self._draw(problem, rng)
        d = gsr_separation.pair_matrix(problem)
        return plan if d is None else separate_draws(problem, plan, d, rng)

    def _draw(self, problem: PlanningProblem, rng: np.random.Generator) -> FloatArray:
        """Return the draws without the team rule (:meth:`plan`)."""
        targets = problem.targets
        if own_kinematics(problem):  # each sensor's kinematics draws on its boundary of F
            _, out, boundary_of = kinematic_boundaries(problem)
            for k, pts in boundary_of.items():  # row-major over the batch, then the sensors
                out[k] = draw_on_boundary(pts, rng.random())
            return out
        if targets.shape[-2] > 1:
            free, out, arcs_of = modes_and_arcs(problem.sensors, targets, problem.r, problem.rho)
            for k in arcs_of:  # free sensors, row-major over the batch, then the sensors
                out[k] = geometry.sample_uniform(arcs_of[k], rng)
            return out
        free, rel = sensor_modes(problem)
        rel = rel.copy()
        origin = targets[..., 0, None, :]  # what sensor_modes is relative to
        c = problem.sensors - origin
        r, rho = problem.r, problem.rho
        for b in np.ndindex(problem.batch_shape):
            for i in np.flatnonzero(free[b]):
                k = b + (i,)
                arcs = geometry.facing_boundary(c[k], float(r[k]), float(rho[k]))
                rel[k] = geometry.sample_uniform(arcs, rng)
        return rel + origin

    def __repr__(self) -> str:
        return "RandomMotion()"


def arc_weights(points: FloatArray) -> FloatArray:
    """Return the arc length each of ``points`` (P, 2) stands for on the curve they sample:
    half the sum of the distances to its two nearest other points (the spacing where the
    points are evenly spaced; a lone point 1, a pair their distance each). Distinct points."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if len(points) < 3:
        gap = float(np.hypot(*(points[-1] - points[0]))) if len(points) == 2 else 0.0
        return np.full(len(points), gap if gap > 0.0 else 1.0)
    dist, _ = cKDTree(points).query(points, k=3)  # itself, then its two nearest
    return 0.5 * (dist[:, 1] + dist[:, 2])


def draw_on_boundary(points: FloatArray, u: FloatArray | float) -> FloatArray:
    """Return the points of ``points`` (P, 2) that uniforms ``u`` pick with probability
    proportional to :func:`arc_weights` (inverse transform), ``shape(u) + (2,)``."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    cdf = np.cumsum(arc_weights(points))
    k = np.searchsorted(cdf, np.asarray(u, dtype=np.float64) * cdf[-1], side="right")
    return points[np.minimum(k, len(points) - 1)]
