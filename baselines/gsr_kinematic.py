"""GSR's numerical single-sensor step for a kinematics whose action is not a 2-D box.

A kinematics with a 2-D action box (every built-in one) is solved in command space
(:mod:`activetrack.baselines.gsr_command`: faster, and at least as good); this module is
the fallback for the others (``PlanningProblem.kinematics``).

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
membership test or its projection) and never worse than the best candidate. It is slow
(a loop over copies in Python; about 0.4 s per step for a unicycle team of 3).
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
    """Return sensor candidates (P, 2), all in ``F`` (or its projection's fallback), of a
    sensor in state ``position`` (its position, or its whole state: ``kin.state_dim``)."""
    r = float(kin.radius)
    xy = np.asarray(position, dtype=np.float64)[:2]
    edge = kin.boundary(position, targets, rho, max(r, 1e-300) * CANDIDATE_SPACING)
    t = np.linspace(-r, r, GRID)
    grid = xy + np.stack(np.meshgrid(t, t), -1).reshape(-1, 2)
    grid = grid[kin.feasible(grid, position, targets, rho)]
    here = kin.project(xy, position, targets, rho)[None]
    return np.concatenate([here, edge.reshape(-1, 2), grid])


def _projected(kin, pts: FloatArray, p: FloatArray, t: FloatArray, rho: float) -> FloatArray:
    """Return :meth:`~activetrack.Kinematics.project` of each of ``pts`` (P, 2): their
    :meth:`~activetrack.Kinematics.clip` in one call where that is feasible (then the
    nearest point of ``F``), the projection of the others one by one."""
    out = np.asarray(kin.clip(pts, p), dtype=np.float64).reshape(-1, 2).copy()
    for j in np.flatnonzero(~kin.feasible(out, p, t, rho)):
        out[j] = kin.project(pts[j], p, t, rho)
    return out


def states_of(problem, current: FloatArray) -> FloatArray:
    """Return the sensors' states (B, M, S): ``problem.sensor_states`` flattened like
    ``current`` (B, M, 2), or ``current`` when the problem has none."""
    if problem.sensor_states is None:
        return current
    return problem.sensor_states.reshape(current.shape[:2] + (-1,))


class Prepared:
    """Every copy's and sensor's step by its kinematics, with the interface of
    :class:`activetrack.baselines.gsr_numeric._Prepared` (``solve(sub, i, base)``)."""

    def __init__(self, problem, entries, current, targets, rho) -> None:
        self.team = problem.kinematics
        self.objective = problem.objective
        self.entries = entries  # (s (B, 1, 2), copies, sensor) -> 3 x (B, K, 1)
        self.current, self.targets, self.rho = current, targets, rho
        self.states = states_of(problem, current)
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
            p, t, rho = self.states[b, i, : kin.state_dim], self.targets[b], float(self.rho[b, i])
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
                trial = _projected(kin, x + step * _DIRS, p, t, rho)
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
    states = states_of(problem, current)
    for i, kin in enumerate(problem.kinematics):
        for b in range(len(s)):
            st = states[b, i, : kin.state_dim]
            if not kin.feasible(s[b, i], st, targets[b], rho[b, i]):
                s[b, i] = kin.project(s[b, i], st, targets[b], rho[b, i])
    return s
