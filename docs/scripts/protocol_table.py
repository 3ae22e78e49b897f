"""Print the reporting protocol's Markdown table rows from ``activetrack evaluate`` runs.

Usage (from the repository's root)::

    python docs/scripts/protocol_table.py runs/eval_urban runs/eval_urban_random

For each run folder (its ``results.json`` and the scenario recorded in its
``episodes.json``), one row per policy: the IQM, median and mean trace with their 95%
bootstrap intervals, the track-loss rate with its interval and the no-detection fraction
(limited sensing; "-" otherwise), and the paired ratios of the IQM and of the mean to
GSR's (``docs/results/protocol.md``). A pooled row (``--pool``) names its number of runs.
"""

from __future__ import annotations

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


def rows(folder: Path) -> list[str]:
    """Return the table rows of one ``activetrack evaluate`` output folder."""
    results = json.loads((folder / "results.json").read_text(encoding="utf-8"))
    meta = json.loads((folder / "episodes.json").read_text(encoding="utf-8"))["meta"]
    task = meta["scenario"] if isinstance(meta["scenario"], str) else meta["scenario"]["name"]
    out = []
    for r in results:
        name = r.get("label", r["policy"]) + (f" ({r['runs']} runs)" if "runs" in r else "")
        unseen = "-" if r.get("no_detection") is None else f"{r['no_detection']:.3f}"
        out.append(
            f"| `{task}` | {name} | {cell(r, 'iqm_trace', '.3f')} | "
            f"{cell(r, 'median_trace', '.3f')} | {cell(r, 'mean_trace', '.3f')} | "
            f"{cell(r, 'track_loss_rate', '.3f')} | {unseen} | "
            f"{cell(r, 'iqm_ratio_to_gsr', '.3f')} | {cell(r, 'ratio_to_gsr', '.3f')} |"
        )
    return out


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__, file=sys.stderr)
        return 2
    print(HEAD)
    print("|" + "---|" * HEAD.count(" | ") + "---|")
    for folder in argv:
        print("\n".join(rows(Path(folder))))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
