"""Evaluation of policies (the planners' expert policies or learned ones) on held-out seeds.

Every policy runs in the PettingZoo environment on the same episodes: episode ``j``
resets with seed ``seed + j``, so all policies face the same initial conditions and the
same process and measurement noise (the environment draws ``n + 2M`` normals per step
whatever the actions), and their differences are paired.

Per episode (steps 1..n_steps, as in :mod:`activetrack.baselines.simulation`): the mean
trace of the posterior position covariance, the RMSE of the position estimate and the
return (sum of rewards). Per policy: the mean trace and the mean RMSE with BCa bootstrap
95% intervals (:func:`bootstrap_ci`: the episodes' traces and RMSEs are positive and
heavy-tailed, and a Student-t interval of them can reach below zero), the median trace,
the return with a Student-t 95% interval, and the ratio of its mean trace to GSR's with a
paired BCa bootstrap 95% interval. The reporting protocol's statistics
(:mod:`activetrack.baselines.protocol`): the interquartile mean (IQM) and the median of
the episodes' mean traces with percentile bootstrap 95% intervals, the ratio of the IQM to
GSR's with a paired one, and with limited sensing the track-loss rate (the fraction of
(step, target) pairs with no measurement and the target's position trace above
``loss_trace``, by default its prior's) with its interval. GSR is always evaluated (the
ratio's reference) even when it is not asked for; it is then reported separately.
``cpu_ms_per_decision`` is the CPU time (``time.process_time``) per decision (one
``plan`` or ``act`` call, per copy in a batched run), measured after one warm-up decision
that is not counted (the compiled kernels' first compilation).

The JSON summary (:meth:`PolicyEvaluation.summary`) names the episodes' seeds
``seed_range`` ``{"first": ..., "last": ...}`` (as the simulation's ``results.json``);
``ms_per_step`` is a deprecated alias of ``cpu_ms_per_decision`` (the same value, kept
for readers of the files written before), and :func:`format_table` still reads a summary
written before that name (``ms_per_step`` only).

A policy is an expert (``plan(problem) -> next positions``), anything with
``act(observations) -> {agent: action}``, a name or a policy file
(:mod:`activetrack.baselines.policy_specs`). Every policy is loaded and checked before the
first episode runs. Every episode is the one episode loop of
:mod:`activetrack.baselines.rollout`.

:func:`write_results` writes a run's files together (:mod:`activetrack.files`); the
figure is :func:`activetrack.baselines.plotting.plot_evaluation`. With ``workers`` or an
``address`` the episodes run as Ray tasks (:mod:`activetrack.baselines.distributed`), with
the same results.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from activetrack.baselines.episodes import (  # noqa: F401 (public here too)
    CENSUS_FIELDS,
    run_batched,
    run_episode,
    run_episodes,
    warm_up,
)
from activetrack.baselines.plotting import short_labels
from activetrack.baselines.policy_specs import (  # noqa: F401 (public here too)
    EXPERT_NAMES,
    POLICY_LOADERS,
    check_compatible,
    policy_loader,
    policy_loaders,
    resolve_policy,
)
from activetrack.baselines.protocol import prior_traces
from activetrack.baselines.simulation import check_planners, mean_ci
from activetrack.files import RunOutputs, prepare_output_dir
from activetrack.validation import check_float, check_int
from activetrack.world.scenarios import make_scenario


@dataclass(eq=False)
class PolicyEvaluation:
    """Per-episode metrics of one policy over seeds ``seeds``.

    Attributes:
        policy: the policy's label (as given on the command line).
        seeds: the episodes' seeds.
        mean_trace, rmse, returns: per-episode mean trace (m^2), RMSE (m) and return.
        requested: False for GSR when it was only added as the ratio's reference.
        nees: per-episode mean position NEES (2 for a consistent filter; the mean over
            targets), NaN where the environment has no world to read it from.
        ms_per_step: per-episode mean CPU time (ms) of the policy's decision (plan or act)
            per step, after a warm-up decision.
        no_detection, longest_gap: per-episode fraction of steps without a measurement of
            a target and the longest such run
            (:func:`activetrack.baselines.simulation.detection_gaps`); None with unlimited
            sensing.
        track_loss: per-episode track-loss rate
            (:func:`activetrack.baselines.protocol.track_loss_rate`); None with unlimited
            sensing.
        loss_trace: its threshold per target (m^2), None with unlimited sensing.
        team: with a filter per robot (a ``communication`` model), per-episode means over
            the steps of the robots' mean score, the worst robot's score and the robots'
            disagreement (m) (:meth:`activetrack.world.World.team_metrics`), (episodes,
            3); else None.
        census: with targets that appear and leave (the field ``births``), per-episode
            arrays ``gospa``, ``fraction_tracked``, ``first_detection`` (s) and
            ``all_tracked`` (1.0 or 0.0) (:data:`activetrack.baselines.episodes.CENSUS_FIELDS`);
            None otherwise.
    """

    policy: str
    seeds: list[int]
    mean_trace: np.ndarray
    rmse: np.ndarray
    returns: np.ndarray
    requested: bool = True
    nees: np.ndarray | None = None
    ms_per_step: np.ndarray | None = None
    no_detection: np.ndarray | None = None
    longest_gap: np.ndarray | None = None
    track_loss: np.ndarray | None = None
    loss_trace: list[float] | None = None
    team: np.ndarray | None = None
    census: dict[str, np.ndarray] | None = None

    def summary(self, reference: PolicyEvaluation | None = None) -> dict[str, Any]:
        """Return the JSON summary; the ratio is to ``reference``'s mean trace (GSR).

        ``cpu_ms_per_decision`` is the mean CPU time per decision (ms, after a warm-up),
        ``ms_per_step`` its deprecated alias (the same value); ``seed_range`` the first and
        last seed (the episodes' seeds are consecutive). The protocol's statistics
        (:mod:`activetrack.baselines.protocol`): ``iqm_trace``, ``iqm_trace_ci95``,
        ``median_trace_ci95``, ``iqm_ratio_to_gsr`` with ``iqm_ratio_to_gsr_ci95`` and,
        with limited sensing, ``track_loss_rate``, ``track_loss_rate_ci95`` and
        ``track_loss_threshold`` (m^2 per target).
        """
        from activetrack.baselines import protocol

        mt = float(np.mean(self.mean_trace))
        mt_lo, mt_hi = bootstrap_ci(self.mean_trace)
        rm = float(np.mean(self.rmse))
        rm_lo, rm_hi = bootstrap_ci(self.rmse)  # positive and heavy-tailed, as the trace
        ret, ret_lo, ret_hi = mean_ci(self.returns)
        ms = None if self.ms_per_step is None else float(np.mean(self.ms_per_step))
        out: dict[str, Any] = {
            "policy": self.policy,
            "label": short_labels([self.policy])[0],
            "mean_trace": mt,
            "mean_trace_ci95": [mt_lo, mt_hi],
            "median_trace": float(np.median(self.mean_trace)),
            "median_trace_ci95": list(protocol.interval(self.mean_trace, "median")[1:]),
            "iqm_trace": float(protocol.iqm(self.mean_trace)),
            "iqm_trace_ci95": list(protocol.interval(self.mean_trace, "iqm")[1:]),
            "rmse": rm,
            "rmse_ci95": [rm_lo, rm_hi],
            "mean_return": ret,
            "mean_return_ci95": [ret_lo, ret_hi],
            "nees": None
            if self.nees is None or not np.all(np.isfinite(self.nees))
            else float(np.mean(self.nees)),
            "cpu_ms_per_decision": ms,
            "ms_per_step": ms,  # deprecated alias of cpu_ms_per_decision
            "ratio_to_gsr": None,
            "ratio_to_gsr_ci95": None,
            "iqm_ratio_to_gsr": None,
            "iqm_ratio_to_gsr_ci95": None,
            "episodes": len(self.seeds),
            "seed_range": {"first": self.seeds[0], "last": self.seeds[-1]},
            "requested": self.requested,
        }
        if self.no_detection is not None and np.all(np.isfinite(self.no_detection)):
            out["no_detection"] = float(np.mean(self.no_detection))
            out["longest_gap"] = int(np.max(self.longest_gap))
        if self.track_loss is not None and np.all(np.isfinite(self.track_loss)):
            rate, lo, hi = protocol.interval(self.track_loss, "mean")
            out["track_loss_rate"], out["track_loss_rate_ci95"] = rate, [lo, hi]
            out["track_loss_threshold"] = self.loss_trace
        if self.team is not None and np.all(np.isfinite(self.team)):
            for key, column in zip(TEAM_METRICS, self.team.T, strict=True):
                out[key] = float(np.mean(column))
        if self.census is not None:  # targets that appear and leave
            c = self.census
            out["gospa"] = float(np.mean(c["gospa"]))
            tracked = c["fraction_tracked"][np.isfinite(c["fraction_tracked"])]
            out["fraction_tracked"] = float(np.mean(tracked)) if tracked.size else None
            first = c["first_detection"][np.isfinite(c["first_detection"])]
            out["first_detection_s"] = float(np.mean(first)) if first.size else None
            out["all_tracked_fraction"] = float(np.mean(c["all_tracked"]))
        # (GSR's trace is 0 only where no track was ever held: births, short episodes)
        if reference is not None and np.mean(reference.mean_trace) > 0:
            out["ratio_to_gsr"] = mt / float(np.mean(reference.mean_trace))
            out["ratio_to_gsr_ci95"] = list(paired_ratio_ci(self.mean_trace, reference.mean_trace))
            ratio, lo, hi = protocol.paired_ratio_interval(self.mean_trace, reference.mean_trace)
            out["iqm_ratio_to_gsr"], out["iqm_ratio_to_gsr_ci95"] = ratio, [lo, hi]
        return out


def json_safe(obj: Any) -> Any:
    """Return ``obj`` with every non-finite float (a figure with nothing to average: e.g.
    the NEES of an episode that never held a track, with ``births``) as None (JSON null)."""
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, (float, np.floating)) and not np.isfinite(obj):
        return None
    return obj


#: The team's metrics of a world with a filter per robot, in the summary and the episodes.
TEAM_METRICS = ("robot_score_mean", "robot_score_worst", "disagreement")

#: Bootstrap resamples of the intervals, and resamples per vectorized batch (memory).
N_RESAMPLES, RESAMPLE_BATCH = 9999, 500


def _bootstrap(data: tuple[np.ndarray, ...], statistic: Any, level: float) -> tuple[float, float]:
    """Return scipy's BCa bootstrap interval of ``statistic`` over paired ``data`` (the
    episodes resampled jointly), from a fixed generator: the interval is reproducible.

    Fewer than two episodes, or data whose every resample gives the same statistic: the
    statistic itself at both ends (there is no spread to estimate).
    """
    from scipy import stats  # lazy: scipy.stats costs ~0.5 s at import

    point = float(statistic(*data, axis=-1))
    if data[0].size < 2:
        return point, point
    # Degenerate data (GSR's ratio to itself) make BCa's acceleration 0/0: scipy warns
    # and gives NaN, handled below.
    with warnings.catch_warnings(), np.errstate(invalid="ignore", divide="ignore"):
        warnings.simplefilter("ignore", stats.DegenerateDataWarning)
        res = stats.bootstrap(
            data, statistic, n_resamples=N_RESAMPLES, batch=RESAMPLE_BATCH, vectorized=True,
            paired=True, axis=-1, confidence_level=level, method="BCa",
            rng=np.random.default_rng(0),
        )  # fmt: skip
    dist = res.bootstrap_distribution
    if np.ptp(dist) <= 1e-12 * abs(point):  # no spread: BCa's acceleration is 0/0
        return point, point
    lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise ValueError(f"no bootstrap interval for {data[0].size} episodes: {lo}, {hi}")
    return lo, hi


def _mean(x: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.mean(x, axis=axis)


def _ratio(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
    return np.mean(x, axis=axis) / np.mean(y, axis=axis)


def bootstrap_ci(values: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """Return a BCa bootstrap interval of the mean of ``values`` (scipy.stats.bootstrap).

    For a positive, skewed quantity (the episodes' mean traces): its ends are means of
    resamples, so they lie within the sample's range (never below its minimum, never
    negative), and BCa corrects the bias and skewness of the mean's distribution.
    """
    v = np.asarray(values, dtype=np.float64)
    return _bootstrap((v,), _mean, level)


def paired_ratio_ci(
    values: np.ndarray, reference: np.ndarray, level: float = 0.95
) -> tuple[float, float]:
    """Return a paired BCa bootstrap interval of ``mean(values) / mean(reference)``.

    Episodes are resampled jointly (the same seeds for both), which keeps the pairing.
    The bootstrap generator is fixed, so the interval is reproducible.
    """
    values, reference = np.asarray(values, float), np.asarray(reference, float)
    if values.shape != reference.shape:
        raise ValueError("paired ratio needs the same episodes for both policies")
    return _bootstrap((values, reference), _ratio, level)


def check_batched(batched: object, workers: object, address: object) -> tuple[int, str | None]:
    """Return the checked ``(workers, address)``; raise ValueError unless ``batched`` is a
    bool that they allow (a batched run is one process: not with Ray workers)."""
    from activetrack.baselines import distributed

    if not isinstance(batched, (bool, np.bool_)):
        raise ValueError(f"batched must be True or False, got {batched!r}")
    workers, address = distributed.check_options(workers, address)
    if batched and distributed.is_distributed(workers, address):
        raise ValueError("batched runs in this process: it cannot be combined with Ray workers")
    return workers, address


def batchable(policy: Any) -> bool:
    """Return whether ``policy`` is a deterministic planner that plans batched problems
    (GSR, the look-ahead planner and their distributed forms), the policies ``batched``
    runs in one world."""
    from activetrack.baselines import policies as p

    kinds = (p.GSRPolicy, p.LookaheadPolicy, p.DistributedGSRPolicy, p.DistributedLookaheadPolicy)
    return isinstance(policy, kinds)


def acts_batched(policy: Any) -> bool:
    """Return whether ``policy`` acts on every copy's observations at once (a learned
    policy's ``act_batch``), so that ``batched`` runs it in one world."""
    return not batchable(policy) and callable(getattr(policy, "act_batch", None))


