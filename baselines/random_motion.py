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
"""

from __future__ import annotations

import numpy as np

from activetrack.baselines._common import modes_and_arcs, sensor_modes
from activetrack.kinematics import geometry
from activetrack.kinematics.team import require_disks
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem


class RandomMotion:
    """Each sensor to a uniformly random point of its curve ADB (Section V, "RM").

    With K > 1 targets: of the boundary of its feasible set (see the module docstring).
    """

    def plan(self, problem: PlanningProblem, rng: np.random.Generator) -> FloatArray:
        """Return random feasible next absolute positions, ``batch_shape + (M, 2)``.

        Draws exactly one uniform per free sensor from ``rng``, in copy order (row-major
        over the batch axes), then sensor order.
        """
        require_disks(problem.kinematics, "RandomMotion")
        targets = problem.targets
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
