"""Studies on Ray workers against the serial loop from the same seeds, and a worker killed.

The reference of every comparison is the serial code path (``--workers 1``, no Ray), run
here in the test process; the results must be equal to the last bit (planning times
aside), whatever the chunking. One local Ray with 2 CPUs serves the whole file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from activetrack import make_scenario
from activetrack.baselines import GSR, RandomMotion, distributed, run_monte_carlo
from activetrack.baselines.evaluation import evaluate
from activetrack.baselines.policies import GSRPolicy
from activetrack.cli import main

ray = pytest.importorskip("ray")


@pytest.fixture(scope="module", autouse=True)
def local_ray():
    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="warning")
    yield
    ray.shutdown()


def _without_timings(obj):
    """Return ``obj`` (parsed JSON) without the planning-time entries (wall clock)."""
    if isinstance(obj, dict):
        return {
            k: _without_timings(v)
            for k, v in obj.items()
            if not k.startswith(("plan_time", "ms_per_step", "cpu_ms_per_decision"))
        }
    if isinstance(obj, list):
        return [_without_timings(v) for v in obj]
    return obj


def _json(path: Path):
    return json.loads(path.read_text())


class _DiesOnce:
    """Kills the worker process at its first call, once overall (a marker file remembers).

    Wraps a planner (``plan(problem, rng)``) or an expert policy (``plan(problem)``,
    ``reset(seed)``); after the kill it is that planner or policy, unchanged.
    """

    def __init__(self, inner, marker: Path) -> None:
        self.inner, self.marker = inner, str(marker)

    def _maybe_die(self) -> None:
        try:
            fd = os.open(self.marker, os.O_CREAT | os.O_EXCL)  # one process wins the kill
        except FileExistsError:
            return
        os.close(fd)
        os._exit(1)

    def plan(self, *args):
        self._maybe_die()
        return self.inner.plan(*args)

    def reset(self, seed):
        self.inner.reset(seed)


def _twice(marker: str, x: int) -> tuple[int, int]:
    """A job that kills its worker the first time any job runs, then returns ``(x, 2x)``."""
    _DiesOnce(None, Path(marker))._maybe_die()
    return x, 2 * x


def test_options_are_checked_at_the_boundary():
    assert distributed.check_options(np.int64(3), " auto ") == (3, "auto")
    assert distributed.check_options() == (1, None)
    for bad in (0, -1, 2.0, True, "2", distributed.MAX_WORKERS + 1, 10**20):
        with pytest.raises(ValueError, match=r"workers must be an integer in \[1, 1024\]"):
            distributed.check_options(bad)
    for bad in ("", "  ", 6379):
        with pytest.raises(ValueError, match="address must be a non-empty string"):
            distributed.check_options(2, bad)
    sc = make_scenario("paper", n_steps=2)
    with pytest.raises(ValueError, match="workers must be"):
        run_monte_carlo(sc, {"gsr": GSR()}, 2, workers=0)
    with pytest.raises(ValueError, match="address must be"):
        evaluate(["rm"], "paper", 1, address="")


def test_cli_rejects_bad_workers_before_computing(tmp_path, capsys):
    for cmd in (["simulate", "--runs", "1"], ["evaluate", "--policy", "rm"]):
        with pytest.raises(SystemExit) as exc:
            main([*cmd, "--workers", "0", "--out", str(tmp_path / "x")])
        assert exc.value.code == 2
        assert "--workers: must be an integer >= 1" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_chunks_keep_the_seeds_in_order():
    seeds = list(range(10, 23))
    for n in (1, 2, 5, 13, 40):
        parts = distributed.chunks(seeds, n)
        assert [s for p in parts for s in p] == seeds
        assert len(parts) == min(n, len(seeds)) and all(parts)


def _echo(tag, seeds):
    """One chunk's result: the seeds it got, tagged by its case (a Ray task's function)."""
    return [(tag, s) for s in seeds]


def test_map_seeds_joins_every_cases_chunks_in_seed_order():
    seeds, counts = list(range(10, 23)), []
    cases = [{"tag": "a"}, {"tag": "b"}]
    per_case = distributed.map_seeds(_echo, cases, seeds, cpus=2, on_done=counts.append)
    assert len(per_case) == 2
    for tag, chunked in zip("ab", per_case, strict=True):
        assert len(chunked) == min(distributed.JOBS_PER_CPU * 2, len(seeds))
        assert [row for chunk in chunked for row in chunk] == [(tag, s) for s in seeds]
    assert sum(counts) == 2 * len(seeds)  # each chunk's seeds reported once


def test_a_killed_worker_is_retried_and_each_job_counted_once(tmp_path):
    marker = tmp_path / "killed"
    done: list[int] = []
    out = distributed.run_tasks(_twice, [(str(marker), x) for x in range(7)], on_done=done.append)
    assert marker.exists()  # a worker did die
    assert out == [(x, 2 * x) for x in range(7)]
    assert sorted(done) == list(range(7))  # every job reported once, none twice


@pytest.mark.slow
def test_simulate_on_workers_equals_serial(tmp_path):
    common = ["simulate", "--steps", "12", "--runs", "7", "--seed", "4", "--no-plot"]
    common += ["--no-progress", "--planner", "gsr", "--planner", "rm"]
    assert main([*common, "--out", str(tmp_path / "serial")]) == 0
    assert main([*common, "--out", str(tmp_path / "ray"), "--workers", "2"]) == 0
    serial, on_ray = _json(tmp_path / "serial/results.json"), _json(tmp_path / "ray/results.json")
    assert list(serial) == ["gsr", "rm"] and serial["gsr"]["runs"] == 7
    assert _without_timings(on_ray) == _without_timings(serial)


@pytest.mark.slow
def test_evaluate_on_workers_equals_serial(tmp_path):
    common = ["evaluate", "--policy", "rm", "--episodes", "5", "--seed", "1000", "--no-plot"]
    assert main([*common, "--no-progress", "--out", str(tmp_path / "serial")]) == 0
    assert main([*common, "--no-progress", "--out", str(tmp_path / "ray"), "--workers", "2"]) == 0
    for name in ("results.json", "episodes.json"):
        ray, serial = (_without_timings(_json(tmp_path / d / name)) for d in ("ray", "serial"))
        assert ray == serial, name


@pytest.mark.slow
def test_a_worker_killed_mid_study_is_retried_and_results_equal_serial(tmp_path):
    sc = make_scenario("paper", n_steps=10)
    planners = {"gsr": GSR(), "rm": RandomMotion()}
    serial = run_monte_carlo(sc, planners, 9, 20, progress=False, keep_records=9)
    marker = tmp_path / "killed"
    dying = {name: _DiesOnce(p, marker) for name, p in planners.items()}
    on_ray = run_monte_carlo(sc, dying, 9, 20, progress=False, keep_records=9, workers=2)
    assert marker.exists()  # a worker did die mid-study
    for name in planners:
        a, b = serial[name], on_ray[name]
        assert b.seeds == a.seeds and [r.seed for r in b.records] == a.seeds
        for key in ("mean_trace", "rmse", "nees"):
            np.testing.assert_array_equal(getattr(b, key), getattr(a, key))
        assert b.plan_times.shape == a.plan_times.shape  # every step of every run, once
        for ra, rb in zip(a.records, b.records, strict=True):
            np.testing.assert_array_equal(rb.sensors, ra.sensors)
            np.testing.assert_array_equal(rb.position_covs, ra.position_covs)
        assert _without_timings(b.summary()) == _without_timings(a.summary())

    marker.unlink()  # the same in evaluation: a policy whose worker dies once
    serial_ev = evaluate({"gsr-dies": GSRPolicy()}, "paper", 4, 1000, progress=False, n_steps=8)
    dying_ev = _DiesOnce(GSRPolicy(), marker)
    ray_ev = evaluate({"gsr-dies": dying_ev}, "paper", 4, 1000, False, workers=2, n_steps=8)
    assert marker.exists()
    for a, b in zip(serial_ev, ray_ev, strict=True):
        assert (a.policy, a.seeds, a.requested) == (b.policy, b.seeds, b.requested)
        for key in ("mean_trace", "rmse", "returns"):
            np.testing.assert_array_equal(getattr(b, key), getattr(a, key))


def _closed_port() -> int:
    """Return a local TCP port nothing listens on (bound, then released)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_unreachable_cluster_fails_fast_with_its_address(tmp_path):
    port = _closed_port()
    for address in (f"127.0.0.1:{port}", f"ray://127.0.0.1:{port}"):
        with pytest.raises(ConnectionError, match=f"cannot reach a Ray cluster at '{address}'"):
            distributed.check_reachable(address, timeout=2.0)
    distributed.check_reachable("auto")  # not HOST:PORT: Ray's to resolve
    # The command line, in a fresh process (this module's Ray is already up): exit 1 in
    # seconds (Ray alone retries for minutes), no output folder.
    import subprocess
    import sys

    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "activetrack.cli", "simulate", "--runs", "2", "--no-progress"]
    res = subprocess.run(
        [*cmd, "--address", f"127.0.0.1:{port}", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 1, res.stderr
    assert f"cannot reach a Ray cluster at '127.0.0.1:{port}'" in res.stderr
    assert "Traceback" not in res.stderr and not out.exists()
