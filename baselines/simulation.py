"""Closed-loop simulation runner and Monte Carlo evaluation of planners (Section V).

One run is a planner driving the core's closed loop, :class:`activetrack.world.World`
(one copy): at every step the world's planning problem of eq. (15)-(17) (from the
prediction of eq. 3), the planner's next positions, and the world's step (move the
sensors, move the true target by eq. 2, measure by eq. 4, update by eq. 11, predict).

Random streams: the world (initial conditions, process and measurement noise) draws from
``np.random.default_rng(seed)`` — ``n + 2M`` standard normals per step, the same draws the
environments make from the same seed — and the planner from a separate
``np.random.default_rng([seed, 1])``, so a planner's own randomness never shifts the world's.

Metrics per step (steps 1..n_steps, posteriors): trace of the position covariance (the
objective of eq. 17), position error, position NEES and planning time; per run: mean
trace, RMSE and mean NEES.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from activetrack.baselines.rollout import PlannerAgent, Recorder, Step, rollout
from activetrack.validation import FloatArray
from activetrack.world import World
from activetrack.world.problem import Planner, PlanningProblem
from activetrack.world.scenarios import Scenario


@dataclass(frozen=True, eq=False)
class RunRecord:
    """One closed-loop run.

    Per-step arrays have one entry per completed step (``n_steps`` unless the run stopped
    early on ``scenario.max_trace``); trajectories have one more (step 0 first).

    Attributes:
        seed: the run's seed.
        trace: trace of the posterior position covariance ``P(k|k)_11``.
        error: position error ``||p_T(k) - p_T_hat(k|k)||``.
        nees: position NEES ``e^T P(k|k)_11^{-1} e``.
        plan_time: wall-clock planning time (s).
        violation: largest constraint violation of the planned positions (m; 0 = feasible).
        true_states, estimates: (K + 1, n) true target states and posterior estimates.
        sensors: (K + 1, M, 2) sensor positions.
        position_covs: (K + 1, 2, 2) posterior position covariances.
        terminated: whether the run stopped early because the trace exceeded ``max_trace``.
        seen: (steps, K) whether some sensor measured each target at each step; None
            with unlimited sensing (every sensor measures every target every step).
        present: (steps, K) whether each slot held a target (targets that appear and
            leave, ``births``); None otherwise (every target at every step).
    """

    seed: int
    trace: FloatArray
    error: FloatArray
    nees: FloatArray
    plan_time: FloatArray
    violation: FloatArray
    true_states: FloatArray
    estimates: FloatArray
    sensors: FloatArray
    position_covs: FloatArray
    terminated: bool = False
    seen: np.ndarray | None = None
    present: np.ndarray | None = None

    @property
    def mean_trace(self) -> float:
        """Return the mean posterior position trace over the run's steps."""
        return float(np.mean(self.trace))

    @property
    def rmse(self) -> float:
        """Return the root mean square position error over the run's steps."""
        return float(np.sqrt(np.mean(self.error**2)))

    @property
    def mean_nees(self) -> float:
        """Return the mean position NEES over the run's steps with a finite one (2 for a
        consistent filter; with ``births`` a step holding no track of a present target has
        none), NaN if no step has one."""
        ok = np.isfinite(self.nees)
        return float(np.mean(self.nees[ok])) if ok.any() else float("nan")

    @property
    def no_detection(self) -> float:
        """Return the fraction of steps in which no sensor measured a target (mean over
        targets; 0 with unlimited sensing)."""
        return 0.0 if self.seen is None else detection_gaps(self.seen, self.present)[0]

    @property
    def longest_gap(self) -> int:
        """Return the longest run of consecutive steps in which no sensor measured a target
        (the longest over targets; 0 with unlimited sensing)."""
        return 0 if self.seen is None else detection_gaps(self.seen, self.present)[1]


def detection_gaps(seen: np.ndarray, present: np.ndarray | None = None) -> tuple[float, int]:
    """Return ``(fraction, longest)`` for ``seen`` (steps, K): the fraction of (step, target)
    pairs in which no sensor measured the target, and the longest run of consecutive steps
    in which some one target went unmeasured.

    ``present`` (the same shape; None: every target at every step) restricts both to the
    pairs in which the target was there: with targets that appear and leave, an empty slot
    is not a missed detection, and a step without the target ends a run. No present pair
    gives ``(0.0, 0)``. (A slot a target leaves and another enters in the same step, which
    happens only when the first was never tracked, continues one run.)
    """
    seen = np.asarray(seen, dtype=bool).reshape(len(seen), -1)
    there = np.ones_like(seen) if present is None else np.asarray(present, bool)
    if there.reshape(len(there), -1).shape != seen.shape:
        raise ValueError(
            f"present must have the shape of seen {seen.shape}, got {np.shape(present)}"
        )
    there = there.reshape(seen.shape)
    if not there.any():
        return 0.0, 0
    missed = ~seen & there
    longest = 0
    for column in missed.T:
        # Lengths of the runs of True: differences of the run boundaries.
        edges = np.flatnonzero(np.diff(np.concatenate([[0], column.astype(np.int8), [0]])))
        if edges.size:
            longest = max(longest, int(np.max(edges[1::2] - edges[::2])))
    return float(missed.sum() / there.sum()), longest


