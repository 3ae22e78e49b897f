"""Look-ahead settings against GSR on validation seeds: the ratio of mean traces, paired.

Runs GSR and ``Lookahead(**settings)`` for each ``--settings`` JSON object on 100 seeds
from each ``--starts`` (one batched world a run, ``lookahead.run_batched``), and prints
each setting's ratio of the look-ahead's mean trace to GSR's per seed set and their mean.
Meant for seeds disjoint from the evaluation's 1000..1099 (README, "Search
alternatives")::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python tools/lookahead_settings.py --starts 2000 3000 \\
        --settings '{}' '{"horizon": 8}' '{"horizon": 12}' '{"headings": 24}' '{"margin": 0}'
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
    parser.add_argument("--settings", nargs="+", default=["{}"], help="Lookahead keywords")
    args = parser.parse_args()
    settings = [json.loads(s) for s in args.settings]
    for kw in settings:  # bad keywords fail here, before the first episode
        la.Lookahead(**kw)
    seeds = {s: list(range(s, s + 100)) for s in args.starts}
    gsr = {s: la.run_batched(args.scenario, seeds[s])[0].mean() for s in args.starts}
    for kw in settings:
        ratios = [
            la.run_batched(args.scenario, seeds[s], la.Lookahead(**kw))[0].mean() / gsr[s]
            for s in args.starts
        ]
        cells = " ".join(f"{s}: {r:.4f}" for s, r in zip(args.starts, ratios, strict=True))
        print(f"{json.dumps(kw):40s} {cells}  mean {np.mean(ratios):.4f}", flush=True)


if __name__ == "__main__":
    main()
