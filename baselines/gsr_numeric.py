"""Gauss-Seidel relaxation beyond the paper: every sensor's step by the numerical solver.

GSR (Section IV-B, eq. 38) minimizes the objective one sensor at a time with the other
sensors' information folded into the prior. On the paper's problem the single-sensor
step is the exact solve of Section IV-A (:mod:`activetrack.baselines.gsr`). On every other
problem (K targets, range-only or bearing-only sensors, uncertain position fixes, the
worst-trace or log-determinant objective) the step is the global numerical solver of
:mod:`activetrack.solvers.numeric`: with sensor ``i``'s information removed, each target's
information entries ``(a0, b0, c0)`` are the base, and the solver minimizes
``objective.of_targets(a0 + a_i(s), ...)`` over sensor ``i``'s feasible set (its reach
disk outside every target's ``rho`` disk), never returning worse than the best candidate
it evaluated.

The rules are GSR's: sensors with ``r = 0`` stay; the warm start is the current positions
(a sensor inside a ``rho`` disk from its nearest feasible point,
:func:`activetrack.kinematics.feasible_set.project`); a sensor's update is kept only if it lowers
the objective, so the result is never worse than the warm start; a sensor whose
subproblem has not changed since its last solve (no other sensor moved) is skipped;
sweeps stop when one improves the objective by at most ``tol`` (relative; by ``tol`` in
absolute terms for an objective that may be negative, the log-determinant), when no
sensor is left to re-solve, or after ``max_sweeps``. A batch is relaxed in one vectorized
sweep over the copies (copies that have stopped are carried).

A sensor that moves by a kinematics of its own with a 2-D action box (a unicycle, a double
integrator) is solved over its commands (:mod:`activetrack.baselines.gsr_command`). With the
team rule ``d_sep`` (``problem.d_sep``) every sensor's subproblem also keeps the world's
pair conditions with the others' current plans
(:mod:`activetrack.baselines.gsr_separation`), so the disk is then solved in command space
too, and so is the lost sensors' approach below: among occluders or under the rule it
goes around the buildings by the geodesic distance and keeps the pair conditions with the
others' plans (:mod:`activetrack.baselines.gsr_approach`).

The sweeps change only the base of a sensor's subproblem, so its candidates and its
information there are prepared once per plan (:func:`activetrack.solvers.numeric.prepare`),
and a re-solve refines from where the sensor's last solve ended
(:class:`activetrack.solvers.numeric.Prepared`, ``remember``).
"""

from __future__ import annotations

import numpy as np

from activetrack.baselines import gsr_approach, gsr_command, gsr_kinematic, gsr_separation
from activetrack.estimation import generic
from activetrack.kinematics import feasible_set
from activetrack.kinematics.team import all_disks
from activetrack.models import sensor_models
from activetrack.models.occluders import line_of_sight, project_move
from activetrack.solvers import numeric as solver_numeric
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem


