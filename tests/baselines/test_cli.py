"""The ``activetrack simulate`` command and the front door: outputs, defaults, bad input."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from activetrack.baselines import GSR, RandomMotion, run_monte_carlo
from activetrack.cli import main
from activetrack.world.scenarios import make_scenario


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
    for name in ("trajectories.png", "comparison.png"):
        png = (out / name).read_bytes()
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    # Consecutive seeds named as a range, both ends included; the warm-up timed apart.
    assert data["gsr"]["seed_range"] == {"first": 3, "last": 4} and "seeds" not in data["gsr"]
    assert data["gsr"]["plan_time_warmup_ms"] >= 0.0


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "--runs", "0"],
        ["simulate", "--planner", "nope"],
        ["simulate", "--gbes-spacing", "-1"],
        ["simulate", "--scenario", "nope"],
        ["simulate", "--seed", "2147483648"],
        ["simulate", "--out", ""],
        ["evaluate", "--policy", "rm", "--seed", "99999999999999999999999"],
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


TINY = ["simulate", "--planner", "rm", "--runs", "1", "--steps", "2", "--no-progress"]


def test_bad_out_fails_before_computing(tmp_path, capsys, monkeypatch):
    """An unusable --out is an argparse-style error before any run: no table, no results."""
    import activetrack.baselines.cli as bcli

    def never(*args, **kwargs):
        raise AssertionError("computed before checking --out")

    monkeypatch.setattr(bcli, "run_monte_carlo", never)
    (tmp_path / "file").write_text("")
    for out, message in [
        ("/proc/x", "/proc/x: cannot write to this folder"),
        (str(tmp_path / "file"), f"{tmp_path / 'file'}: exists and is not a folder"),
    ]:
        assert main([*TINY, "--out", out]) == 2
        captured = capsys.readouterr()
        assert captured.out == ""  # no table
        assert captured.err.startswith("usage: activetrack simulate")
        assert f"activetrack simulate: error: {message}" in captured.err


def test_out_with_results_needs_overwrite(tmp_path, capsys):
    out = tmp_path / "res"
    assert main([*TINY, "--seed", "1", "--out", str(out)]) == 0
    (out / "notes.txt").write_text("mine")
    first = (out / "results.json").read_bytes()
    assert (out / "trajectories.png").is_file()
    capsys.readouterr()
    assert main([*TINY, "--seed", "2", "--out", str(out), "--no-plot"]) == 2
    err = capsys.readouterr().err
    assert "already holds results (results.json, trajectories.png, comparison.png)" in err
    assert "--overwrite" in err
    assert (out / "results.json").read_bytes() == first
    # With --overwrite and --no-plot: new results, the old figure removed, other files kept.
    assert main([*TINY, "--seed", "2", "--out", str(out), "--no-plot", "--overwrite"]) == 0
    assert json.loads((out / "results.json").read_text())["rm"]["seed"] == 2
    assert not (out / "trajectories.png").exists()
    assert (out / "notes.txt").read_text() == "mine"
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "results.json"]


def test_planner_defaults_come_from_the_dataclasses():
    """Options not given are None and the planners keep their dataclass defaults."""
    from activetrack.baselines import GBES
    from activetrack.baselines.cli import make_planner
    from activetrack.cli import build_parser

    args = build_parser(["simulate"]).parse_args(["simulate"])
    assert args.gsr_tol is None and args.gsr_max_sweeps is None and args.gbes_spacing is None
    gsr, cfg = make_planner("gsr", args)
    assert cfg == {
        "type": "GSR",
        "tol": GSR().tol,
        "max_sweeps": GSR().max_sweeps,
        "restarts": False,
    }
    assert cfg["tol"] == 1e-9 and cfg["max_sweeps"] == 100  # the documented defaults
    gbes, cfg = make_planner("gbes", args)
    assert cfg == {"type": "GBES", "spacing": GBES().spacing} and gbes.spacing == np.pi / 200
    args = build_parser(["simulate"]).parse_args(["simulate", "--gsr-tol", "1e-6"])
    assert make_planner("gsr-restarts", args)[1]["tol"] == 1e-6


def test_help_imports_no_layer_and_no_torch():
    """``activetrack --help`` lists every command without importing the layers."""
    code = (
        "import sys\n"
        "from activetrack.cli import main\n"
        "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
        "bad = [m for m in ('torch', 'activetrack.baselines', 'activetrack.train', "
        "'stable_baselines3', 'matplotlib') if m in sys.modules]\n"
        "print(bad, file=sys.stderr); sys.exit(1 if bad else 0)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    for command in ("simulate", "evaluate", "train"):
        assert command in proc.stdout
    # simulate's own help loads the baselines only.
    code = code.replace("['--help']", "['simulate', '--help']").replace(
        "'activetrack.baselines', ", ""
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    assert "--overwrite" in proc.stdout and "(default 1e-09)" in proc.stdout


def test_summaries_are_the_layers_help():
    """The front door's one-line summaries are what the layers' subparsers show."""
    import argparse

    from activetrack.cli import COMMANDS, build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help for c in sub._choices_actions}
    assert helps == {name: summary for name, (_, summary) in COMMANDS.items()}


def test_ctrl_c_is_one_line_and_exit_130(tmp_path, capsys, monkeypatch):
    import activetrack.baselines.cli as bcli

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(bcli, "run_monte_carlo", interrupted)
    assert main([*TINY, "--out", str(tmp_path / "res")]) == 130
    err = capsys.readouterr().err
    assert "activetrack simulate: interrupted" in err and "Traceback" not in err
    assert not (tmp_path / "res").exists()  # nothing staged, no folder left behind


def test_a_grid_gbes_cannot_search_fails_before_any_run(tmp_path, capsys):
    # Four sensors at the paper's spacing: 400^4 combinations, over GBES's cap. The
    # first planner (GSR) must not run: its plans are counted.
    calls = []

    class Counted(GSR):
        def plan(self, problem, rng=None):
            calls.append(1)
            return super().plan(problem, rng)

    from activetrack.baselines import GBES

    sc = make_scenario("two_targets", n_steps=3)
    # adapt=False: the strict grid (the default widens it; tests/baselines/test_gbes_defaults.py
    # runs the CLI's defaults on every preset).
    with pytest.raises(ValueError, match=r"more than max_combinations.*--gbes-spacing"):
        run_monte_carlo(sc, {"gsr": Counted(), "gbes": GBES(adapt=False)}, 2, 0, progress=False)
    assert calls == []


BAD_ADDRESSES = ["127.0.0.1:-5", "127.0.0.1:+1", "127.0.0.1:1.5", "127.0.0.1:0", "h:65536", ":80"]


@pytest.mark.parametrize("address", BAD_ADDRESSES)
def test_a_malformed_address_fails_before_any_probe_or_run(address, tmp_path, capsys, monkeypatch):
    """A port that is not an integer in [1, 65535] (or no host) is an argparse-style error
    before the reachability probe and before computing; Ray would wait for minutes."""
    import socket

    import activetrack.baselines.cli as bcli
    from activetrack.baselines import distributed

    def never(*args, **kwargs):
        raise AssertionError("probed or computed with a malformed address")

    monkeypatch.setattr(bcli, "run_monte_carlo", never)
    monkeypatch.setattr(socket, "create_connection", never)
    with pytest.raises(ValueError, match=r"PORT an integer in \[1, 65535\]"):
        distributed.check_reachable(address)
    out = tmp_path / "res"
    for argv in (TINY, ["evaluate", "--policy", "rm", "--episodes", "1", "--no-progress"]):
        assert main([*argv, "--address", address, "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "error: address must be 'auto', 'local', HOST:PORT" in err and address in err
        assert not out.exists()


def test_well_formed_addresses_are_accepted():
    from activetrack.baselines import distributed

    for address in ("auto", " local ", "127.0.0.1:1", "ray://head-1.example:10001", "[::1]:65535"):
        assert distributed.check_options(1, address) == (1, address.strip())


def unusable_outs(tmp_path):
    """Return (--out, expected message) of output folders that cannot be made."""
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    return [
        (tmp_path / "dangling", "is a symbolic link to"),
        (tmp_path / ("x" * 300), "cannot write to this folder (File name too long)"),
    ]


def test_a_dangling_link_or_long_name_as_out_fails_before_computing(tmp_path, capsys, monkeypatch):
    import activetrack.baselines.cli as bcli
    import activetrack.baselines.evaluation as ev

    def never(*args, **kwargs):
        raise AssertionError("computed before checking --out")

    monkeypatch.setattr(bcli, "run_monte_carlo", never)
    monkeypatch.setattr(ev, "evaluate", never)
    for out, message in unusable_outs(tmp_path):
        for argv in (TINY, ["evaluate", "--policy", "rm", "--episodes", "1", "--no-progress"]):
            assert main([*argv, "--out", str(out)]) == 2
            err = capsys.readouterr().err
            assert f"error: {out}: " in err and message in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling"]


def test_evaluate_estimator_option_runs_the_imm(tmp_path):
    """``--estimator imm`` evaluates in the IMM world (the Python API's
    ``estimator=IMMSpec.from_behaviour(MANEUVERING)``, row for row), where planning from
    the first mode alone is another policy; a scenario without modes is refused."""
    from activetrack import IMMSpec
    from activetrack.baselines.evaluation import evaluate
    from activetrack.world.presets import MANEUVERING

    out, names = tmp_path / "imm", ["gsr", "gsr-single-model"]
    argv = ["evaluate", "--scenario", "maneuvering", "--estimator", "imm", "--episodes", "2",
            "--no-plot", "--no-progress", "--policy", names[0], "--policy", names[1]]  # fmt: skip
    assert main([*argv, "--out", str(out)]) == 0
    rows = {r["label"]: r["mean_trace"] for r in json.loads((out / "results.json").read_text())}
    spec = IMMSpec.from_behaviour(MANEUVERING)
    imm = evaluate(names, "maneuvering", 2, progress=False, estimator=spec)
    for res in imm:
        assert rows[res.policy] == pytest.approx(float(res.mean_trace.mean()), rel=1e-12)
    ekf = evaluate(["gsr"], "maneuvering", 2, progress=False)[0]
    assert rows["gsr"] != pytest.approx(float(ekf.mean_trace.mean()), rel=1e-6)
    assert rows["gsr"] != rows["gsr-single-model"]
    bad = ["evaluate", "--scenario", "paper", "--estimator", "imm", "--policy", "gsr",
           "--episodes", "1", "--no-plot", "--no-progress"]  # fmt: skip
    assert main([*bad, "--out", str(tmp_path / "bad")]) == 2
    assert not (tmp_path / "bad" / "results.json").exists()
