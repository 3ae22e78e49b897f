"""Candidate paths of a receding-horizon planner and the information along them.

A path is H positions of one sensor, each within reach of the previous one. The world's
rules apply at every step, exactly as the world applies them to a move
(:func:`activetrack.kinematics.sensor_motion.move_to`: outside every predicted target's ``rho``
disk,
eq. 14-16; with occluders :func:`activetrack.models.occluders.project_move`: no step ends in or
passes through one). :class:`PathModel` holds those rules and the sensors' measurement
models for one batch of planning problems; the paths here are built from it:

- constant headings at full speed (:func:`heading_paths`);
- target-relative waypoints, full speed towards ``t_k(h) + rho u`` (:func:`bearing_paths`);
- a previous plan shifted by one step (:func:`shifted_paths`).

The information a sensor contributes at a planned position is eq. (17)'s (with the sensor
models, pose uncertainty and, under limited sensing, its expected value: detection
probability, range and line of sight to the predicted target,
:func:`activetrack.models.sensor_models.information_entries`), one matrix per target.
"""

from __future__ import annotations

import math

import numpy as np

from activetrack.estimation import generic
from activetrack.kinematics.geometry import project_feasible
from activetrack.kinematics.sensor_motion import move_to
from activetrack.kinematics.team import TeamMotion, all_disks
from activetrack.models import sensor_models
from activetrack.models.objective import sensor_information
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem


