"""The reporting protocol of the results tables: robust statistics of the episodes' traces
and the track-loss rate (the aggregate metrics of Agarwal et al. 2021, "Deep RL at the
edge of the statistical precipice").

A policy's scores on one task are a (runs, episodes) matrix: one row per training seed
(a planner, deterministic, is one run), one column per held-out episode seed, the same
seeds for every run and every policy. Every statistic pools the whole matrix, as rliable
pools its (runs, tasks) matrices:

- :func:`iqm`, the interquartile mean: the mean of the middle 50% of the pooled values,
  ``scipy.stats.trim_mean(x, 0.25)`` as rliable's ``aggregate_iqm`` (the lowest and the
  highest ``floor(n / 4)`` values cut, so for ``n`` not divisible by 4 slightly more than
  half is kept: 3 of 5, 4 of 6, 5 of 7);
- the median and the mean of the pooled values;
- :func:`interval`, a percentile bootstrap interval (rliable's default method) of any of
  them; :func:`paired_ratio_interval` of a ratio of two policies' statistics on the same
  episode seeds;
- :func:`track_loss_rate`: the fraction of (step, target) pairs in which no sensor
  measured the target *and* its position trace exceeded a threshold;
- :func:`pooled_summary`: one policy's training seeds as one row of ``activetrack
  evaluate``'s table (``--pool``).

The bootstrap (:func:`resample`) is stratified by task, as rliable's
``StratifiedBootstrap`` (each task's matrix resampled within itself, and the statistic
computed over the pooled resamples), and within a task it resamples the rows (training
seeds) and the columns (episode seeds) independently, each with replacement: a two-way
("pigeonhole", Owen 2007) bootstrap. Why not rliable's within-task scheme (runs resampled
independently in each column): here one training seed plays every episode, so a row's
values share that run's quality; resampling each column's runs on their own averages the
runs out and gives intervals too narrow, and with one training seed (every learned row
so far, and every planner) no interval at all. Resampling whole rows keeps the run
effect; resampling the columns, the same for every row and every policy, keeps the
pairing of the episodes (the ratio to GSR) and the episode-to-episode spread. With one
run it is the ordinary bootstrap of the episodes; with one episode, that of the runs.
Its variance of the mean is exact for this resampling (tests/baselines/test_protocol.py);
like every bootstrap of ``R`` values it sees the run-to-run variance scaled by
``1 - 1/R``, a fifth short with 5 runs: 10 runs where affordable.

rliable itself is not used: it pulls arch, statsmodels and seaborn, and it draws its
resamples from numpy's global random state (``np.random.choice``), where the project draws
only from a seeded ``np.random.Generator`` (here a fixed one: the intervals are
reproducible).

The track-loss threshold (:func:`prior_traces`) is, per target, the position trace of its
prior ``P0`` (m^2): a target is lost while it goes unmeasured and the filter knows its
position less well than it did before any measurement. It is a parameter (``loss_trace``)
wherever the rate is computed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from activetrack.validation import FloatArray, check_float, check_int

#: The fraction cut from each end by the interquartile mean (rliable's ``aggregate_iqm``).
IQM_CUT = 0.25
#: Bootstrap resamples of the intervals, and resamples per vectorized batch (memory).
N_RESAMPLES, RESAMPLE_BATCH = 9999, 500
#: At most this many resampled values per batch (16 MB of float64): fewer resamples per
#: batch for a large matrix.
BATCH_VALUES = 2_000_000


def _batch(values_per_resample: int) -> int:
    """Return the resamples per batch for resamples of ``values_per_resample`` values."""
    return max(1, min(RESAMPLE_BATCH, BATCH_VALUES // max(values_per_resample, 1)))


def iqm(values: Any, axis: int | None = None) -> Any:
    """Return the interquartile mean of ``values`` (over all of them, or along ``axis``):
    ``scipy.stats.trim_mean(values, 0.25)``, the mean after cutting the ``floor(n / 4)``
    lowest and highest values (rliable's ``aggregate_iqm``)."""
    from scipy import stats  # lazy: scipy.stats costs ~0.5 s at import

    return stats.trim_mean(values, IQM_CUT, axis=axis)


def _iqm(x: np.ndarray) -> np.ndarray:
    return iqm(x, axis=-1)


def _median(x: np.ndarray) -> np.ndarray:
    return np.median(x, axis=-1)


def _mean(x: np.ndarray) -> np.ndarray:
    return np.mean(x, axis=-1)


#: The pooled statistics by name: each maps (..., n) values to (...,).
STATISTICS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "iqm": _iqm,
    "median": _median,
    "mean": _mean,
}


