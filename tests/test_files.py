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


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
@pytest.mark.parametrize("where", ["atomic_path", "prepare_output_dir"])
def test_an_interrupt_just_after_a_temporary_file_is_made_leaves_none(where, tmp_path, monkeypatch):
    """Ctrl-C right after mkstemp made the file, before its name is returned: the file is
    still removed (the interrupt waits until it is known)."""
    import signal

    import activetrack.files as files

    real = files.tempfile.mkstemp

    def made_then_interrupted(*args, **kwargs):
        made = real(*args, **kwargs)
        os.kill(os.getpid(), signal.SIGINT)
        return made

    monkeypatch.setattr(files.tempfile, "mkstemp", made_then_interrupted)
    before = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            if where == "atomic_path":
                atomic_write_bytes(tmp_path / "r.bin", b"new")
            else:
                prepare_output_dir(tmp_path / "out", ("a.json",))
    finally:
        signal.signal(signal.SIGINT, before)
    assert temp_files(tmp_path) == []
    assert not (tmp_path / "r.bin").exists()


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
    assert set(before) == {"results.json", "comparison.png", "trajectories.png"}
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


# One run per folder: a lock for the run, or a refusal at the commit. -----------------------
def test_a_second_run_on_the_same_folder_is_refused_while_the_first_runs(tmp_path):
    folder = tmp_path / "new"
    owned = ("results.json",)
    with prepare_output_dir(folder, owned) as first:
        with pytest.raises(ValueError, match="another run is writing to this folder"):
            prepare_output_dir(folder, owned)  # refused at once, before any computation
        first.write_text("results.json", "first")
        first.commit()
    assert (folder / "results.json").read_text() == "first"
    # The first run has ended: the next one finds its results.
    with pytest.raises(ValueError, match="already holds results"):
        prepare_output_dir(folder, owned)
    assert temp_files(folder) == []


def test_without_a_lock_the_commit_refuses_results_that_appeared(tmp_path, monkeypatch):
    """On a file system without flock, two runs into the same new folder both start; the
    one that finishes last must not replace the other's results."""
    import activetrack.files as files

    monkeypatch.setattr(files, "_lock", lambda folder: None)
    folder = tmp_path / "new"
    owned = ("results.json", "tb/")
    a = prepare_output_dir(folder, owned)
    b = prepare_output_dir(folder, owned)
    with a:
        a.write_text("results.json", "a")
        (a.staged("tb/") / "events").write_text("a")
        a.commit()
    with pytest.raises(ValueError, match=r"another run wrote results \(results.json, tb/\)"), b:
        b.write_text("results.json", "b")
        b.commit()
    assert (folder / "results.json").read_text() == "a"
    assert (folder / "tb" / "events").read_text() == "a"
    assert temp_files(folder) == []


def test_a_killed_runs_staging_is_removed_by_the_next_run(tmp_path):
    folder = tmp_path / "out"
    (folder / f"{TEMP_PREFIX}run-abc" / "tb").mkdir(parents=True)  # SIGKILL left it
    (folder / f"{TEMP_PREFIX}results-x.json").write_text("half")
    with prepare_output_dir(folder, ("results.json",)) as out:
        out.write_text("results.json", "new")
        out.commit()
    assert sorted(p.name for p in folder.iterdir()) == ["results.json"]


def test_unusable_output_paths_are_refused_before_the_run(tmp_path):
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    for bad in ("dangling", "dangling/sub"):
        with pytest.raises(ValueError, match="is a symbolic link to .*nowhere, which does not"):
            prepare_output_dir(tmp_path / bad, ("a",))
    long = tmp_path / ("x" * 300)
    with pytest.raises(ValueError, match="cannot write to this folder .*too long"):
        prepare_output_dir(long / "sub", ("a",))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dangling"]  # nothing made


def test_signals_are_held_back_until_the_block_ends():
    import signal

    from activetrack.files import signals_deferred

    SIGS = (signal.SIGINT, signal.SIGTERM)
    seen = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        # Both signals raise KeyboardInterrupt before the block, whatever an earlier test
        # (or library) left as their handlers: the block must hand them back to that.
        previous = {s: signal.signal(s, signal.default_int_handler) for s in SIGS}
        try:
            with pytest.raises(KeyboardInterrupt), signals_deferred():
                os.kill(os.getpid(), signum)
                os.kill(os.getpid(), signum)  # twice: delivered once
                seen.append(signum)  # reached: the signal waits for the block's end
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
    assert seen == [signal.SIGINT, signal.SIGTERM]