def evaluate(
    policies: Sequence[Any] | Mapping[str, Any],
    scenario: Any = "paper",
    episodes: int = 100,
    seed: int = 1000,
    progress: bool = True,
    *,
    workers: int = 1,
    address: str | None = None,
    batched: bool = False,
    loss_trace: float | None = None,
    **overrides: Any,
) -> list[PolicyEvaluation]:
    """Return one :class:`PolicyEvaluation` per policy (GSR first added if it is missing).

    ``policies`` is a list of specs (names, paths or objects; labels are ``str(spec)``
    for names and paths, the class name otherwise) or a mapping from label to spec.
    ``workers > 1`` or an ``address`` runs the episodes as Ray tasks
    (:mod:`activetrack.baselines.distributed`), each :func:`run_episode` on its seed in
    an environment of its own, so the results equal the serial ones. ``batched`` runs each
    deterministic planner (GSR, the look-ahead planner) on all episodes at once in a
    batched world (:func:`run_batched`: far faster for the look-ahead planner; its rows
    equal the serial ones bit for bit, see there), and each learned policy with
    ``act_batch`` (:class:`activetrack.train.policy_io.LearnedPolicy`) on all episodes'
    observations at once (rows equal the serial ones to float32 rounding); random motion
    still runs episode by episode. ``loss_trace`` (m^2, > 0) is
    the track-loss rate's threshold for every target; None: each target's prior position
    trace (:func:`activetrack.baselines.protocol.prior_traces`).
    """
    from tqdm.auto import tqdm

    from activetrack.baselines import distributed
    from activetrack.envs import parallel_env

    episodes = check_int("episodes", episodes, 1)
    seed = check_int("seed", seed, 0)
    workers, address = check_batched(batched, workers, address)
    if loss_trace is not None:
        loss_trace = check_float("loss_trace", loss_trace, 0.0, low_open=True)
    if isinstance(policies, Mapping):
        items = list(policies.items())
    else:
        items = [(str(p) if isinstance(p, (str, Path)) else type(p).__name__, p) for p in policies]
    if not items:
        raise ValueError("give at least one policy")
    labels = [label for label, _ in items]
    if len(set(labels)) != len(labels):
        raise ValueError(f"policy labels must be distinct, got {labels}")
    has_gsr = any(isinstance(s, str) and s.lower() == "gsr" for _, s in items)
    if not has_gsr:  # the ratio's reference, computed anyway and marked as not requested
        items.append(("gsr", "gsr"))
    seeds = [seed + j for j in range(episodes)]
    env = parallel_env(scenario, **overrides)
    limited = env.unwrapped.world.scenario.limited_sensing
    births = env.unwrapped.world.scenario.births is not None
    thresholds = (
        prior_traces(env.unwrapped.world.scenario)
        if loss_trace is None
        else np.full(env.unwrapped.world.n_targets, loss_trace)
    ).tolist()
    try:
        # Every policy loaded and checked before the first episode.
        resolved = []
        for label, spec in items:
            policy = resolve_policy(spec)
            check_compatible(policy, env, label)
            resolved.append(policy)
        env.reset(seed=seeds[0])
        check_planners(resolved, env.planning_problem())
    except BaseException:
        env.close()
        raise
    # Progress in steps (an episode's or a batch's), each policy under its short label.
    n_steps = env.unwrapped.world.scenario.n_steps
    names = short_labels([label for label, _ in items])
    bar = tqdm(
        total=episodes * n_steps * len(items), disable=not progress, unit="step", leave=False,
        unit_scale=True,
    )  # fmt: skip
    try:
        if distributed.is_distributed(workers, address):
            per_policy = _episodes_on_ray(
                scenario, overrides, resolved, seeds, workers, address, bar, n_steps, loss_trace
            )
        else:
            per_policy = []
            for name, policy in zip(names, resolved, strict=True):
                bar.set_description(name)
                done = bar.n
                if batched and (batchable(policy) or acts_batched(policy)):
                    per_policy.append(
                        run_batched(scenario, overrides, policy, seeds, bar.update, loss_trace)
                    )
                else:
                    warm_up(env, policy, seeds[0])
                    rows = []
                    for s in seeds:
                        rows.append(run_episode(env, policy, s, bar.update, loss_trace))
                        bar.update(done + len(rows) * n_steps - bar.n)  # ended early
                    per_policy.append(rows)
                bar.update(done + len(seeds) * n_steps - bar.n)
    finally:
        bar.close()
        env.close()
    results = []
    for index, ((label, _), rows) in enumerate(zip(items, per_policy, strict=True)):
        arr = np.asarray(rows)
        requested = has_gsr or index < len(items) - 1
        gaps = (arr[:, 5], arr[:, 6], arr[:, 7], thresholds) if limited else (None,) * 4
        results.append(
            PolicyEvaluation(
                label,
                seeds,
                arr[:, 0],
                arr[:, 1],
                arr[:, 2],
                requested,
                arr[:, 3],
                arr[:, 4],
                *gaps,
                arr[:, 8:11] if np.all(np.isfinite(arr[:, 8:11])) else None,
                census=dict(zip(CENSUS_FIELDS, arr[:, 11:15].T, strict=True)) if births else None,
            )  # fmt: skip
        )
    return results


