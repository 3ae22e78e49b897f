"""Safe output files: atomic writes, staged run outputs, and a failed write under a size limit."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from activetrack.files import (
    TEMP_PREFIX,
    atomic_path,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    prepare_output_dir,
)


def temp_files(folder: Path) -> list[Path]:
    return sorted(folder.rglob(f"{TEMP_PREFIX}*"))


def test_atomic_writes_replace_and_leave_no_temp(tmp_path):
    p = tmp_path / "a.json"
    atomic_write_text(p, "old")
    atomic_write_json(p, {"x": [1, 2]})
    assert json.loads(p.read_text()) == {"x": [1, 2]} and p.read_text().endswith("\n")
    atomic_write_bytes(tmp_path / "b.bin", b"\x00\x01")
    assert (tmp_path / "b.bin").read_bytes() == b"\x00\x01"
    assert temp_files(tmp_path) == []
    # The usual permissions (0666 minus the umask), not mkstemp's private 0600.
    mask = os.umask(0)
    os.umask(mask)
    assert (p.stat().st_mode & 0o777) == (0o666 & ~mask)


def test_a_failed_write_keeps_the_old_file(tmp_path):
    p = tmp_path / "r.json"
    p.write_text("good")
    with pytest.raises(RuntimeError), atomic_path(p) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".json"
        tmp.write_text("half")
        raise RuntimeError("disk full")
    with pytest.raises(TypeError):  # not serializable: nothing is written at all
        atomic_write_json(p, {"x": object()})
    assert p.read_text() == "good"
    assert temp_files(tmp_path) == []


def test_run_outputs_commit_together_or_not_at_all(tmp_path):
    (tmp_path / "results.json").write_text("old results")
    (tmp_path / "plot.png").write_text("old plot")
    owned = ("results.json", "plot.png")
    with pytest.raises(RuntimeError), prepare_output_dir(tmp_path, owned, overwrite=True) as out:
        out.write_text("results.json", "new results")
        raise RuntimeError("the plot failed")
    assert out.state == "discarded"
    assert (tmp_path / "results.json").read_text() == "old results"
    assert (tmp_path / "plot.png").read_text() == "old plot"
    assert temp_files(tmp_path) == []
    # A successful run without the plot: the stale plot goes, the results are new.
    with prepare_output_dir(tmp_path, owned, overwrite=True) as out:
        out.write_json("results.json", {"v": 1})
        assert (tmp_path / "results.json").read_text() == "old results"  # until the commit
        written = out.commit()
    assert written == {"results.json": tmp_path / "results.json"}
    assert json.loads((tmp_path / "results.json").read_text()) == {"v": 1}
    assert not (tmp_path / "plot.png").exists()
    assert temp_files(tmp_path) == []
    with pytest.raises(ValueError, match="not one of this run's outputs"):
        out.staged("other.txt")


def test_prepare_output_dir_refuses_results_unless_overwrite(tmp_path):
    owned = ("results.json", "tb/")
    folder = tmp_path / "new" / "deep"
    with prepare_output_dir(folder, owned):  # made (and locked) for the run...
        assert folder.is_dir()
    assert not (tmp_path / "new").exists()  # ...and removed: the run wrote nothing
    folder.mkdir(parents=True)
    (folder / "notes.txt").write_text("mine")
    (folder / "tb").mkdir()
    prepare_output_dir(folder, owned).close()  # unrelated files, empty folders: no results
    (folder / "tb" / "events").write_text("x")
    (folder / "results.json").write_text("{}")
    with pytest.raises(
        ValueError, match=r"already holds results \(results.json, tb/\).*--overwrite"
    ):
        prepare_output_dir(folder, owned)
    with prepare_output_dir(folder, owned, overwrite=True) as out:
        (out.staged("tb/") / "new-events").write_text("y")
        # Nothing is replaced before the commit, folders included.
        assert (folder / "tb" / "events").read_text() == "x"
        assert (folder / "results.json").exists()
        out.write_text("results.json", "new")
        out.commit()
    assert sorted(p.name for p in (folder / "tb").iterdir()) == ["new-events"]
    assert (folder / "notes.txt").read_text() == "mine"
    assert temp_files(folder) == []


def test_prepare_output_dir_rejects_unusable_paths(tmp_path):
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="is not a folder"):
        prepare_output_dir(tmp_path / "file", ("a",))
    with pytest.raises(ValueError, match="file is not a folder"):
        prepare_output_dir(tmp_path / "file" / "sub", ("a",))
    with pytest.raises(ValueError, match="non-empty path"):
        prepare_output_dir("", ("a",))
    if Path("/proc/self").exists():
        with pytest.raises(ValueError, match="/proc/x: cannot write"):
            prepare_output_dir("/proc/x", ("a",))


# A failed write in a real run: a file size limit (RLIMIT_FSIZE) in a subprocess. -----------
LIMITED = """
import resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a too large write then fails with EFBIG
resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, resource.RLIM_INFINITY))
from activetrack.cli import main
sys.exit(main({argv!r}))
"""


def run_limited(argv: list[str], limit: int) -> subprocess.CompletedProcess:
    code = textwrap.dedent(LIMITED.format(limit=limit, argv=argv))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)


def snapshot(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs resource limits (POSIX)")
def test_simulate_failing_to_write_keeps_the_previous_outputs(tmp_path):
    from activetrack.cli import main

    out = tmp_path / "sim"
    base = ["simulate", "--planner", "rm", "--runs", "1", "--steps", "3", "--no-progress"]
    assert main([*base, "--seed", "1", "--out", str(out)]) == 0
    before = snapshot(out)
    assert set(before) == {"results.json", "trajectories.png"}
    assert len(before["results.json"]) < 16_000 < len(before["trajectories.png"])
    # Another seed: new results.json fits under the limit, the figure does not.
    proc = run_limited([*base, "--seed", "2", "--out", str(out), "--overwrite"], 16_000)
    assert proc.returncode == 1, proc.stderr
    assert "activetrack simulate: error:" in proc.stderr and "Traceback" not in proc.stderr
    assert "File too large" in proc.stderr and "trajectories.png" in proc.stderr  # the file
    assert snapshot(out) == before  # both old files, consistent with each other
    assert json.loads(before["results.json"])["rm"]["seed"] == 1
    assert temp_files(out) == []


@pytest.mark.slow
@pytest.mark.skipif(not hasattr(os, "fork"), reason="needs resource limits (POSIX)")
def test_train_failing_to_write_keeps_the_previous_policy(tmp_path):
    pytest.importorskip("torch")
    from activetrack.cli import main
    from activetrack.train.policy_io import load_policy

    out = tmp_path / "bc"
    base = ["train", "bc", "--episodes", "1", "--epochs", "1", "--no-progress", "--out", str(out)]
    assert main([*base, "--hidden", "8"]) == 0
    before = snapshot(out)
    assert len(before["policy.zip"]) < 64_000
    # A wider network: its policy.zip (about 0.6 MB) is over the limit.
    proc = run_limited([*base, "--hidden", "256", "256", "--overwrite"], 64_000)
    assert proc.returncode == 1, proc.stderr
    assert "activetrack train bc: error:" in proc.stderr and "Traceback" not in proc.stderr
    assert snapshot(out) == before
    assert load_policy(out / "policy.zip").meta["net"]["hidden"] == [8]
    assert json.loads(before["config.json"])["net"]["hidden"] == [8]
    assert temp_files(out) == []


def test_a_run_that_writes_nothing_leaves_no_folder_and_json_is_standard(tmp_path):
    with pytest.raises(RuntimeError), prepare_output_dir(tmp_path / "a" / "b", ("r.json",)):
        raise RuntimeError("the computation failed")
    assert not (tmp_path / "a").exists()  # made for the run, removed with it
    with prepare_output_dir(tmp_path / "a" / "b", ("results.json",)) as out:
        out.write_json("results.json", {"x": 1.0})
        out.commit()
    assert json.loads((tmp_path / "a" / "b" / "results.json").read_text()) == {"x": 1.0}
    for bad in (float("nan"), float("inf")):
        with pytest.raises(ValueError, match="JSON compliant"):
            atomic_write_json(tmp_path / "x.json", {"x": bad})
    assert not (tmp_path / "x.json").exists()
