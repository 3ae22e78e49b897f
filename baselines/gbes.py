"""Grid-based exhaustive search (GBES), the benchmark planner of Section V.

Each free sensor's curve ADB (Lemma 3, :func:`activetrack.kinematics.geometry.facing_boundary`) is
discretized into points at most ``spacing`` apart (the paper uses pi/200 m) and the
combination of grid points minimizing the objective of eq. (17),
``tr((P11^{-1} + sum_i info_i)^{-1})``, is found exactly: the returned configuration is
the grid optimum (up to floating-point ties).

Speed comes from two facts. The information is additive, so every candidate's 2x2 entries
``(a, b, c)`` are computed once and a configuration costs a few additions and one call of
the problem's objective on the summed entries (``objective.of_entries``; for the trace,
``(A + C) / (AC - B^2)``). And the search is a branch and bound with exact bounds: each
sensor's candidates are grouped into blocks of ``block`` consecutive points, and since the
objective ``phi(Y)`` is convex on positive definite matrices, its tangent plane
(``objective.tangent``) at the sum ``Y0`` of the blocks' mean information is below it
everywhere; that linear bound separates over the sensors, so its minimum over a block
combination costs ``M * block`` operations instead of ``block^M``
(``_BlockSearch._bounds``). A block combination is skipped only when its bound exceeds the
best configuration found (with a 1e-10 relative margin for rounding), so nothing better
than the reported optimum is ever skipped. With ``prune=False`` every combination is
evaluated. Both paths work in memory-bounded batches.

The grid size is counted from the arc lengths before any grid is built
(:meth:`GBES.n_combinations`), so a grid over ``max_combinations`` is refused without
allocating it. A batched problem is searched copy by copy.

**Every planning problem.** With one target, Lemma 3 holds for every sensor model and
pose covariance (docs/sensor-models-design.md), so the grid stays on the curves ADB; the
candidates' entries are :func:`activetrack.models.sensor_models.information_entries` (the paper's
case keeps :func:`activetrack.models.objective.sensor_information`, bit-identical). With K > 1
targets the grid covers the whole boundary of each sensor's feasible set ``F_i`` (reach
disk minus the K ``rho`` disks, :func:`activetrack.kinematics.feasible_set.boundary_arcs`):
each arc (reach-circle pieces outside the ``rho`` disks, ``rho``-circle pieces inside the
reach disk) is discretized as above, its end points (the feasible circle-circle
intersections) included once. A candidate's features are the K targets' entries (3K
numbers) and a configuration's value is ``objective.of_targets(prior + sum)``. The bound
stays exact: the objective is convex in each target's ``Y_k``, so each target has its
tangent plane ``phi_k(Y_k) >= phi_k(Y0_k) + <G_k, Y_k - Y0_k>``. For a sum over targets
(``combine`` a sum: TRACE, LOGDET) the sum of the K planes is again linear and separates
over the sensors; for the largest target (WORST_TRACE, ``combine`` a max)
``max_k phi_k >= phi_j >= tangent_j`` for every ``j``, so the bound is the largest over
``j`` of target ``j``'s separable bound (``_TargetsSearch._bounds``).

**A kinematics of its own** (``problem.kinematics`` not all built-in
:class:`activetrack.Disk`): there are no arcs; each free sensor's grid is its kinematics'
:meth:`~activetrack.Kinematics.boundary` of its feasible set (reach set minus the K ``rho``
disks) at ``spacing``, exact repeats dropped
(:func:`activetrack.baselines._common.kinematic_boundaries`); the sizes are counted from
the built grids (a grid beyond the memory bound is refused from the radius before it is
built). A sensor whose feasible set is empty goes to its kinematics'
:meth:`~activetrack.Kinematics.project` of its position, one that cannot move stays. The
entries and the search are the ones above (``_target_features``: the problem's sensor
models, detection, occluders).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from activetrack.baselines import gsr_separation, separated
from activetrack.baselines._common import kinematic_boundaries, own_kinematics, sensor_modes
from activetrack.kinematics import geometry
from activetrack.kinematics.feasible_set import boundary_arcs
from activetrack.models import sensor_models
from activetrack.models.objective import TRACE, TraceObjective, sensor_information
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem

#: Relative margin of the bound test: a block combination is pruned only if its lower
#: bound exceeds the incumbent by this factor, which covers the rounding of both.
_PRUNE_RTOL = 1e-10
#: The most sensors GBES takes: its grid search broadcasts one array axis per sensor and
#: one more, and NumPy's arrays have at most 32 axes.
GBES_MAX_SENSORS = 31

#: Arc-length steps above this keep every grid point: the grid drops points closer than
#: 1e-12 m in both coordinates, and with 2 or more steps per arc (each at most pi radians)
#: consecutive points differ by at least ``step * 2 / (pi sqrt 2)`` in one coordinate.
_DISTINCT_STEP = 1e-11


@dataclass(frozen=True)
class GBESResult:
    """What one GBES search returns.

    Attributes:
        positions: the next absolute positions (M, 2).
        value: their objective, eq. (17).
        n_combinations: the size of the grid product that was searched.
        n_evaluated: how many configurations were actually evaluated (the rest were
            excluded by the exact bound).
        spacing: the grid spacing searched (m): ``GBES.spacing``, or wider where
            ``GBES.adapt`` widened it to fit ``max_combinations``.
    """

    positions: FloatArray
    value: float
    n_combinations: int
    n_evaluated: int
    spacing: float = math.nan


@dataclass
class GBES:
    """Grid-based exhaustive search over the curves ADB of all sensors (Section V).

    With K > 1 targets: over the boundaries of their feasible sets (module docstring).

    Attributes:
        spacing: largest distance between neighbouring grid points on a curve ADB (m);
            the paper uses ``pi / 200``.
        max_combinations: the largest grid (product of the sensors' grid sizes) searched.
        adapt: the rule for a problem whose grid at ``spacing`` is larger: True (the
            default) widens the spacing for that problem until the grid has at most
            ``max_combinations`` combinations (by about the root of the excess over the
            free sensors, recounted, at least 5% a round; no grid is built), so the
            default runs on every preset: the paper's three sensors keep ``pi / 200``, four
            sensors get a coarser grid, :attr:`GBESResult.spacing` says which; False
            refuses it (ValueError). A grid too large even with one step per arc is
            refused either way.
        block: grid points per block of the branch and bound (>= 1).
        prune: if False, evaluate every combination (no bounds; slower, same answer).
        batch_elements: configurations evaluated per vectorized batch (memory bound).
        last_result: the :class:`GBESResult` of the latest :meth:`plan` call.
    """

    #: Keeps the team rule ``d_sep`` itself (:mod:`activetrack.baselines.gsr_separation`).
    keeps_d_sep = True

    spacing: float = math.pi / 200.0
    max_combinations: float = 5e8
    block: int = 16
    prune: bool = True
    batch_elements: int = 1 << 17
    adapt: bool = True
    last_result: GBESResult | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if not (isinstance(self.spacing, (int, float)) and math.isfinite(self.spacing)) or (
            self.spacing <= 0
        ):
            raise ValueError(f"spacing must be a finite number > 0 (metres), got {self.spacing!r}")
        if not self.max_combinations >= 1:
            raise ValueError(f"max_combinations must be >= 1, got {self.max_combinations!r}")
        if not isinstance(self.adapt, (bool, np.bool_)):
            raise ValueError(f"adapt must be True or False, got {self.adapt!r}")
        for name in ("block", "batch_elements"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")

    # Grid ---------------------------------------------------------------------------------
    def candidates(self, problem: PlanningProblem) -> list[FloatArray]:
        """Return each sensor's grid of next positions relative to the target, (K_i, 2).

        With K > 1 targets: relative to the first, ``problem.targets[0]``. ``problem`` is
        single. A kinematics of its own: its boundary grids (module docstring).
        """
        if own_kinematics(problem):
            return self._kinematic_grids(problem)
        free, fixed_rel = sensor_modes(problem)
        if problem.n_targets > 1:
            return self._boundary_grids(problem, free, fixed_rel)
        c = problem.sensors - problem.targets[0]
        out = []
        for i in range(problem.n_sensors):
            if not free[i]:
                out.append(fixed_rel[i : i + 1].copy())
                continue
            arcs = geometry.facing_boundary(c[i], float(problem.r[i]), float(problem.rho[i]))
            pts = geometry.discretize(arcs, self.spacing)
            # Adjacent arcs share their end points (A and B of Fig. 3): drop the repeats.
            keep = np.ones(len(pts), dtype=bool)
            keep[1:] = np.any(np.abs(np.diff(pts, axis=0)) > 1e-12, axis=1)
            out.append(pts[keep])
        return out

    def grid_sizes(self, problem: PlanningProblem) -> list[int]:
        """Return each sensor's grid size, counted from the arc lengths (no grid is built).

        The same count as ``len`` of :meth:`candidates`: ``ceil(length / spacing) + 1``
        points per arc, less the shared end points of adjacent arcs (K > 1 targets:
        :meth:`_arc_plan`). ``problem`` is single. A kinematics of its own: the sizes of
        the built grids (:meth:`_kinematic_grids`).

        Raises:
            ValueError: (one target) ``spacing`` is below ``_DISTINCT_STEP`` (1e-11 m), near
                the 1e-12 m at which the grid drops repeated points, so its size cannot be
                counted.
        """
        if own_kinematics(problem):
            return [len(g) for g in self._kinematic_grids(problem)]
        free, _ = sensor_modes(problem)
        if problem.n_targets > 1:
            plans = [self._arc_plan(problem, i) if free[i] else None for i in range(len(free))]
            return [
                1 if plan is None else sum(n - 1 + k0 + k1 for _, n, k0, k1 in plan)
                for plan in plans
            ]
        c = problem.sensors - problem.targets[0]
        sizes = []
        for i in range(problem.n_sensors):
            if not free[i]:
                sizes.append(1)
                continue
            arcs = geometry.facing_boundary(c[i], float(problem.r[i]), float(problem.rho[i]))
            sizes.append(self._count(arcs))
        return sizes

    def _arc_plan(
        self, problem: PlanningProblem, i: int
    ) -> list[tuple[geometry.Arc, int, bool, bool]]:
        """Return sensor ``i``'s boundary arcs (K > 1) as ``(arc, n, keep_start, keep_end)``.

        Each arc gets ``n = max(1, ceil(length / spacing))`` steps: ``n - 1`` interior
        points, and its end points unless one lies within 1e-12 m (both coordinates) of an
        end point of an earlier arc or of its own start (a full circle). Counted from the
        end points alone, so the grid size is known before the grid is built.
        """
        arcs = boundary_arcs(
            problem.sensors[i], float(problem.r[i]), problem.targets, float(problem.rho[i])
        )
        seen: list[FloatArray] = []
        plan = []
        for arc in arcs:
            n = max(1, math.ceil(arc.length / self.spacing))
            start, end = arc.points(np.array([arc.t0, arc.t1]))
            keep0 = all(_distinct(start, q) for q in seen)
            seen.append(start)
            keep1 = all(_distinct(end, q) for q in seen)
            seen.append(end)
            plan.append((arc, n, keep0, keep1))
        return plan

    def _boundary_grids(
        self, problem: PlanningProblem, free: np.ndarray, fixed_rel: FloatArray
    ) -> list[FloatArray]:
        """Return :meth:`candidates` for K > 1 targets (see :meth:`_arc_plan`)."""
        origin = problem.targets[0]
        out = []
        for i in range(problem.n_sensors):
            if not free[i]:
                out.append(fixed_rel[i : i + 1].copy())
                continue
            pieces = []
            for arc, n, keep0, keep1 in self._arc_plan(problem, i):
                pts = arc.points(np.linspace(arc.t0, arc.t1, n + 1))
                pieces.append(pts[(0 if keep0 else 1) : (n + 1 if keep1 else n)])
            out.append(np.concatenate(pieces) - origin)
        return out

    def _kinematic_grids(
        self, problem: PlanningProblem, absolute: bool = False
    ) -> list[FloatArray]:
        """Return :meth:`candidates` when the sensors move by their own kinematics: each
        free sensor's boundary grid of its feasible set at ``spacing``, a fixed sensor's
        next position, relative to ``problem.targets[0]`` (or ``absolute``)."""
        free, fixed, boundary_of = kinematic_boundaries(problem, self.spacing)
        origin = 0.0 if absolute else problem.targets[0]
        return [
            boundary_of[(i,)] - origin if free[i] else fixed[i : i + 1] - origin
            for i in range(problem.n_sensors)
        ]

    def _count(self, arcs: list[geometry.Arc]) -> int:
        """Return the number of distinct points :meth:`candidates` keeps on ``arcs``."""
        count = 0
        prev_end = None
        for arc in arcs:
            n = max(1, int(np.ceil(arc.length / self.spacing)))
            ends = arc.points(np.array([arc.t0, arc.t1]))
            if n == 1:  # its two points may coincide (a tiny arc, or a full circle)
                count += 1 + int(_distinct(ends[0], ends[1]))
            elif arc.length / n > _DISTINCT_STEP:
                count += n + 1  # consecutive points differ by more than the dedup tolerance
            else:
                raise ValueError(
                    f"spacing must be at least {_DISTINCT_STEP:g} m for a countable grid, "
                    f"got {self.spacing!r}"
                )
            if prev_end is not None and not _distinct(prev_end, ends[0]):
                count -= 1  # adjacent arcs share their end point (A and B of Fig. 3)
            prev_end = ends[1]
        return count

    def n_combinations(self, problem: PlanningProblem) -> int:
        """Return the number of grid combinations of ``problem`` (product of grid sizes)."""
        return math.prod(self.grid_sizes(problem))

    def fitted(self, problem: PlanningProblem) -> GBES:
        """Return the search run on ``problem``: this one if its grid fits
        ``max_combinations`` (or ``adapt`` is False), else a copy whose spacing is widened
        just enough (``adapt``, see the class docstring; counted, no grid built)."""
        sizes = self.grid_sizes(problem)
        total = math.prod(sizes)
        out = self
        # Sizes scale about as 1 / spacing: widen by the root of the excess over the free
        # sensors, recount, and repeat (at least 5% a round) until the grid fits; past the
        # length of the longest arc the sizes stop falling and check() refuses the grid.
        for _ in range(400):
            if total <= self.max_combinations or not self.adapt:
                return out
            free = max(1, sum(n > 1 for n in sizes))
            factor = max(1.05, (total / self.max_combinations) ** (1.0 / free) * 1.01)
            out = dataclasses.replace(out, spacing=out.spacing * factor)
            sizes = out.grid_sizes(problem)
            total = math.prod(sizes)
        return out

    def check(self, problem: PlanningProblem) -> int:
        """Return the number of combinations of the grid searched on a single ``problem``
        (:meth:`fitted`), or raise the ValueError of a grid over ``max_combinations`` (the
        runners call this on a scenario's first problem, before any run)."""
        fit = self.fitted(problem)
        if fit is not self:
            return fit.check(problem)
        sizes = self.grid_sizes(problem)
        total = math.prod(sizes)
        if total > self.max_combinations:
            # Sizes scale as 1 / spacing: this spacing brings the product under the cap.
            free = max(1, sum(n > 1 for n in sizes))
            fits = self.spacing * (total / self.max_combinations) ** (1.0 / free) * 1.01
            raise ValueError(
                f"GBES grid has {total:.3g} combinations ({' x '.join(map(str, sizes))} points "
                f"at spacing {self.spacing:.4g} m), more than max_combinations="
                f"{self.max_combinations:.3g}; use a spacing of about {fits:.3g} m or more "
                "(GBES(spacing=...), or --gbes-spacing of activetrack simulate and evaluate), "
                "adapt=True, or raise max_combinations"
            )
        return total

    # Planning -----------------------------------------------------------------------------
    def plan(self, problem: PlanningProblem, rng: np.random.Generator | None = None) -> FloatArray:
        """Return the grid-optimal next absolute positions, ``batch_shape + (M, 2)``.

        A batch is searched copy by copy (``last_result`` is then the last copy's).
        """
        if not problem.batch_shape:
            return self.search(problem).positions
        out = np.empty(problem.sensors.shape)
        for b in np.ndindex(problem.batch_shape):
            out[b] = self.search(problem[b]).positions
        return out

    def search(self, problem: PlanningProblem) -> GBESResult:
        """Return the grid optimum of a single ``problem`` with search statistics.

        Raises:
            ValueError: the grid searched (:meth:`fitted`) has more than
                ``max_combinations`` combinations (counted before the grid is built); with
                ``prune``, the objective does not declare ``convex`` (the bound needs it),
                or (K > 1) its ``combine`` is neither a sum nor a max.
        """
        if problem.batch_shape:
            raise ValueError(
                f"search takes a single problem, got batch_shape {problem.batch_shape}; "
                "use plan, or index the problem"
            )
        if problem.n_sensors > GBES_MAX_SENSORS:
            raise ValueError(
                f"GBES searches every sensor's grid jointly, one array axis each: at most "
                f"{GBES_MAX_SENSORS} sensors, got {problem.n_sensors}; plan with GSR"
            )
        fit = self.fitted(problem)
        total = fit.check(problem)
        args = (self.block, self.batch_elements, self.prune)
        if own_kinematics(problem):  # the grid points themselves (absolute, feasible)
            grids = fit._kinematic_grids(problem, absolute=True)
            cands = [g - problem.targets[0] for g in grids]
        else:
            cands = fit.candidates(problem)
            grids = [c + problem.targets[0] for c in cands]
        # The team rule d_sep: only combinations whose pairs keep it (gsr_separation).
        d = gsr_separation.pair_matrix(problem)
        pairs = None if d is None else gsr_separation.pair_masks(d, problem.sensors, grids)
        idx, n_eval = _grid_search(problem, cands, *args, pairs=pairs)
        if idx is None:  # no combination keeps the rule: the best one, repaired
            idx, _ = _grid_search(problem, cands, *args)
            positions = separated.separate(
                problem, np.stack([grids[i][k] for i, k in enumerate(idx)]), problem.d_sep
            )
        else:
            positions = np.stack([grids[i][k] for i, k in enumerate(idx)])
        result = GBESResult(
            positions, float(problem.score(positions)), total, n_eval, float(fit.spacing)
        )
        self.last_result = result
        return result


def grid_optimum(
    problem: PlanningProblem,
    candidates: list[FloatArray],
    block: int = 16,
    batch_elements: int = 1 << 17,
    prune: bool = True,
) -> tuple[FloatArray, int]:
    """Return the best combination of per-sensor candidates and the evaluation count.

    ``candidates[i]`` (K_i, 2) are sensor ``i``'s candidate positions relative to the
    predicted target (with K targets: the first, ``problem.targets[0]``); the result
    (M, 2) is relative too. Exact over the candidates. ``problem`` is single.
    """
    idx, n_eval = _grid_search(problem, candidates, block, batch_elements, prune)
    return np.stack([candidates[i][k] for i, k in enumerate(idx)]), n_eval


def _grid_search(
    problem: PlanningProblem,
    candidates: list[FloatArray],
    block: int = 16,
    batch_elements: int = 1 << 17,
    prune: bool = True,
    pairs: list | None = None,
) -> tuple[tuple[int, ...] | None, int]:
    """Return :func:`grid_optimum` as each sensor's index into its candidates; with
    ``pairs`` (:func:`activetrack.baselines.gsr_separation.pair_masks`) only among the
    combinations they allow (None when there is none)."""
    if prune and not problem.objective.convex:
        raise ValueError(
            f"GBES's branch and bound needs an objective convex in each target's information "
            f"(its tangent plane a lower bound); objective {problem.objective.name!r} "
            f"({problem.objective!r}) does not declare convex = True: use prune=False "
            "(every combination) or another planner"
        )
    if problem.is_paper:  # the paper's arithmetic, unchanged
        feats = [
            _entries(sensor_information(p, problem.sigma_d2[i], problem.sigma_theta2[i]))
            for i, p in enumerate(candidates)
        ]
        search = _BlockSearch(
            feats, _entries(problem.prior_info), block, batch_elements, problem.objective
        )
    else:
        feats = _target_features(problem, candidates)  # per sensor (K_i, K, 3)
        prior = _entries(problem.prior_infos)  # (K, 3)
        if problem.n_targets == 1:
            feats = [f[:, 0] for f in feats]
            search = _BlockSearch(feats, prior[0], block, batch_elements, problem.objective)
        else:
            search = _TargetsSearch(feats, prior, block, batch_elements, problem.objective)
    search.pairs = pairs or []
    return search.run(prune)


def _target_features(problem: PlanningProblem, candidates: list[FloatArray]) -> list[FloatArray]:
    """Return every candidate's information entries about every target, (K_i, K, 3) each.

    :func:`activetrack.models.sensor_models.information_entries` at ``candidate - t_k`` with the
    sensor's weights, pose covariance and detection (candidates relative to
    ``problem.targets[0]``).
    """
    targets = problem.targets
    shift = targets[0] - targets  # (K, 2): candidate + shift_k = position - t_k
    w_d, w_t = problem.weights
    out = []
    det = problem.detect
    for i, p in enumerate(candidates):
        cov = None if problem.pose_cov is None else problem.pose_cov[i]
        rel = p[:, None, :] + shift[None, :, :]  # (K_i, K, 2)
        di = None if det is None else (det[0][i], det[1][i])  # the expected information
        if problem.occluders is not None:
            from activetrack.models.occluders import blocked  # noqa: PLC0415

            seen = ~blocked(p[:, None, :] + targets[0], targets[None], problem.occluders)
            di = (*di, seen)
        if problem.sensor_objects is not None:  # a model of one's own: its information
            J = problem.sensor_objects[i].information(rel, 1 / w_d[i], 1 / w_t[i], cov, di)
            out.append(np.stack([J[..., 0, 0], J[..., 0, 1], J[..., 1, 1]], -1))
            continue
        out.append(np.stack(sensor_models.information_entries(rel, w_d[i], w_t[i], cov, di), -1))
    return out


def _entries(info: FloatArray) -> FloatArray:
    """Return the independent entries ``(a, b, c)`` of 2x2 symmetric matrices, (..., 3)."""
    return np.stack([info[..., 0, 0], info[..., 0, 1], info[..., 1, 1]], -1)


def _distinct(p: FloatArray, q: FloatArray) -> bool:
    """Return whether :meth:`GBES.candidates` keeps both of consecutive points ``p``, ``q``."""
    return bool(np.any(np.abs(q - p) > 1e-12))


class _BlockSearch:
    """Exact branch and bound over block combinations (see the module docstring)."""

    def __init__(
        self,
        feats: list[FloatArray],
        prior: FloatArray,
        block: int,
        batch: int,
        objective: TraceObjective = TRACE,
    ):
        self.prior = prior
        self.objective = objective
        self.sizes = [len(f) for f in feats]
        self.bsize = [min(block, k) for k in self.sizes]
        # One block combination is evaluated whole (block^M configurations): with many
        # sensors, blocks shrink (largest first) until one fits the batch's memory bound.
        while math.prod(self.bsize) > max(batch, 1) and max(self.bsize) > 1:
            self.bsize[self.bsize.index(max(self.bsize))] -= 1
        self.nblocks = [-(-k // b) for k, b in zip(self.sizes, self.bsize, strict=True)]
        self.blocks = []  # per sensor 3 x (n_blocks, block) entries, last block padded by repeats
        self.means = []  # per sensor (n_blocks, 3): the blocks' mean information
        self.devs = []  # per sensor 3 x (n_blocks, block): entries minus their block's mean
        for f, b, nb in zip(feats, self.bsize, self.nblocks, strict=True):
            n_e = f.shape[-1]  # 3 entries per target
            pad = np.concatenate([f, np.repeat(f[-1:], nb * b - len(f), axis=0)])
            blk = pad.reshape(nb, b, n_e)
            mean = blk.mean(axis=1)
            # Entry-major copies (contiguous (n_blocks, block) arrays) vectorize best.
            self.blocks.append([np.ascontiguousarray(blk[..., e]) for e in range(n_e)])
            self.means.append(mean)
            self.devs.append(
                [np.ascontiguousarray(blk[..., e] - mean[:, e : e + 1]) for e in range(n_e)]
            )
        self.per_combo = math.prod(self.bsize)
        self.batch = max(1, batch // self.per_combo)
        self.n_block_combos = math.prod(self.nblocks)
        self.chunk = max(1, min(self.n_block_combos, 1 << 18))
        self.best = math.inf
        self.best_idx: tuple[int, ...] | None = None
        self.n_eval = 0
        self.pairs: list = []  # the team rule's allowed pairs (_grid_search)

    def run(self, prune: bool) -> tuple[tuple[int, ...], int]:
        """Return the optimal candidate index of every sensor and the evaluation count."""
        if not prune:
            for lo in range(0, self.n_block_combos, self.batch):
                hi = min(lo + self.batch, self.n_block_combos)
                self._evaluate(np.arange(lo, hi))
            return self.best_idx, self.n_eval
        # Pass 1: a good incumbent from the lowest-bound block combination of each chunk.
        cached = None
        seeds = []
        for lo in range(0, self.n_block_combos, self.chunk):
            flat, lb = self._bounds(lo)
            seeds.append(flat[np.argmin(lb)])
            if lo == 0 and len(flat) == self.n_block_combos:
                cached = (flat, lb)
        for start in range(0, len(seeds), self.batch):  # within the memory bound
            self._evaluate(np.asarray(seeds[start : start + self.batch]))
        # Pass 2: evaluate, in order of increasing bound, what the bound cannot exclude.
        for lo in range(0, self.n_block_combos, self.chunk):
            flat, lb = cached if cached is not None else self._bounds(lo)
            keep = lb <= self.best * (1.0 + _PRUNE_RTOL)
            flat, lb = flat[keep], lb[keep]
            order = np.argsort(lb, kind="stable")
            flat, lb = flat[order], lb[order]
            for start in range(0, len(flat), self.batch):
                if lb[start] > self.best * (1.0 + _PRUNE_RTOL):
                    break
                self._evaluate(flat[start : start + self.batch])
        return self.best_idx, self.n_eval

    def _bounds(self, lo: int) -> tuple[np.ndarray, FloatArray]:
        """Return block combinations ``lo ...`` (flat indices) and their lower bounds.

        The objective ``phi(Y)`` (``tr(Y^{-1})``) is convex on positive definite matrices,
        so at the sum ``Y0`` of the blocks' mean information, ``phi(Y) >= phi(Y0) + <grad,
        Y - Y0>`` (``objective.tangent``; ``grad = -Y0^{-2}`` for the trace). ``Y - Y0`` is
        a sum of per-sensor deviations from the block means, so the bound's minimum over a
        block combination is a sum of per-sensor minima over ``block`` points each,
        instead of ``block^M`` configurations.
        """
        flat = np.arange(lo, min(lo + self.chunk, self.n_block_combos))
        idx = np.unravel_index(flat, self.nblocks)
        y0 = self.prior + sum(mu[i] for mu, i in zip(self.means, idx, strict=True))
        lb, ga, gb, gc = self.objective.tangent(y0[:, 0], y0[:, 1], y0[:, 2])
        for dev, i in zip(self.devs, idx, strict=True):
            lin = ga[:, None] * dev[0][i] + gb[:, None] * dev[1][i] + gc[:, None] * dev[2][i]
            lb = lb + lin.min(axis=1)
        return flat, lb

    def _evaluate(self, flat: np.ndarray) -> None:
        """Evaluate every configuration of the block combinations ``flat``; update the best."""
        if len(flat) == 0:
            return
        idx = np.unravel_index(flat, self.nblocks)
        m = len(self.blocks)
        n_e = len(self.prior)
        tot = [None] * n_e
        for i in range(m):
            shape = [len(flat)] + [1] * m
            shape[1 + i] = self.bsize[i]
            for e in range(n_e):
                term = self.blocks[i][e][idx[i]].reshape(shape)
                tot[e] = term + self.prior[e] if tot[e] is None else tot[e] + term
        val = self._value(tot)
        if self.pairs:  # combinations that break the team rule d_sep are out
            cand = [
                np.minimum(idx[i][:, None] * b + np.arange(b), k - 1).reshape(
                    [len(flat)] + [b if j == i else 1 for j in range(m)]
                )
                for i, (b, k) in enumerate(zip(self.bsize, self.sizes, strict=True))
            ]
            for a, b, ok in self.pairs:
                val = np.where(ok[cand[a], cand[b]], val, np.inf)
        self.n_eval += val.size
        k = int(np.argmin(val))
        v = float(val.flat[k])
        if v < self.best:
            pos = np.unravel_index(k, val.shape)
            self.best = v
            self.best_idx = tuple(
                min(int(idx[i][pos[0]]) * self.bsize[i] + int(pos[1 + i]), self.sizes[i] - 1)
                for i in range(m)
            )

    def _value(self, tot: list[FloatArray]) -> FloatArray:
        """Return the objective of summed entries ``tot`` (a, b, c)."""
        return self.objective.of_entries(*tot)


class _TargetsSearch(_BlockSearch):
    """:class:`_BlockSearch` over K > 1 targets: features (K_i, K, 3), prior (K, 3)."""

    def __init__(
        self,
        feats: list[FloatArray],
        prior: FloatArray,
        block: int,
        batch: int,
        objective: TraceObjective = TRACE,
    ):
        self.n_targets = prior.shape[0]
        self.kind = _combine_kind(objective)
        flat = [f.reshape(len(f), -1) for f in feats]  # target-major: a_0 b_0 c_0 a_1 ...
        super().__init__(flat, prior.reshape(-1), block, batch, objective)

    def _bounds(self, lo: int) -> tuple[np.ndarray, FloatArray]:
        """Return block combinations ``lo ...`` (flat indices) and their lower bounds.

        Per target ``k`` the tangent plane at the blocks' mean information ``Y0_k``.
        A sum over targets: the sum of the planes, minimized sensor by sensor. A max:
        the largest over ``k`` of target ``k``'s plane minimized sensor by sensor.
        """
        flat = np.arange(lo, min(lo + self.chunk, self.n_block_combos))
        idx = np.unravel_index(flat, self.nblocks)
        y0 = self.prior + sum(mu[i] for mu, i in zip(self.means, idx, strict=True))
        planes = [
            self.objective.tangent(*y0[:, 3 * k : 3 * k + 3].T) for k in range(self.n_targets)
        ]
        if self.kind == "sum":
            lb = sum(p[0] for p in planes)
            for dev, i in zip(self.devs, idx, strict=True):
                lin = 0.0
                for k, (_, ga, gb, gc) in enumerate(planes):
                    da, db, dc = (dev[3 * k + e][i] for e in range(3))
                    lin = lin + (ga[:, None] * da + gb[:, None] * db + gc[:, None] * dc)
                lb = lb + lin.min(axis=1)
            return flat, lb
        bounds = []
        for k, (lb, ga, gb, gc) in enumerate(planes):
            for dev, i in zip(self.devs, idx, strict=True):
                da, db, dc = (dev[3 * k + e][i] for e in range(3))
                lb = lb + (ga[:, None] * da + gb[:, None] * db + gc[:, None] * dc).min(axis=1)
            bounds.append(lb)
        return flat, np.max(bounds, axis=0)

    def _value(self, tot: list[FloatArray]) -> FloatArray:
        """Return ``objective.combine`` of the K targets' values of summed entries ``tot``."""
        vals = [self.objective.of_entries(*tot[3 * k : 3 * k + 3]) for k in range(self.n_targets)]
        return self.objective.combine(np.stack(np.broadcast_arrays(*vals)), axis=0)


def _combine_kind(objective: TraceObjective) -> str:
    """Return "sum" or "max": how ``objective.combine`` reduces the targets' values.

    The bound of :class:`_TargetsSearch` is exact for these two only.

    Raises:
        ValueError: ``combine`` is neither (probed on the values 1, 2, 4).
    """
    got = float(objective.combine(np.array([1.0, 2.0, 4.0])))
    if got == 7.0:
        return "sum"
    if got == 4.0:
        return "max"
    raise ValueError(
        f"GBES needs an objective whose combine over targets is a sum or a max, got {objective!r}"
    )