def _episodes_on_ray(
    scenario: Any,
    overrides: dict[str, Any],
    policies: list[Any],
    seeds: list[int],
    workers: int,
    address: str | None,
    bar: Any,
    n_steps: int,
    loss_trace: float | None = None,
) -> list[list[tuple[float, ...]]]:
    """Return every policy's episode rows, :func:`run_episodes` as Ray tasks over chunks of
    ``seeds`` (:func:`activetrack.baselines.distributed.map_seeds`)."""
    from activetrack.baselines import distributed

    bar.set_description("ray")
    cases = [
        {"scenario": scenario, "overrides": overrides, "policy": p, "loss_trace": loss_trace}
        for p in policies
    ]
    with distributed.session(workers, address) as cpus:
        done = distributed.map_seeds(
            run_episodes, cases, seeds, cpus, on_done=lambda k: bar.update(k * n_steps)
        )
    return [[row for chunk in chunked for row in chunk] for chunked in done]


def _gsr_of(results: Sequence[PolicyEvaluation]) -> PolicyEvaluation:
    for r in results:
        if r.policy.lower() == "gsr":
            return r
    raise ValueError("the results hold no GSR evaluation")


def summaries(
    results: Sequence[PolicyEvaluation], pools: Mapping[str, Sequence[str]] | None = None
) -> list[dict[str, Any]]:
    """Return the JSON summary of each result, with its ratio to GSR's mean trace, then one
    row per pool (``{name: [policy labels]}``: the training seeds of one policy,
    :func:`activetrack.baselines.protocol.pooled_summary`)."""
    from activetrack.baselines.protocol import pooled_summary

    ref = _gsr_of(results)
    rows = [r.summary(ref) for r in results]
    for row, label in zip(rows, short_labels([r.policy for r in results]), strict=True):
        row["label"] = label  # distinct among these results
    by_label = {r.policy: r for r in results}
    pools = check_pools(pools, list(by_label))
    rows += [pooled_summary(n, [by_label[m] for m in ms], ref) for n, ms in pools.items()]
    return rows


