"""``activetrack evaluate``'s reporting-protocol columns (IQM, median and track-loss rate
with their intervals), each recomputed from the written episodes or from the simulation
runner's own records."""

from __future__ import annotations

import json

import numpy as np
import pytest

from activetrack import make_scenario
from activetrack.baselines import RandomMotion
from activetrack.baselines.evaluation import evaluate, format_table, summaries
from activetrack.baselines.simulation import simulate
from activetrack.cli import main

SEED = 1000


def hand_iqm(values) -> float:
    x = np.sort(np.ravel(values))
    k = x.size // 4
    return float(np.mean(x[k : x.size - k]))


def test_cli_writes_the_protocol_columns_on_the_paper_task(tmp_path, capsys):
    """Three paper episodes through the command: every old key is still there and the new
    ones are the statistics of episodes.json's values; unlimited sensing has no track
    loss."""
    out = tmp_path / "run"
    code = main(
        ["evaluate", "--scenario", "paper", "--policy", "gsr", "--policy", "rm",
         "--episodes", "3", "--no-progress", "--no-plot", "--out", str(out)]
    )  # fmt: skip
    assert code == 0
    printed = capsys.readouterr().out
    assert "IQM [95% CI]" in printed and "median [95% CI]" in printed
    assert "IQM ratio to GSR" in printed and "track loss" not in printed
    rows = json.loads((out / "results.json").read_text())
    episodes = json.loads((out / "episodes.json").read_text())["policies"]
    old = {"policy", "label", "mean_trace", "mean_trace_ci95", "median_trace", "rmse",
           "rmse_ci95", "mean_return", "mean_return_ci95", "nees", "cpu_ms_per_decision",
           "ms_per_step", "ratio_to_gsr", "ratio_to_gsr_ci95", "episodes", "seed_range",
           "requested"}  # fmt: skip
    gsr = np.asarray(episodes["gsr"]["mean_trace"])
    for r in rows:
        assert old <= r.keys()
        assert not {"track_loss_rate", "no_detection"} & r.keys()
        trace = np.asarray(episodes[r["policy"]]["mean_trace"])
        assert r["iqm_trace"] == pytest.approx(hand_iqm(trace), rel=1e-12)
        assert r["median_trace"] == pytest.approx(np.median(trace), rel=1e-12)
        for key in ("iqm_trace", "median_trace"):
            lo, hi = r[f"{key}_ci95"]
            assert trace.min() <= lo <= r[key] <= hi <= trace.max()
        assert r["iqm_ratio_to_gsr"] == pytest.approx(hand_iqm(trace) / hand_iqm(gsr))
        lo, hi = r["iqm_ratio_to_gsr_ci95"]
        assert lo <= r["iqm_ratio_to_gsr"] <= hi
    assert rows[0]["iqm_ratio_to_gsr_ci95"] == [1.0, 1.0]  # GSR to itself


@pytest.fixture(scope="module")
def urban():
    # Episode 1001 loses the target for long stretches, 1002 briefly.
    return evaluate(["rm"], "urban", 2, 1001, progress=False, batched=True)


def test_track_loss_rate_equals_the_simulation_runners_records(urban):
    """The evaluation's per-episode track-loss rate is, on the simulation runner's record
    of the same episode, the fraction of steps with no detection and a position trace
    above the prior's, tr P0[:2, :2] = 8 m^2; the summary's rate is their mean."""
    rm, _ = urban
    sc = make_scenario("urban")
    assert rm.loss_trace == [8.0]
    for seed, rate in zip(rm.seeds, rm.track_loss, strict=True):
        rec = simulate(sc, RandomMotion(), seed)
        traces = np.trace(rec.position_covs[1:], axis1=1, axis2=2)
        lost = ~rec.seen[:, 0] & (traces > 8.0)
        assert rate == pytest.approx(np.mean(lost), abs=1e-15)
        assert rm.no_detection[list(rm.seeds).index(seed)] == pytest.approx(np.mean(~rec.seen))
    assert np.any(rm.track_loss > 0)  # the episodes do lose the target
    row = summaries(urban)[0]
    assert row["track_loss_rate"] == pytest.approx(np.mean(rm.track_loss))
    lo, hi = row["track_loss_rate_ci95"]
    assert rm.track_loss.min() <= lo <= row["track_loss_rate"] <= hi <= rm.track_loss.max()
    assert row["track_loss_threshold"] == [8.0]
    assert "track loss" in format_table([row])


def test_loss_trace_sets_the_threshold():
    """GSR's urban episode 1002 misses the target in some steps, never for long: at the
    default threshold (8 m^2) it is never lost; at 1e9 m^2 neither; at 1e-9 m^2 every
    unmeasured step is a loss (the no-detection fraction)."""

    def gsr(loss_trace):
        return evaluate(
            {"gsr": "gsr"}, "urban", 1, 1002, progress=False, batched=True, loss_trace=loss_trace
        )[0]

    default, high, low = gsr(None), gsr(1e9), gsr(1e-9)
    assert default.no_detection[0] > 0 and default.track_loss.tolist() == [0.0]
    assert high.track_loss.tolist() == [0.0] and high.loss_trace == [1e9]
    assert low.track_loss.tolist() == low.no_detection.tolist() == default.no_detection.tolist()
    with pytest.raises(ValueError, match="loss_trace must be a number"):
        evaluate(["rm"], "paper", 1, SEED, progress=False, loss_trace=0.0)