class _RunRecorder(Recorder):
    """Keeps one serial run's :class:`RunRecord` fields (copy 0, read unbatched)."""

    def __init__(self, limited: bool) -> None:
        self.limited = limited

    def reset(self, world: World, copy: int, episode: int) -> None:
        g = world.get
        self.true_states, self.estimates = [g("x_true", 0).copy()], [g("x_hat", 0).copy()]
        self.sensors, self.covs = [g("sensors", 0).copy()], [g("P", 0)[..., :2, :2].copy()]
        self.trace, self.error, self.nees, self.plan_time, self.violation, self.seen = (
            [], [], [], [], [], [])  # fmt: skip
        self.present: list[np.ndarray] = []  # with births: the slots holding a target

    def step(self, step: Step) -> None:
        world, g = step.world, step.world.get
        self.plan_time.append(step.seconds)
        self.violation.append(float(np.max(step.problem.violation(step.positions))))
        self.trace.append(float(g("trace", 0)))
        self.error.append(float(world.position_error(0)))
        self.nees.append(float(world.position_nees(0)))
        if self.limited:
            self.seen.append(g("detected", 0).any(axis=-1))
        if world.scenario.births is not None:
            self.present.append(world.present[0].copy())
        self.true_states.append(g("x_true", 0).copy())
        self.estimates.append(g("x_hat", 0).copy())
        self.sensors.append(g("sensors", 0).copy())
        self.covs.append(g("P", 0)[..., :2, :2].copy())

    def record(self, seed: int, terminated: bool) -> RunRecord:
        return RunRecord(
            seed=int(seed),
            trace=np.array(self.trace),
            error=np.array(self.error),
            nees=np.array(self.nees),
            plan_time=np.array(self.plan_time),
            violation=np.array(self.violation),
            true_states=np.array(self.true_states),
            estimates=np.array(self.estimates),
            sensors=np.array(self.sensors),
            position_covs=np.array(self.covs),
            terminated=terminated,
            seen=np.array(self.seen) if self.limited else None,
            present=np.array(self.present) if self.present else None,
        )


def simulate(scenario: Scenario, planner: Planner, seed: int) -> RunRecord:
    """Return one closed-loop run of ``planner`` on ``scenario`` with world seed ``seed``
    (the rollout of :mod:`activetrack.baselines.rollout`, serial)."""
    world = World(scenario, 1)
    recorder = _RunRecorder(world.scenario.limited_sensing)
    rollout(world, PlannerAgent(planner), [seed], recorder)
    return recorder.record(seed, bool(world.get("terminated", 0)))


def check_planners(planners: Iterable[Any], problem: PlanningProblem) -> None:
    """Call ``check(problem)`` of every planner that has one (GBES: its grid's size) on the
    first problem of a run, so that settings the scenario cannot take fail before any run."""
    for planner in planners:
        check = getattr(planner, "check", None)
        if callable(check):
            check(problem)


def warm_up(planner: Planner, problem: PlanningProblem) -> float:
    """Plan once on ``problem``, untimed in the study, and return the seconds it took.

    The first call of a planner in a process compiles its kernels (or loads them from
    numba's cache: up to a minute and more on a fresh clone), which would otherwise be
    counted as that step's planning time. The plan is thrown away and drawn with its own
    generator, so the runs' results do not change (planners are functions of the problem
    and the generator they are given).
    """
    t0 = time.perf_counter()
    planner.plan(problem, np.random.default_rng(0))
    return time.perf_counter() - t0


def mean_ci(values: FloatArray, level: float = 0.95) -> tuple[float, float, float]:
    """Return ``(mean, low, high)``: the mean and its Student-t confidence interval."""
    from scipy import stats  # lazy: scipy.stats costs ~0.5 s at import

    v = np.asarray(values, dtype=np.float64)
    mean = float(np.mean(v))
    if v.size < 2:
        return mean, mean, mean
    half = float(stats.t.ppf(0.5 + level / 2, v.size - 1) * np.std(v, ddof=1) / np.sqrt(v.size))
    return mean, mean - half, mean + half


