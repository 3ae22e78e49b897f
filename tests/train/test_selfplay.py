"""Self-play on ``pursuit`` end to end with a tiny budget: the evader learns (its return
against GSR rises above its measured start, beyond the paired episodes' noise), the
command writes its files, and the evaluation's ratios are its scores'."""

import json

import numpy as np
import pytest
from scipy.stats import trim_mean

pytest.importorskip("stable_baselines3")

from activetrack.cli import main  # noqa: E402
from activetrack.train import selfplay as sp  # noqa: E402


def test_the_evader_learns_against_gsr_and_the_sensors_train_against_it():
    cfg = sp.SelfPlayConfig(rounds=1, evader_steps=2048, sensor_steps=512, n_steps=256,
                            eval_episodes=8)  # fmt: skip
    res = sp.train_selfplay(seed=0, config=cfg)
    evader, sensors = res.history
    assert (evader["side"], evader["opponent"]) == ("evader", "gsr")
    assert (sensors["side"], sensors["opponent"]) == ("sensors", "learned evader")
    # Paired by episode seed: the gain must exceed three standard errors of its mean.
    gain = np.array(evader["after"]) - np.array(evader["before"])
    assert gain.mean() > 3.0 * gain.std(ddof=1) / np.sqrt(gain.size), gain
    # The measured end, re-measured the other way round: GSR's mean trace against the
    # learned evader on the same seeds (zero-sum: the evader's mean reward per step).
    seeds = list(range(sp.VALIDATION_SEED, sp.VALIDATION_SEED + 8))
    traces = sp.pursuit_episodes("gsr", sp._deterministic(res.evader), seeds)
    np.testing.assert_allclose(traces, evader["after"], rtol=1e-12)
    assert res.sensors is not None


def test_the_commands_run_end_to_end(tmp_path):
    out = tmp_path / "run"
    assert main(["train", "selfplay", "--out", str(out), "--rounds", "2", "--evader-steps",
                 "128", "--sensor-steps", "64", "--n-steps", "64", "--batch-size", "32",
                 "--eval-episodes", "1"]) == 0  # fmt: skip
    record = json.loads((out / "selfplay.json").read_text())
    assert [(h["round"], h["side"]) for h in record["history"]] == [
        (0, "evader"), (0, "sensors"), (1, "evader"), (1, "sensors")]  # fmt: skip
    assert record["history"][2]["opponent"] == "learned sensors"
    assert (out / "sensors.zip").is_file()
    ev = tmp_path / "eval"
    assert main(["train", "selfplay-evaluate", "--evader", str(out / "evader.zip"),
                 "--policy", "gsr", "--policy", "rm", "--episodes", "4",
                 "--out", str(ev)]) == 0  # fmt: skip
    rows = {(r["policy"], r["evader"]): r for r in json.loads(
        (ev / "pursuit_eval.json").read_text())["rows"]}  # fmt: skip
    assert set(rows) == {(p, e) for p in ("gsr", "rm") for e in ("scripted", "learned")}
    for (p, e), r in rows.items():
        x = np.array(r["scores"])
        assert r["iqm"] == pytest.approx(trim_mean(x, 0.25), rel=1e-12)
        gsr = np.array(rows["gsr", e]["scores"])
        assert r["ratio_to_gsr"][0] == pytest.approx(
            trim_mean(x, 0.25) / trim_mean(gsr, 0.25), rel=1e-12)  # fmt: skip
        if e == "learned":
            scripted = np.array(rows[p, "scripted"]["scores"])
            assert r["ratio_to_scripted"][0] == pytest.approx(
                trim_mean(x, 0.25) / trim_mean(scripted, 0.25), rel=1e-12)  # fmt: skip
    # The scripted rows are the evader task's GSR (the fallback is its evader): episodes
    # of the registered tracking game, independently.
    from activetrack.baselines.evaluation import run_episode
    from activetrack.baselines.policy_specs import resolve_policy
    from activetrack.envs import parallel_env

    env = parallel_env("evader")
    for p in ("gsr", "rm"):  # (RM draws: reseeded per episode as the runner does)
        for j, seed in enumerate((1000, 1003)):
            got = run_episode(env, resolve_policy(p), seed)
            assert rows[p, "scripted"]["scores"][3 * j] == pytest.approx(got[0], rel=1e-12)
    assert "| gsr | learned |" in (ev / "pursuit_eval.md").read_text()


def test_bad_settings_name_their_field(tmp_path):
    with pytest.raises(ValueError, match="rounds"):
        sp.SelfPlayConfig(rounds=0)
    with pytest.raises(ValueError, match="sensors"):
        sp.SelfPlayConfig(sensors="gbes")
    with pytest.raises(ValueError, match="hidden"):
        sp.SelfPlayConfig(hidden=(0,))
    with pytest.raises(ValueError, match="no such evader file"):
        sp.load_evader(tmp_path / "none.zip")
    bad = tmp_path / "bad.zip"
    bad.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="not an evader.zip"):
        sp.load_evader(bad)


def test_the_commands_check_their_arguments_before_training(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["train", "selfplay", "--rounds", "0", "--out", str(out)]) == 2
    assert "activetrack train selfplay: error: rounds must be" in capsys.readouterr().err
    missing = tmp_path / "none.zip"
    argv = ["train", "selfplay-evaluate", "--evader", str(missing), "--out", str(out)]
    assert main(argv) == 2
    assert "no such evader file" in capsys.readouterr().err
    assert main([*argv[:-2], "--episodes", "0", "--out", str(out)]) == 2
    assert "episodes must be" in capsys.readouterr().err
    assert not out.exists()