class PathModel:
    """The rules and measurement models of a batch of B problems, flattened to (B, ...).

    ``targets`` arguments are the predicted target positions of one step, (B, K, 2), or of
    every step, (B, H, K, 2). The paper's problem (:attr:`PlanningProblem.is_paper`) keeps
    the paper's own arithmetic (one ``rho`` disk, eq. 17's information).
    """

    def __init__(self, problem: PlanningProblem) -> None:
        B = math.prod(problem.batch_shape)
        M = problem.n_sensors
        self.paper = problem.is_paper
        self.team = problem.sensor_objects  # models of one's own (their information), or None
        kin = problem.kinematics
        # A kinematics of its own: each step mended by it (the world's TeamMotion rule).
        self.motion = None if kin is None or all_disks(kin) else TeamMotion(kin)
        # A state beyond the position (a heading, a velocity): paths carry whole states
        # (B, M, ..., S), advanced by the kinematics each step, from the problem's.
        self.n_state = 2 if self.motion is None else self.motion.state_dim
        states = problem.sensor_states
        self.states0 = None if states is None else states.reshape(B, M, self.n_state)
        self.occluders = problem.occluders
        self.sigma_d2 = problem.sigma_d2.reshape(B, M)
        self.sigma_theta2 = problem.sigma_theta2.reshape(B, M)
        w_d, w_t = problem.weights
        self.w_d, self.w_t = w_d.reshape(B, M), w_t.reshape(B, M)
        self.pose_cov = None if problem.pose_cov is None else problem.pose_cov.reshape(B, M, 2, 2)
        detect = problem.detect
        self.detect = None if detect is None else tuple(d.reshape(B, M) for d in detect)

    def begin(self, start: FloatArray) -> FloatArray:
        """Return the states (B, M, S) of sensors at ``start`` (B, M, 2): ``start`` itself
        when S is 2, else the problem's states beyond the position appended."""
        if self.n_state == 2 or self.states0 is None:
            return start
        return np.concatenate([start, self.states0[..., 2:]], -1)

    def restated(self, points: FloatArray, states: FloatArray) -> FloatArray:
        """Return the states (B, M, S) after the moves from ``states`` to the reachable
        ``points`` (B, M, 2) (``points`` when S is 2)."""
        if self.n_state == 2:
            return points
        return self.motion.restate(points, states)

    def mend(
        self,
        prop: FloatArray,
        prev: FloatArray,
        targets: FloatArray,
        r: FloatArray,
        rho: FloatArray,
    ) -> FloatArray:
        """Return moves from ``prev`` towards ``prop`` (B, M, ..., 2) made legal.

        ``prop`` must be within reach ``r`` of ``prev`` (or is scaled onto it); ``r`` and
        ``rho`` broadcast against ``prev.shape[:-1]``; ``targets`` (B, K, 2) this step's.
        With a state beyond the position (S > 2) ``prev`` holds states (B, M, ..., S) and
        so does the result (the kinematics' next states; a move an occluder stops short
        keeps the rest of the state of its unstopped move).
        """
        B, K = targets.shape[0], targets.shape[-2]
        if self.n_state > 2:
            shape = prop.shape[:-1] + (self.n_state,)
            pr, pv = np.moveaxis(prop, 1, -2), np.moveaxis(np.broadcast_to(prev, shape), 1, -2)
            t = np.broadcast_to(targets.reshape((B,) + (1,) * (prev.ndim - 3) + (K, 2)),
                                pr.shape[:-2] + (K, 2))  # fmt: skip
            rh = np.moveaxis(np.broadcast_to(rho, prop.shape[:-1]), 1, -1)
            nxt = np.moveaxis(self.motion.move(True, pr, pv, t, rh)[2], -2, 1)
            if self.occluders is not None:
                from activetrack.models import occluders  # noqa: PLC0415

                start = np.broadcast_to(prev, shape)[..., :2]
                nxt = nxt.copy()
                nxt[..., :2] = occluders.project_move(start, nxt[..., :2], self.occluders, r)[0]
            return nxt
        if self.motion is not None:  # the sensor axis (1) last but one, as the world's
            pr, pv = np.moveaxis(prop, 1, -2), np.moveaxis(np.broadcast_to(prev, prop.shape), 1, -2)
            t = np.broadcast_to(targets.reshape((B,) + (1,) * (prev.ndim - 3) + (K, 2)),
                                pr.shape[:-2] + (K, 2))  # fmt: skip
            rh = np.moveaxis(np.broadcast_to(rho, prop.shape[:-1]), 1, -1)
            moved = np.moveaxis(self.motion.move_to(pr, pv, t, None, rh)[0], -2, 1)
        elif self.paper:
            t = targets[:, 0].reshape((B,) + (1,) * (prev.ndim - 2) + (2,))
            return project_feasible(prop - t, prev - t, r, rho) + t
        else:
            t = targets.reshape((B,) + (1,) * (prev.ndim - 3) + (K, 2))
            moved = move_to(prop, prev, t, r, rho)[0]
        if self.occluders is not None:
            from activetrack.models import occluders  # noqa: PLC0415 (occluded scenarios only)

            moved = occluders.project_move(prev, moved, self.occluders, r)[0]
        return moved

    def outside_rho(self, paths: FloatArray, targets: FloatArray, rho: FloatArray) -> np.ndarray:
        """Return whether each path (B, M, O, H, 2) keeps ``rho`` (B, M) from every predicted
        target (B, H, K, 2) at every step, (B, M, O) bool.

        Only occluders break it: a move they stop short (the nearest reachable point) can
        end inside a ``rho`` disk that :func:`activetrack.kinematics.sensor_motion.move_to` kept it
        out
        of; without occluders every mended step keeps ``rho`` wherever any reachable point
        does, and every path is kept.
        """
        if self.occluders is None:
            return np.ones(paths.shape[:3], dtype=bool)
        d = paths[..., None, :] - targets[:, None, None]  # (B, M, O, H, K, 2)
        near = np.hypot(d[..., 0], d[..., 1]).min(axis=-1)  # (B, M, O, H)
        tol = 1e-9 * (1.0 + np.abs(paths).max(axis=(2, 3, 4)))  # (B, M)
        return np.all(near >= (rho - tol)[:, :, None, None], axis=-1)

    def information(self, positions: FloatArray, targets: FloatArray) -> list[FloatArray]:
        """Return each target's per-sensor information at ``positions`` (B, M, O, H, 2).

        ``targets`` (B, H, K, 2) are step h's predicted positions. Returns K arrays
        (B, M, O, H, 2, 2): eq. (17)'s matrices, at their expected value under limited
        sensing.
        """
        B, M, O, H = positions.shape[:4]
        if self.paper:
            rel = positions - targets[:, None, None, :, 0]
            sd2, st2 = self.sigma_d2[:, :, None, None], self.sigma_theta2[:, :, None, None]
            return [sensor_information(rel, sd2, st2)]
        K = targets.shape[-2]
        # One row per (copy, option, step): the sensors (B, O, H, M, 2) against the step's
        # targets (B, 1, H, K, 2); the occluder layout stays on the first axis.
        pos = np.moveaxis(positions, 1, 3)
        tgt = targets[:, None]
        rel = pos[..., None, :, :] - tgt[..., :, None, :]  # (B, O, H, K, M, 2)
        row = (slice(None), None, None, None)  # a per-sensor (B, M) array against rel
        pose = None if self.pose_cov is None else self.pose_cov[row]
        detect = None
        if self.detect is not None:
            detect = tuple(d[row] for d in self.detect)
            if self.occluders is not None:
                from activetrack.models.occluders import line_of_sight  # noqa: PLC0415

                seen = line_of_sight(pos, np.broadcast_to(tgt, (B, O, H, K, 2)), self.occluders)
                detect = (*detect, seen)
        if self.team is not None:  # each model's information (the generic path)
            a, b, c = generic.entries(
                self.team, rel, 1.0 / self.w_d[row], 1.0 / self.w_t[row], pose, detect
            )
        else:
            a, b, c = sensor_models.information_entries(
                rel, self.w_d[row], self.w_t[row], pose, detect
            )  # (B, O, H, K, M)
        info = np.stack([np.stack([a, b], -1), np.stack([b, c], -1)], -2)
        info = np.moveaxis(info, 4, 1)  # (B, M, O, H, K, 2, 2)
        return [info[..., k, :, :] for k in range(K)]