# Signals: SIGINT and SIGTERM leave the old complete results or the new complete ones. -----
SIM = ["simulate", "--planner", "rm", "--runs", "1", "--steps", "2", "--no-progress"]


def _old_results(folder: Path) -> dict[str, bytes]:
    """Write a complete run's results (seed 1, with its figure) in ``folder``; return them."""
    from activetrack.cli import main

    assert main([*SIM, "--seed", "1", "--out", str(folder)]) == 0
    return snapshot(folder)


def _check_outcome(folder: Path, old: dict[str, bytes], code: int, err: str) -> str:
    """Check the folder holds the old or the new complete results, no temporary file, and
    that the exit code and message say which; return "old" or "new"."""
    assert temp_files(folder) == [], err
    now = snapshot(folder)
    seed = json.loads(now["results.json"])["rm"]["seed"]
    if seed == 1:
        assert now == old, err  # every old file, unchanged
        outcome = "old"
    else:  # the new run (seed 2, --no-plot): its results and no stale figure
        assert seed == 2 and set(now) == {"results.json"}, (sorted(now), err)
        outcome = "new"
    assert "Traceback" not in err, err
    if code == 0:
        assert outcome == "new", err
    else:
        assert code in (130, 143), err
        name = "SIGINT" if code == 130 else "SIGTERM"
        assert f"activetrack simulate: interrupted ({name}); " in err, err
        assert err.count("interrupted") == 1, err
        expected = (
            f"{folder} holds this run's complete new results"
            if outcome == "new"
            else f"{folder} still holds its previous results, unchanged"
        )
        assert expected in err, err
    return outcome


