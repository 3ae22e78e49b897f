"""Look-ahead settings against GSR on validation seeds: the ratio of mean traces, paired.

Runs GSR and ``Lookahead(**settings)`` for each ``--settings`` JSON object on
``--episodes`` seeds from each ``--starts`` (one batched world a run,
``lookahead.run_batched``), and prints each setting's ratio of the look-ahead's mean trace
to GSR's per seed set and their mean; with ``--paired``, each later setting's difference
from the first (in units of GSR's mean trace, per seed set, with its paired 95% interval)
and the episodes in which a sensor ended inside the true target's ``rho`` disk (GSR's
count first). Meant for seeds disjoint from the evaluation's 1000..1099 (README, "Search
alternatives")::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python tools/lookahead_settings.py --starts 2000 3000 \\
        --settings '{}' '{"horizon": 8}' '{"horizon": 12}' '{"headings": 24}' '{"margin": 0}'
    OPENBLAS_NUM_THREADS=1 .venv/bin/python tools/lookahead_settings.py --starts 2000 3000 \\
        --episodes 1000 --paired --settings '{"tail": 0}' '{}'
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from activetrack.baselines import lookahead as la


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="paper")
    parser.add_argument("--starts", type=int, nargs="+", default=[2000, 3000])
    parser.add_argument("--episodes", type=int, default=100, help="seeds per start")
    parser.add_argument("--settings", nargs="+", default=["{}"], help="Lookahead keywords")
    parser.add_argument("--paired", action="store_true", help="differences from the first")
    args = parser.parse_args()
    settings = [json.loads(s) for s in args.settings]
    for kw in settings:  # bad keywords fail here, before the first episode
        la.Lookahead(**kw)
    seeds = {s: list(range(s, s + args.episodes)) for s in args.starts}
    gsr = {s: la.run_batched(args.scenario, seeds[s]) for s in args.starts}
    if args.paired:
        counts = " ".join(f"{s}: {np.count_nonzero(gsr[s][1] > 0)}" for s in args.starts)
        print(f"{'GSR':40s} inside a rho disk {counts}", flush=True)
    first: dict = {}
    for kw in settings:
        cells, ratios = [], []
        for s in args.starts:
            trace, deepest = la.run_batched(args.scenario, seeds[s], la.Lookahead(**kw))
            ratios.append(trace.mean() / gsr[s][0].mean())
            cells.append(f"{s}: {ratios[-1]:.4f}")
            if args.paired and s in first:
                d = (trace - first[s]) / gsr[s][0].mean()
                half = 1.96 * d.std(ddof=1) / np.sqrt(d.size)
                inside = np.count_nonzero(deepest > 0)
                cells[-1] += f" ({d.mean():+.4f} +- {half:.4f}, inside {inside})"
            elif args.paired:
                first[s] = trace
                cells[-1] += f" (inside {np.count_nonzero(deepest > 0)})"
        print(f"{json.dumps(kw):40s} {' '.join(cells)}  mean {np.mean(ratios):.4f}", flush=True)


if __name__ == "__main__":
    main()