def check_pools(pools: Any, labels: Sequence[str]) -> dict[str, list[str]]:
    """Return ``pools`` checked: a mapping from a new name (not one of ``labels``) to one
    or more distinct policy ``labels``; raise ValueError naming what is wrong."""
    if pools is None:
        return {}
    if not isinstance(pools, Mapping):
        raise ValueError(f"pools must map a name to policy labels, got {pools!r}")
    out = {}
    for name, members in pools.items():
        if not isinstance(name, str) or not name or name in labels:
            raise ValueError(f"pool names must be new non-empty names, got {name!r}")
        if isinstance(members, str):
            members = [members]
        members = list(members) if isinstance(members, (list, tuple)) else [members]
        unknown = [m for m in members if not isinstance(m, str) or m not in labels]
        if not members or unknown or len(set(members)) != len(members):
            raise ValueError(
                f"pool {name!r} must name distinct evaluated policies (one of {list(labels)}), "
                f"got {members}"
            )
        out[name] = members
    return out


def _with_ci(r: dict[str, Any], key: str, digits: str = ".4g") -> str:
    """Return ``r[key]`` with its ``[low, high]`` interval (``key_ci95``) if ``r`` has one,
    "-" if it has no ``key`` (a summary written before the key existed)."""
    value = r.get(key)
    if value is None:
        return "-"
    ci = r.get(f"{key}_ci95")
    text = f"{value:{digits}}"
    return text if ci is None else f"{text} [{ci[0]:{digits}}, {ci[1]:{digits}}]"


