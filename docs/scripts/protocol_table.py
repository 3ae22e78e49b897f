"""Print the reporting protocol's Markdown table rows from ``activetrack evaluate`` runs.

Usage (from the repository's root)::

    python docs/scripts/protocol_table.py runs/eval_urban runs/eval_urban_random
    python docs/scripts/protocol_table.py --pooled-only --rmse-nees runs/eval_NAME

For each run folder (its ``results.json`` and the scenario recorded in its
``episodes.json``), one row per policy: the IQM, median and mean trace with their 95%
bootstrap intervals, the track-loss rate with its interval and the no-detection fraction
(limited sensing; "-" otherwise), and the paired ratios of the IQM and of the mean to
GSR's (``docs/results/protocol.md``). A pooled row (``--pool``) names its number of runs.
Runs of a task whose targets appear and leave (``births``: the results carry ``gospa``)
get a second table, the multi-target census: GOSPA, the fraction of the time present
each target was tracked, the time to first detection, the episodes in which every
target was tracked, RMSE, NEES and the decision time. ``--pooled-only`` leaves out the
rows of the runs a pool holds (the pool's row stands for them); ``--rmse-nees`` adds the
mean RMSE and NEES columns.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HEAD = (
    "| task | policy | IQM trace (m^2) [95% CI] | median [95% CI] | mean [95% CI] "
    "| track loss [95% CI] | no detection | IQM ratio to GSR [paired 95% CI] "
    "| mean ratio to GSR [paired 95% CI] |"
)


def cell(row: dict, key: str, digits: str) -> str:
    """Return ``row[key] [low, high]`` (``key_ci95``), or "-" if the row has no ``key``."""
    if row.get(key) is None:
        return "-"
    lo, hi = row[f"{key}_ci95"]
    return f"{row[key]:{digits}} [{lo:{digits}}, {hi:{digits}}]"


def load(folder: Path) -> tuple[str, list[dict]]:
    """Return ``(task, results)`` of one ``activetrack evaluate`` output folder: the
    scenario's name (from ``episodes.json``) and the rows of ``results.json``."""
    results = json.loads((folder / "results.json").read_text(encoding="utf-8"))
    meta = json.loads((folder / "episodes.json").read_text(encoding="utf-8"))["meta"]
    task = meta["scenario"] if isinstance(meta["scenario"], str) else meta["scenario"]["name"]
    return task, results


def rows(folder: Path, pooled_only: bool = False, rmse_nees: bool = False) -> list[str]:
    """Return the table rows of one ``activetrack evaluate`` output folder."""
    task, results = load(folder)
    members = {p for r in results for p in r.get("pooled", ())} if pooled_only else set()
    out = []
    for r in results:
        if r["policy"] in members:
            continue
        name = r.get("label", r["policy"]) + (f" ({r['runs']} runs)" if "runs" in r else "")
        unseen = "-" if r.get("no_detection") is None else f"{r['no_detection']:.3f}"
        extra = f" {value(r, 'rmse', '.3f')} | {value(r, 'nees', '.2f')} |" if rmse_nees else ""
        out.append(
            f"| `{task}` | {name} | {cell(r, 'iqm_trace', '.3f')} | "
            f"{cell(r, 'median_trace', '.3f')} | {cell(r, 'mean_trace', '.3f')} | "
            f"{cell(r, 'track_loss_rate', '.3f')} | {unseen} | "
            f"{cell(r, 'iqm_ratio_to_gsr', '.3f')} | {cell(r, 'ratio_to_gsr', '.3f')} |{extra}"
        )
    return out


def value(row: dict, key: str, digits: str) -> str:
    """Return ``row[key]`` formatted, or "-" if the row has none (None: not defined)."""
    return "-" if row.get(key) is None else f"{row[key]:{digits}}"


CENSUS_HEAD = (
    "| task | policy | GOSPA (m) | tracked | first detection (s) | all tracked "
    "| RMSE (m) | NEES | CPU ms/decision |"
)


def census_rows(folder: Path) -> list[str]:
    """Return the census table's rows of one output folder (none without ``gospa``)."""
    task, results = load(folder)
    out = []
    for r in results:
        if r.get("gospa") is None:
            continue
        n = r["episodes"]
        ok = "-" if r.get("all_tracked_fraction") is None else round(r["all_tracked_fraction"] * n)
        out.append(
            f"| `{task}` | {r.get('label', r['policy'])} | {value(r, 'gospa', '.3f')} | "
            f"{value(r, 'fraction_tracked', '.3f')} | {value(r, 'first_detection_s', '.2f')} | "
            f"{ok}/{n} | {value(r, 'rmse', '.3f')} | {value(r, 'nees', '.2f')} | "
            f"{value(r, 'cpu_ms_per_decision', '.3g')} |"
        )
    return out


def main(argv: list[str]) -> int:
    """Print the tables of the folders in ``argv``; return the exit code."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folders", nargs="+", type=Path, help="activetrack evaluate --out folders")
    parser.add_argument("--pooled-only", action="store_true", help="leave out a pool's members")
    parser.add_argument("--rmse-nees", action="store_true", help="add RMSE and NEES columns")
    args = parser.parse_args(argv)
    folders = args.folders
    for folder in folders:
        missing = [f for f in ("results.json", "episodes.json") if not (folder / f).is_file()]
        if missing:
            parser.error(f"{folder}: not an activetrack evaluate folder (no {', '.join(missing)})")
    head = HEAD + (" RMSE (m) | NEES |" if args.rmse_nees else "")
    print(head)
    print("|" + "---|" * head.count(" | ") + "---|")
    for folder in folders:
        print("\n".join(rows(folder, args.pooled_only, args.rmse_nees)))
    census = [row for folder in folders for row in census_rows(folder)]
    if census:
        print()
        print(CENSUS_HEAD)
        print("|" + "---|" * CENSUS_HEAD.count(" | ") + "---|")
        print("\n".join(census))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
