"""The evaluation's team metrics (a world with a filter per robot, issue 37): each episode's
row and the summary against a longhand loop over the world's own metrics."""

from __future__ import annotations

import numpy as np

from activetrack.baselines import GSR
from activetrack.baselines.evaluation import PolicyEvaluation, run_batched, run_episode
from activetrack.baselines.policies import GSRPolicy
from activetrack.envs import parallel_env
from activetrack.world import World

SEEDS = [21, 22, 23]


def _longhand(name, seeds):
    """Return per seed the means over the steps of (robots' mean score, worst, spread)."""
    out = []
    for s in seeds:
        w = World(name, 1)
        w.reset(seeds=[s])
        rows = []
        while not w.truncated.all():
            w.step(GSR().plan(w.planning_problem()))
            m = w.team_metrics(0)
            scores = w.robot_scores(0)
            assert m["robot_score_mean"] == scores.mean() and m["robot_score_worst"] == scores.max()
            rows.append([m["robot_score_mean"], m["robot_score_worst"], m["disagreement"]])
        out.append(np.mean(rows, axis=0))
    return np.array(out)


def test_rows_carry_the_team_metrics_serial_and_batched():
    want = _longhand("radio", SEEDS)
    batched = np.array(run_batched("radio", {}, GSRPolicy(), SEEDS))
    np.testing.assert_allclose(batched[:, 8:11], want, rtol=1e-12)
    env = parallel_env("radio")
    serial = np.array([run_episode(env, GSRPolicy(), s) for s in SEEDS])
    np.testing.assert_allclose(serial[:, 8:11], want, rtol=1e-12)
    # a world with one central filter has none
    assert np.isnan(run_batched("paper", {}, GSRPolicy(), SEEDS[:1])[0][8:11]).all()


def test_the_summary_reports_the_team_metrics_means():
    team = np.array([[1.0, 2.0, 0.5], [3.0, 5.0, 0.25]])
    ev = PolicyEvaluation("gsr", [1, 2], np.ones(2), np.ones(2), -np.ones(2), team=team)
    s = ev.summary()
    assert (s["robot_score_mean"], s["robot_score_worst"], s["disagreement"]) == (2.0, 3.5, 0.375)
    assert "disagreement" not in PolicyEvaluation("gsr", [1], np.ones(1), np.ones(1),
                                                  -np.ones(1)).summary()  # fmt: skip
