"""A global numerical single-sensor solver: any measurement model, pose uncertainty, K targets.

The subproblem of Gauss-Seidel relaxation for sensor ``i`` with the other sensors folded
in (``docs/sensor-models-design.md``, section 4; the paper's eq. 22-24 generalized):

    minimize over s in F:  f(s) = objective.of_targets(a0 + ai(s), b0 + bi(s), c0 + ci(s))

where ``(a0, b0, c0)`` (..., K) are the entries of each target's information without
sensor ``i`` (prior plus the other sensors, eq. 12), ``(ai, bi, ci)(s)`` is sensor ``i``'s
information about each target (:func:`activetrack.models.sensor_models.information_entries`,
eq. 17 with the model's weights and the effective noise of an uncertain pose) and ``F``
is the feasible set of :mod:`activetrack.kinematics.feasible_set` (eq. 15-16 with K targets).

Method (deterministic, batched over leading axes without Python loops over the batch):

1. Candidates. On the reach circle a uniform grid of ``n_boundary`` angles plus, around
   the direction to each target, angles at offsets ``+-sigma {1/8, ..., 4}`` and 0, where
   ``sigma = max(| |t - p| - r |, rho) / r`` is the angular width of the target's well
   (the bearing information grows as the inverse squared distance, so where the reach
   circle passes near a target ``f`` varies on that scale); on each ``rho`` circle
   ``n_boundary`` uniform angles (its own target is at constant distance). Every pairwise
   circle intersection (the arcs' ends, where constrained optima sit). With K >= 2 a
   square grid of ``n_interior x n_interior`` points over the reach disk: the optimum
   need not lie on the boundary (Lemma 3 holds per target only); with K = 1 it does
   (Lemma 3 holds for every measurement model and pose covariance), so no interior grid.
   Infeasible candidates get the value ``+inf`` (ragged arc sets become masks). All
   candidates are evaluated in one call.
2. Refinement. From the best ``N_LOCAL_ARC`` local minima (no neighbour lower) of each
   circle, steps on the angle; from the best ``N_LOCAL_PLANE`` local minima of the
   interior grids, steps in the plane. Derivatives are central differences with a step
   ``FD_STEP`` of the local length scale (the distance to the nearest target, capped by
   the radius). Steps minimize a local model within a trust radius that starts at the
   grid spacing and shrinks by 4 after a rejected step: Newton's quadratic model for a
   smooth objective (TRACE, LOGDET); for an objective that takes the maximum over
   targets (WORST_TRACE, nonsmooth where two targets tie), the maximum of the per-target
   quadratic models, minimized over its kinks as in SQP for minimax problems. A step is
   accepted only when its point is feasible and strictly better. A start stops when its
   proposed step falls below ``CONVERGED`` of the local scale; for a smooth objective
   also after an accepted step shorter than ``SETTLED`` of it (Newton's next step would
   be of the order of its square, below the resolution of the difference quotients); and
   after ``MAX_MISSES`` steps leaving F (the optimum nearby lies on another piece of the
   boundary: a circle intersection, which is a candidate, or an arc, which has its own
   starts). In large batches the converged rows drop out.
   (The candidates: :mod:`activetrack.solvers._candidates`; the refinement:
   :mod:`activetrack.solvers._refine`.)
3. The answer is the best point evaluated (grid, intersections, accepted steps), so it is
   never worse than any candidate. When no candidate is feasible (``F`` empty), the
   answer is :func:`activetrack.kinematics.feasible_set.fallback` and its value. The returned value
   is ``f`` at the returned absolute position.

Gauss-Seidel relaxation solves the same sensor's subproblem once per sweep with another
base: :func:`prepare` computes everything that does not depend on the base once (the
candidates, their feasibility, the sensor's information there, the neighbour tables of
the local-minimum test), :func:`solve_prepared` the rest. A prepared batch with
``remember`` set (the relaxation's own) starts the next solve's refinement, in the rows
whose starts come from the same candidates, where the last one ended; the answer is then
the same local minima to the refinement's tolerance, not bit for bit.

Occluders (``occluders``): a candidate or refinement step counts as feasible only if the
sensor's straight move to it is not blocked (:func:`activetrack.models.occluders.blocked`: it
neither crosses nor ends in an occluder), so the answer lies in the reachable set the
world's moves keep to (:func:`activetrack.models.occluders.project_move`); the information about
a target is counted only where its predicted position is in sight. The objective jumps
across shadow boundaries, which the candidates resolve only to their spacing.

Special cases: ``r = 0`` returns the sensor's position (its only reachable point, feasible
or the fallback); a point at zero distance from a target gets no information about it
(the rule of :mod:`activetrack.models.sensor_models`); with ``rho = 0`` and a target within reach
an infimum that is not attained (the bearing information unbounded) is approached only
to the resolution of the candidates.

Computation is relative to the sensor's position (rounding scales with the reach, not
with the absolute coordinates); the returned positions are absolute.
"""