@dataclass(eq=False)
class MonteCarloResult:
    """Per-run statistics of one planner over seeds ``seed, seed + 1, ...``.

    Attributes:
        name: the planner's label.
        seeds: the runs' seeds.
        mean_trace, rmse, nees: per-run mean trace, RMSE and mean NEES, shape (runs,).
        plan_times: every step's planning time (s), all runs concatenated.
        max_violation: largest constraint violation over all steps and runs (m).
        n_terminated: runs stopped early on ``max_trace``.
        records: the kept :class:`RunRecord` objects (by default the first run's only).
        no_detection, longest_gap: per-run fraction of steps without a measurement of a
            target and longest such run (:func:`detection_gaps`); None with unlimited
            sensing.
        traces: every run's trace of ``P(k|k)_11`` per step, shape (runs, T) (NaN after
            a run that ended early on ``max_trace``): the study's comparison over time.
        warmup_time: the untimed first plan before the runs (s): its kernels compiled or
            loaded from the cache (:func:`warm_up`), so that ``plan_times`` time planning
            only; None when Ray's workers ran the study (each warms itself).
    """

    name: str
    seeds: list[int]
    mean_trace: FloatArray
    rmse: FloatArray
    nees: FloatArray
    plan_times: FloatArray
    max_violation: float
    n_terminated: int
    records: list[RunRecord] = field(default_factory=list)
    no_detection: FloatArray | None = None
    longest_gap: np.ndarray | None = None
    traces: FloatArray | None = None
    warmup_time: float | None = None

    def summary(self, reference: MonteCarloResult | None = None) -> dict[str, Any]:
        """Return JSON-friendly summary statistics with their 95% intervals.

        The means' intervals are Student-t ones (:func:`mean_ci`). The reporting protocol's
        statistics of the runs' mean traces (:mod:`activetrack.baselines.protocol`):
        ``iqm_trace`` and ``median_trace`` with percentile bootstrap intervals and, given a
        ``reference`` on the same seeds (GSR), ``ratio_to_gsr`` and ``iqm_ratio_to_gsr``
        with paired bootstrap intervals (None where a run has no finite trace).
        """
        from activetrack.baselines import protocol

        out: dict[str, Any] = {"runs": len(self.seeds)}
        for key, values in (
            ("mean_trace", self.mean_trace),
            ("rmse", self.rmse),
            ("nees", self.nees),
        ):
            values = np.asarray(values)[np.isfinite(values)]  # NaN: no track held (births)
            if values.size == 0:  # written as null, not as NaN (not JSON)
                out[key], out[f"{key}_ci95"] = None, [None, None]
                continue
            mean, lo, hi = mean_ci(values)
            out[key] = mean
            out[f"{key}_ci95"] = [lo, hi]
        traces = np.asarray(self.mean_trace, dtype=float)
        finite = traces.size > 0 and bool(np.all(np.isfinite(traces)))
        for stat in ("iqm", "median"):
            point, lo, hi = protocol.interval(traces, stat) if finite else (None, None, None)
            out[f"{stat}_trace"], out[f"{stat}_trace_ci95"] = point, [lo, hi]
        for key, stat in (("ratio_to_gsr", "mean"), ("iqm_ratio_to_gsr", "iqm")):
            out[key], out[f"{key}_ci95"] = None, [None, None]
            if reference is None or not finite or reference.seeds != self.seeds:
                continue
            ref = np.asarray(reference.mean_trace, dtype=float)
            if np.all(np.isfinite(ref)) and protocol.STATISTICS[stat](ref) > 0:
                ratio, lo, hi = protocol.paired_ratio_interval(traces, ref, stat)
                out[key], out[f"{key}_ci95"] = ratio, [lo, hi]
        out["plan_time_ms_median"] = float(np.median(self.plan_times) * 1e3)
        out["plan_time_ms_mean"] = float(np.mean(self.plan_times) * 1e3)
        out["plan_time_ms_max"] = float(np.max(self.plan_times) * 1e3)
        # The first plan of a fresh process compiles the kernels (or loads them from
        # numba's cache): timed apart, not as a plan.
        warm = self.warmup_time
        out["plan_time_warmup_ms"] = None if warm is None else float(warm * 1e3)
        out["max_violation"] = self.max_violation
        out["n_terminated"] = self.n_terminated
        # Consecutive seeds, both ends included (runs = last - first + 1).
        out["seed_range"] = {"first": self.seeds[0], "last": self.seeds[-1]}
        if self.no_detection is not None:
            out["no_detection"] = float(np.mean(self.no_detection))
            out["longest_gap"] = int(np.max(self.longest_gap))
        return out


