"""GOSPA against its definition: by brute force over every partial assignment (the paper's
Proposition 1, on the distances not cut), on hand-made cases worked out by hand and on
random small sets; against Stone Soup's ``GOSPAMetric`` when it is installed."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from activetrack import gospa


def brute_force(X, Y, c, p):
    """Return (distance, localization, n_missed, n_false) minimizing Proposition 1's cost
    over every partial assignment gamma (each truth to one estimate or to none)."""
    n, m = len(X), len(Y)
    best = None
    for choice in itertools.product(range(-1, m), repeat=n):  # -1: the truth is missed
        used = [j for j in choice if j >= 0]
        if len(used) != len(set(used)):
            continue
        loc = sum(
            np.linalg.norm(np.subtract(X[i], Y[j])) ** p for i, j in enumerate(choice) if j >= 0
        )
        cost = loc + c**p / 2 * (n + m - 2 * len(used))
        if best is None or cost < best[0] - 1e-12:
            best = (cost, loc, n - len(used), m - len(used))
    return best[0] ** (1 / p), best[1], best[2], best[3]


def test_hand_made_cases():
    # One truth, no estimate: one missed target, (c^p / 2)^(1/p).
    r = gospa([[0.0, 0.0]], [], c=3.0, p=2.0)
    assert r.distance == pytest.approx(np.sqrt(4.5)) and r.missed == 4.5 and r.false == 0.0
    assert (r.n_missed, r.n_false) == (1, 0)
    # Nothing at all: 0.
    assert gospa([], [], c=1.0).distance == 0.0
    # A pair within c: its distance (p = 2: sqrt(1^2)).
    r = gospa([[0.0, 0.0]], [[1.0, 0.0]], c=3.0, p=2.0)
    assert r.distance == pytest.approx(1.0) and r.localization == pytest.approx(1.0)
    # A pair beyond c (5 > 3): one missed and one false, c^p/2 each; p = 1: 3.
    r = gospa([[0.0, 0.0]], [[5.0, 0.0]], c=3.0, p=1.0)
    assert r.distance == pytest.approx(3.0) and (r.n_missed, r.n_false) == (1, 1)
    assert r.pairs.shape == (0, 2)
    # Two truths 2 away from one estimate, c = 3, p = 1: one pair (2) and one missed (1.5).
    r = gospa([[0.0, 0.0], [4.0, 0.0]], [[2.0, 0.0]], c=3.0, p=1.0)
    assert r.distance == pytest.approx(3.5) and r.localization == pytest.approx(2.0)
    assert r.missed == pytest.approx(1.5) and (r.n_missed, r.n_false) == (1, 0)
    # The nearest pair is not the best assignment: truths at 0 and 2, estimates at 1 and 3
    # on a line, p = 1: (0-1, 2-3) costs 2, (2-1, 0-3) costs 4 (0-3 = 3 < c = 10).
    r = gospa([[0.0], [2.0]], [[1.0], [3.0]], c=10.0, p=1.0)
    assert r.distance == pytest.approx(2.0)
    assert sorted(map(tuple, r.pairs.tolist())) == [(0, 0), (1, 1)]


@pytest.mark.parametrize("seed", range(40))
def test_random_sets_against_brute_force(seed):
    rng = np.random.default_rng(seed)
    n, m = rng.integers(0, 5, size=2)
    d = int(rng.integers(1, 4))
    X, Y = rng.uniform(0, 10, (n, d)), rng.uniform(0, 10, (m, d))
    c = float(rng.uniform(0.5, 12.0))  # cut-offs below and above the typical distances
    p = float(rng.choice([1.0, 2.0, 3.5]))
    r = gospa(X, Y, c=c, p=p)
    dist, loc, n_missed, n_false = brute_force(X, Y, c, p)
    assert r.distance == pytest.approx(dist, rel=1e-12, abs=1e-12)
    # The decomposition: it adds up, and (ties aside, which random reals exclude) is the
    # brute force's optimal assignment.
    assert r.localization + r.missed + r.false == pytest.approx(r.distance**p, rel=1e-12)
    assert (r.n_missed, r.n_false) == (n_missed, n_false)
    assert r.localization == pytest.approx(loc, rel=1e-12, abs=1e-12)
    assert r.missed == pytest.approx(c**p / 2 * n_missed)
    for i, j in r.pairs:
        assert np.linalg.norm(X[i] - Y[j]) < c


def test_symmetric_and_a_metric_on_random_sets():
    # A metric (the paper's Theorem): symmetric (missed and false swap), triangle inequality.
    rng = np.random.default_rng(7)
    for _ in range(30):
        A, B, C = (rng.uniform(0, 5, (rng.integers(0, 4), 2)) for _ in range(3))
        ab, ba = gospa(A, B, c=2.0, p=2.0), gospa(B, A, c=2.0, p=2.0)
        assert ab.distance == pytest.approx(ba.distance)
        assert (ab.n_missed, ab.n_false) == (ba.n_false, ba.n_missed)
        ac, cb = gospa(A, C, c=2.0).distance, gospa(C, B, c=2.0).distance
        assert ab.distance <= ac + cb + 1e-12


def test_against_stone_soup_if_installed():
    stonesoup = pytest.importorskip("stonesoup")  # noqa: F841 (optional reference)
    from stonesoup.measures import Euclidean
    from stonesoup.metricgenerator.ospametric import GOSPAMetric
    from stonesoup.types.array import StateVector
    from stonesoup.types.state import State

    rng = np.random.default_rng(3)
    for _ in range(10):
        X, Y = (
            rng.uniform(0, 10, (rng.integers(0, 5), 2)),
            rng.uniform(0, 10, (rng.integers(0, 5), 2)),
        )
        metric = GOSPAMetric(c=4.0, p=2.0, measure=Euclidean())
        ref, _ = metric.compute_gospa_metric(
            [State(StateVector(y)) for y in Y], [State(StateVector(x)) for x in X]
        )
        assert gospa(X, Y, c=4.0, p=2.0).distance == pytest.approx(ref.value["distance"])


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"c": 0.0}, "c"),
        ({"c": -1.0}, "c"),
        ({"c": float("nan")}, "c"),
        ({"c": 1.0, "p": 0.5}, "p"),
        ({"c": 1.0, "p": float("inf")}, "p"),
    ],
)
def test_bad_parameters_name_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf"^{field} "):
        gospa([[0.0, 0.0]], [[1.0, 0.0]], **kwargs)


def test_bad_sets_name_the_argument():
    with pytest.raises(ValueError, match="truths"):
        gospa([[np.nan, 0.0]], [[1.0, 0.0]], c=1.0)
    with pytest.raises(ValueError, match="estimates"):
        gospa([[0.0, 0.0]], [1.0, 0.0], c=1.0)
    with pytest.raises(ValueError, match="one dimension"):
        gospa([[0.0, 0.0]], [[1.0, 0.0, 2.0]], c=1.0)