def toward(prev: FloatArray, goal: FloatArray, r: FloatArray) -> FloatArray:
    """Return the point at most ``r`` from ``prev`` on the way to ``goal``."""
    d = goal - prev
    dist = np.hypot(d[..., 0], d[..., 1])
    scale = np.where(dist > r, r / np.where(dist > 0.0, dist, 1.0), 1.0)
    return prev + d * scale[..., None]


def heading_paths(
    model: PathModel, start: FloatArray, targets: FloatArray, r: FloatArray, rho: FloatArray,
    dirs: FloatArray,
) -> FloatArray:  # fmt: skip
    """Return constant-heading paths at full speed, (B, M, O, H, 2), mended each step.

    ``start`` (B, M, 2), ``targets`` (B, H, K, 2), ``r`` and ``rho`` (B, M), ``dirs``
    (O, 2) unit headings.
    """
    B, M = start.shape[:2]
    O, H = dirs.shape[0], targets.shape[1]
    out = np.empty((B, M, O, H, 2))
    begin = model.begin(start)
    prev = np.broadcast_to(begin[:, :, None], (B, M, O, begin.shape[-1]))
    step = r[:, :, None, None] * dirs
    rr, rh = r[:, :, None], rho[:, :, None]
    for h in range(H):
        prev = model.mend(prev[..., :2] + step, prev, targets[:, h], rr, rh)
        out[:, :, :, h] = prev[..., :2]
    return out


def bearing_paths(
    model: PathModel, start: FloatArray, targets: FloatArray, r: FloatArray, rho: FloatArray,
    dirs: FloatArray,
) -> FloatArray:  # fmt: skip
    """Return paths towards target-relative waypoints ``t_k(h) + rho u``, (B, M, K O, H, 2).

    Arguments as :func:`heading_paths`; one set of ``dirs`` about each target.
    """
    B, M = start.shape[:2]
    O, H, K = dirs.shape[0], targets.shape[1], targets.shape[2]
    out = np.empty((B, M, K * O, H, 2))
    begin = model.begin(start)
    prev = np.broadcast_to(begin[:, :, None], (B, M, K * O, begin.shape[-1]))
    offset = rho[:, :, None, None] * dirs  # (B, M, O, 2)
    rr, rh = r[:, :, None], rho[:, :, None]
    for h in range(H):
        goal = (targets[:, h, None, :, None] + offset[:, :, None]).reshape(B, M, K * O, 2)
        prev = model.mend(toward(prev[..., :2], goal, rr), prev, targets[:, h], rr, rh)
        out[:, :, :, h] = prev[..., :2]
    return out


def shifted_paths(
    model: PathModel, previous: FloatArray, start: FloatArray, targets: FloatArray,
    r: FloatArray, rho: FloatArray,
) -> FloatArray:  # fmt: skip
    """Return the previous plan (B, M, H', 2) shifted by one step and mended, (B, M, H, 2).

    Past its end the plan continues at its last step's velocity.
    """
    B, M, Hp = previous.shape[:3]
    H = targets.shape[1]
    goals = np.empty((B, M, H, 2))
    k = min(Hp - 1, H)
    goals[:, :, :k] = previous[:, :, 1 : 1 + k]
    last = previous[:, :, -1]
    vel = previous[:, :, -1] - previous[:, :, -2] if Hp > 1 else np.zeros_like(last)
    for h in range(k, H):
        last = last + vel
        goals[:, :, h] = last
    out = np.empty((B, M, H, 2))
    prev = model.begin(start)
    for h in range(H):
        prev = model.mend(toward(prev[..., :2], goals[:, :, h], r), prev, targets[:, h], r, rho)
        out[:, :, h] = prev[..., :2]
    return out
