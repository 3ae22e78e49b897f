"""Evaluation of policies on held-out seeds, checked against the simulation runner."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from scipy import stats

from activetrack import make_scenario
from activetrack.baselines import GSR, RandomMotion
from activetrack.baselines.evaluation import (
    bootstrap_ci,
    evaluate,
    format_table,
    paired_ratio_ci,
    run_evaluation,
    summaries,
    write_results,
)
from activetrack.baselines.simulation import simulate

SEED, EPISODES = 1000, 4


@pytest.fixture(scope="module")
def rm_and_gsr():
    return evaluate(["rm"], "paper", EPISODES, SEED, progress=False)


def test_episodes_match_the_simulation_runner(rm_and_gsr):
    """The env-based evaluation reproduces simulate() on the same seeds (GSR added last)."""
    rm, gsr = rm_and_gsr
    assert [r.policy for r in rm_and_gsr] == ["rm", "gsr"]
    assert rm.requested and not gsr.requested
    sc = make_scenario("paper")
    for planner, res in ((RandomMotion(), rm), (GSR(), gsr)):
        assert res.seeds == [SEED + j for j in range(EPISODES)]
        recs = [simulate(sc, planner, s) for s in res.seeds]
        np.testing.assert_allclose(res.mean_trace, [r.mean_trace for r in recs], rtol=1e-10)
        np.testing.assert_allclose(res.rmse, [r.rmse for r in recs], rtol=1e-10)
        # The return is minus the summed trace (reward_scale 1, 50 steps).
        np.testing.assert_allclose(res.returns, [-r.trace.sum() for r in recs], rtol=1e-10)
    assert np.mean(rm.mean_trace) > np.mean(gsr.mean_trace)


def test_summary_statistics_are_independent_computations(rm_and_gsr):
    rows = summaries(rm_and_gsr)
    rm, gsr = rm_and_gsr
    r = rows[0]
    assert r["policy"] == "rm"
    assert r["mean_trace"] == pytest.approx(np.mean(rm.mean_trace))
    assert r["median_trace"] == pytest.approx(np.median(rm.mean_trace))
    lo, hi = r["mean_trace_ci95"]  # a bootstrap interval: within the sample's range
    assert rm.mean_trace.min() <= lo <= r["mean_trace"] <= hi <= rm.mean_trace.max()
    lo, hi = r["rmse_ci95"]  # the same bootstrap interval (tested below)
    assert rm.rmse.min() <= lo <= r["rmse"] <= hi <= rm.rmse.max()
    assert r["rmse"] == pytest.approx(np.mean(rm.rmse))
    assert r["mean_return"] == pytest.approx(np.mean(rm.returns))
    assert r["ratio_to_gsr"] == pytest.approx(np.mean(rm.mean_trace) / np.mean(gsr.mean_trace))
    lo, hi = r["ratio_to_gsr_ci95"]
    assert lo <= r["ratio_to_gsr"] <= hi
    assert rows[1]["ratio_to_gsr"] == 1.0 and rows[1]["ratio_to_gsr_ci95"] == [1.0, 1.0]
    table = format_table(rows)
    assert "gsr (reference)" in table and table.count("\n") == 3


def test_paired_ratio_interval():
    rng = np.random.default_rng(0)
    ref = rng.uniform(1, 3, 200)
    assert paired_ratio_ci(ref, ref) == (1.0, 1.0)
    lo, hi = paired_ratio_ci(1.1 * ref + rng.normal(0, 0.05, 200), ref)
    assert lo < 1.1 < hi and hi - lo < 0.05  # pairing removes the between-episode spread


class TowardsTarget:
    """An expert: every sensor heads straight for the predicted target at full speed."""

    def plan(self, problem):
        c = problem.rel_sensors
        return problem.sensors - problem.r[:, None] * c / np.linalg.norm(c, axis=1, keepdims=True)


def test_policy_objects_and_mapping_labels():
    res = evaluate({"towards": TowardsTarget(), "gsr": "gsr"}, "paper", 2, SEED, progress=False)
    assert [r.policy for r in res] == ["towards", "gsr"]
    assert all(r.requested for r in res)
    # Deterministic policy, same seeds: the same numbers again.
    again = evaluate({"towards": TowardsTarget()}, "paper", 2, SEED, progress=False)
    np.testing.assert_array_equal(again[0].mean_trace, res[0].mean_trace)


def test_write_results_and_cli_function(tmp_path, capsys):
    rows = run_evaluation(["gsr", "rm"], "paper", 3, SEED, out_dir=tmp_path, progress=False)
    out = capsys.readouterr().out
    assert "rm" in out and "reference" not in out
    data = json.loads((tmp_path / "results.json").read_text())
    assert isinstance(data, list) and [d["policy"] for d in data] == ["gsr", "rm"]
    for d in data:
        assert {
            "policy",
            "mean_trace",
            "mean_trace_ci95",
            "rmse",
            "mean_return",
            "ratio_to_gsr",
        } <= d.keys()
    assert data == json.loads(json.dumps(rows))
    episodes = json.loads((tmp_path / "episodes.json").read_text())
    rm = episodes["policies"]["rm"]
    assert rm["seeds"] == [SEED, SEED + 1, SEED + 2]
    assert rm["ms_per_step"] == rm["cpu_ms_per_decision"] and len(rm["ms_per_step"]) == 3
    np.testing.assert_allclose(np.mean(rm["cpu_ms_per_decision"]), data[1]["cpu_ms_per_decision"])
    assert (tmp_path / "mean_trace.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_errors(tmp_path):
    with pytest.raises(ValueError, match="unknown policy"):
        evaluate(["nope"], "paper", 1, SEED, progress=False)
    with pytest.raises(TypeError, match="act"):
        evaluate([object()], "paper", 1, SEED, progress=False)
    with pytest.raises(ValueError, match="distinct"):
        evaluate(["rm", "rm"], "paper", 1, SEED, progress=False)
    with pytest.raises(ValueError, match="episodes"):
        evaluate(["rm"], "paper", 0, SEED, progress=False)
    for episodes, seed, field in [(2.5, SEED, "episodes"), (True, SEED, "episodes"),
                                  (1, -1, "seed"), (1, "a", "seed")]:  # fmt: skip
        with pytest.raises(ValueError, match=f"{field} must be an integer"):
            evaluate(["rm"], "paper", episodes, seed, progress=False)
    with pytest.raises(ValueError, match="no such policy file"):
        evaluate([str(tmp_path / "policy.zip")], "paper", 1, SEED, progress=False)


def _install_loader(root, suffix, module):
    """Put on ``root`` a distribution whose entry point loads ``*.suffix`` files with
    ``module.load`` (an RM policy; it records the paths it was given)."""
    info = root / "fakeloader-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: fakeloader\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        f"[activetrack.policy_loaders]\n{suffix} = {module}:load\n"
        "broken = no_such_module_for_activetrack:load\n"
    )
    (root / f"{module}.py").write_text(
        "from activetrack.baselines.policies import RMPolicy\n"
        "paths = []\n"
        "def load(path):\n"
        "    paths.append(path)\n"
        "    return RMPolicy()\n"
    )


def test_a_policy_file_loads_through_the_installed_entry_points(rm_and_gsr, tmp_path, monkeypatch):
    # A third package's loader, found by the file's suffix: its policy is the one evaluated
    # (the same episodes as the named RM policy), and it received the path given.
    plugins = tmp_path / "site"
    plugins.mkdir()
    _install_loader(plugins, "rmpolicy", "fake_rm_loader")
    monkeypatch.syspath_prepend(str(plugins))
    monkeypatch.delitem(sys.modules, "fake_rm_loader", raising=False)
    policy_file = tmp_path / "mine.RMPolicy"
    policy_file.write_text("any content: the loader decides")
    rm, gsr = evaluate([str(policy_file)], "paper", EPISODES, SEED, progress=False)
    assert sys.modules["fake_rm_loader"].paths == [policy_file]
    assert rm.policy == str(policy_file)
    np.testing.assert_array_equal(rm.mean_trace, rm_and_gsr[0].mean_trace)
    np.testing.assert_array_equal(gsr.mean_trace, rm_and_gsr[1].mean_trace)
    # A loader that cannot be imported is named, before any episode.
    broken = tmp_path / "x.broken"
    broken.write_text("")
    with pytest.raises(ImportError, match="x.broken: its loader no_such_module_for_activetrack"):
        evaluate([str(broken)], "paper", 1, SEED, progress=False)


def test_a_policy_file_without_a_loader_is_refused_naming_the_installed_ones(tmp_path):
    notes = tmp_path / "notes.txt"
    notes.write_text("not a policy")
    # The train layer provides .zip (pyproject.toml); nothing provides .txt.
    with pytest.raises(ValueError, match=r"notes.txt: no policy loader for '.txt' files "
                                         r"\(installed: .*\.zip"):  # fmt: skip
        evaluate([str(notes)], "paper", 1, SEED, progress=False)
    bare = tmp_path / "policy"
    bare.write_text("")
    with pytest.raises(ValueError, match="no policy loader for files without a suffix"):
        evaluate([str(bare)], "paper", 1, SEED, progress=False)


def test_a_scenario_object_is_written_as_its_fields(tmp_path, capsys):
    sc = make_scenario("paper", n_steps=3)
    run_evaluation(["rm"], sc, 2, SEED, out_dir=tmp_path / "out", plot=False, progress=False)
    meta = json.loads((tmp_path / "out" / "episodes.json").read_text())["meta"]
    assert meta["scenario"] == json.loads(json.dumps(sc.to_dict()))


def test_no_training_stack_at_import():
    code = (
        "import sys, activetrack.baselines.evaluation; "
        "bad = [m for m in ('activetrack.train', 'torch', 'stable_baselines3', 'matplotlib') "
        "if m in sys.modules]; print(bad); sys.exit(1 if bad else 0)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_write_results_without_plot(rm_and_gsr, tmp_path):
    paths = write_results(rm_and_gsr, tmp_path, plot=False)
    assert set(paths) == {"results", "episodes"}
    assert not (tmp_path / "mean_trace.png").exists()


def test_every_policy_is_checked_before_the_first_episode(tmp_path, monkeypatch):
    pytest.importorskip("torch")
    import activetrack.baselines.evaluation as ev

    def never(*args, **kwargs):
        raise AssertionError("an episode ran before every policy was checked")

    monkeypatch.setattr(ev, "run_episode", never)
    bad = tmp_path / "policy.zip"
    bad.write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(ValueError, match=f"{bad}: not a policy.zip"):
        evaluate(["gsr", "rm", str(bad)], "paper", 1000, SEED, progress=False)
    with pytest.raises(ValueError, match="unknown policy 'nope'"):
        evaluate(["gsr", "nope"], "paper", 1000, SEED, progress=False)


def test_results_in_the_folder_need_overwrite(rm_and_gsr, tmp_path, monkeypatch):
    write_results(rm_and_gsr, tmp_path)
    before = (tmp_path / "results.json").read_bytes()
    with pytest.raises(ValueError, match="already holds results.*--overwrite"):
        write_results(rm_and_gsr, tmp_path, plot=False)
    import activetrack.baselines.evaluation as ev

    def never(*args, **kwargs):
        raise AssertionError("evaluated before checking the output folder")

    monkeypatch.setattr(ev, "evaluate", never)
    with pytest.raises(ValueError, match="already holds results"):
        run_evaluation(["rm"], "paper", 2, SEED, out_dir=tmp_path, progress=False)
    assert (tmp_path / "results.json").read_bytes() == before
    paths = write_results(rm_and_gsr, tmp_path, plot=False, overwrite=True)
    assert set(paths) == {"results", "episodes"}
    assert not (tmp_path / "mean_trace.png").exists()  # the old figure does not stay


def test_evaluation_nees_and_trace_equal_the_simulation_runners():
    # Two entry points of the one episode loop (activetrack.baselines.rollout): evaluate()
    # with an expert policy in the PettingZoo env's world and the simulation runner with a
    # planner in a World of its own; the same seeds give the same episodes, bit for bit
    # (the loop itself is checked against longhand World loops in test_rollout.py).
    from activetrack.baselines import GSR
    from activetrack.baselines.evaluation import evaluate
    from activetrack.baselines.simulation import simulate
    from activetrack.world.scenarios import make_scenario

    sc = make_scenario("mixed", n_steps=10)
    (ev,) = evaluate(["gsr"], sc, 3, 1000, progress=False)
    for i, seed in enumerate(range(1000, 1003)):
        rec = simulate(sc, GSR(), seed)
        assert ev.mean_trace[i] == rec.mean_trace
        assert ev.nees[i] == rec.mean_nees
        assert ev.ms_per_step[i] > 0.0


def test_batched_rows_equal_the_serial_ones_bit_for_bit():
    kw = dict(episodes=3, seed=SEED, progress=False, n_steps=6)
    policies = ["rm", "lookahead"]
    for scenario in ("paper", "two_targets"):
        serial = evaluate(policies, scenario, **kw)
        batched = evaluate(policies, scenario, batched=True, **kw)
        assert [r.policy for r in batched] == ["rm", "lookahead", "gsr"]
        for a, b in zip(serial, batched, strict=True):
            # Random motion is not batched; the planners' batched rows equal the serial ones
            # (every preset: tests/baselines/test_batch_independence.py).
            for name in ("mean_trace", "rmse", "returns", "nees"):
                np.testing.assert_array_equal(getattr(b, name), getattr(a, name), name)


def test_batched_is_checked(tmp_path, capsys):
    from activetrack.cli import main

    out = tmp_path / "out"
    argv = ["evaluate", "--policy", "gsr", "--batched", "--workers", "2", "--out", str(out)]
    assert main(argv) == 2
    assert "batched runs in this process" in capsys.readouterr().err
    assert not out.exists()  # checked before the output folder
    with pytest.raises(ValueError, match="batched must be True or False"):
        evaluate(["gsr"], "paper", 1, SEED, progress=False, batched="yes")
    with pytest.raises(ValueError, match="batched runs in this process"):
        evaluate(["gsr"], "paper", 1, SEED, progress=False, batched=True, workers=2)


def _coverage_band(reps: int, level: float = 0.95) -> tuple[float, float]:
    """Return the central 99% range of the covered fraction of ``reps`` intervals whose
    true coverage is ``level`` (binomial)."""
    lo, hi = stats.binom.ppf([0.005, 0.995], reps, level)
    return lo / reps, hi / reps


def test_mean_trace_interval_covers_the_mean_of_a_heavy_tailed_quantity(monkeypatch):
    """Lognormal episodes (positive, right-skewed, like the traces): the nominal 95%
    interval covers the true mean exp(mu + s^2 / 2) in a binomial band around 95% of 1000
    samples (a 10% narrower interval covers about 92.4% and fails)."""
    import activetrack.baselines.evaluation as ev

    monkeypatch.setattr(ev, "N_RESAMPLES", 1999)  # the Monte Carlo error of each end only
    rng = np.random.default_rng(35)
    mu, sigma, n, reps = 0.0, 0.5, 100, 1000
    truth = np.exp(mu + sigma**2 / 2)
    covered = 0
    for _ in range(reps):
        x = rng.lognormal(mu, sigma, n)
        lo, hi = bootstrap_ci(x)
        assert x.min() <= lo <= np.mean(x) <= hi <= x.max()
        covered += lo <= truth <= hi
    band = _coverage_band(reps)
    assert band[0] <= covered / reps <= band[1], (covered, band)


def test_paired_ratio_interval_covers_the_ratio_of_means(monkeypatch):
    """Paired lognormal episodes y = x z (z independent of x): mean(y) / mean(x) estimates
    E[z] = exp(m + s^2 / 2); its nominal 95% interval covers it in the binomial band."""
    import activetrack.baselines.evaluation as ev

    monkeypatch.setattr(ev, "N_RESAMPLES", 1999)
    rng = np.random.default_rng(36)
    n, reps, m, s = 100, 1000, 0.1, 0.2
    truth = np.exp(m + s**2 / 2)
    covered = 0
    for _ in range(reps):
        x = rng.lognormal(0.0, 0.5, n)
        y = x * rng.lognormal(m, s, n)
        lo, hi = paired_ratio_ci(y, x)
        covered += lo <= truth <= hi
    band = _coverage_band(reps)
    assert band[0] <= covered / reps <= band[1], (covered, band)


def test_mean_trace_interval_never_below_the_sample_minimum():
    """One episode 100 times the others' trace: a Student-t interval reaches below zero
    (the issue's 10.28 [-1.84, 22.41]); the bootstrap's stays above the sample minimum."""
    x = np.r_[np.full(19, 0.2), 40.0] + np.linspace(0.0, 0.01, 20)
    lo, hi = bootstrap_ci(x)
    assert x.min() <= lo < np.mean(x) < hi <= x.max()
    half = stats.t.ppf(0.975, x.size - 1) * np.std(x, ddof=1) / np.sqrt(x.size)
    assert np.mean(x) - half < 0.0  # what the t interval gave


def _summary_of(rmse: np.ndarray) -> dict:
    """Return the summary of a policy whose episodes had RMSE ``rmse`` (the other metrics
    of one episode only: their intervals are then points and cost nothing)."""
    from activetrack.baselines.evaluation import PolicyEvaluation

    one = np.ones(1)
    return PolicyEvaluation("p", list(range(rmse.size)), one, rmse, -one).summary()


def test_rmse_interval_never_below_the_sample_minimum():
    """The RMSE is positive and heavy-tailed like the trace: its interval is the same
    bootstrap one, never below the sample minimum, where a Student-t interval reaches
    below zero (the issue's 2 episodes: [-1.30, 3.24]; one episode far off out of 20)."""
    for x in (np.array([0.4, 1.54]), np.r_[np.full(19, 0.2), 40.0] + np.linspace(0, 0.01, 20)):
        r = _summary_of(x)
        lo, hi = r["rmse_ci95"]
        assert x.min() <= lo <= r["rmse"] <= hi <= x.max(), (x, lo, hi)
        half = stats.t.ppf(0.975, x.size - 1) * np.std(x, ddof=1) / np.sqrt(x.size)
        assert np.mean(x) - half < 0.0  # what the t interval gave


def test_rmse_interval_covers_the_mean_of_a_heavy_tailed_quantity(monkeypatch):
    """Lognormal RMSEs: the summary's nominal 95% interval covers the true mean
    exp(mu + s^2 / 2) in the binomial band around 95% of 1000 samples, and lies within
    each sample's range (as the mean trace's, test above)."""
    import activetrack.baselines.evaluation as ev

    monkeypatch.setattr(ev, "N_RESAMPLES", 1999)  # the Monte Carlo error of each end only
    rng = np.random.default_rng(37)
    mu, sigma, n, reps = 0.0, 0.5, 100, 1000
    truth = np.exp(mu + sigma**2 / 2)
    covered = 0
    for _ in range(reps):
        x = rng.lognormal(mu, sigma, n)
        lo, hi = _summary_of(x)["rmse_ci95"]
        assert x.min() <= lo <= np.mean(x) <= hi <= x.max()
        covered += lo <= truth <= hi
    band = _coverage_band(reps)
    assert band[0] <= covered / reps <= band[1], (covered, band)


def test_table_names_policy_files_by_their_folder(rm_and_gsr):
    """Long policy paths: the table shows the folder name whole, the JSON the full path."""
    import copy

    long = "/home/user/experiments/verify3/runs/bc1000_la/policy.zip"
    results = copy.copy(rm_and_gsr)
    results[0] = copy.copy(rm_and_gsr[0])
    results[0].policy = long
    rows = summaries(results)
    assert rows[0]["policy"] == long and rows[0]["label"] == "bc1000_la"
    table = format_table(rows)
    assert "bc1000_la " in table and "..." not in table and "median" in table
    assert "CPU ms/decision" in table
    # Two files in folders of the same name keep the folder above as well.
    other = copy.copy(rm_and_gsr[0])
    other.policy = "/home/user/b/bc1000_la/policy.zip"
    labels = [r["label"] for r in summaries([results[0], other, rm_and_gsr[1]])]
    assert labels == ["runs/bc1000_la", "b/bc1000_la", "gsr"]


def _figure_of(results, monkeypatch):
    import activetrack.baselines.plotting as plotting

    saved = {}

    def keep(fig, path, dpi=plotting.DPI):
        saved["fig"] = fig
        return path

    monkeypatch.setattr(plotting, "save_figure", keep)
    plotting.plot_evaluation(results, "unused.png")
    return saved["fig"]


@pytest.mark.parametrize("spread", [1.02, 1.5, 30.0])
def test_evaluation_plot_has_labelled_ticks(spread, monkeypatch):
    """Both axes carry at least two labelled ticks inside their limits, for data spanning
    2% (less than a decade, where the decades' ticks leave none), 50% and 30 times."""
    from types import SimpleNamespace

    rng = np.random.default_rng(5)
    gsr = 0.3 * rng.uniform(1.0, 1.01, 20)
    other = gsr * rng.uniform(1.0, spread, 20)
    results = [
        SimpleNamespace(policy="runs/bc/policy.zip", seeds=list(range(20)), mean_trace=other),
        SimpleNamespace(policy="gsr", seeds=list(range(20)), mean_trace=gsr),
    ]
    fig = _figure_of(results, monkeypatch)
    fig.canvas.draw()
    for axis in fig.axes:
        lo, hi = axis.get_ylim()
        shown = [
            t for t in axis.yaxis.get_major_ticks() + axis.yaxis.get_minor_ticks()
            if t.label1.get_visible() and t.label1.get_text() and lo <= t.get_loc() <= hi
        ]  # fmt: skip
        assert len(shown) >= 2, (spread, axis.get_ylabel(), lo, hi)
        # The labels name their ticks' values (not an offset or a rounded-away value).
        for t in shown:
            text = t.label1.get_text().replace("\u2212", "-").strip("$")
            assert float(text) == pytest.approx(t.get_loc(), rel=1e-6)
        assert [x.get_text() for x in axis.get_xticklabels()] == ["bc", "gsr"]


class _Recorder:
    """A stand-in for tqdm that records its total and every update."""

    made: list = []

    def __init__(self, *args, total=None, **kwargs):
        self.total, self.n, self.updates = total, 0, []
        _Recorder.made.append(self)

    def update(self, k=1):
        self.n += k
        self.updates.append(k)

    def set_description(self, *args, **kwargs):
        pass

    def close(self):
        pass


def test_batched_progress_advances_every_step(monkeypatch):
    """The bar counts steps: a batched policy advances it at every one of its steps (not
    once when the whole policy is done), and it ends full."""
    import tqdm.auto

    monkeypatch.setattr(tqdm.auto, "tqdm", _Recorder)
    _Recorder.made = []
    steps, episodes = 5, 3
    evaluate(["gsr", "rm"], "paper", episodes, SEED, batched=True, n_steps=steps)
    (bar,) = _Recorder.made
    assert bar.total == 2 * episodes * steps and bar.n == bar.total
    # GSR batched: one update of 3 copies per step; RM serial: one per episode step.
    assert bar.updates.count(episodes) >= steps and bar.updates.count(1) >= episodes * steps


class _CostlyFirstCall:
    """An expert that stays put; its first call burns 0.3 s of CPU (a compilation), its
    later ones sleep 5 ms (waiting is not computing)."""

    def __init__(self):
        self.calls = 0

    def plan(self, problem):
        import time

        self.calls += 1
        if self.calls == 1:
            end = time.process_time() + 0.3
            while time.process_time() < end:
                pass
        else:
            time.sleep(0.005)
        return problem.sensors


def test_summary_names_cpu_time_per_decision_and_the_seed_range(rm_and_gsr):
    """The decision time is named for what it is (CPU ms per decision after a warm-up),
    ``ms_per_step`` its deprecated alias with the same value; the seeds are a range
    ``{"first", "last"}`` (a pair ``[first, last]`` read as two seeds), as simulate's."""
    rows = summaries(rm_and_gsr)
    for r, ev in zip(rows, rm_and_gsr, strict=True):
        assert r["cpu_ms_per_decision"] == pytest.approx(np.mean(ev.ms_per_step), rel=1e-12)
        assert r["ms_per_step"] == r["cpu_ms_per_decision"]
        assert r["seed_range"] == {"first": SEED, "last": SEED + EPISODES - 1}
        assert "seeds" not in r
    # A summary written before the rename (``ms_per_step`` and ``seeds`` only) still
    # prints its decision time.
    old = {k: v for k, v in rows[0].items() if k not in ("cpu_ms_per_decision", "seed_range")}
    old.update(ms_per_step=12.5, seeds=[SEED, SEED + EPISODES - 1])
    new = {**rows[0], "cpu_ms_per_decision": 7.25, "ms_per_step": 7.25}
    assert " 12.5 " in format_table([old]) and " 7.25 " in format_table([new])


def test_ms_per_step_is_cpu_time_after_a_warm_up():
    """The first call (compilation) is a warm-up, not counted; sleeping costs no CPU.
    Counted, the first call alone would give 0.3 s / 4 steps = 75 ms per decision; wall
    time would give at least 5 ms."""
    policy = _CostlyFirstCall()
    (res, _) = evaluate({"stay": policy}, "paper", 1, SEED, progress=False, n_steps=4)
    assert policy.calls == 5  # the warm-up and the 4 steps
    assert 0.0 <= res.ms_per_step[0] < 2.5
