"""The decentralized tables of docs/results/decentralized.md (issue 37), in the reporting
protocol's form (docs/results/protocol.md).

``scaling``: a set policy (``--policy``, trained on 4 robots) beside distributed GSR and
central GSR on teams of 4, 8, 16 and 32 robots of the ``radio`` family (radio's range,
drops and target with every robot range-and-bearing, range variance 2 m^2, bearing
variance 0.01 rad^2), 100 held-out episodes each (seeds 1000..1099, paired). The team's
score is the robots' mean trace on their own estimates (``team[:, 0]`` of the rows).

``sweep``: on ``radio`` itself, the team's mean trace as the range shrinks (drop 0.2) and
as the drop rate grows (range 10 m), for central GSR, distributed GSR, the look-ahead per
group and a set policy (``--policy``, trained on radio); a figure (``--figure``).

``--policy`` repeated names a set policy's training seeds: they are evaluated on the same
episodes and pooled as one row (the IQM, median and mean of their (runs, episodes) scores
with the two-way bootstrap's intervals, and paired ratios;
:mod:`activetrack.baselines.protocol`). Both write their rows to ``--out`` (JSON, a new
file) and print a Markdown table::

    OPENBLAS_NUM_THREADS=1 python docs/scripts/decentralized_tables.py scaling \\
        --policy runs/set_m4_s1/policy.zip ... --policy runs/set_m4_s5/policy.zip \\
        --out scaling.json
    OPENBLAS_NUM_THREADS=1 python docs/scripts/decentralized_tables.py sweep \\
        --policy runs/set_radio_s1/policy.zip ... --policy runs/set_radio_s5/policy.zip \\
        --out sweep.json --figure docs/_static/figures/radio_sweep.png
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

#: The scaling family's overrides of ``radio`` (a team of any size).
FAMILY = {"sigma_d2": 2.0, "sigma_theta2": 0.01, "team_observation": True}
SIZES = (4, 8, 16, 32)
RANGES = (math.inf, 10.0, 5.0, 2.5)
DROPS = (0.0, 0.2, 0.5, 0.8)


def _rows(runs: list, reference: str, pools: dict[str, list[str]]) -> list[dict[str, Any]]:
    """Return one row per planner and per pool (a learned policy's training seeds pooled,
    ``pools``: row name -> the runs' labels) in the reporting protocol's form: the IQM,
    median and mean of the episodes' robots' mean traces with their two-way bootstrap
    intervals, the IQM's and the mean's ratios to ``reference`` (paired on the episodes),
    the central filter's mean trace and the CPU ms per decision. A pool's row also gives
    each run's mean ratio (``members``)."""
    from activetrack.baselines import protocol

    by_label = {r.policy: r for r in runs}
    team = {label: r.team[:, 0] for label, r in by_label.items()}
    pooled = {label for labels in pools.values() for label in labels}
    groups = {label: [label] for label in by_label if label not in pooled} | pools
    ref = team[reference]
    out = []
    for name, labels in groups.items():
        scores = np.stack([team[label] for label in labels])
        row: dict[str, Any] = {"policy": name, "runs": len(labels)}
        stats = protocol.summary(scores)
        for stat in ("iqm", "median", "mean"):
            row[f"{stat}_trace"], row[f"{stat}_trace_ci95"] = stats[stat], stats[f"{stat}_ci95"]
        for key, stat in (("ratio", "mean"), ("iqm_ratio", "iqm")):
            point, lo, hi = protocol.paired_ratio_interval(scores, ref, stat)
            row[key], row[f"{key}_ci95"] = point, [lo, hi]
        row["central_trace"] = float(np.mean([by_label[x].mean_trace.mean() for x in labels]))
        row["ms_per_step"] = float(np.mean([np.mean(by_label[x].ms_per_step) for x in labels]))
        if len(labels) > 1:
            row["members"] = {x: float(team[x].mean() / ref.mean()) for x in labels}
        out.append(row)
    return out


def _learned(policies: list[str]) -> tuple[dict[str, Any], dict[str, list[str]]]:
    """Return the set policies loaded under the labels ``set policy 1..N`` and the pool
    naming them (one row, ``set policy (N runs)``; a single policy is its own row)."""
    from activetrack.train.policy_io import load_policy

    if len(policies) == 1:
        return {"set policy": load_policy(policies[0])}, {}
    labels = [f"set policy {i}" for i in range(1, len(policies) + 1)]
    loaded = {label: load_policy(p) for label, p in zip(labels, policies, strict=True)}
    return loaded, {f"set policy ({len(policies)} runs)": labels}


def scaling(policies: list[str], episodes: int) -> list[dict[str, Any]]:
    """Return the scaling rows, one per (team size, planner or pooled policy)."""
    from activetrack.baselines.evaluation import evaluate

    learned, pools = _learned(policies)
    out = []
    for m in SIZES:
        runs = evaluate(
            {"gsr": "gsr", "distributed-gsr": "distributed-gsr", **learned},
            "radio", episodes=episodes, seed=1000, batched=True, progress=False,
            n_sensors=m, **FAMILY,
        )  # fmt: skip
        for row in _rows(runs, "distributed-gsr", pools):
            out.append({"robots": m, **row})
            print(out[-1], flush=True)
    return out


def sweep(policies: list[str], episodes: int) -> list[dict[str, Any]]:
    """Return the sweep rows, one per (range, drop, planner or pooled policy)."""
    from activetrack.baselines.evaluation import evaluate
    from activetrack.models.communication import RangeLimited

    learned, pools = _learned(policies)
    cases = [(r, 0.2) for r in RANGES] + [(10.0, d) for d in DROPS if d != 0.2]
    out = []
    for rng, drop in cases:
        comm = RangeLimited(range=rng, drop=drop)
        runs = evaluate(
            {
                "gsr": "gsr", "distributed-gsr": "distributed-gsr",
                "distributed-lookahead": "distributed-lookahead", **learned,
            },
            "radio", episodes=episodes, seed=1000, batched=True, progress=False,
            communication=comm, team_observation=True,
        )  # fmt: skip
        for row in _rows(runs, "gsr", pools):
            out.append({"range": rng if math.isfinite(rng) else None, "drop": drop, **row})
            print(out[-1], flush=True)
    return out


def figure(rows: list[dict[str, Any]], path: Path) -> None:
    """Draw the robots' mean trace against the range (drop 0.2) and the drop (range 10 m)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from activetrack.files import atomic_path

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for name in dict.fromkeys(r["policy"] for r in rows):
        mine = [r for r in rows if r["policy"] == name]
        by_range = [r for r in mine if r["drop"] == 0.2]
        xs = [r["range"] if r["range"] is not None else 40.0 for r in by_range]
        a.plot(xs, [r["mean_trace"] for r in by_range], "o-", label=name)
        by_drop = sorted((r for r in mine if r["range"] == 10.0), key=lambda r: r["drop"])
        b.plot([r["drop"] for r in by_drop], [r["mean_trace"] for r in by_drop], "o-")
    a.set_xscale("log")
    a.set_xticks([2.5, 5.0, 10.0, 40.0], ["2.5", "5", "10", "unlimited"])
    a.minorticks_off()
    a.set_xlabel("communication range (m), drop 0.2")
    b.set_xlabel("drop probability, range 10 m")
    a.set_ylabel("robots' mean trace (m$^2$)")
    a.legend()
    fig.suptitle("radio, 100 held-out episodes")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    plt.close(fig)


def table(rows: list[dict[str, Any]], keys: tuple[str, ...]) -> str:
    """Return the rows as a Markdown table led by ``keys``, in the protocol's form."""
    head = [*keys, "policy", "IQM [95% CI]", "median [95% CI]", "mean [95% CI]",
            "IQM ratio [paired 95% CI]", "mean ratio [paired 95% CI]", "central trace",
            "ms/step"]  # fmt: skip
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def ci(r: dict[str, Any], key: str) -> str:
        lo, hi = r[f"{key}_ci95"]
        return f"{r[key]:.3f} [{lo:.3f}, {hi:.3f}]"

    for r in rows:
        lead = ["inf" if r[k] is None else f"{r[k]:g}" for k in keys]
        lines.append("| " + " | ".join([
            *lead, r["policy"], ci(r, "iqm_trace"), ci(r, "median_trace"),
            ci(r, "mean_trace"), ci(r, "iqm_ratio"), ci(r, "ratio"),
            f"{r['central_trace']:.3f}", f"{r['ms_per_step']:.2f}",
        ]) + " |")  # fmt: skip
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    """Run the chosen table, write its rows and print it."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("which", choices=("scaling", "sweep"))
    parser.add_argument(
        "--policy", required=True, action="append",
        help="a set policy's policy.zip; repeated: its training seeds, pooled as one row",
    )  # fmt: skip
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--out", type=Path, required=True, help="a new JSON file")
    parser.add_argument("--figure", type=Path, help="sweep: the figure's PNG path")
    args = parser.parse_args(argv)
    if args.out.exists():
        parser.error(f"--out: {args.out} exists (results are not overwritten)")
    if args.episodes < 1:
        parser.error(f"--episodes must be a positive integer, got {args.episodes}")
    from activetrack.files import atomic_write_json
    from activetrack.train.utils import configure_torch

    configure_torch(1)  # one torch thread: the policy's ms/step is its own
    if args.which == "scaling":
        rows = scaling(args.policy, args.episodes)
        print(table(rows, ("robots",)))
    else:
        rows = sweep(args.policy, args.episodes)
        print(table(rows, ("range", "drop")))
        if args.figure is not None:
            figure(rows, args.figure)
    atomic_write_json(args.out, rows)


if __name__ == "__main__":
    main()
