"""The ``activetrack simulate`` command: table, results.json, trajectories.png, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from activetrack.baselines import GSR, RandomMotion, run_monte_carlo
from activetrack.cli import main
from activetrack.scenarios import make_scenario


def test_simulate_writes_results_and_plot(tmp_path, capsys):
    out = tmp_path / "res"
    code = main(
        [
            "simulate",
            "--planner",
            "gsr",
            "--planner",
            "rm",
            "--planner",
            "gbes",
            "--runs",
            "2",
            "--seed",
            "3",
            "--steps",
            "4",
            "--gbes-spacing",
            "0.1",
            "--out",
            str(out),
            "--no-progress",
        ]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "gsr" in text and "gbes" in text and "mean trace" in text
    data = json.loads((out / "results.json").read_text())
    assert list(data) == ["gsr", "rm", "gbes"]
    for entry in data.values():
        for key in ("mean_trace", "rmse", "nees", "plan_time_ms_median", "runs", "seed"):
            assert key in entry
        assert entry["runs"] == 2 and entry["seed"] == 3
        lo, hi = entry["mean_trace_ci95"]
        assert lo <= entry["mean_trace"] <= hi
    assert data["gbes"]["config"]["planner"]["spacing"] == 0.1
    assert data["gsr"]["config"]["scenario"]["n_steps"] == 4
    # The same numbers as the library called directly on the same seeds.
    sc = make_scenario("paper", n_steps=4)
    ref = run_monte_carlo(sc, {"gsr": GSR(), "rm": RandomMotion()}, 2, 3, progress=False)
    assert data["gsr"]["mean_trace"] == pytest.approx(np.mean(ref["gsr"].mean_trace))
    assert data["rm"]["rmse"] == pytest.approx(np.mean(ref["rm"].rmse))
    png = (out / "trajectories.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--runs", "0"],
        ["simulate", "--planner", "nope"],
        ["simulate", "--gbes-spacing", "-1"],
        ["simulate", "--scenario", "nope"],
    ],
)
def test_simulate_rejects_bad_arguments(argv, capsys):
    with pytest.raises(SystemExit) as err:
        main(argv)
    assert err.value.code == 2


def test_library_value_errors_become_exit_code_2(tmp_path, capsys):
    code = main(["simulate", "--gsr-tol", "-1", "--runs", "1", "--out", str(tmp_path)])
    assert code == 2
    assert "tol" in capsys.readouterr().err


def test_no_command_prints_help(capsys):
    assert main([]) == 2
    assert "simulate" in capsys.readouterr().out
