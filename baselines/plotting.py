"""Figures of closed-loop runs in the style of the paper's Fig. 4.

One panel per planner: the sensors' trajectories, the true and the estimated target
track, and the 3-sigma ellipses of the posterior position covariance every few steps.
matplotlib is imported inside the functions (Agg backend) so that importing the
baselines never needs a display or pays matplotlib's import time.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from activetrack.baselines.simulation import RunRecord
from activetrack.validation import FloatArray


def ellipse_points(center: FloatArray, cov: FloatArray, n_sigma: float = 3.0, n: int = 64):
    """Return (n, 2) points of the ``n_sigma`` ellipse of a 2x2 covariance around ``center``."""
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    t = np.linspace(0.0, 2.0 * np.pi, n)
    unit = np.stack([np.cos(t), np.sin(t)], -1) * (n_sigma * np.sqrt(np.clip(w, 0.0, None)))
    return np.asarray(center)[:2] + unit @ v.T


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
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(records)
    fig, axes = plt.subplots(1, n, figsize=(5.2 * n, 5.0), squeeze=False)
    colors = plt.get_cmap("tab10").colors
    for ax, (name, rec) in zip(axes[0], records.items(), strict=True):
        for i in range(rec.sensors.shape[1]):
            col = colors[(i + 2) % len(colors)]
            xy = rec.sensors[:, i]
            ax.plot(xy[:, 0], xy[:, 1], "-", color=col, lw=1.2, label=f"sensor {i + 1}")
            ax.plot(*xy[0], "o", color=col, ms=5)
            ax.plot(*xy[-1], "s", color=col, ms=5)
        ax.plot(rec.true_states[:, 0], rec.true_states[:, 1], "k-", lw=1.5, label="target (true)")
        ax.plot(
            rec.estimates[:, 0],
            rec.estimates[:, 1],
            "--",
            color="tab:red",
            lw=1.2,
            label="target (estimate)",
        )
        for k in range(0, len(rec.estimates), ellipse_every):
            e = ellipse_points(rec.estimates[k], rec.position_covs[k])
            ax.plot(e[:, 0], e[:, 1], "-", color="tab:red", lw=0.6, alpha=0.7)
        ax.set_title(f"{name}: mean trace {rec.mean_trace:.3g} m$^2$, RMSE {rec.rmse:.3g} m")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.grid(True, alpha=0.3)
    axes[0][0].legend(loc="best", fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