def relax(
    problem: PlanningProblem, tol: float, max_sweeps: int
) -> tuple[FloatArray, FloatArray, np.ndarray, FloatArray]:
    """Return ``(positions, value, sweeps, warm_value)``: GSR with numerical steps.

    Shapes: ``positions`` ``batch_shape + (M, 2)`` absolute, ``value``, ``sweeps`` and the
    warm start's value ``batch_shape``.
    """
    shape = problem.batch_shape
    B = int(np.prod(shape, dtype=np.int64))
    M, K = problem.n_sensors, problem.n_targets
    targets = problem.targets.reshape(B, K, 2)
    prior = problem.prior_infos.reshape(B, K, 2, 2)
    current = problem.sensors.reshape(B, M, 2)
    r = problem.r.reshape(B, M)
    rho = problem.rho.reshape(B, M)
    w_d, w_t = (w.reshape(B, M) for w in problem.weights)
    pose = None if problem.pose_cov is None else problem.pose_cov.reshape(B, M, 2, 2)
    det = None if problem.detect is None else tuple(d.reshape(B, M) for d in problem.detect)
    occ = problem.occluders
    if occ is not None and occ.batched and len(shape) > 1:  # a layout per flattened copy
        occ = occ[np.repeat(np.arange(shape[0]), B // shape[0])]
    custom = problem.kinematics is not None and not all_disks(problem.kinematics)
    if custom and gsr_command.supports(problem.kinematics):  # warm start in command space
        s = gsr_command.warm_start(
            problem.kinematics, gsr_kinematic.states_of(problem, current), current, targets, rho
        )
    elif custom:  # a kinematics of its own: its own feasible sets (baselines.gsr_kinematic)
        s = gsr_kinematic.warm_start(problem, current, targets, rho)
    else:
        s = _warm_start(current, r, targets, rho)
    team = problem.sensor_objects  # models of one's own, or None (built-in)
    entries = _entries(s, targets, w_d, w_t, pose, det, occ, team)  # 3 x (B, K, M)
    base = (prior[..., 0, 0], prior[..., 0, 1], prior[..., 1, 1])
    totals = [base[e] + entries[e].sum(axis=-1) for e in range(3)]
    value = problem.objective.of_targets(*totals)
    warm = value.copy()
    sweeps = np.zeros(B, dtype=np.int64)
    active = np.ones(B, dtype=bool)
    free = r > 0.0
    # changed[b, i]: sensor i's subproblem in copy b changed since its last solve (another
    # sensor moved); an unchanged subproblem would give the same answer, so it is skipped.
    changed = free.copy()
    # The team rule d_sep: each subproblem keeps the pair conditions with the others' plans.
    sep = gsr_separation.pair_matrix(problem)
    if (custom and gsr_command.supports(problem.kinematics)) or (sep is not None and not custom):
        kin, states = problem.kinematics, gsr_kinematic.states_of(problem, current)
        if not custom:  # disks: each copy's own radius in the state
            kin = (gsr_separation.RadiusDisk(),) * M
            states = np.concatenate([current, r[..., None]], -1)
        prepared = gsr_command.Prepared(
            kin, states, targets, rho, _sensor_at(targets, w_d, w_t, pose, det, occ, team),
            problem.objective,
            constraints=None if sep is None else gsr_separation.constraints(sep, current, s),
            compiled=(w_d, w_t) if _built_in(problem, pose, det, occ, team) else None,
        )  # fmt: skip
    elif custom:
        one = _one_sensor(targets, w_d, w_t, pose, det, occ, team)
        prepared = gsr_kinematic.Prepared(problem, one, current, targets, rho)
    else:
        prepared = _Prepared(problem, current, r, targets, rho, w_d, w_t, pose, det, occ)
    for _ in range(max_sweeps):
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        before = value[rows].copy()
        sweeps[rows] += 1
        for i in range(M):
            sub = rows[changed[rows, i]]
            if sub.size == 0:
                continue
            others = tuple(totals[e][sub] - entries[e][sub, :, i] for e in range(3))
            pos, val = prepared.solve(sub, i, others)
            changed[sub, i] = False
            better = val < value[sub]
            if not np.any(better):
                continue
            keep = sub[better]
            s[keep, i] = pos[better]
            changed[keep] |= free[keep]
            changed[keep, i] = False
            one = slice(i, i + 1)
            cov1 = None if pose is None else pose[keep, one]
            det1 = None if det is None else tuple(d[keep, one] for d in det)
            new = _entries(
                s[keep, one],
                targets[keep],
                w_d[keep, one],
                w_t[keep, one],
                cov1,
                det1,
                None if occ is None else occ[keep],
                None if problem.sensor_objects is None else problem.sensor_objects[one],
            )
            for e in range(3):
                entries[e][keep, :, i] = new[e][..., 0]
                # Rebuilt from the parts (not updated by differences): no drift over sweeps.
                totals[e][keep] = base[e][keep] + entries[e][keep].sum(axis=-1)
            value[keep] = problem.objective.of_targets(*(t[keep] for t in totals))
        gain = before - value[rows]
        # Relative to the value where it is never negative, else to max(|value|, 1).
        nonneg = problem.objective.nonnegative
        scale = before if nonneg else np.maximum(np.abs(before), 1.0)
        active[rows] = (gain > tol * scale) & changed[rows].any(axis=1)
    if det is not None and (occ is not None or np.any(np.isfinite(det[1]))):
        s, value = _approach(problem, s, value, current, r, targets, rho, det, (w_d, w_t, pose),
                             occ, sep)  # fmt: skip
    return s.reshape(*shape, M, 2), value.reshape(shape), sweeps.reshape(shape), warm.reshape(shape)


def _approach(problem, s, value, current, r, targets, rho, det, weights, occ, sep):
    """Return ``(positions, value)`` with every free sensor out of range of every target
    moved to its feasible point nearest the nearest predicted target, where that is no worse.

    Out of range the sensor's expected information is 0 wherever it can reach (its
    subproblem is flat), so relaxation leaves it where it stands; closing in is the
    sensible tie-break (it can only add information), and it is what lets a sensor that has
    lost a target find it again. Among occluders or under the team rule ``sep`` (M, M) the
    nearest is by the geodesic distance around the occluders, over the points each sensor
    can reach in command space that keep the rule with the others' plans
    (:func:`activetrack.baselines.gsr_approach.approach`); on the open plane without the
    rule, each sensor's exact projection of the target.
    """
    rel = s[:, None, :, :] - targets[:, :, None, :]  # (B, K, M, 2)
    seen = sensor_models.detection_factor(rel, det[0][:, None], det[1][:, None]) > 0.0
    if occ is not None:
        seen = line_of_sight(s, targets, occ, where=seen)
    lost = ~seen.any(axis=1) & (r > 0.0) & (det[0] > 0.0)  # (B, M)
    if not np.any(lost):
        return s, value
    team = problem.kinematics
    custom = team is not None and not all_disks(team)
    commands = not custom or gsr_command.supports(team)
    if (occ is not None or sep is not None) and commands:  # the geodesic, in command space
        kin, states = team, gsr_kinematic.states_of(problem, current)
        if not custom:  # disks: each copy's own radius in the state
            kin = (gsr_separation.RadiusDisk(),) * r.shape[1]
            states = np.concatenate([current, r[..., None]], -1)
        moved = gsr_approach.approach(kin, states, s, current, lost, targets, rho, occ, sep)
    elif sep is not None:  # no command space to keep the rule in: the plans stay
        return s, value
    else:
        b, i = np.nonzero(lost)
        d2 = np.sum((targets[b] - current[b, i][:, None]) ** 2, axis=-1)  # (L, K)
        goal = targets[b, np.argmin(d2, axis=-1)]
        moved = s.copy()
        if custom:  # each sensor's own projection
            for j, (bj, ij) in enumerate(zip(b.tolist(), i.tolist(), strict=True)):
                moved[bj, ij] = team[ij].project(goal[j], current[bj, ij], targets[bj], rho[bj, ij])
        else:
            moved[b, i] = feasible_set.project(goal, current[b, i], r[b, i], targets[b], rho[b, i])
        if occ is not None:  # a straight move the world allows: around the occluders
            moved[b, i] = project_move(current[b, i], moved[b, i], occ[b], r[b, i])[0]
    w_d, w_t, pose = weights
    prior = problem.prior_infos.reshape(len(s), -1, 2, 2)
    new = problem.objective.of_targets(
        *(
            prior[..., e0, e1] + x.sum(axis=-1)
            for (e0, e1), x in zip(
                ((0, 0), (0, 1), (1, 1)),
                _entries(moved, targets, w_d, w_t, pose, det, occ, problem.sensor_objects),
                strict=True,
            )
        )
    )
    better = new <= value
    return np.where(better[:, None, None], moved, s), np.where(better, new, value)


class _Prepared:
    """Every sensor's candidates and information there (:class:`solver_numeric.Prepared`),
    and where each copy's last solve of each sensor ended.

    They do not change over the sweeps (the reach disk, the targets and ``rho`` are
    fixed; only the other sensors' information does), so a small batch prepares all
    sensors of all copies once, in one call; a large batch (whose preparation is
    vectorized over its copies anyway) prepares sensor ``i``'s rows when it solves them,
    which bounds the memory to one sensor's candidates.

    A re-solve of sensor ``i`` in copy ``b`` refines from where its previous solve in that
    copy ended (``Prepared.remember``), whichever other copies are solved with it: the
    memory is kept per copy, so a copy's plan is the same alone or in any batch.
    """

    #: Batches of at most this many sensor rows (copies x M) are prepared at once.
    ROWS = 256

    def __init__(self, problem, current, r, targets, rho, w_d, w_t, pose, det, occ) -> None:
        self.args = (current, r, targets, rho, w_d, w_t, pose, det)
        self.occ = occ
        self.team = problem.sensor_objects  # models of one's own (their information), or None
        self.objective = problem.objective
        B, M = r.shape
        self.m = M
        self.all = None
        self.b = B
        # sensor -> (starts chosen, final angles, final plane points, solved before), per copy
        self.memory: dict[int, tuple[np.ndarray, FloatArray, FloatArray, np.ndarray]] = {}
        if B * M <= self.ROWS:
            self.all = self._prepare(np.arange(B)[:, None], np.arange(M)[None, :])

    def _prepare(self, rows: np.ndarray, cols: np.ndarray) -> solver_numeric.Prepared:
        current, r, targets, rho, w_d, w_t, pose, det = self.args
        return solver_numeric.prepare(
            current[rows, cols], r[rows, cols], targets[rows], rho[rows, cols],
            w_d[rows, cols], w_t[rows, cols], None if pose is None else pose[rows, cols],
            self.objective,
            detect=None if det is None else tuple(d[rows, cols] for d in det),
            occluders=None if self.occ is None else self.occ[np.asarray(rows).reshape(-1)],
            models=None if self.team is None else (self.team, cols),
        )  # fmt: skip

    def rows(self, sub: np.ndarray, i: int) -> solver_numeric.Prepared:
        """Return the prepared subproblems of sensor ``i`` in copies ``sub`` (no memory)."""
        if self.all is not None:
            return self.all.take(sub * self.m + i)
        return self._prepare(sub, np.array(i))

    def solve(
        self, sub: np.ndarray, i: int, base: tuple[FloatArray, FloatArray, FloatArray]
    ) -> tuple[FloatArray, FloatArray]:
        """Return :func:`solver_numeric.solve_prepared` of sensor ``i`` in copies ``sub``
        with the others' entries ``base``, each copy refining from its own last solve."""
        prepared = self.rows(sub, i)
        prepared.remember = True
        memory = self.memory.get(i)
        if memory is not None:
            prepared.last = tuple(x[sub] for x in memory)
        out = solver_numeric.solve_prepared(prepared, base)
        chosen, th, x = prepared.last[:3]
        if memory is None:
            memory = (
                np.zeros((self.b,) + chosen.shape[1:], chosen.dtype),
                np.zeros((self.b,) + th.shape[1:]),
                np.zeros((self.b,) + x.shape[1:]),
                np.zeros(self.b, dtype=bool),
            )
            self.memory[i] = memory
        memory[0][sub], memory[1][sub], memory[2][sub] = chosen, th, x
        memory[3][sub] = True
        return out


def _one_sensor(targets, w_d, w_t, pose, det, occ, objects):
    """Return ``entries(pts, b, i)``: sensor ``i``'s entries in copy ``b`` at ``pts`` (P, 2)
    about every target, 3 x (P, K) (:func:`_entries` of P copies of the sensor; ``objects``
    the sensors' models of one's own, or None)."""

    def entries(pts: FloatArray, b: int, i: int) -> tuple[FloatArray, ...]:
        n = len(pts)
        row = (np.array([b]), np.full((1, n), i))
        cov = None if pose is None else pose[row]
        d = None if det is None else tuple(x[row] for x in det)
        layout = None if occ is None else occ[np.array([b])]
        own = None if objects is None else (objects[i],) * n
        out = _entries(pts[None], targets[[b]], w_d[row], w_t[row], cov, d, layout, own)
        return tuple(x[0].T for x in out)

    return entries


def _built_in(problem, pose, det, occ, team) -> bool:
    """Return whether the information is the built-in models' ``J0`` and the objective the
    trace (what :mod:`activetrack.baselines.gsr_command_kernel` computes)."""
    from activetrack.models.objective import is_trace  # noqa: PLC0415

    return (
        is_trace(problem.objective)
        and pose is None
        and det is None
        and occ is None
        and (team is None)
    )


def _sensor_at(targets, w_d, w_t, pose, det, occ, objects):
    """Return ``entries(pts, sub, i)``: sensor ``i``'s entries in copies ``sub`` at points
    ``pts`` (S, P, 2) about every target, 3 x (S, P, K) (:func:`_entries` with the P points
    as P copies of the sensor; ``objects`` the sensors' models of one's own, or None)."""

    def entries(pts: FloatArray, sub: np.ndarray, i: int) -> tuple[FloatArray, ...]:
        S, P = pts.shape[:2]
        wd = np.broadcast_to(w_d[sub, i][:, None], (S, P))
        wt = np.broadcast_to(w_t[sub, i][:, None], (S, P))
        cov = None if pose is None else np.broadcast_to(pose[sub, i][:, None], (S, P, 2, 2))
        d = None if det is None else tuple(np.broadcast_to(x[sub, i][:, None], (S, P)) for x in det)
        layout = None if occ is None else occ[sub]
        own = None if objects is None else (objects[i],) * P
        out = _entries(pts, targets[sub], wd, wt, cov, d, layout, own)
        return tuple(np.swapaxes(x, 1, 2) for x in out)

    return entries


def _warm_start(
    current: FloatArray, r: FloatArray, targets: FloatArray, rho: FloatArray
) -> FloatArray:
    """Return the current positions, each sensor inside a ``rho`` disk at its nearest
    feasible point (sensors that cannot move stay)."""
    each = np.broadcast_to(targets[:, None], (*current.shape[:-1], *targets.shape[-2:]))
    if feasible_set.contains(current, current, r, each, rho).all():
        return current.copy()  # the common case: project would return every point as is
    start = feasible_set.project(current, current, r, each, rho)
    return np.where((r > 0.0)[..., None], start, current)


def _entries(
    s: FloatArray,
    targets: FloatArray,
    w_d: FloatArray,
    w_t: FloatArray,
    pose: FloatArray | None,
    det: tuple[FloatArray, FloatArray] | None = None,
    occ: object = None,
    team: tuple | None = None,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return the sensors' (expected) information entries about every target, 3 x (B, K, M);
    ``team``: the M sensors' models of one's own (their information), None: built-in."""
    rel = s[:, None, :, :] - targets[:, :, None, :]  # (B, K, M, 2)
    cov = None if pose is None else pose[:, None]
    d = None if det is None else tuple(x[:, None] for x in det)
    if occ is not None:
        d = (*d, line_of_sight(s, targets, occ))
    if team is not None:
        return generic.entries(team, rel, 1.0 / w_d[:, None], 1.0 / w_t[:, None], cov, d)
    return sensor_models.information_entries(rel, w_d[:, None], w_t[:, None], cov, d)
