"""The closed-loop runner against a hand-written loop, and the Monte Carlo statistics."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from activetrack import ExtendedKalmanFilter, make_scenario
from activetrack.baselines import GSR, RandomMotion, mean_ci, run_monte_carlo, simulate
from activetrack.models import measurement
from tests.core.helpers import range_bearing


class _Towards:
    """A deterministic planner: every sensor one reach towards the predicted target."""

    def plan(self, problem, rng):
        c = problem.rel_sensors
        n = np.hypot(*c.T)[:, None]
        return problem.sensors - problem.r[:, None] * c / n


def test_simulate_matches_a_hand_written_loop():
    # Independent loop: the stateful EKF class, the measurement model, and the documented
    # draw order (2M uniforms for the sensors, then n process + 2M measurement normals).
    sc = make_scenario("paper", n_steps=15)
    rec = simulate(sc, _Towards(), seed=5)
    rng = np.random.default_rng(5)
    u = rng.random((3, 2))
    sensors = np.array(sc.sensor_center) + (5 * np.sqrt(u[:, 0]))[:, None] * np.stack(
        [np.cos(2 * np.pi * u[:, 1]), np.sin(2 * np.pi * u[:, 1])], -1
    )
    model = sc.model
    x = np.array(sc.x0, float)
    kf = ExtendedKalmanFilter(model, sc.x0_hat, np.diag(sc.P0))
    sd2, st2 = np.array(sc.sigma_d2), np.array(sc.sigma_theta2)
    traces, errors = [], []
    for _ in range(sc.n_steps):
        kf.predict()
        c = sensors - kf.x[:2]
        sensors = sensors - 1.0 * c / np.hypot(*c.T)[:, None]
        w = rng.standard_normal(10)
        x = model.Phi @ x + model.noise_factor @ w[:4]
        z = range_bearing(x[:2], sensors) + w[4:].reshape(3, 2) * np.sqrt(np.stack([sd2, st2], -1))
        z[:, 1] = measurement.wrap_angle(z[:, 1])
        kf.update(z, sensors, sd2, st2)
        traces.append(np.trace(kf.position_cov))
        errors.append(np.hypot(*(x[:2] - kf.x[:2])))
    assert np.allclose(rec.trace, traces, rtol=1e-9)
    assert np.allclose(rec.error, errors, rtol=1e-7, atol=1e-9)
    assert np.allclose(rec.sensors[-1], sensors)
    assert rec.rmse == pytest.approx(np.sqrt(np.mean(np.square(errors))))


def test_planner_randomness_does_not_shift_the_world():
    class Noisy(_Towards):
        def plan(self, problem, rng):
            rng.standard_normal(7)  # draws, then acts like _Towards
            return super().plan(problem, rng)

    sc = make_scenario("paper", n_steps=10)
    a, b = simulate(sc, _Towards(), 3), simulate(sc, Noisy(), 3)
    assert np.array_equal(a.true_states, b.true_states)
    assert np.array_equal(a.trace, b.trace)


def test_rm_runs_reproduce_from_the_seed():
    sc = make_scenario("paper", n_steps=10)
    a, b = simulate(sc, RandomMotion(), 4), simulate(sc, RandomMotion(), 4)
    assert np.array_equal(a.sensors, b.sensors)
    assert np.all(a.violation <= 1e-9)


def test_max_trace_stops_the_run():
    sc = make_scenario("paper", n_steps=30, max_trace=3.5)
    rec = simulate(sc, _Towards(), 0)
    assert rec.terminated
    assert rec.trace[-1] > 3.5 and np.all(rec.trace[:-1] <= 3.5)
    assert len(rec.sensors) == len(rec.trace) + 1


def test_mean_ci_is_the_student_t_interval():
    x = np.array([1.0, 2.0, 4.0, 7.0])
    mean, lo, hi = mean_ci(x)
    half = stats.t.ppf(0.975, 3) * np.std(x, ddof=1) / 2.0
    assert (mean, lo, hi) == pytest.approx((3.5, 3.5 - half, 3.5 + half))


def test_monte_carlo_pairs_seeds_and_summarizes():
    sc = make_scenario("paper", n_steps=5)
    res = run_monte_carlo(sc, {"gsr": GSR(), "towards": _Towards()}, 3, seed=7, progress=False)
    assert list(res) == ["gsr", "towards"]
    assert res["gsr"].seeds == [7, 8, 9]
    direct = simulate(sc, _Towards(), 8)
    assert res["towards"].mean_trace[1] == pytest.approx(direct.mean_trace)
    s = res["gsr"].summary()
    assert s["runs"] == 3 and s["mean_trace_ci95"][0] <= s["mean_trace"] <= s["mean_trace_ci95"][1]
    with pytest.raises(ValueError, match="runs"):
        run_monte_carlo(sc, {"gsr": GSR()}, 0)


def test_a_studys_summary_reports_the_protocols_statistics():
    # The IQM against scipy's trimmed mean with the quarter cut (rliable's aggregate_iqm),
    # the median against numpy's; each point inside its interval; the paired ratios to
    # GSR are the ratios of the runs' means and IQMs, GSR's own exactly 1.
    sc = make_scenario("paper", n_steps=6)
    res = run_monte_carlo(sc, {"gsr": GSR(), "towards": _Towards()}, 9, seed=3, progress=False)
    gsr, other = res["gsr"], res["towards"]
    s, own = other.summary(gsr), gsr.summary(gsr)
    x, y = other.mean_trace, gsr.mean_trace
    assert s["iqm_trace"] == pytest.approx(stats.trim_mean(x, 0.25), rel=1e-12)
    assert s["median_trace"] == pytest.approx(np.median(x), rel=1e-12)
    for key in ("iqm_trace", "median_trace", "ratio_to_gsr", "iqm_ratio_to_gsr"):
        lo, hi = s[f"{key}_ci95"]
        assert lo <= s[key] <= hi, key
    assert s["ratio_to_gsr"] == pytest.approx(np.mean(x) / np.mean(y), rel=1e-12)
    iqm_ratio = stats.trim_mean(x, 0.25) / stats.trim_mean(y, 0.25)
    assert s["iqm_ratio_to_gsr"] == pytest.approx(iqm_ratio, rel=1e-12)
    assert own["ratio_to_gsr"] == own["iqm_ratio_to_gsr"] == 1.0
    assert own["ratio_to_gsr_ci95"] == [1.0, 1.0]
    alone = other.summary()  # no reference: no ratio
    assert alone["ratio_to_gsr"] is None and alone["iqm_trace"] == s["iqm_trace"]
    shifted = run_monte_carlo(sc, {"gsr": GSR()}, 9, seed=4, progress=False)["gsr"]
    unpaired = other.summary(shifted)  # other seeds: no paired ratio
    assert unpaired["ratio_to_gsr"] is None and unpaired["iqm_ratio_to_gsr_ci95"] == [None, None]


def test_two_target_runs_record_every_target_and_plot(tmp_path):
    from activetrack.baselines import GSR
    from activetrack.baselines.plotting import plot_trajectories
    from activetrack.baselines.simulation import simulate
    from activetrack.world.scenarios import make_scenario

    sc = make_scenario("two_targets", n_steps=4)
    rec = simulate(sc, GSR(), 0)
    assert rec.true_states.shape == (5, 2, 4) and rec.position_covs.shape == (5, 2, 2, 2)
    # The recorded covariances are each target's position block, read independently.
    from activetrack.world import World

    w = World(sc)
    w.reset(seeds=[0])
    np.testing.assert_array_equal(rec.position_covs[0, 1], w.get("P", 0, 1)[:2, :2])
    path = plot_trajectories({"gsr": rec}, tmp_path / "t.png")
    assert path.stat().st_size > 1000


class _Counting(_Towards):
    """:class:`_Towards` that records the problems it is asked to plan."""

    def __init__(self):
        self.problems = []

    def plan(self, problem, rng):
        self.problems.append(problem)
        return super().plan(problem, rng)


def test_the_first_plan_is_a_warm_up_outside_the_timings():
    # One untimed plan on the first seed's first problem before the runs (the compile of a
    # fresh process), then exactly one timed plan per step; the runs are unchanged.
    sc = make_scenario("paper", n_steps=5, max_trace=None)
    planner = _Counting()
    res = run_monte_carlo(sc, {"c": planner}, 3, seed=4, progress=False, keep_records=3)
    assert len(planner.problems) == 1 + 3 * 5 == 1 + res["c"].plan_times.size
    first = simulate(sc, _Counting(), 4)
    np.testing.assert_array_equal(planner.problems[0].sensors, planner.problems[1].sensors)
    for k, rec in enumerate(res["c"].records):
        np.testing.assert_array_equal(rec.trace, simulate(sc, _Towards(), 4 + k).trace)
    np.testing.assert_array_equal(res["c"].records[0].sensors, first.sensors)
    s = res["c"].summary()
    assert s["plan_time_warmup_ms"] >= 0.0 and "seeds" not in s
    assert s["seed_range"] == {"first": 4, "last": 6}  # both ends included: 3 runs
    # Every run's per-step trace, as the runs recorded it.
    np.testing.assert_array_equal(res["c"].traces, [r.trace for r in res["c"].records])


def test_traces_of_runs_ended_early_are_padded_with_nan():
    sc = make_scenario("paper", n_steps=9, max_trace=3.5)
    res = run_monte_carlo(sc, {"rm": RandomMotion()}, 4, seed=0, progress=False, keep_records=4)
    r = res["rm"]
    lengths = [len(rec.trace) for rec in r.records]
    assert r.n_terminated >= 1 and min(lengths) < 9  # the case is exercised
    for row, rec in zip(r.traces, r.records, strict=True):
        np.testing.assert_array_equal(row[: len(rec.trace)], rec.trace)
        assert np.isnan(row[len(rec.trace) :]).all()


def test_comparison_figure_plots_every_runs_mean_trace_and_its_band(tmp_path, monkeypatch):
    from activetrack.baselines import plotting

    sc = make_scenario("paper", n_steps=6, max_trace=None)
    res = run_monte_carlo(sc, {"towards": _Towards(), "rm": RandomMotion()}, 4, progress=False)
    drawn = []
    monkeypatch.setattr(plotting, "save_figure", lambda fig, path: drawn.append(fig) or path)
    plotting.plot_comparison(res, tmp_path / "c.png")
    ax, bx = drawn[0].axes
    for line, band, r in zip(ax.lines, ax.collections, res.values(), strict=True):
        # The mean over the 4 runs and its Student-t 95% band, step by step.
        traces = np.asarray(r.traces)
        half = stats.t.ppf(0.975, 3) * traces.std(axis=0, ddof=1) / 2.0
        np.testing.assert_allclose(line.get_ydata(), traces.mean(axis=0), rtol=1e-12)
        verts = band.get_paths()[0].vertices  # the band's outline: upper edge, lower edge
        lo, hi = traces.mean(0) - half, traces.mean(0) + half
        for y in (lo, hi):
            assert all(np.isclose(verts[:, 1], v, rtol=1e-12).any() for v in y)
    # Right: each run's mean trace as a point.
    points = [ln.get_ydata() for ln in bx.lines if ln.get_marker() == "o"]
    for got, r in zip(points, res.values(), strict=True):
        np.testing.assert_array_equal(got, r.mean_trace)
    # The trajectory figure names what its markers and ellipses are.
    plotting.plot_trajectories({k: r.records[0] for k, r in res.items()}, tmp_path / "t.png")
    labels = [t.get_text() for t in drawn[1].legends[0].get_texts()]
    assert {"start (k = 0)", "end"} <= set(labels) and any("3-sigma" in t for t in labels)
    lines = drawn[1].axes[0].lines
    from matplotlib.colors import to_hex

    sensor_cols = {to_hex(ln.get_color()) for ln in lines if ln.get_label().startswith("sensor")}
    assert len(sensor_cols) == 3  # the paper's 3 sensors, each its own colour
    assert not sensor_cols & {to_hex("tab:red"), to_hex("k")}  # none a target's colour