def format_table(rows: Sequence[dict[str, Any]]) -> str:
    """Return the summaries as a plain-text table (GSR added only for the ratio is marked).

    Policies by their short label (a policy file's folder; the full path is the JSON's
    ``policy``); the mean trace, its IQM and its median, each with its bootstrap interval;
    ``CPU ms/decision`` is ``cpu_ms_per_decision`` (CPU time per decision after a warm-up;
    a summary written before that name gives its ``ms_per_step``); the ratios of the mean
    and of the IQM to GSR's; with limited sensing the track-loss rate, then the fraction
    of steps without a detection and the longest such run; with targets that appear and
    leave the mean GOSPA, the fraction of time tracked, the mean time to first detection
    and the fraction of episodes in which every target was tracked. A summary written
    before a column existed shows "-" there.
    """
    width = max([len("policy")] + [len(r.get("label", r["policy"])) + 12 for r in rows])
    head = (
        f"{'policy':<{width}} {'mean trace [95% CI]':>26} {'IQM [95% CI]':>26} "
        f"{'median [95% CI]':>26} {'RMSE':>7} {'NEES':>5} {'CPU ms/decision':>15} "
        f"{'return':>8} {'ratio to GSR':>22} {'IQM ratio to GSR':>22}"
    )
    lines = [head, "-" * len(head)]
    for r in rows:
        name = r.get("label", r["policy"]) + ("" if r["requested"] else " (reference)")
        name += f" ({r['runs']} runs)" if "runs" in r else ""  # a pool of training seeds
        traces = [_with_ci(r, k) for k in ("mean_trace", "iqm_trace", "median_trace")]
        ratios = [_with_ci(r, k, ".3f") for k in ("ratio_to_gsr", "iqm_ratio_to_gsr")]
        nees = "-" if r.get("nees") is None else f"{r['nees']:.2f}"
        cpu_ms = r.get("cpu_ms_per_decision", r.get("ms_per_step"))
        ms = "-" if cpu_ms is None else f"{cpu_ms:.3g}"
        line = (
            f"{name:<{width}} {traces[0]:>26} {traces[1]:>26} {traces[2]:>26} "
            f"{r['rmse']:>7.3f} {nees:>5} {ms:>15} {r['mean_return']:>8.2f} "
            f"{ratios[0]:>22} {ratios[1]:>22}"
        )
        extra = []
        if "track_loss_rate" in r:  # limited sensing: unmeasured and uncertain
            extra.append(f"track loss {_with_ci(r, 'track_loss_rate', '.3f')}")
        if "no_detection" in r:  # limited sensing: steps without a measurement, longest run
            extra.append(f"no detection {r['no_detection']:.3f}")
            extra.append(f"longest gap {r['longest_gap']}")
        if "disagreement" in r:  # a filter per robot: its robots' scores, their spread
            extra.append(
                f"robots mean {r['robot_score_mean']:.4g}, worst {r['robot_score_worst']:.4g}, "
                f"disagreement {r['disagreement']:.3g} m"
            )
        if "gospa" in r:  # targets that appear and leave
            first = r["first_detection_s"]
            extra.append(f"GOSPA {r['gospa']:.3f}")
            tracked = r["fraction_tracked"]
            extra.append("tracked " + ("-" if tracked is None else f"{tracked:.3f} of the time"))
            extra.append("first detection " + ("-" if first is None else f"{first:.2f} s"))
            extra.append(f"all tracked in {r['all_tracked_fraction']:.2f} of episodes")
        if extra:
            line += "  " + ", ".join(extra)
        lines.append(line)
    return "\n".join(lines)


