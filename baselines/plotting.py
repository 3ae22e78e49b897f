"""The baselines' figures: closed-loop runs (Fig. 4 style) and policy evaluations.

- :func:`plot_trajectories`: one panel per planner with the sensors' trajectories, the
  true and the estimated target track, and the 3-sigma ellipses of the posterior position
  covariance every few steps (the paper's Fig. 4): one run, a sanity check;
- :func:`plot_comparison`: the study's comparison over all runs: each planner's trace of
  ``P(k|k)_11`` per step (mean and 95% band) and its runs' mean traces;
- :func:`plot_evaluation`: box plots of per-episode mean traces and their ratios to GSR's
  (the figure of ``activetrack evaluate``);
- :func:`save_figure`: every figure is written to a temporary file and renamed into place.

matplotlib is imported inside the functions (Agg backend) so that importing the
baselines never needs a display or pays matplotlib's import time.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from activetrack.baselines.simulation import MonteCarloResult, RunRecord, mean_ci
from activetrack.files import atomic_path
from activetrack.validation import FloatArray

#: Resolution of the saved figures.
DPI = 110


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: str | Path, dpi: int = DPI) -> Path:
    """Save ``fig`` to ``path`` (format from the suffix) atomically, close it; return the path.

    The image goes to a temporary file beside ``path`` and is renamed into place, so a
    failed write leaves the previous image.
    """
    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format=fmt)
    finally:
        _pyplot().close(fig)
    return path


def ellipse_points(center: FloatArray, cov: FloatArray, n_sigma: float = 3.0, n: int = 64):
    """Return (n, 2) points of the ``n_sigma`` ellipse of a 2x2 covariance around ``center``."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    t = np.linspace(0.0, 2.0 * np.pi, n)
    unit = np.stack([np.cos(t), np.sin(t)], -1) * (n_sigma * np.sqrt(np.clip(w, 0.0, None)))
    return np.asarray(center)[:2] + unit @ v.T


#: (true track, estimate) colours of targets 1, 2, ... (the first is the paper figure's).
_TARGET_COLORS = (
    ("k", "tab:red"),
    ("darkmagenta", "magenta"),
    ("teal", "c"),
    ("saddlebrown", "orange"),
)
#: Sensor colours, none of them a target's (tab10 without its red, orange, pink and cyan).
_SENSOR_COLORS = (
    "tab:blue", "tab:green", "tab:purple", "tab:olive", "tab:gray", "navy", "goldenrod",
    "yellowgreen",
)  # fmt: skip
#: Planner colours and line styles of the comparison figure, in the order the planners are
#: given (the styles keep planners that nearly coincide, GSR and GBES, both visible).
_PLANNER_COLORS = ("tab:green", "tab:blue", "tab:orange", "tab:purple", "tab:brown", "tab:gray")
_PLANNER_STYLES = ("-", "--", "-.", ":")


