"""GSR's numerical single-sensor step for any kinematics (``PlanningProblem.kinematics``).

The disk's step (:mod:`activetrack.solvers.numeric`) knows the feasible set's circles. A
sensor whose :class:`activetrack.Kinematics` is not a built-in disk is solved from what
its kinematics says about its feasible set ``F`` (its reach set minus the ``rho`` disks):

1. **candidates**: points of the boundary of ``F`` (:meth:`~activetrack.Kinematics.boundary`,
   ``CANDIDATE_SPACING`` of the radius apart; Lemma 3 puts the disk's optimum there), the
   feasible points of a ``GRID x GRID`` grid over the radius' square, and the sensor's
   current position made feasible (:meth:`~activetrack.Kinematics.project`); the best by
   the objective;
2. **refinement**: a compass search from it, each trial point projected onto ``F``
   (:meth:`~activetrack.Kinematics.project`), the step halved when no direction improves,
   down to ``1e-9`` of the radius.

The result is feasible (every evaluated point comes from the kinematics' boundary, its
membership test or its projection) and never worse than the best candidate. It is slower
than the disk's step (a loop over copies in Python), which the built-in disk keeps.
"""

from __future__ import annotations

import numpy as np

from activetrack.validation import FloatArray

#: Boundary candidates' spacing, in units of the radius.
CANDIDATE_SPACING = 1.0 / 64
#: Grid candidates per axis over the square ``[-radius, radius]^2`` about the sensor.
GRID = 15
#: The compass search's directions (8, unit vectors) and its last step (of the radius).
_DIRS = np.array([[np.cos(a), np.sin(a)] for a in np.arange(8) * np.pi / 4])
_STOP = 1e-9
#: At most this many compass rounds per solve (each improves or halves the step).
_ROUNDS = 400


def candidates(kin, position: FloatArray, targets: FloatArray, rho: float) -> FloatArray:
    """Return sensor candidates (P, 2), all in ``F`` (or its projection's fallback)."""
    r = float(kin.radius)
    edge = kin.boundary(position, targets, rho, max(r, 1e-300) * CANDIDATE_SPACING)
    t = np.linspace(-r, r, GRID)
    grid = position + np.stack(np.meshgrid(t, t), -1).reshape(-1, 2)
    grid = grid[kin.feasible(grid, position, targets, rho)]
    here = kin.project(position, position, targets, rho)[None]
    return np.concatenate([here, edge.reshape(-1, 2), grid])


class Prepared:
    """Every copy's and sensor's step by its kinematics, with the interface of
    :class:`activetrack.baselines.gsr_numeric._Prepared` (``solve(sub, i, base)``)."""

    def __init__(self, problem, entries, current, targets, rho) -> None:
        self.team = problem.kinematics
        self.objective = problem.objective
        self.entries = entries  # (s (B, 1, 2), copies, sensor) -> 3 x (B, K, 1)
        self.current, self.targets, self.rho = current, targets, rho
        self.cache: dict[tuple[int, int], FloatArray] = {}

    def _value(self, b: int, i: int, pts: FloatArray, base: tuple) -> FloatArray:
        """Return the objective (P,) with sensor ``i`` of copy ``b`` at ``pts`` (P, 2)."""
        a, bb, c = self.entries(pts, b, i)  # 3 x (P, K)
        return self.objective.of_targets(base[0] + a, base[1] + bb, base[2] + c)

    def solve(self, sub: np.ndarray, i: int, base: tuple) -> tuple[FloatArray, FloatArray]:
        """Return ``(positions (S, 2), values (S,))`` of sensor ``i`` in copies ``sub`` with
        the others' entries ``base`` (3 x (S, K))."""
        kin = self.team[i]
        pos, val = np.empty((len(sub), 2)), np.empty(len(sub))
        for j, b in enumerate(sub.tolist()):
            p, t, rho = self.current[b, i], self.targets[b], float(self.rho[b, i])
            key = (b, i)
            if key not in self.cache:  # the candidates do not change over the sweeps
                self.cache[key] = candidates(kin, p, t, rho)
            cand = self.cache[key]
            own = tuple(x[j] for x in base)
            v = self._value(b, i, cand, own)
            best = int(np.argmin(v))
            x, fx = cand[best], float(v[best])
            step = 0.5 * float(kin.radius) * CANDIDATE_SPACING
            stop = _STOP * max(float(kin.radius), 1e-300)
            for _ in range(_ROUNDS):
                if step <= stop:
                    break
                trial = np.array([kin.project(x + step * d, p, t, rho) for d in _DIRS])
                tv = self._value(b, i, trial, own)
                k = int(np.argmin(tv))
                if tv[k] < fx:
                    x, fx = trial[k], float(tv[k])
                else:
                    step *= 0.5
            pos[j], val[j] = x, fx
        return pos, val


def warm_start(problem, current: FloatArray, targets: FloatArray, rho: FloatArray) -> FloatArray:
    """Return the current positions (B, M, 2), each infeasible one projected onto its ``F``
    by its kinematics."""
    s = current.copy()
    for i, kin in enumerate(problem.kinematics):
        for b in range(len(s)):
            if not kin.feasible(s[b, i], s[b, i], targets[b], rho[b, i]):
                s[b, i] = kin.project(s[b, i], current[b, i], targets[b], rho[b, i])
    return s