@pytest.mark.parametrize("signum", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize(
    "point", ["computing", "in_a_library", "staging_folder", "staging", "committing"]
)
def test_a_signal_at_each_stage_of_a_run(signum, point, tmp_path, monkeypatch, capsys):
    """The signal sent by the process to itself at a known point of an --overwrite run."""
    import signal

    import activetrack.baselines.cli as bcli
    import activetrack.files as files
    from activetrack.cli import main

    folder = tmp_path / "out"
    old = _old_results(folder)
    sig = getattr(signal, signum)

    def send_then(fn):
        def wrapped(*args, **kwargs):
            os.kill(os.getpid(), sig)
            return fn(*args, **kwargs)

        return wrapped

    def library_reraising(*args, **kwargs):
        # As Ray's ``get`` does: the handler's exception is caught and a plain
        # KeyboardInterrupt raised in its place (the signal's name is lost).
        try:
            os.kill(os.getpid(), sig)
            for _ in range(1000):  # the handler runs at the next bytecode
                pass
        except KeyboardInterrupt:
            raise KeyboardInterrupt() from None
        raise AssertionError("the handler did not run")

    if point == "computing":
        monkeypatch.setattr(bcli, "run_monte_carlo", send_then(bcli.run_monte_carlo))
    elif point == "in_a_library":
        monkeypatch.setattr(bcli, "run_monte_carlo", library_reraising)
    elif point == "staging_folder":  # the staging folder made, its name not yet returned
        real = files.tempfile.mkdtemp

        def made_then_signal(*args, **kwargs):
            path = real(*args, **kwargs)
            os.kill(os.getpid(), sig)
            return path

        monkeypatch.setattr(files.tempfile, "mkdtemp", made_then_signal)
    elif point == "staging":
        monkeypatch.setattr(bcli, "format_table", send_then(bcli.format_table))
    else:  # inside the commit, between the renames: held back until they are done
        monkeypatch.setattr(files, "_fsync_dir", send_then(files._fsync_dir))
    capsys.readouterr()
    before = signal.getsignal(signal.SIGTERM)  # (another test's Ray may have set its own)
    code = main([*SIM, "--seed", "2", "--no-plot", "--overwrite", "--out", str(folder)])
    assert code == 128 + sig
    outcome = _check_outcome(folder, old, code, capsys.readouterr().err)
    assert outcome == ("new" if point == "committing" else "old")
    assert signal.getsignal(signal.SIGTERM) is before  # main restored the handlers


def test_a_signal_before_any_output_folder(tmp_path, monkeypatch, capsys):
    import signal

    import activetrack.baselines.cli as bcli
    from activetrack.cli import main

    def interrupted(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(bcli, "make_scenario", interrupted)
    out = tmp_path / "out"
    assert main([*SIM, "--out", str(out)]) == 143
    assert "interrupted (SIGTERM); no output folder was touched" in capsys.readouterr().err
    out2 = tmp_path / "fresh"
    monkeypatch.undo()
    monkeypatch.setattr(bcli, "run_monte_carlo", interrupted)
    assert main([*SIM, "--out", str(out2)]) == 143
    err = capsys.readouterr().err
    assert f"no results were written to {out2} (the folder made for it was removed)" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.skipif(not hasattr(os, "kill") or os.name != "posix", reason="POSIX signals")
def test_timed_signals_in_a_real_process(tmp_path):
    """A real process, the signal sent from outside at a few delays after the results table
    (just before, during or just after the commit): old or new complete results, never a
    mix, no temporary file, and a message saying which."""
    import signal
    import time

    folder = tmp_path / "out"
    old = _old_results(folder)
    argv = [*SIM, "--seed", "2", "--no-plot", "--overwrite", "--out", str(folder)]
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    outcomes = []
    for delay, sig in [(0.0, signal.SIGTERM), (0.005, signal.SIGINT), (0.03, signal.SIGTERM)]:
        proc = subprocess.Popen(
            [sys.executable, "-m", "activetrack.cli", *argv],  # as the program
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for line in proc.stdout:  # the table is printed just before the outputs are written
            if line.startswith("rm "):
                break
        time.sleep(delay)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
        outcomes.append(_check_outcome(folder, old, proc.returncode, err))
        if outcomes[-1] == "new":  # back to the old results for the next delay
            for p in folder.iterdir():
                p.unlink()
            for name, data in old.items():
                (folder / name).write_bytes(data)
    assert len(outcomes) == 3


@pytest.mark.slow
@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
@pytest.mark.parametrize("delay", [0.5, 4.0])
def test_sigterm_with_ray_workers_exits_143_without_a_native_stack_dump(delay, tmp_path):
    """SIGTERM while Ray starts or runs the tasks: Ray's handlers (its Python one exits with
    15, its native one dumps a stack and aborts) must not take it from the command."""
    pytest.importorskip("ray")
    import signal
    import time

    out = tmp_path / "out"
    argv = ["simulate", "--planner", "rm", "--runs", "8", "--steps", "30", "--workers", "2"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "activetrack.cli", *argv, "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 120
    while not out.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)  # the folder is made (and locked) just before Ray starts
    time.sleep(delay)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    if proc.returncode == 0:  # finished first (a fast machine): nothing to check
        return
    assert proc.returncode == 143, err[-3000:]
    assert "SIGTERM received" not in err and "Traceback" not in err, err[-3000:]
    assert f"interrupted (SIGTERM); no results were written to {out}" in err
    assert not out.exists()


def test_a_commit_failing_part_way_keeps_the_replaced_outputs(tmp_path, monkeypatch):
    """If a rename of the commit failed (it should not), the outputs it had moved aside are
    kept where the next run does not clean up, and the folder's state is reported."""
    import activetrack.files as files

    folder = tmp_path / "out"
    (folder / "tb").mkdir(parents=True)
    (folder / "tb" / "events").write_text("old")
    real_rename = os.rename

    def failing(src, dst):
        if Path(dst) == folder / "tb":  # the new folder into place: fails
            raise OSError(5, "Input/output error", str(dst))
        return real_rename(src, dst)

    with prepare_output_dir(folder, ("tb/",), overwrite=True) as out:
        (out.staged("tb/") / "events").write_text("new")
        monkeypatch.setattr(files.os, "rename", failing)
        with pytest.raises(OSError, match="Input/output error"):
            out.commit()
        monkeypatch.undo()
    assert out.state == "failed" and "commit failed part-way" in out.describe()
    prepare_output_dir(folder, ("tb/",), overwrite=True).close()  # the next run
    (kept,) = folder.glob(".failed-commit-*")
    assert (kept / ".old" / "tb" / "events").read_text() == "old"
