"""Random motion (RM), the naive baseline of Section V.

Every sensor moves to a point drawn uniformly, by arc length, from its curve ADB
(Lemma 3, Fig. 3 (a)-(c)): a random heading "towards the target" that respects the
speed limit (eq. 15) and the minimum distance (eq. 16). Sensors that cannot move
(``r = 0``) stay; sensors that cannot keep the minimum distance go to
:func:`activetrack.geometry.unreachable_fallback`.
"""

from __future__ import annotations

import numpy as np

from activetrack import geometry
from activetrack.baselines._common import sensor_modes
from activetrack.problem import PlanningProblem
from activetrack.validation import FloatArray


class RandomMotion:
    """Each sensor to a uniformly random point of its curve ADB (Section V, "RM")."""

    def plan(self, problem: PlanningProblem, rng: np.random.Generator) -> FloatArray:
        """Return random feasible next absolute positions, ``batch_shape + (M, 2)``.

        Draws exactly one uniform per free sensor from ``rng``, in copy order (row-major
        over the batch axes), then sensor order.
        """
        free, rel = sensor_modes(problem)
        rel = rel.copy()
        c = problem.rel_sensors
        r, rho = problem.r, problem.rho
        for b in np.ndindex(problem.batch_shape):
            for i in np.flatnonzero(free[b]):
                k = b + (i,)
                arcs = geometry.facing_boundary(c[k], float(r[k]), float(rho[k]))
                rel[k] = geometry.sample_uniform(arcs, rng)
        return rel + problem.target[..., None, :]

    def __repr__(self) -> str:
        return "RandomMotion()"
