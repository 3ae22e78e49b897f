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
    half = stats.t.ppf(0.975, EPISODES - 1) * np.std(rm.mean_trace, ddof=1) / np.sqrt(EPISODES)
    assert r["mean_trace"] == pytest.approx(np.mean(rm.mean_trace))
    assert r["mean_trace_ci95"] == pytest.approx([r["mean_trace"] - half, r["mean_trace"] + half])
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
    assert episodes["policies"]["rm"]["seeds"] == [SEED, SEED + 1, SEED + 2]
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
    # Two drivers of the same world: evaluate() through the PettingZoo env and the
    # simulation runner through World directly; the same seeds give the same episodes.
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


def test_batched_rows_equal_the_serial_ones_to_the_planners_tolerance():
    kw = dict(episodes=3, seed=SEED, progress=False, n_steps=6)
    policies = ["rm", "lookahead"]
    for scenario in ("paper", "two_targets"):
        serial = evaluate(policies, scenario, **kw)
        batched = evaluate(policies, scenario, batched=True, **kw)
        assert [r.policy for r in batched] == ["rm", "lookahead", "gsr"]
        for a, b in zip(serial, batched, strict=True):
            # Random motion is not batched: its rows are the serial ones exactly.
            rtol = 0.0 if a.policy == "rm" else 1e-6
            for name in ("mean_trace", "rmse", "returns", "nees"):
                np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=rtol)


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
