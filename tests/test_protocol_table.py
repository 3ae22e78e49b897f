"""``docs/scripts/protocol_table.py``, which prints the results pages' protocol tables
from ``activetrack evaluate`` folders: every row's cells come from ``results.json``, a
pool's members are left out with ``--pooled-only``, and ``--rmse-nees`` adds two columns
to the header and to every row alike."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.doc_scripts import load


def _script():
    return load("protocol_table")


def _row(policy: str, trace: float, **extra: object) -> dict:
    out = {"policy": policy, "label": policy, "rmse": 0.5, "nees": 2.0}
    for key in ("mean_trace", "iqm_trace", "median_trace"):
        out[key], out[f"{key}_ci95"] = trace, [trace - 0.1, trace + 0.1]
    for key in ("ratio_to_gsr", "iqm_ratio_to_gsr"):
        out[key], out[f"{key}_ci95"] = trace / 2.0, [trace / 2.0 - 0.01, trace / 2.0 + 0.01]
    return {**out, **extra}


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    rows = [
        _row("gsr", 2.0),
        _row("runs/a/policy.zip", 2.2),
        _row("runs/b/policy.zip", 2.4),
        _row("DAgger", 2.3, runs=2, pooled=["runs/a/policy.zip", "runs/b/policy.zip"]),
    ]
    (tmp_path / "results.json").write_text(json.dumps(rows), encoding="utf-8")
    meta = {"meta": {"scenario": "range_only"}}
    (tmp_path / "episodes.json").write_text(json.dumps(meta), encoding="utf-8")
    return tmp_path


def test_rows_hold_the_results_and_pools_stand_for_their_members(folder, capsys):
    script = _script()
    assert script.main([str(folder)]) == 0
    every = capsys.readouterr().out.strip().splitlines()
    assert len(every) == 2 + 4  # header, rule, one row per policy
    assert every[-1].startswith("| `range_only` | DAgger (2 runs) | 2.300 [2.200, 2.400] |")
    assert every[-1].endswith("| 1.150 [1.140, 1.160] | 1.150 [1.140, 1.160] |")
    assert script.main(["--pooled-only", "--rmse-nees", str(folder)]) == 0
    pooled = capsys.readouterr().out.strip().splitlines()
    policies = [line.split(" | ")[1] for line in pooled[2:]]
    assert policies == ["gsr", "DAgger (2 runs)"]
    columns = {line.count("|") for line in pooled}
    assert columns == {every[0].count("|") + 2}  # header, rule and rows alike
    assert pooled[-1].endswith("| 0.500 | 2.00 |")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        ([], "the following arguments are required: folders"),
        (["--pooled"], "the following arguments are required: folders"),
        (["--pooled-only", "--bogus", "FOLDER"], "unrecognized arguments: --bogus"),
        (["EMPTY"], "not an activetrack evaluate folder (no results.json, episodes.json)"),
    ],
)
def test_bad_arguments_are_refused_naming_them(argv, message, folder, tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    argv = [{"FOLDER": str(folder), "EMPTY": str(empty)}.get(a, a) for a in argv]
    with pytest.raises(SystemExit) as exc:
        _script().main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr()
    assert message in err.err and err.out == ""