def run_monte_carlo(
    scenario: Scenario,
    planners: Mapping[str, Planner],
    runs: int,
    seed: int = 0,
    *,
    progress: bool = True,
    keep_records: int = 1,
    workers: int = 1,
    address: str | None = None,
) -> dict[str, MonteCarloResult]:
    """Return each planner's :class:`MonteCarloResult` over seeds ``seed .. seed + runs - 1``.

    All planners face the same seeds (the same initial conditions and the same noise
    draws), so their differences are paired. ``keep_records`` first runs keep their full
    trajectories (for plotting). A tqdm progress bar counts runs unless ``progress`` is False.

    ``workers > 1`` or an ``address`` runs the seeds as Ray tasks
    (:mod:`activetrack.baselines.distributed`: a local Ray with ``workers`` CPUs, or the
    cluster at ``address``); every run is :func:`simulate` on its seed as in the serial
    loop, so the results equal the serial ones (planning times aside).
    """
    if not isinstance(runs, (int, np.integer)) or runs < 1:
        raise ValueError(f"runs must be an integer >= 1, got {runs!r}")
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    if not planners:
        raise ValueError("planners must name at least one planner")
    from activetrack.baselines import distributed

    workers, address = distributed.check_options(workers, address)
    from tqdm.auto import tqdm

    seeds = [int(seed) + k for k in range(runs)]
    world = World(scenario, 1)
    world.reset(seeds=[seeds[0]])
    problem = world.planning_problem(0)
    check_planners(planners.values(), problem)
    # Serially each planner is warmed here; Ray's workers warm themselves (simulate_seeds).
    warmup: dict[str, float | None] = dict.fromkeys(planners)
    bar = tqdm(total=runs * len(planners), disable=not progress, unit="run", leave=False)
    try:
        if distributed.is_distributed(workers, address):
            records = _records_on_ray(scenario, planners, seeds, workers, address, bar)
        else:
            records = {}
            for name, planner in planners.items():
                bar.set_description(f"{name} (compiling)")
                warmup[name] = warm_up(planner, problem)
                bar.set_description(name)
                recs = []
                for s in seeds:
                    recs.append(simulate(scenario, planner, s))
                    bar.update()
                records[name] = recs
    finally:
        bar.close()
    return {
        name: _result(name, seeds, recs, keep_records, warmup[name])
        for name, recs in records.items()
    }


def simulate_seeds(scenario: Scenario, planner: Planner, seeds: list[int]) -> list[RunRecord]:
    """Return :func:`simulate` on each of ``seeds`` (one Ray task's chunk of a study), after
    :func:`warm_up` on the first seed's problem (a worker process compiles too)."""
    world = World(scenario, 1)
    world.reset(seeds=[seeds[0]])
    warm_up(planner, world.planning_problem(0))
    return [simulate(scenario, planner, s) for s in seeds]


def _records_on_ray(
    scenario: Scenario,
    planners: Mapping[str, Planner],
    seeds: list[int],
    workers: int,
    address: str | None,
    bar: Any,
) -> dict[str, list[RunRecord]]:
    """Return every planner's run records, :func:`simulate_seeds` as Ray tasks over chunks
    of ``seeds`` (:func:`activetrack.baselines.distributed.map_seeds`)."""
    from activetrack.baselines import distributed

    bar.set_description("ray")
    cases = [{"scenario": scenario, "planner": planner} for planner in planners.values()]
    with distributed.session(workers, address) as cpus:
        done = distributed.map_seeds(simulate_seeds, cases, seeds, cpus, on_done=bar.update)
    return {
        name: [rec for chunk in chunked for rec in chunk]
        for name, chunked in zip(planners, done, strict=True)
    }


def _result(
    name: str, seeds: list[int], recs: list[RunRecord], keep: int, warmup: float | None
) -> MonteCarloResult:
    """Return the :class:`MonteCarloResult` of one planner's runs (in seed order)."""
    steps = max(len(r.trace) for r in recs)
    traces = np.full((len(recs), steps), np.nan)
    for i, r in enumerate(recs):
        traces[i, : len(r.trace)] = r.trace
    return MonteCarloResult(
        name=name,
        seeds=seeds,
        mean_trace=np.array([r.mean_trace for r in recs]),
        rmse=np.array([r.rmse for r in recs]),
        nees=np.array([r.mean_nees for r in recs]),
        plan_times=np.concatenate([r.plan_time for r in recs]),
        max_violation=float(max(np.max(r.violation) for r in recs)),
        n_terminated=sum(r.terminated for r in recs),
        records=recs[: max(0, keep)],
        no_detection=None if recs[0].seen is None else np.array([r.no_detection for r in recs]),
        longest_gap=None if recs[0].seen is None else np.array([r.longest_gap for r in recs]),
        traces=traces,
        warmup_time=warmup,
    )