#: The files ``write_results`` writes in its output folder.
OUTPUTS = ("results.json", "episodes.json", "mean_trace.png")


def write_results(
    results: Sequence[PolicyEvaluation],
    out_dir: str | Path | RunOutputs,
    meta: dict[str, Any] | None = None,
    plot: bool = True,
    overwrite: bool = False,
    pools: Mapping[str, Sequence[str]] | None = None,
) -> dict[str, Path]:
    """Write ``results.json`` (a list, one object per policy), ``episodes.json`` and the plot.

    Returns the written paths by name (``results``, ``episodes``, ``plot``). ``meta``
    (scenario, seeds...) goes to ``episodes.json`` along with every episode's metrics
    (``cpu_ms_per_decision`` with its deprecated alias ``ms_per_step``, as the summary).
    ``out_dir`` is a folder (checked by :func:`~activetrack.files.prepare_output_dir`:
    one that holds results needs ``overwrite``) or the :class:`RunOutputs` of one checked
    earlier. ``pools`` adds pooled rows to ``results.json`` (:func:`summaries`). The files
    are committed together (a failed write leaves the previous ones);
    a previous ``mean_trace.png`` is removed when ``plot`` is false.
    """
    outputs = out_dir if isinstance(out_dir, RunOutputs) else None
    if outputs is None:
        outputs = prepare_output_dir(out_dir, OUTPUTS, overwrite)
    per_episode = {
        "meta": meta or {},
        "policies": {
            r.policy: {
                "seeds": r.seeds,
                "mean_trace": r.mean_trace.tolist(),
                "rmse": r.rmse.tolist(),
                "return": r.returns.tolist(),
                **({} if r.nees is None else {"nees": r.nees.tolist()}),
                **(
                    {}
                    if r.ms_per_step is None  # ms_per_step: deprecated alias, as the summary's
                    else dict.fromkeys(
                        ("cpu_ms_per_decision", "ms_per_step"), r.ms_per_step.tolist()
                    )
                ),
                **(
                    {}
                    if r.no_detection is None
                    else {
                        "no_detection": r.no_detection.tolist(),
                        "longest_gap": r.longest_gap.tolist(),
                    }
                ),
                **({} if r.track_loss is None else {"track_loss": r.track_loss.tolist()}),
                **(
                    {}
                    if r.team is None
                    else {k: c.tolist() for k, c in zip(TEAM_METRICS, r.team.T, strict=True)}
                ),
                **(
                    {}
                    if r.census is None  # NaN (no target detected) written as null
                    else {
                        k: [None if not np.isfinite(v) else float(v) for v in a]
                        for k, a in r.census.items()
                    }
                ),
            }
            for r in results
        },
    }
    with outputs:
        outputs.write_json("results.json", json_safe(summaries(results, pools)))
        outputs.write_json("episodes.json", json_safe(per_episode))
        if plot:
            from activetrack.baselines.plotting import plot_evaluation

            plot_evaluation(results, outputs.staged("mean_trace.png"))
        written = outputs.commit()
    keys = {"results.json": "results", "episodes.json": "episodes", "mean_trace.png": "plot"}
    return {keys[name]: p for name, p in written.items()}