def score_matrix(name: str, scores: Any) -> FloatArray:
    """Return ``scores`` as a finite float64 (runs, episodes) matrix: a 1-D array is one
    run's episodes. Raise ValueError naming ``name`` otherwise."""
    from activetrack.validation import real_array

    arr = real_array(name, scores)
    if arr.ndim == 1:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.size == 0:
        raise ValueError(
            f"{name} must be a non-empty (episodes,) or (runs, episodes) array, got shape "
            f"{arr.shape}"
        )
    return arr


def resample(
    scores: FloatArray, n: int, rng: np.random.Generator, columns: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(values, columns)``: ``n`` two-way bootstrap resamples of one task's
    (runs, episodes) ``scores``, shape (n, runs * episodes), and the episode indices drawn,
    (n, episodes). Rows and columns are drawn independently with replacement; ``columns``
    (a paired policy's draw) is reused instead of drawing new ones."""
    runs, episodes = scores.shape
    rows = rng.integers(0, runs, size=(n, runs))
    if columns is None:
        columns = rng.integers(0, episodes, size=(n, episodes))
    return scores[rows[:, :, None], columns[:, None, :]].reshape(n, -1), columns


def _bootstrap_distribution(
    tasks: Sequence[FloatArray], statistic: Callable, n_resamples: int, rng: np.random.Generator
) -> np.ndarray:
    out = np.empty(n_resamples)
    batch = _batch(sum(t.size for t in tasks))
    for start in range(0, n_resamples, batch):
        n = min(batch, n_resamples - start)
        pooled = np.concatenate([resample(t, n, rng)[0] for t in tasks], axis=1)
        out[start : start + n] = statistic(pooled)
    return out


def _percentile(dist: np.ndarray, level: float, point: float) -> tuple[float, float]:
    lo, hi = np.quantile(dist, [(1 - level) / 2, (1 + level) / 2])
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise ValueError(f"no bootstrap interval: {lo}, {hi}")
    # Rounding (a statistic of identical values summed in another order) must not put the
    # point outside its interval; a percentile interval may otherwise exclude it (kept).
    tiny = 1e-12 * max(abs(point), np.finfo(float).tiny)
    lo = point if point < lo <= point + tiny else lo
    hi = point if point - tiny <= hi < point else hi
    return float(lo), float(hi)


def _check(statistic: str, level: Any, n_resamples: Any) -> tuple[Callable, float, int]:
    if statistic not in STATISTICS:
        raise ValueError(f"statistic must be one of {list(STATISTICS)}, got {statistic!r}")
    level = check_float("level", level, 0.0, 1.0, low_open=True, high_open=True)
    return STATISTICS[statistic], level, check_int("n_resamples", n_resamples, 1, 10**6)


def interval(
    scores: Any,
    statistic: str = "iqm",
    level: float = 0.95,
    *,
    n_resamples: int = N_RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """Return ``(point, low, high)``: the ``statistic`` (``"iqm"``, ``"median"`` or
    ``"mean"``) of one task's pooled (runs, episodes) ``scores`` (a 1-D array: one run)
    and its percentile bootstrap interval at ``level`` (the two-way bootstrap of the module
    docstring). The resamples come from ``np.random.default_rng(seed)``: the same scores
    give the same interval. A single value has no spread: ``(x, x, x)``.
    """
    return stratified_interval(
        [score_matrix("scores", scores)], statistic, level, n_resamples=n_resamples, seed=seed
    )


def stratified_interval(
    tasks: Sequence[Any],
    statistic: str = "iqm",
    level: float = 0.95,
    *,
    n_resamples: int = N_RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """Return ``(point, low, high)`` as :func:`interval` for several tasks' (runs,
    episodes) matrices pooled (rliable's aggregate over tasks; scores on a common scale,
    e.g. ratios to GSR): every resample resamples each task within itself (the strata)
    and takes ``statistic`` of all the tasks' resampled values together."""
    fn, level, n_resamples = _check(statistic, level, n_resamples)
    if isinstance(tasks, np.ndarray) or not isinstance(tasks, Sequence) or not tasks:
        raise ValueError("tasks must be a non-empty list of (runs, episodes) matrices")
    mats = [score_matrix(f"tasks[{t}]", s) for t, s in enumerate(tasks)]
    point = float(fn(np.concatenate([m.ravel() for m in mats])))
    if sum(m.size for m in mats) < 2:
        return point, point, point
    dist = _bootstrap_distribution(mats, fn, n_resamples, np.random.default_rng(seed))
    return (point, *_percentile(dist, level, point))


def paired_ratio_interval(
    scores: Any,
    reference: Any,
    statistic: str = "iqm",
    level: float = 0.95,
    *,
    n_resamples: int = N_RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """Return ``(ratio, low, high)``: ``statistic(scores) / statistic(reference)`` for one
    task, and its percentile bootstrap interval at ``level``.

    Both are (runs, episodes) matrices (1-D: one run) on the same episode seeds, so the
    columns are resampled jointly (the pairing kept) and each policy's runs on their own.
    """
    fn, level, n_resamples = _check(statistic, level, n_resamples)
    x, y = score_matrix("scores", scores), score_matrix("reference", reference)
    if x.shape[1] != y.shape[1]:
        raise ValueError(
            f"scores and reference must hold the same episodes, got {x.shape[1]} and "
            f"{y.shape[1]} columns"
        )
    den = float(fn(y.ravel()))
    if not den > 0:
        raise ValueError(f"reference's {statistic} must be > 0 for a ratio, got {den}")
    point = float(fn(x.ravel())) / den
    if x.shape[1] < 2 and x.shape[0] < 2 and y.shape[0] < 2:
        return point, point, point
    rng = np.random.default_rng(seed)
    dist = np.empty(n_resamples)
    batch = _batch(x.size + y.size)
    for start in range(0, n_resamples, batch):
        n = min(batch, n_resamples - start)
        xs, columns = resample(x, n, rng)
        ys, _ = resample(y, n, rng, columns)
        with np.errstate(divide="ignore", invalid="ignore"):
            dist[start : start + n] = fn(xs) / fn(ys)
    return (point, *_percentile(dist, level, point))


def summary(scores: Any, level: float = 0.95, *, seed: int = 0) -> dict[str, Any]:
    """Return the protocol's statistics of one task's (runs, episodes) ``scores`` (1-D: one
    run): ``{"iqm", "iqm_ci95", "median", "median_ci95", "mean", "mean_ci95", "runs",
    "episodes"}``, each interval ``[low, high]`` (:func:`interval`)."""
    mat = score_matrix("scores", scores)
    out: dict[str, Any] = {}
    for name in STATISTICS:
        point, lo, hi = interval(mat, name, level, seed=seed)
        out[name], out[f"{name}_ci95"] = point, [lo, hi]
    out["runs"], out["episodes"] = mat.shape
    return out


def prior_traces(scenario: Any) -> FloatArray:
    """Return the default track-loss threshold of ``scenario``'s targets, shape (K,): the
    trace of each target's prior position covariance ``P0[:2, :2]`` (m^2)."""
    return np.array([float(np.trace(np.asarray(p)[:2, :2])) for p in scenario.initial_covs])


def track_loss_rate(seen: Any, traces: Any, threshold: Any, present: Any = None) -> float:
    """Return the fraction of (step, target) pairs in which no sensor measured the target
    and its posterior position trace exceeded ``threshold`` (m^2, one per target or one
    for all).

    ``seen`` and ``traces`` are (steps, K) (or (steps,) for one target): whether some
    sensor measured each target at each step, and the trace of its position covariance
    after the step (``inf`` where the team holds no track of it). ``present`` (the same
    shape; None: always) keeps only the pairs in which the target was there, for targets
    that appear and leave. An episode without such a pair has a rate of 0.
    """
    from activetrack.validation import real_array

    seen = np.asarray(seen, dtype=bool)
    traces = real_array("traces", traces, finite=False)
    if np.isnan(traces).any() or (traces < 0).any():
        raise ValueError("traces must be >= 0 (inf: no track), got NaN or a negative value")
    there = np.ones_like(seen) if present is None else np.asarray(present, dtype=bool)
    if seen.shape != traces.shape or seen.shape != there.shape or seen.ndim not in (1, 2):
        raise ValueError(
            f"seen, traces and present must have the same shape (steps,) or (steps, K), "
            f"got {seen.shape}, {traces.shape} and {there.shape}"
        )
    if seen.ndim == 1:  # one target
        seen, traces, there = seen[:, None], traces[:, None], there[:, None]
    limit = real_array("threshold", threshold)
    if limit.ndim > 1 or limit.size not in (1, traces.shape[1]) or np.any(limit < 0):
        raise ValueError(
            f"threshold must be >= 0, one value or one per target ({traces.shape[1]}), "
            f"got {threshold!r}"
        )
    if not there.any():
        return 0.0
    return float(np.sum(~seen & there & (traces > limit)) / np.sum(there))


def pooled_summary(name: str, runs: Sequence[Any], reference: Any) -> dict[str, Any]:
    """Return the summary of several training seeds of one policy pooled as one row: the
    (runs, episodes) matrices of their evaluations (each a
    :class:`~activetrack.baselines.evaluation.PolicyEvaluation` on the same episode seeds)
    and the ratio to ``reference``'s (GSR's, one run) on those seeds.

    Keys as :meth:`PolicyEvaluation.summary`'s where they apply (``mean_trace``,
    ``iqm_trace``, ``median_trace``, ``rmse``, ``mean_return``, ``ratio_to_gsr`` and
    ``iqm_ratio_to_gsr``, the track-loss rate and the no-detection fraction, each
    interval the two-way bootstrap's, :func:`interval`), plus ``runs`` (their number)
    and ``pooled`` (their labels). ``nees`` and ``cpu_ms_per_decision`` are means over
    every run's episodes; ``longest_gap`` the longest.
    """
    if not runs:
        raise ValueError(f"pool {name!r} must name at least one evaluated policy")
    seeds = runs[0].seeds
    for r in runs:
        if list(r.seeds) != list(seeds):
            raise ValueError(f"pool {name!r}: {r.policy!r} ran other episode seeds")

    def matrix(field: str) -> np.ndarray | None:
        values = [getattr(r, field) for r in runs]
        return None if any(v is None for v in values) else np.stack(values)

    trace = matrix("mean_trace")
    out: dict[str, Any] = {"policy": name, "label": name, "pooled": [r.policy for r in runs]}
    for key, field, stat in (
        ("mean_trace", "mean_trace", "mean"),
        ("iqm_trace", "mean_trace", "iqm"),
        ("median_trace", "mean_trace", "median"),
        ("rmse", "rmse", "mean"),
        ("mean_return", "returns", "mean"),
    ):
        point, lo, hi = interval(matrix(field), stat)
        out[key], out[f"{key}_ci95"] = point, [lo, hi]
    for key, field in (("nees", "nees"), ("cpu_ms_per_decision", "ms_per_step")):
        m = matrix(field)
        out[key] = None if m is None or not np.all(np.isfinite(m)) else float(np.mean(m))
    out["ms_per_step"] = out["cpu_ms_per_decision"]  # deprecated alias, as the summary's
    for key, stat in (("ratio_to_gsr", "mean"), ("iqm_ratio_to_gsr", "iqm")):
        ratio, lo, hi = paired_ratio_interval(trace, reference.mean_trace, stat)
        out[key], out[f"{key}_ci95"] = ratio, [lo, hi]
    lost, unseen = matrix("track_loss"), matrix("no_detection")
    if lost is not None and np.all(np.isfinite(lost)):
        rate, lo, hi = interval(lost, "mean")
        out["track_loss_rate"], out["track_loss_rate_ci95"] = rate, [lo, hi]
        out["track_loss_threshold"] = runs[0].loss_trace
    if unseen is not None and np.all(np.isfinite(unseen)):
        out["no_detection"] = float(np.mean(unseen))
        out["longest_gap"] = int(np.max(matrix("longest_gap")))
    out["runs"], out["episodes"] = len(runs), len(seeds)
    out["seed_range"] = {"first": seeds[0], "last": seeds[-1]}
    out["requested"] = True
    return out
