"""The patrol task (issue 38): the multi-target census on a hand-made episode, and GSR
tracking every target that enters."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from activetrack.metrics.track_census import TrackCensus


def test_census_on_a_hand_made_episode():
    # Two slots, c = 10, p = 2. Target 0 enters at step 0 in slot 0, is tracked from step
    # 1 (1 m off), leaves after step 2; target 1 enters at step 2 in slot 1, never tracked.
    census = TrackCensus(dt=0.5, c=10.0, p=2.0, grace=1)
    far = np.array([[0.0, 0.0], [50.0, 50.0]])
    est = np.array([[1.0, 0.0], [0.0, 0.0]])
    census.add([True, False], [False, False], [0, -1], far, est)  # one missed: c^2/2 = 50
    census.add([True, False], [True, False], [0, -1], far, est)  # paired at 1 m: 1
    census.add([True, True], [True, False], [0, 1], far, est)  # 1 + one missed: 51
    census.add([False, True], [False, False], [-1, 1], far, est)  # one missed: 50
    s = census.summary()
    assert s["gospa"] == pytest.approx(np.mean(np.sqrt([50.0, 1.0, 51.0, 50.0])))
    assert s["fraction_tracked"] == [pytest.approx(2 / 3), 0.0]
    assert s["first_detection"] == [pytest.approx(0.5), None]
    assert s["all_tracked"] is False  # target 1 entered 1 >= grace steps before the end
    assert s["n_targets"] == 2
    census.grace = 2  # now it entered too late to count
    assert census.summary()["all_tracked"] is True


@pytest.mark.slow  # 20 batched GSR episodes of 300 steps
def test_gsr_tracks_every_target_that_enters_patrol():
    # The acceptance: every target that enters is tracked in >= 95% of episodes. With n
    # episodes, a true rate of 0.95 gives at least x successes with probability 0.99
    # (x = the binomial's 1% quantile); fewer fails the test.
    from activetrack.baselines.evaluation import evaluate

    n = 20
    res = evaluate(["gsr"], "patrol", episodes=n, seed=0, progress=False, batched=True)[0]
    ok = res.census["all_tracked"]
    x = stats.binom.ppf(0.01, n, 0.95)
    assert ok.sum() >= x, ok
    assert np.all(np.isfinite(res.census["gospa"]))
    first = res.census["first_detection"]
    assert np.all(first[np.isfinite(first)] >= 0.0)
    summary = res.summary()
    assert {"gospa", "fraction_tracked", "first_detection_s", "all_tracked_fraction"} <= set(
        summary
    )