def run_evaluation(
    policies: Sequence[str],
    scenario: str = "paper",
    episodes: int = 100,
    seed: int = 1000,
    out_dir: str | Path | None = None,
    plot: bool = True,
    progress: bool = True,
    overwrite: bool = False,
    *,
    workers: int = 1,
    address: str | None = None,
    batched: bool = False,
    loss_trace: float | None = None,
    pools: Mapping[str, Sequence[str]] | None = None,
    **overrides: Any,
) -> list[dict[str, Any]]:
    """Evaluate, print the table, write ``out_dir`` if given; return the JSON summaries.

    The command ``activetrack evaluate`` is this function. Everything that can be checked
    before the episodes is: the output folder (one holding results needs ``overwrite``)
    and every policy (names, policy files, their observation size), ``workers``,
    ``address`` and ``batched`` (:func:`evaluate`), and ``pools`` (names of pooled rows,
    each a list of ``policies``' labels: one policy's training seeds, :func:`summaries`).
    """
    workers, address = check_batched(batched, workers, address)
    if isinstance(policies, Mapping):
        labels = list(policies)
    else:  # evaluate's labels, and its GSR reference if none is given
        labels = [str(p) if isinstance(p, (str, Path)) else type(p).__name__ for p in policies]
    if not any(label.lower() == "gsr" for label in labels):
        labels.append("gsr")
    pools = check_pools(pools, labels)
    if out_dir is not None and not isinstance(out_dir, RunOutputs):
        with prepare_output_dir(out_dir, OUTPUTS, overwrite) as outputs:  # locked for the run
            return run_evaluation(
                policies,
                scenario,
                episodes,
                seed,
                outputs,
                plot,
                progress,
                overwrite,
                workers=workers,
                address=address,
                batched=batched,
                loss_trace=loss_trace,
                pools=pools,
                **overrides,
            )
    outputs = out_dir
    results = evaluate(
        policies,
        scenario,
        episodes,
        seed,
        progress,
        workers=workers,
        address=address,
        batched=batched,
        loss_trace=loss_trace,
        **overrides,
    )
    rows = summaries(results, pools)
    name = getattr(scenario, "name", scenario)
    print(f"scenario {name!r}, {episodes} episodes, seeds {seed}..{seed + episodes - 1}")
    print(format_table(rows))
    if not results[-1].requested:
        print("gsr was not requested: it was evaluated on the same seeds as the ratio's reference")
    if outputs is not None:
        given = scenario.to_dict() if hasattr(scenario, "to_dict") else scenario  # a Scenario
        # Overrides as the scenario records them (a model, kinematics or objective of one's
        # own by name and class: JSON has no object).
        record = make_scenario(scenario, **overrides).to_dict()
        overrides = {k: record.get(k, v) for k, v in overrides.items()}
        meta = {"scenario": given, "overrides": overrides, "episodes": episodes, "seed": seed}
        paths = write_results(results, outputs, meta, plot=plot, pools=pools)
        print("wrote " + ", ".join(str(p) for p in paths.values()))
    return rows
