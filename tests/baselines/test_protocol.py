"""The reporting protocol's statistics, each against an independent computation: the IQM
by hand, the bootstrap's exact variance (closed form), the intervals' coverage of known
IQMs and medians (Monte Carlo, binomial bands), the track-loss rate by hand."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from activetrack import make_scenario
from activetrack.baselines.protocol import (
    interval,
    iqm,
    paired_ratio_interval,
    prior_traces,
    resample,
    stratified_interval,
    summary,
    track_loss_rate,
)


def hand_iqm(values) -> float:
    """Sort, cut floor(n / 4) from each end (rliable's aggregate_iqm, scipy's trim_mean
    convention: 1 of 5, 1 of 7, 2 of 8), average what is left."""
    x = sorted(float(v) for v in np.ravel(values))
    k = len(x) // 4
    kept = x[k : len(x) - k]
    return sum(kept) / len(kept)


@pytest.mark.parametrize("n", range(1, 14))
def test_iqm_is_the_mean_of_the_middle_after_cutting_a_quarter_from_each_end(n):
    rng = np.random.default_rng(n)
    x = rng.lognormal(0.0, 1.0, n)
    assert iqm(x) == pytest.approx(hand_iqm(x), rel=1e-14)


def test_iqm_by_hand_on_small_arrays():
    # n = 4: the two middle values; n = 5: the middle three; n = 6: the middle four.
    assert iqm([10.0, 1.0, 3.0, 2.0]) == pytest.approx(2.5)
    assert iqm([100.0, 1.0, 2.0, 3.0, -50.0]) == pytest.approx(2.0)
    assert iqm([6.0, 1.0, 5.0, 2.0, 4.0, 3.0]) == pytest.approx(3.5)
    # n = 7: one value cut at each end, five kept.
    assert iqm([0.0, 1, 2, 3, 4, 5, 1000]) == pytest.approx(3.0)


def test_iqm_pools_a_runs_by_episodes_matrix():
    rng = np.random.default_rng(3)
    m = rng.normal(size=(5, 7))
    point, lo, hi = interval(m, "iqm", n_resamples=99)
    assert point == pytest.approx(hand_iqm(m), rel=1e-14)
    assert lo <= point <= hi
    assert interval(m, "median", n_resamples=9)[0] == pytest.approx(np.median(m.ravel()))


def bootstrap_variance_of_the_mean(y: np.ndarray) -> float:
    """Exact variance of the two-way bootstrap's mean of (R, E) ``y``: rows and columns
    drawn with replacement, independently. The mean of a resample is w^T y v with
    w = m / R, v = c / E for multinomial counts m ~ Mult(R, 1/R), c ~ Mult(E, 1/E), so its
    variance is tr(y^T E[w w^T] y E[v v^T]) - (E[w]^T y E[v])^2, with
    E[w w^T] = (I - J / R) / R^2 + J / R^2 (multinomial covariance plus the mean's square)."""
    r, e = y.shape

    def second_moment(n: int) -> np.ndarray:
        return (np.eye(n) - np.ones((n, n)) / n) / n**2 + np.ones((n, n)) / n**2

    a, b = second_moment(r), second_moment(e)
    return float(np.trace(y.T @ a @ y @ b) - np.mean(y) ** 2)


def test_two_way_bootstrap_has_the_exact_variance_of_resampling_rows_and_columns():
    """The resamples' mean has the closed-form variance of drawing rows (runs) and columns
    (episodes, the same for every row) with replacement: a row-only, column-only or
    per-row-column scheme has another (printed in the message)."""
    rng = np.random.default_rng(4)
    y = rng.normal(0, 1, (6, 1)) + rng.normal(0, 1, (1, 9)) + rng.normal(0, 0.3, (6, 9))
    n = 200_000
    means = resample(y, n, np.random.default_rng(5))[0].mean(axis=1)
    exact = bootstrap_variance_of_the_mean(y)
    # Monte Carlo band of a sample variance: sd^2 = (m4 - var^2) / n.
    centred = means - means.mean()
    sd = np.sqrt((np.mean(centred**4) - np.mean(centred**2) ** 2) / n)
    assert abs(np.var(means) - exact) <= 5 * sd, (np.var(means), exact, sd)
    assert 5 * sd < 0.05 * exact  # the band is far tighter than a 10% error
    rows_only = np.var(y.mean(axis=1)) / y.shape[0]
    columns_only = np.var(y.mean(axis=0)) / y.shape[1]
    assert min(abs(rows_only - exact), abs(columns_only - exact)) > 0.1 * exact


def lognormal_iqm(mu: float, s: float) -> float:
    """IQM of LogNormal(mu, s): 2 * int_{q1}^{q3} x f(x) dx
    = 2 exp(mu + s^2 / 2) [Phi(z3 - s) - Phi(z1 - s)], z1, z3 the normal quartiles."""
    z1, z3 = stats.norm.ppf([0.25, 0.75])
    return float(2 * np.exp(mu + s**2 / 2) * (stats.norm.cdf(z3 - s) - stats.norm.cdf(z1 - s)))


def _coverage_band(reps: int, level: float = 0.95) -> tuple[float, float]:
    """Return the central 99% range of the covered fraction of ``reps`` intervals whose
    true coverage is ``level`` (binomial)."""
    lo, hi = stats.binom.ppf([0.005, 0.995], reps, level)
    return lo / reps, hi / reps


def test_lognormal_iqm_closed_form_against_a_large_sample():
    x = np.random.default_rng(6).lognormal(0.3, 0.7, 2_000_000)
    assert stats.trim_mean(x, 0.25) == pytest.approx(lognormal_iqm(0.3, 0.7), rel=2e-3)


@pytest.mark.parametrize("statistic", ["iqm", "median"])
def test_interval_covers_the_iqm_and_median_of_a_heavy_tailed_quantity(statistic):
    """100 lognormal episodes (positive, right-skewed, like the traces): the nominal 95%
    interval covers the true IQM (closed form) or median exp(mu) in a binomial band
    around 95% of 1000 samples (a 10% narrower interval covers about 92.4% and fails)."""
    rng = np.random.default_rng(40 if statistic == "iqm" else 41)
    mu, s, n, reps = 0.0, 0.5, 100, 1000
    truth = lognormal_iqm(mu, s) if statistic == "iqm" else np.exp(mu)
    covered = 0
    for rep in range(reps):
        x = rng.lognormal(mu, s, n)
        _, lo, hi = interval(x, statistic, n_resamples=999, seed=rep)
        covered += lo <= truth <= hi
    band = _coverage_band(reps)
    assert band[0] <= covered / reps <= band[1], (covered, band)


def test_paired_ratio_interval_covers_the_ratio_of_iqms():
    """Paired lognormal episodes x = exp(a), y = exp(a + b) (b independent of a): the
    ratio of the IQMs estimates lognormal_iqm(m, sqrt(s_a^2 + s_b^2)) /
    lognormal_iqm(0, s_a); its nominal 95% interval covers it in the binomial band."""
    rng = np.random.default_rng(42)
    n, reps, sa, m, sb = 100, 1000, 0.5, 0.1, 0.2
    truth = lognormal_iqm(m, np.hypot(sa, sb)) / lognormal_iqm(0.0, sa)
    covered = 0
    for rep in range(reps):
        a = rng.normal(0.0, sa, n)
        x, y = np.exp(a), np.exp(a + rng.normal(m, sb, n))
        _, lo, hi = paired_ratio_interval(y, x, "iqm", n_resamples=999, seed=rep)
        covered += lo <= truth <= hi
    band = _coverage_band(reps)
    assert band[0] <= covered / reps <= band[1], (covered, band)


def test_paired_ratio_keeps_the_pairing():
    """y = 1.2 x episode by episode: every paired resample has the ratio 1.2 exactly,
    while the spread of x alone is wide."""
    x = np.random.default_rng(7).lognormal(0.0, 1.0, 50)
    ratio, lo, hi = paired_ratio_interval(1.2 * x, x, "iqm", n_resamples=999)
    assert ratio == pytest.approx(1.2) and lo == pytest.approx(1.2) and hi == pytest.approx(1.2)
    assert paired_ratio_interval(x, x, "median", n_resamples=99) == (1.0, 1.0, 1.0)
    _, lo, hi = interval(x, "iqm", n_resamples=999)
    assert hi / lo > 1.3


def test_stratified_interval_resamples_each_task_within_itself():
    """Two tasks, the first constant 0 and the second constant 10: a resample within each
    task keeps half the values at 0 and half at 10, so the pooled mean is 5 in every
    resample; resampling the pooled values across tasks would not be."""
    tasks = [np.zeros((3, 4)), np.full((3, 4), 10.0)]
    assert stratified_interval(tasks, "mean", n_resamples=199) == (5.0, 5.0, 5.0)
    # Pooled: the IQM of all 24 values (six cut from each end).
    rng = np.random.default_rng(8)
    tasks = [rng.normal(size=(3, 5)), rng.normal(3.0, 1.0, size=(2, 4))]
    point, lo, hi = stratified_interval(tasks, "iqm", n_resamples=199)
    assert point == pytest.approx(hand_iqm(np.concatenate([t.ravel() for t in tasks])))
    assert lo < point < hi


def test_summary_and_reproducibility():
    x = np.random.default_rng(9).lognormal(0.0, 1.0, (2, 30))
    out = summary(x)
    assert out["runs"] == 2 and out["episodes"] == 30
    assert out["iqm"] == pytest.approx(hand_iqm(x))
    assert out["median"] == pytest.approx(np.median(x)) and out["mean"] == pytest.approx(x.mean())
    for name in ("iqm", "median", "mean"):
        lo, hi = out[f"{name}_ci95"]
        assert x.min() <= lo <= out[name] <= hi <= x.max()
    assert summary(x) == out  # a fixed generator: the same intervals
    assert interval([3.0], "iqm") == (3.0, 3.0, 3.0)


def test_track_loss_rate_on_a_hand_made_episode():
    # Two targets, five steps; threshold 8 m^2 for the first, 2 m^2 for the second.
    seen = np.array([[1, 1], [0, 0], [0, 1], [0, 0], [1, 0]], dtype=bool)
    traces = np.array([[1.0, 1.0], [5.0, 3.0], [9.0, 0.5], [12.0, 1.5], [20.0, 2.5]])
    # Lost: (1, 1) unseen and 3 > 2; (2, 0) unseen and 9 > 8; (3, 0) 12 > 8; (4, 1)
    # 2.5 > 2. Not lost: (1, 0) unseen but 5 <= 8; (3, 1) unseen but 1.5 <= 2; (4, 0) seen.
    assert track_loss_rate(seen, traces, [8.0, 2.0]) == pytest.approx(4 / 10)
    assert track_loss_rate(seen, traces, 4.0) == pytest.approx(3 / 10)  # (1,0) (2,0) (3,0)
    assert track_loss_rate(seen[:, 0], traces[:, 0], 8.0) == pytest.approx(2 / 5)
    assert track_loss_rate(np.ones((0, 2), bool), np.ones((0, 2)), 1.0) == 0.0


def test_track_loss_rate_counts_only_present_targets():
    # Targets that appear and leave (patrol): the episode above with slot 1 empty at
    # steps 0-2 and slot 0 held without a track (inf) at step 4. Present pairs: 7. Lost:
    # (2, 0) 9 > 8, (3, 0) 12 > 8, (4, 1) 2.5 > 2; not lost: (1, 0) 5 <= 8, (3, 1)
    # 1.5 <= 2, (4, 0) measured even without a track. The empty slot's (1, 1) is gone.
    seen = np.array([[1, 1], [0, 0], [0, 1], [0, 0], [1, 0]], dtype=bool)
    traces = np.array([[1.0, 1.0], [5.0, 3.0], [9.0, 0.5], [12.0, 1.5], [np.inf, 2.5]])
    present = np.array([[1, 0], [1, 0], [1, 0], [1, 1], [1, 1]], dtype=bool)
    assert track_loss_rate(seen, traces, [8.0, 2.0], present) == pytest.approx(3 / 7)
    traces[4, 0], seen[4, 0] = np.inf, False  # unseen and no track: lost
    assert track_loss_rate(seen, traces, [8.0, 2.0], present) == pytest.approx(4 / 7)
    assert track_loss_rate(seen, traces, 1.0, np.zeros_like(seen)) == 0.0  # nobody there
    with pytest.raises(ValueError, match="traces must be >= 0"):
        track_loss_rate(seen, np.full(seen.shape, np.nan), 1.0)
    with pytest.raises(ValueError, match="seen, traces and present must have the same shape"):
        track_loss_rate(seen, traces, 1.0, present.T)
    with pytest.raises(ValueError, match="traces must be >= 0"):
        track_loss_rate(seen, -traces, 1.0)


def test_prior_traces_are_the_position_block_of_p0():
    assert prior_traces(make_scenario("urban")).tolist() == [4.0 + 4.0]  # P0 (4, 4, 25, 25)
    two = make_scenario("two_targets")
    assert prior_traces(two).tolist() == [np.trace(p[:2, :2]) for p in two.initial_covs]
    assert len(prior_traces(two)) == 2


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: interval([], "iqm"), "scores must be a non-empty"),
        (lambda: interval(np.ones((2, 2, 2))), "scores must be a non-empty"),
        (lambda: interval([1.0, np.nan]), "scores must be finite"),
        (lambda: interval(["a"]), "scores must"),
        (lambda: interval([1.0, 2.0], "mode"), "statistic must be one of"),
        (lambda: interval([1.0, 2.0], level=1.0), "level must be"),
        (lambda: interval([1.0, 2.0], n_resamples=0), "n_resamples must be"),
        (lambda: paired_ratio_interval([1.0, 2.0], [1.0]), "the same episodes"),
        (lambda: paired_ratio_interval([1.0], [0.0]), "reference's iqm must be > 0"),
        (lambda: stratified_interval([]), "tasks must be a non-empty list"),
        (lambda: track_loss_rate([True], [1.0, 2.0], 1.0), "the same shape"),
        (lambda: track_loss_rate([True, False], [1.0, 2.0], [1.0, 1.0, 1.0]), "threshold"),
        (lambda: track_loss_rate([True], [1.0], -1.0), "threshold must be >= 0"),
    ],
)
def test_errors_name_the_field(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_a_large_matrix_is_resampled_in_batches_of_bounded_size(monkeypatch):
    """Memory is bounded: with at most 1000 values per batch, a 10 x 60 matrix (600 values
    a resample) is resampled one resample at a time; a paired ratio's 3 x 10 and 1 x 10
    (40 values) 25 at a time."""
    from activetrack.baselines import protocol

    sizes = []
    real = protocol.resample

    def recorded(scores, n, rng, columns=None):
        sizes.append(n * scores.size)
        return real(scores, n, rng, columns)

    monkeypatch.setattr(protocol, "BATCH_VALUES", 1000)
    monkeypatch.setattr(protocol, "resample", recorded)
    rng = np.random.default_rng(12)
    interval(rng.normal(size=(10, 60)), "iqm", n_resamples=50)
    assert sizes == [600] * 50
    sizes.clear()
    paired_ratio_interval(rng.uniform(1, 2, (3, 10)), rng.uniform(1, 2, 10), n_resamples=40)
    assert sizes == [25 * 30, 25 * 10, 15 * 30, 15 * 10]