def test_pooled_row_of_training_seeds_is_the_runs_by_episodes_statistics():
    """Three 'training seeds' of one policy on the same five episodes pooled into one row:
    its statistics are those of the 3 x 5 matrix, by hand; its ratios are to GSR's."""
    from activetrack.baselines.evaluation import PolicyEvaluation

    rng = np.random.default_rng(11)
    seeds = list(range(SEED, SEED + 5))

    def run(label, trace):
        e = trace.size
        return PolicyEvaluation(
            label, seeds, trace, np.sqrt(trace), -50 * trace, True, np.full(e, 2.0),
            np.full(e, 1.5), rng.uniform(0, 0.3, e), np.arange(e), rng.uniform(0, 0.2, e), [8.0],
        )  # fmt: skip

    gsr = run("gsr", rng.lognormal(0.0, 0.5, 5))
    runs = [run(f"dagger_{k}", gsr.mean_trace * rng.lognormal(0.1, 0.2, 5)) for k in range(3)]
    rows = summaries([*runs, gsr], {"dagger": [r.policy for r in runs]})
    assert [r["policy"] for r in rows] == ["dagger_0", "dagger_1", "dagger_2", "gsr", "dagger"]
    pooled = rows[-1]
    m = np.stack([r.mean_trace for r in runs])
    assert pooled["runs"] == 3 and pooled["episodes"] == 5
    assert pooled["pooled"] == ["dagger_0", "dagger_1", "dagger_2"]
    assert pooled["iqm_trace"] == pytest.approx(hand_iqm(m))  # 15 values, 3 cut each end
    assert pooled["median_trace"] == pytest.approx(np.median(m))
    assert pooled["mean_trace"] == pytest.approx(np.mean(m))
    assert pooled["ratio_to_gsr"] == pytest.approx(np.mean(m) / np.mean(gsr.mean_trace))
    assert pooled["iqm_ratio_to_gsr"] == pytest.approx(hand_iqm(m) / hand_iqm(gsr.mean_trace))
    assert pooled["mean_return"] == pytest.approx(-50 * np.mean(m))
    assert pooled["rmse"] == pytest.approx(np.mean(np.sqrt(m)))
    lost = np.stack([r.track_loss for r in runs])
    assert pooled["track_loss_rate"] == pytest.approx(np.mean(lost))
    assert pooled["no_detection"] == pytest.approx(np.mean([r.no_detection for r in runs]))
    assert pooled["longest_gap"] == 4 and pooled["nees"] == 2.0
    for key in ("mean_trace", "iqm_trace", "median_trace", "track_loss_rate"):
        lo, hi = pooled[f"{key}_ci95"]
        assert lo <= pooled[key] <= hi
    assert "dagger (3 runs)" in format_table(rows)
    with pytest.raises(ValueError, match="pool 'x' must name distinct evaluated policies"):
        summaries([*runs, gsr], {"x": ["dagger_0", "nope"]})
    with pytest.raises(ValueError, match="pool names must be new"):
        summaries([*runs, gsr], {"gsr": ["dagger_0"]})
    for bad in ({"x": 3}, {"x": []}, {"x": ["dagger_0", "dagger_0"]}, {"x": [None]}):
        with pytest.raises(ValueError, match="pool 'x' must name distinct"):
            summaries([*runs, gsr], bad)
    with pytest.raises(ValueError, match="pools must map a name"):
        summaries([*runs, gsr], ["dagger_0"])


def test_cli_pool_option(tmp_path, capsys):
    """--pool adds a row whose IQM is that of the pooled episodes written; a pool naming a
    policy not evaluated is refused before any episode runs (no output folder)."""
    out = tmp_path / "run"
    argv = ["evaluate", "--scenario", "paper", "--policy", "gsr", "--policy", "rm",
            "--episodes", "2", "--no-progress", "--no-plot", "--out", str(out)]  # fmt: skip
    assert main([*argv, "--pool", "both=gsr,rm"]) == 0
    rows = json.loads((out / "results.json").read_text())
    episodes = json.loads((out / "episodes.json").read_text())["policies"]
    both = rows[-1]
    assert (
        both["policy"] == "both"
        and both["runs"] == 2
        and "both (2 runs)" in capsys.readouterr().out
    )
    m = [episodes[p]["mean_trace"] for p in ("gsr", "rm")]
    assert both["iqm_trace"] == pytest.approx(hand_iqm(m))
    bad = tmp_path / "bad"
    assert main([*argv[:-1], str(bad), "--pool", "x=gsr,lookahead"]) == 2
    assert "pool 'x' must name distinct evaluated policies" in capsys.readouterr().err
    assert not bad.exists()
    assert main([*argv[:-1], str(bad), "--pool", "x=gsr", "--pool", "x=rm"]) == 2
    assert "each NAME once" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse's usage error
        main([*argv[:-1], str(bad), "--pool", "x"])
    assert "must be NAME=POLICY" in capsys.readouterr().err
    assert not bad.exists()
