"""Section V on the ``paper`` preset: GSR as good as GBES, random motion clearly worse.

The README's figures come from 100 runs (``activetrack simulate --runs 100``); this test
uses the first 20 seeds, with tolerances that hold for them honestly: on 100 seeds plain
GSR's mean trace is 0.27% above GBES's, almost all from one seed (84) where a local
optimum at the first step sends the team on a worse course (24% worse on that run);
GSR with restarts matches GBES there and on average.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack import make_scenario
from activetrack.baselines import GBES, GSR, RandomMotion, run_monte_carlo
from tests.core.helpers import nees_band


@pytest.mark.slow
def test_gsr_matches_gbes_and_beats_random_motion_on_the_paper_preset():
    sc = make_scenario("paper")
    planners = {
        "gsr": GSR(),
        "gsr-restarts": GSR(restarts=True),
        "gbes": GBES(),
        "rm": RandomMotion(),
    }
    res = run_monte_carlo(sc, planners, runs=20, seed=0, progress=False)
    gsr, gsr_r, gbes, rm = (res[k].mean_trace for k in planners)
    # Paired over the same seeds: GSR within 1% of GBES (or better) on average.
    assert gsr.mean() <= 1.01 * gbes.mean()
    assert gsr_r.mean() <= 1.001 * gbes.mean()
    # Random motion: clearly worse, in the mean and in most runs.
    assert rm.mean() >= 1.5 * gsr.mean()
    assert np.mean(rm > gsr) >= 0.75
    # Consistent filter under GSR: the mean over runs of each run's time-averaged
    # position NEES lies in the 99% band of that statistic (tests.core.helpers.nees_band,
    # about 2 +- 0.3 for 20 runs; this was 1.0 < mean < 3.5). 20 runs do not resolve a
    # 10% error in R (-7% to +9% in the mean NEES): tests/core/test_tasks.py checks that
    # on this preset with 400 runs.
    lo, hi = nees_band(res["gsr"].nees)
    assert lo <= res["gsr"].nees.mean() <= hi, (res["gsr"].nees.mean(), (lo, hi))
    # Violations only come from sensors the target has passed within rho - r (no choice).
    assert res["gsr"].max_violation <= 0.1
