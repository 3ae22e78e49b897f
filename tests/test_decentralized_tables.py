"""``docs/scripts/decentralized_tables.py``'s rows, in the reporting protocol's form: a
planner's row is its own episodes' statistics, a pool's row those of its training seeds'
episodes together, each recomputed here with scipy and numpy; the ratios are paired on
the reference's episodes; the printed table shows the rows' figures."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.stats import trim_mean

from tests.doc_scripts import load


def _script():
    return load("decentralized_tables")


def _run(policy: str, robots_trace: np.ndarray, central: float, ms: float) -> SimpleNamespace:
    """An evaluation's fields the rows read: ``team[:, 0]``, the robots' mean trace."""
    n = robots_trace.size
    team = np.column_stack([robots_trace, np.zeros(n)])
    return SimpleNamespace(
        policy=policy, team=team, mean_trace=np.full(n, central), ms_per_step=np.full(n, ms)
    )


@pytest.fixture
def runs() -> list[SimpleNamespace]:
    rng = np.random.default_rng(7)
    base = rng.lognormal(0.0, 0.3, size=40)  # the episodes' difficulty, shared
    return [
        _run("distributed-gsr", base, 0.5, 3.0),
        _run("gsr", 1.1 * base, 0.45, 0.1),
        _run("set policy 1", 0.9 * base * rng.lognormal(0, 0.05, 40), 0.52, 1.0),
        _run("set policy 2", 0.95 * base * rng.lognormal(0, 0.05, 40), 0.54, 1.2),
    ]


def test_rows_pool_the_seeds_and_give_the_protocols_statistics(runs):
    module = _script()
    pools = {"set policy (2 runs)": ["set policy 1", "set policy 2"]}
    rows = {r["policy"]: r for r in module._rows(runs, "distributed-gsr", pools)}
    assert list(rows) == ["distributed-gsr", "gsr", "set policy (2 runs)"]
    ref = runs[0].team[:, 0]
    pooled = np.stack([runs[2].team[:, 0], runs[3].team[:, 0]])
    for name, scores in (("gsr", runs[1].team[:, 0]), ("set policy (2 runs)", pooled)):
        r = rows[name]
        assert r["iqm_trace"] == pytest.approx(trim_mean(scores.ravel(), 0.25), rel=1e-12)
        assert r["median_trace"] == pytest.approx(np.median(scores), rel=1e-12)
        assert r["mean_trace"] == pytest.approx(np.mean(scores), rel=1e-12)
        assert r["ratio"] == pytest.approx(np.mean(scores) / np.mean(ref), rel=1e-12)
        iqm_ratio = trim_mean(scores.ravel(), 0.25) / trim_mean(ref, 0.25)
        assert r["iqm_ratio"] == pytest.approx(iqm_ratio, rel=1e-12)
        for key in ("iqm_trace", "median_trace", "mean_trace", "ratio", "iqm_ratio"):
            lo, hi = r[f"{key}_ci95"]
            assert lo < r[key] < hi, (name, key)
    # GSR is 1.1 times the reference on every episode: its paired ratio has no spread.
    assert rows["gsr"]["ratio_ci95"] == pytest.approx([1.1, 1.1], rel=1e-9)
    assert rows["distributed-gsr"]["ratio_ci95"] == [1.0, 1.0]
    # A pool's row: the members' mean ratios, the means of their central traces and times.
    pool = rows["set policy (2 runs)"]
    assert pool["runs"] == 2
    members = {"set policy 1": runs[2], "set policy 2": runs[3]}
    expected = {label: run.team[:, 0].mean() / ref.mean() for label, run in members.items()}
    assert pool["members"] == pytest.approx(expected, rel=1e-12)
    assert pool["central_trace"] == pytest.approx(0.53) and pool["ms_per_step"] == pytest.approx(
        1.1
    )


def test_the_table_shows_every_row_s_figures(runs):
    module = _script()
    rows = module._rows(runs, "gsr", {"set policy (2 runs)": ["set policy 1", "set policy 2"]})
    rows = [{"robots": 4, **r} for r in rows]
    lines = module.table(rows, ("robots",)).splitlines()
    assert len(lines) == 2 + len(rows)
    for line, r in zip(lines[2:], rows, strict=True):
        cells = [c.strip() for c in line.split("|")[1:-1]]
        assert cells[:2] == ["4", r["policy"]]
        for cell, key in zip(
            cells[2:7],
            ("iqm_trace", "median_trace", "mean_trace", "iqm_ratio", "ratio"),
            strict=True,
        ):
            lo, hi = r[f"{key}_ci95"]
            assert cell == f"{r[key]:.3f} [{lo:.3f}, {hi:.3f}]"