def plot_trajectories(
    records: Mapping[str, RunRecord],
    path: str | Path,
    *,
    ellipse_every: int = 5,
    title: str | None = None,
) -> Path:
    """Draw one Fig. 4 style panel per planner side by side and save it to ``path``.

    Args:
        records: planner name -> a run (typically all planners on the same seed).
        path: the image file to write (the format follows the suffix, e.g. ``.png``).
        ellipse_every: draw a 3-sigma ellipse every this many steps (>= 1).
        title: optional figure title.

    Returns:
        The path written.
    """
    if not records:
        raise ValueError("records must hold at least one run")
    if not isinstance(ellipse_every, int) or ellipse_every < 1:
        raise ValueError(f"ellipse_every must be an integer >= 1, got {ellipse_every!r}")
    plt = _pyplot()
    from matplotlib.lines import Line2D

    n = len(records)
    fig, axes = plt.subplots(
        1, n, figsize=(5.2 * n + 2.6, 5.0), squeeze=False, layout="constrained"
    )
    for ax, (name, rec) in zip(axes[0], records.items(), strict=True):
        for i in range(rec.sensors.shape[1]):
            col = _SENSOR_COLORS[i % len(_SENSOR_COLORS)]
            xy = rec.sensors[:, i]
            ax.plot(xy[:, 0], xy[:, 1], "-", color=col, lw=1.2, label=f"sensor {i + 1}")
            ax.plot(*xy[0], "o", color=col, ms=5)
            ax.plot(*xy[-1], "s", color=col, ms=5)
        # One target: (T, n) tracks; K targets: (T, K, n), one colour pair per target.
        multi = rec.true_states.ndim == 3
        truths = np.moveaxis(rec.true_states, 1, 0) if multi else rec.true_states[None]
        ests = np.moveaxis(rec.estimates, 1, 0) if multi else rec.estimates[None]
        covs = np.moveaxis(rec.position_covs, 1, 0) if multi else rec.position_covs[None]
        for j, (truth, est, cov) in enumerate(zip(truths, ests, covs, strict=True)):
            tag = f"target {j + 1}" if multi else "target"
            true_col, est_col = _TARGET_COLORS[j % len(_TARGET_COLORS)]
            ax.plot(truth[:, 0], truth[:, 1], "-", color=true_col, lw=1.5, label=f"{tag} (true)")
            ax.plot(est[:, 0], est[:, 1], "--", color=est_col, lw=1.2, label=f"{tag} (estimate)")
            ax.plot(*truth[0, :2], "o", color=true_col, ms=5)
            ax.plot(*truth[-1, :2], "s", color=true_col, ms=5)
            for k in range(0, len(est), ellipse_every):
                e = ellipse_points(est[k], cov[k])
                ax.plot(e[:, 0], e[:, 1], "-", color=est_col, lw=0.6, alpha=0.7)
        ax.set_title(f"{name}: mean trace {rec.mean_trace:.3g} m$^2$, RMSE {rec.rmse:.3g} m")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.grid(True, alpha=0.3)
    # The lines' own entries, then what the markers and thin curves mean (proxies: they
    # are drawn many times, in every colour).
    handles, _ = axes[0][0].get_legend_handles_labels()
    handles += [
        Line2D([], [], ls="", marker="o", color="0.3", ms=5, label="start (k = 0)"),
        Line2D([], [], ls="", marker="s", color="0.3", ms=5, label="end"),
        Line2D([], [], color="tab:red", lw=0.6, alpha=0.7,
               label=f"3-sigma ellipse of P(k|k), every {ellipse_every} steps"),
    ]  # fmt: skip
    fig.legend(handles=handles, loc="outside right center", fontsize=8)
    if title:
        fig.suptitle(title)
    return save_figure(fig, path)


def plot_comparison(
    results: Mapping[str, MonteCarloResult], path: str | Path, *, title: str | None = None
) -> Path:
    """Draw the study's comparison of planners over all its runs and save it to ``path``.

    Left: each planner's trace of ``P(k|k)_11`` per step, the mean over the runs and its
    95% Student-t band (:func:`~activetrack.baselines.simulation.mean_ci` per step; a run
    that ended early on ``max_trace`` counts until its end). Right: each run's mean trace
    (points, the same seeds for every planner) and their mean with its 95% interval. Log
    scales: planners several times apart stay readable together.

    Args:
        results: planner name -> its :class:`MonteCarloResult` with ``traces``.
        path: the image file to write (the format follows the suffix, e.g. ``.png``).
        title: optional figure title.

    Returns:
        The path written.
    """
    if not results:
        raise ValueError("results must hold at least one planner's study")
    missing = [name for name, r in results.items() if r.traces is None]
    if missing:
        raise ValueError(f"results {missing} hold no per-step traces")
    plt = _pyplot()
    from matplotlib.ticker import LogLocator, NullFormatter, ScalarFormatter

    fig, (ax, bx) = plt.subplots(
        1, 2, figsize=(11.0, 4.6), gridspec_kw={"width_ratios": [2.2, 1.0]}
    )
    jitter = np.random.default_rng(0)  # the points' horizontal spread only
    for i, (name, res) in enumerate(results.items()):
        col = _PLANNER_COLORS[i % len(_PLANNER_COLORS)]
        traces = np.asarray(res.traces, np.float64)
        steps = np.arange(1, traces.shape[1] + 1)
        stats = np.array([mean_ci(col_[np.isfinite(col_)]) for col_ in traces.T])
        runs = traces.shape[0]
        style = _PLANNER_STYLES[i % len(_PLANNER_STYLES)]
        ax.plot(steps, stats[:, 0], style, color=col, lw=1.8, label=f"{name} (mean of {runs})")
        ax.fill_between(steps, stats[:, 1], stats[:, 2], color=col, alpha=0.2, lw=0)
        mean, lo, hi = mean_ci(res.mean_trace)
        x = i + jitter.uniform(-0.18, 0.18, res.mean_trace.size)
        bx.plot(x, res.mean_trace, "o", color=col, ms=3.5, alpha=0.6)
        bx.errorbar(i + 0.32, mean, yerr=[[mean - lo], [hi - mean]], fmt="D", color="k",
                    ms=5, capsize=4)  # fmt: skip
    ax.set_xlabel("step k")
    ax.set_ylabel("trace of P(k|k)$_{11}$ (m$^2$)")
    ax.set_title("trace per step: mean over the runs, 95% band")
    ax.legend(loc="best", fontsize=8)
    bx.set_xticks(range(len(results)), list(results))
    bx.set_xlim(-0.5, len(results) - 0.3)
    bx.set_ylabel("mean trace of a run (m$^2$)")
    bx.set_title("run's mean trace; mean, 95% CI")
    for axis in (ax, bx):
        axis.set_yscale("log")
        axis.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))  # labels within a decade
        axis.yaxis.set_major_formatter(ScalarFormatter())
        axis.yaxis.set_minor_formatter(NullFormatter())
        axis.grid(True, which="both", alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path)