from __future__ import annotations

import numpy as np

from activetrack.kinematics import feasible_set
from activetrack.models.objective import TRACE, TraceObjective
from activetrack.models.occluders import blocked
from activetrack.models.sensor_models import information_entries
from activetrack.solvers._candidates import (
    _arc_candidates,
    _interior_candidates,
    _polar_candidates,
    _tables,
)
from activetrack.solvers._refine import _TINY, _refine
from activetrack.validation import FloatArray

#: Local minima refined per circle and in the interior.
N_LOCAL_ARC = 2
N_LOCAL_PLANE = 3


class _Problem:
    """The flattened batch (B rows), relative to each sensor's position, and ``f``."""

    def __init__(
        self, base, center, r, targets, rho, w_d, w_theta, pose_cov, objective, detect=None,
        occluders=None, models=None,
    ):  # fmt: skip
        """Flatten the batch; ``base=None`` leaves the base to :meth:`with_base`.

        ``models = (team, index)``: sensor models of one's own, ``team`` a tuple of
        :class:`activetrack.SensorModel` and ``index`` (batch shape) each row's model in it,
        whose :meth:`~activetrack.SensorModel.information` replaces the built-ins' entries
        (the weights are then ``1/sigma^2``); None: built-in models (the weights')."""
        center = np.asarray(center, dtype=np.float64)
        targets = np.asarray(targets, dtype=np.float64)
        r, rho = np.asarray(r, dtype=np.float64), np.asarray(rho, dtype=np.float64)
        w_d, w_theta = np.asarray(w_d, dtype=np.float64), np.asarray(w_theta, dtype=np.float64)
        k = targets.shape[-2]
        shapes = [
            center.shape[:-1], targets.shape[:-2], r.shape, rho.shape, w_d.shape, w_theta.shape,
        ]  # fmt: skip
        if base is not None:
            base = tuple(np.asarray(x, dtype=np.float64) for x in base)
            shapes += [x.shape[:-1] for x in base]
        if pose_cov is not None:
            pose_cov = np.asarray(pose_cov, dtype=np.float64)
            shapes.append(pose_cov.shape[:-2])
        if detect is not None:
            detect = tuple(np.asarray(x, dtype=np.float64) for x in detect)
            shapes += [x.shape for x in detect]
        self.shape = np.broadcast_shapes(*shapes)
        self.k = k
        flat = self._flat
        self.center = flat(center, (2,))
        if base is not None:
            self.a0, self.b0, self.c0 = (flat(x, (k,)) for x in base)
        self.t_abs = flat(targets, (k, 2))
        self.t = self.t_abs - self.center[:, None, :]
        self.r, self.rho = flat(r), flat(rho)
        self.wd = flat(w_d)[:, None, None]
        self.wt = flat(w_theta)[:, None, None]
        self.pc = None if pose_cov is None else flat(pose_cov, (2, 2))[:, None, None]
        self.pc_abs = None if pose_cov is None else self.pc[:, 0]
        self.objective = objective
        self.team = None if models is None else models[0]
        self.model_of = None if models is None else flat(np.asarray(models[1]))
        self.minimax = k > 1 and _is_max(objective)
        self.zero = np.zeros((len(self.r), 2))
        self.origins, self.radii = feasible_set.circles(self.zero, self.r, self.t, self.rho)
        # The line of sight (activetrack.models.occluders), or None; a layout per copy (batched
        # over the batch's first axis) is gathered to one per flattened row.
        if occluders is not None and occluders.batched:
            lead = np.arange(self.shape[0]).reshape((-1,) + (1,) * (len(self.shape) - 1))
            occluders = occluders[np.broadcast_to(lead, self.shape).ravel()]
        self.occ = occluders
        self.det = self.det_abs = None
        if occluders is not None and detect is None:
            detect = (np.ones(self.shape), np.full(self.shape, np.inf))
        if detect is not None:  # the expected information (p_detect, max_range^2)
            p_det, r2 = flat(detect[0]), flat(detect[1])
            self.det = (p_det[:, None, None], r2[:, None, None])
            self.det_abs = (p_det[:, None], r2[:, None])
            finite = np.isfinite(r2)
            if np.any(finite):
                # The objective jumps where a target leaves the range: candidates and arc
                # refinement on each range circle, just inside (0 where unlimited).
                rad = np.where(finite, np.sqrt(np.where(finite, r2, 0.0)) * (1.0 - 1e-9), 0.0)
                self.origins = np.concatenate([self.origins, self.t], axis=1)
                self.radii = np.concatenate(
                    [self.radii, np.broadcast_to(rad[:, None], self.t.shape[:-1])], axis=1
                )

    def _flat(self, x: FloatArray, tail: tuple[int, ...] = ()) -> FloatArray:
        """Return ``x`` broadcast to the batch and flattened, (B,) + tail."""
        if x.shape != self.shape + tail:
            x = np.broadcast_to(x, self.shape + tail)
        return x.reshape((int(np.prod(self.shape)),) + tail)

    def with_base(self, base: tuple[FloatArray, FloatArray, FloatArray]) -> _Problem:
        """Return this (flattened) batch with the base entries ``(a0, b0, c0)``, each (B, K)."""
        sub = object.__new__(_Problem)
        sub.__dict__.update(vars(self))
        sub.a0, sub.b0, sub.c0 = (np.asarray(x, dtype=np.float64) for x in base)
        return sub

    def entries(self, pts: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return the sensor's information entries at points (B, C, 2) (relative), 3 x (B, C, K)."""
        rel = pts[:, :, None, :] - self.t[:, None, :, :]
        det = self.det
        if self.occ is not None:  # no information about a target it cannot see
            seen = ~blocked((pts + self.center[:, None])[:, :, None, :],
                            self.t_abs[:, None, :, :], self.occ)  # fmt: skip
            det = (*det, seen)
        return self._information(rel, self.wd, self.wt, self.pc, det)

    def _information(self, rel, wd, wt, pc, det):  # noqa: ANN001, ANN202 (the rows' arrays)
        """Return :func:`information_entries` of the rows (leading axis B), or with models of
        one's own each row's model's information."""
        if self.team is None:
            return information_entries(rel, wd, wt, pc, det)
        out = np.zeros((3,) + rel.shape[:-1])
        for j, model in enumerate(self.team):
            rows = self.model_of == j
            if not np.any(rows):
                continue
            d = None if det is None else tuple(np.asarray(x)[rows] for x in det)
            cov = None if pc is None else pc[rows]
            J = model.information(rel[rows], 1.0 / wd[rows], 1.0 / wt[rows], cov, d)
            out[0][rows], out[1][rows], out[2][rows] = J[..., 0, 0], J[..., 0, 1], J[..., 1, 1]
        return out[0], out[1], out[2]

    def at_absolute(self, positions: FloatArray) -> FloatArray:
        """Return ``f`` at absolute positions (B, 2), (B,)."""
        rel = positions[:, None, :] - self.t_abs
        det = self.det_abs
        if self.occ is not None:
            det = (*det, ~blocked(positions[:, None, :], self.t_abs, self.occ))
        a, b, c = self._information(rel, self.wd[:, 0], self.wt[:, 0], self.pc_abs, det)
        return self.objective.of_targets(self.a0 + a, self.b0 + b, self.c0 + c)

    def take(self, rows: np.ndarray) -> _Problem:
        """Return the sub-batch of the given rows."""
        sub = object.__new__(_Problem)
        for key, value in vars(self).items():
            if key in ("det", "det_abs") and value is not None:  # (p_detect, range^2)
                value = tuple(v[rows] for v in value)
            elif key == "occ" and value is not None:  # a layout per row, or one shared
                value = value[rows]
            sub.__dict__[key] = value[rows] if isinstance(value, np.ndarray) else value
        return sub

    def f(self, pts: FloatArray) -> FloatArray:
        """Return the objective at points (B, C, 2) relative to the sensor, (B, C)."""
        return self.value(self.entries(pts))

    def value(self, info: tuple[FloatArray, FloatArray, FloatArray]) -> FloatArray:
        """Return the objective from the sensor's information entries 3 x (B, C, K), (B, C)."""
        a, b, c = info
        a0, b0, c0 = self.a0[:, None], self.b0[:, None], self.c0[:, None]
        return self.objective.of_targets(a0 + a, b0 + b, c0 + c)

    def pieces(self, pts: FloatArray) -> FloatArray:
        """Return the smooth pieces of ``f`` at points (B, C, 2): (B, C, P).

        For a maximum over targets (``WORST_TRACE``) the per-target values (P = K), whose
        maximum is ``f``; otherwise ``f`` itself (P = 1), smooth.
        """
        if not self.minimax:
            return self.f(pts)[..., None]
        a, b, c = self.entries(pts)
        a0, b0, c0 = self.a0[:, None], self.b0[:, None], self.c0[:, None]
        return self.objective.of_entries(a0 + a, b0 + b, c0 + c)

    def combine(self, pieces: FloatArray) -> FloatArray:
        """Return ``f`` from its pieces (..., P)."""
        return np.max(pieces, axis=-1) if self.minimax else pieces[..., 0]

    def feasible(self, pts: FloatArray) -> np.ndarray:
        """Return whether points (B, C, 2) lie in F (with the tolerance), (B, C); with
        occluders also reachable: the straight move there is not blocked."""
        ok = feasible_set.contains(
            pts, self.zero[:, None], self.r[:, None], self.t[:, None], self.rho[:, None]
        )
        if self.occ is not None and np.any(ok):
            c = self.center[:, None, :]
            ok &= ~blocked(np.broadcast_to(c, pts.shape), pts + c, self.occ)
        return ok

    def masked(self, pts: FloatArray) -> FloatArray:
        """Return ``f`` at points (B, C, 2), ``+inf`` where infeasible."""
        return np.where(self.feasible(pts), self.f(pts), np.inf)

    def scale(self, pts: FloatArray) -> FloatArray:
        """Return the distance from points (B, C, 2) to the nearest target, (B, C)."""
        e = pts[:, :, None, :] - self.t[:, None, :, :]
        return np.min(np.hypot(e[..., 0], e[..., 1]), axis=-1)


def _is_max(objective: TraceObjective) -> bool:
    """Return whether the objective combines its targets by their maximum (``WORST_TRACE``)."""
    probe = np.array([1.0, 3.0, 2.0])
    return bool(objective.combine(probe) == 3.0 and objective.combine(-probe) == -1.0)


def solve_sensor(
    base: tuple[FloatArray, FloatArray, FloatArray],
    center: FloatArray,
    r: FloatArray | float,
    targets: FloatArray,
    rho: FloatArray | float,
    w_d: FloatArray | float,
    w_theta: FloatArray | float,
    pose_cov: FloatArray | None = None,
    objective: TraceObjective = TRACE,
    *,
    n_boundary: int = 64,
    n_interior: int = 16,
    n_iter: int = 30,
    detect: tuple[FloatArray, FloatArray] | None = None,
    occluders: object = None,
) -> tuple[FloatArray, FloatArray]:
    """Return ``(positions (..., 2), values (...))``: the best next position of one sensor.

    Unchecked kernel (callers pass validated arrays), batched over leading axes ``...``.

    Args:
        base: ``(a0, b0, c0)``, each (..., K): every target's information entries without
            this sensor (SPD: prior plus the other sensors).
        center: the sensor's current position (..., 2).
        r: its reach (...), >= 0.
        targets: the K predicted target positions (..., K, 2).
        rho: its minimum distance to every target (...), >= 0.
        w_d, w_theta: its measurement weights (...)
        (:func:`activetrack.models.sensor_models.weights`).
        pose_cov: its pose covariance (..., 2, 2) PSD, or None.
        objective: a K-target objective of :mod:`activetrack.models.objective`.
        n_boundary: uniform angles per boundary circle.
        n_interior: points per side of the square interior grid.
        n_iter: refinement iterations (one batched evaluation each).
        detect: ``(p_detect, max_range**2)`` (...): the sensor's information counts at its
            expected value (:func:`activetrack.models.sensor_models.detection_factor`); None:
            always measured.
        occluders: an :class:`activetrack.models.occluders.Occluders` (shared, or batched over
            the first batch axis): no information about a target hidden from a point (the
            line of sight); None: an open plane. The
            objective then jumps across shadow boundaries, which the candidates resolve
            only to their spacing (no candidates are placed on the boundaries).

    Returns ``values = f(positions)``; positions lie in ``F`` (to the tolerance of
    :func:`activetrack.kinematics.feasible_set.contains`) unless ``F`` is empty (then the fallback).
    """
    p = _Problem(
        base, center, r, targets, rho, w_d, w_theta, pose_cov, objective, detect, occluders
    )
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        prepared = Prepared(p, n_boundary, n_interior, n_iter)
    positions, values = solve_prepared(prepared, (p.a0, p.b0, p.c0))
    return positions.reshape(p.shape + (2,)), values.reshape(p.shape)


class Prepared:
    """The part of a batch of subproblems that does not depend on the base ``(a0, b0, c0)``.

    The candidates (:func:`_arc_candidates`, the circle intersections, with K >= 2 the
    interior and polar grids), their feasibility, the sensor's information entries at them
    and the refinement start each would be depend only on the sensor's reach disk, the
    targets, ``rho``, the weights and the pose covariance, which Gauss-Seidel relaxation
    keeps fixed over its sweeps while the base (the other sensors' information) changes.
    Built once by :func:`prepare`, solved for any base by :func:`solve_prepared`.

    Candidates are laid out as [circle intersections, reach circle (sorted angles),
    ``rho`` circles, interior grid points inside the disk, polar grids]; ``neighbours``
    (C, 4) and the start ``groups`` (G, n) index them, with ``C`` standing for "none"
    (value ``+inf``).
    """

    def __init__(self, p: _Problem, n_boundary: int, n_interior: int, n_iter: int):
        b, k = len(p.r), p.k
        self.problem, self.n_iter = p, n_iter
        #: With ``remember``, each solve keeps its starts and where they ended (``last``);
        #: the next solve refines from there the rows whose starts are the same candidates
        #: (a caller may set ``last`` with a fourth entry, the rows that have a last solve).
        self.remember, self.last = False, None
        (o0, r0, th0, pts0), (o1, r1, th1, pts1) = _arc_candidates(p, n_boundary)
        n0, n1 = th0.shape[-1], th1.shape[-1]
        pts_v, ok_v = feasible_set.pair_points(p.origins, p.radii)
        nc = th1.shape[1]  # circles about the targets
        nv, na = pts_v.shape[1], n0 + nc * n1
        self.nv, self.na = nv, na
        # Arc candidates: circle origin, radius, angle and initial trust radius.
        self.arc_o = np.concatenate([np.repeat(o0, n0, axis=1), np.repeat(o1, n1, axis=1)], axis=1)
        self.arc_r = np.concatenate([np.repeat(r0, n0, axis=1), np.repeat(r1, n1, axis=1)], axis=1)
        self.arc_th = np.concatenate([th0.reshape(b, -1), th1.reshape(b, -1)], axis=1)
        pts_a = np.concatenate([pts0.reshape(b, -1, 2), pts1.reshape(b, -1, 2)], axis=1)
        # The trust radius of an arc start: the larger gap to a neighbouring angle, at
        # least the uniform spacing in units of the local scale (repeated angles: gap 0).
        reach = []
        for th in (th0, th1):
            gap = np.diff(th, axis=-1, append=th[..., :1] + 2.0 * np.pi)
            reach.append(np.maximum(gap, np.roll(gap, 1, axis=-1)).reshape(b, -1))
        local_scale = p.scale(pts_a) / np.maximum(self.arc_r, _TINY)
        self.arc_d = np.maximum(
            np.concatenate(reach, axis=1),
            (2.0 * np.pi / n_boundary) * np.minimum(local_scale, 1.0),
        )
        parts = [pts_v, pts_a]
        self.interior = k > 1 and n_interior > 0
        self.plane_x = np.zeros((b, 0, 2))
        self.plane_d = np.zeros((b, 0))
        if self.interior:
            grid, inside, spacing = _interior_candidates(p, n_interior)
            polar, polar_step = _polar_candidates(p)
            ng = len(inside)
            self.plane_x = np.concatenate([grid[:, inside], polar.reshape(b, -1, 2)], axis=1)
            self.plane_d = np.concatenate(
                [
                    np.broadcast_to(spacing[:, None], (b, ng)),
                    np.broadcast_to(polar_step[..., None], polar.shape[:-1]).reshape(b, -1),
                ],
                axis=1,
            )
            parts.append(self.plane_x)
        self.pts = np.concatenate(parts, axis=1)
        self.neighbours, self.groups, self.arc_groups = _tables(
            nv, n0, n1, nc, k, n_interior if self.interior else 0
        )
        # Start attributes indexed by candidate (and "none", the last index).
        c = self.pts.shape[1]
        at = {"arc_o": (nv, 2), "arc_r": (nv, 0), "arc_th": (nv, 0), "arc_d": (nv, 0)}
        if self.interior:
            at.update(plane_x=(nv + na, 2), plane_d=(nv + na, 0))
        for key, (first, width) in at.items():
            value = getattr(self, key)
            full = np.zeros((b, c + 1) + ((width,) if width else ()))
            full[:, first : first + value.shape[1]] = value
            setattr(self, key, full)
        feasible = p.feasible(self.pts)
        feasible[:, :nv] &= ok_v
        self.feasible = feasible
        self.info = p.entries(self.pts)

    def take(self, rows: np.ndarray) -> Prepared:
        """Return the sub-batch of the given rows."""
        sub = object.__new__(Prepared)
        sub.__dict__.update(vars(self))
        sub.problem = self.problem.take(rows)
        sub.last, sub.remember = None, False
        for key in ("arc_o", "arc_r", "arc_th", "arc_d", "plane_x", "plane_d", "pts", "feasible"):
            setattr(sub, key, getattr(self, key)[rows])
        sub.info = tuple(x[rows] for x in self.info)
        return sub

    def starts(self, vals: FloatArray) -> tuple[tuple[FloatArray, ...], tuple[FloatArray, ...]]:
        """Return the refinement starts for candidate values ``vals`` (B, C).

        ``N_LOCAL_ARC`` best local minima (no neighbour lower) of each circle and
        ``N_LOCAL_PLANE`` of the square and of the polar grids, as
        ``arcs = (origin, radius, theta, value, delta)`` and ``plane = (x, value, delta)``.
        """
        b = len(vals)
        ext = np.concatenate([vals, np.full((b, 1), np.inf)], axis=1)
        local = vals <= ext[:, self.neighbours].min(axis=-1)
        ext[:, :-1] = np.where(local & np.isfinite(vals), vals, np.inf)
        grouped = ext[:, self.groups]  # (B, G, n)
        order = np.argsort(grouped, axis=-1, kind="stable")[..., :N_LOCAL_PLANE]
        idx = self.groups[np.arange(len(self.groups))[:, None], order]  # (B, G, m)
        rows = np.arange(b)[:, None]
        value = grouped[rows[..., None], np.arange(len(self.groups))[:, None], order]
        ga = self.arc_groups
        self.chosen = idx
        ia = idx[:, :ga, :N_LOCAL_ARC].reshape(b, -1)
        fa = value[:, :ga, :N_LOCAL_ARC].reshape(b, -1)
        arcs = (
            self.arc_o[rows, ia], self.arc_r[rows, ia], self.arc_th[rows, ia], fa,
            self.arc_d[rows, ia],
        )  # fmt: skip
        if not self.interior:
            empty = np.zeros((b, 0))
            return arcs, (np.zeros((b, 0, 2)), empty, empty)
        ip = idx[:, ga:].reshape(b, -1)
        plane = (self.plane_x[rows, ip], value[:, ga:].reshape(b, -1), self.plane_d[rows, ip])
        return arcs, plane


def prepare(
    center: FloatArray,
    r: FloatArray,
    targets: FloatArray,
    rho: FloatArray,
    w_d: FloatArray,
    w_theta: FloatArray,
    pose_cov: FloatArray | None = None,
    objective: TraceObjective = TRACE,
    *,
    n_boundary: int = 64,
    n_interior: int = 16,
    n_iter: int = 30,
    detect: tuple[FloatArray, FloatArray] | None = None,
    occluders: object = None,
    models: tuple | None = None,
) -> Prepared:
    """Return the base-independent part of a batch of subproblems, flattened to B rows.

    Arguments as :func:`solve_sensor` without ``base`` (their leading axes broadcast to
    the batch shape, flattened row-major); ``models`` as :class:`_Problem`'s.
    """
    p = _Problem(
        None,
        center,
        r,
        targets,
        rho,
        w_d,
        w_theta,
        pose_cov,
        objective,
        detect,
        occluders,
        models,
    )
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return Prepared(p, n_boundary, n_interior, n_iter)


def solve_prepared(
    prepared: Prepared, base: tuple[FloatArray, FloatArray, FloatArray]
) -> tuple[FloatArray, FloatArray]:
    """Return ``(positions (B, 2), values (B,))`` of :func:`solve_sensor` for a prepared batch.

    ``base`` ``(a0, b0, c0)``, each (B, K), for the rows of ``prepared``.
    """
    p = prepared.problem.with_base(base)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        pts, _ = _solve(p, prepared)
    positions = pts + p.center
    # The value at the returned (absolute) positions, as a caller computes it: it differs
    # from the value found in relative coordinates by the rounding of the addition.
    return positions, p.at_absolute(positions)


def _solve(p: _Problem, cand: Prepared) -> tuple[FloatArray, FloatArray]:
    """Return the best points (B, 2) relative to the sensors and their values (B,).

    All candidates (arcs, circle intersections, interior grid) are evaluated in one call.
    With one target there is no interior grid: the optimum lies on the boundary (Lemma 3
    holds for every measurement model and pose covariance, ``docs/sensor-models-design.md``
    section 5).
    """
    vals = np.where(cand.feasible, p.value(cand.info), np.inf)
    arcs, plane = cand.starts(vals)
    chosen = cand.chosen
    if cand.last is not None:
        # A repeated solve (Gauss-Seidel's next sweep, the base changed a little): rows
        # whose starts come from the same candidates refine from where those ended.
        same = np.all(chosen == cand.last[0], axis=(1, 2))
        if len(cand.last) > 3:  # per row: whether it was solved before
            same &= cand.last[3]
        arcs = arcs[:2] + (np.where(same[:, None], cand.last[1], arcs[2]),) + arcs[3:]
        plane = (np.where(same[:, None, None], cand.last[2], plane[0]),) + plane[1:]
    pts_r, vals_r, th_r, x_r = _refine(p, arcs, plane, cand.n_iter)
    if cand.remember:
        cand.last = (chosen, th_r, x_r)
    all_pts = np.concatenate([pts_r, cand.pts], axis=1)
    all_vals = np.concatenate([vals_r, vals], axis=1)
    best = np.argmin(all_vals, axis=1)
    rows = np.arange(len(best))
    s, value = all_pts[rows, best], all_vals[rows, best]
    empty = ~np.isfinite(value)
    if np.any(empty):  # F empty: no candidate is feasible
        fb = feasible_set.fallback(p.zero, p.r, p.t, p.rho)
        s = np.where(empty[:, None], fb, s)
        value = np.where(empty, p.f(s[:, None])[:, 0], value)
    return s, value
