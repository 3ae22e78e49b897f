"""Draw the time-to-GSR figure of ``activetrack train pathwise`` runs from a fresh network.

Usage (from the repository's root)::

    python docs/scripts/time_to_gsr.py runs/sight_s0 runs/sight_s1 ... \\
        --label "sight frame" --out docs/_static/figures/time_to_gsr.png

Each run folder holds a ``validation.json`` (the validation mean trace on the episodes of
seeds 500000, ... and the training seconds at each point). A chain of runs, each started
from the previous one's policy, is one argument joined by commas (its seconds add up).
The figure shows, against the training wall time (validations excluded) and against the
episodes simulated, each run's validation mean trace over GSR's on the same validation
episodes (computed here), its running best (the policy the trainer keeps) and the median
over runs; GSR's level is the dashed line at 1. Every run folder must use the same
validation episodes. The figure is written to a temporary file renamed into place.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def chain(spec: str) -> dict[str, np.ndarray]:
    """Return one run's curve: ``seconds``, ``episodes`` and ``trace`` (the validation mean
    trace), the folders of the comma-joined ``spec`` one after the other."""
    seconds, episodes, traces, offset_s, offset_e = [], [], [], 0.0, 0.0
    for i, folder in enumerate(spec.split(",")):
        folder = Path(folder)
        val = json.loads((folder / "validation.json").read_text(encoding="utf-8"))
        cfg = json.loads((folder / "config.json").read_text(encoding="utf-8"))
        its = np.array([it for it, _ in val["curve"]], dtype=np.float64)
        skip = 0 if i == 0 else 1  # a chained run's first point is its start: the last end
        seconds += [offset_s + s for s in val["train_seconds"][skip:]]
        episodes += list(offset_e + its[skip:] * cfg["batch"])
        traces += [t for _, t in val["curve"][skip:]]
        offset_s, offset_e = seconds[-1], episodes[-1]
    return {k: np.asarray(v) for k, v in (("seconds", seconds), ("episodes", episodes),
                                          ("trace", traces))}  # fmt: skip


def gsr_trace(folder: Path) -> tuple[float, int, int]:
    """Return ``(mean trace, first seed, episodes)`` of GSR on the validation episodes of
    the run ``folder`` (its scenario, seeds and count)."""
    from activetrack.baselines.evaluation import evaluate

    val = json.loads((folder / "validation.json").read_text(encoding="utf-8"))
    cfg = json.loads((folder / "config.json").read_text(encoding="utf-8"))
    seed, n = int(val["validation_seed"]), int(cfg["eval_episodes"])
    # pathwise trains on presets only (the paper's loop): the name is the scenario
    task = cfg["scenario"]["name"]
    rows = evaluate(["gsr"], task, episodes=n, seed=seed, progress=False, batched=True)
    return float(np.mean(rows[0].mean_trace)), seed, n


def main(argv: list[str] | None = None) -> int:
    """Draw the figure; return the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", help="run folders (a chain joined by commas)")
    parser.add_argument("--label", default="pathwise from a fresh network")
    parser.add_argument("--out", type=Path, required=True, help="the figure (.png)")
    parser.add_argument("--overwrite", action="store_true")
    args = parser.parse_args(argv)
    if args.out.exists() and not args.overwrite:
        parser.error(f"{args.out} exists (give --overwrite to replace it)")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from activetrack.files import atomic_path

    curves = [chain(spec) for spec in args.runs]
    gsr, seed, n = gsr_trace(Path(args.runs[0].split(",")[0]))
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8), sharey=True)
    for ax, x_key, x_scale, x_label in (
        (axes[0], "seconds", 60.0, "training wall time (min, validations excluded)"),
        (axes[1], "episodes", 1e3, "episodes simulated (thousands)"),
    ):
        for c in curves:
            ratio = c["trace"] / gsr
            ax.plot(c[x_key] / x_scale, ratio, color="tab:blue", alpha=0.25, lw=0.8)
            ax.plot(c[x_key] / x_scale, np.minimum.accumulate(ratio), color="tab:blue",
                    alpha=0.6, lw=1.0, drawstyle="steps-post")  # fmt: skip
        if len({len(c[x_key]) for c in curves}) == 1:
            best = np.median([np.minimum.accumulate(c["trace"] / gsr) for c in curves], 0)
            x = np.median([c[x_key] for c in curves], 0) / x_scale
            ax.plot(x, best, color="black", lw=1.6, drawstyle="steps-post",
                    label=f"median of the running best, {len(curves)} seeds")  # fmt: skip
        ax.axhline(1.0, color="tab:red", ls="--", lw=1.0, label="GSR")
        ax.set_xlabel(x_label)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel(f"validation mean trace / GSR's\n({n} episodes, seeds {seed}...)")
    axes[0].set_ylim(0.93, 1.25)
    axes[0].set_title(args.label, fontsize=10)
    axes[1].legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    print(f"GSR validation mean trace {gsr:.4f}; wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