def short_labels(labels: Sequence[str]) -> list[str]:
    """Return short labels for policies: a policy file's folder name
    (``runs/bc1000/policy.zip`` -> ``bc1000``), a name as it is.

    Where two files would share a label, they keep as many trailing folders as tell
    them apart (``a/bc/policy.zip``, ``b/bc/policy.zip`` -> ``a/bc``, ``b/bc``).
    """
    paths = [Path(x) for x in labels]
    files = [p.suffix == ".zip" and len(p.parts) > 1 for p in paths]
    depth = 1
    while True:
        out = [
            "/".join(p.parent.parts[-depth:]) if f else x
            for x, p, f in zip(labels, paths, files, strict=True)
        ]
        deepest = max((len(p.parent.parts) for p, f in zip(paths, files, strict=True) if f),
                      default=0)  # fmt: skip
        if len(set(out)) == len(out) or depth >= deepest:
            return out if len(set(out)) == len(out) else list(labels)
        depth += 1


def plot_evaluation(results: Sequence[Any], path: str | Path, title: str = "") -> Path:
    """Write box plots of the per-episode mean traces and their ratios to GSR; return the path.

    ``results`` are :class:`~activetrack.baselines.evaluation.PolicyEvaluation` objects
    (``policy``, ``seeds``, ``mean_trace``), one of them GSR's on the same seeds. Left:
    each episode's mean trace; right: each episode's mean trace over GSR's on the same
    seed (the paired comparison). Both on a log scale, so that random motion (several
    times GSR's trace) and policies within a few percent of GSR are readable together;
    an axis spanning less than a decade (no power of ten or only one inside) gets evenly
    spaced labelled ticks instead of the decades'. Policies are named by their short
    labels (:func:`short_labels`).
    """
    plt = _pyplot()
    from matplotlib.ticker import MaxNLocator, NullFormatter, NullLocator, ScalarFormatter

    gsr = next((r for r in results if r.policy.lower() == "gsr"), None)
    if gsr is None:
        raise ValueError("the results hold no GSR evaluation (the ratio's reference)")
    labels = short_labels([r.policy for r in results])
    ticks = range(1, len(results) + 1)
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(2.5 + 1.5 * len(results), 4.4))
    ax.boxplot([r.mean_trace for r in results], showmeans=True)
    ax.axhline(float(np.mean(gsr.mean_trace)), color="tab:green", ls="--", lw=1, label="GSR mean")
    ax.set_ylabel("episode mean trace of P(k|k)_11 [m^2]")
    bx.boxplot([r.mean_trace / gsr.mean_trace for r in results], showmeans=True)
    bx.axhline(1.0, color="tab:green", ls="--", lw=1, label="GSR")
    bx.set_ylabel("episode mean trace / GSR's (same seed)")
    for axis in (ax, bx):
        axis.set_yscale("log")
        lo, hi = axis.get_ylim()
        if np.floor(np.log10(hi)) - np.ceil(np.log10(lo)) < 1:  # fewer than two decades in view
            axis.yaxis.set_major_locator(MaxNLocator(nbins=6))
            axis.yaxis.set_minor_locator(NullLocator())
        axis.yaxis.set_major_formatter(ScalarFormatter(useOffset=False))
        axis.yaxis.set_minor_formatter(NullFormatter())
        axis.set_xticks(ticks, labels, rotation=25, ha="right")
        axis.legend(loc="upper right", fontsize=8)
    fig.suptitle(title or f"{len(results[0].seeds)} held-out episodes (triangles: means)")
    fig.tight_layout()
    return save_figure(fig, path)
