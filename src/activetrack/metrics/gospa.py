"""The generalized optimal subpattern assignment (GOSPA) distance between two finite sets.

GOSPA (Rahmathullah, García-Fernández and Svensson, "Generalized optimal sub-pattern
assignment metric", FUSION 2017) compares the set of true targets ``X`` with the set of
estimates ``Y`` (points of the same dimension, e.g. positions). With cut-off ``c > 0``,
order ``1 <= p < inf`` and ``alpha = 2`` (the value for which it decomposes), their
Proposition 1 writes it over partial assignments ``gamma`` (sets of pairs ``(i, j)``, each
``i`` and each ``j`` in at most one pair)::

    d(X, Y) = ( min_gamma  sum_{(i, j) in gamma} |x_i - y_j|^p
                + c^p / 2 (|X| + |Y| - 2 |gamma|) )^(1/p),

so a true target left unassigned is *missed* and an estimate left unassigned is *false*,
each costing ``c^p / 2``. A pair at distance ``>= c`` never lowers the sum below leaving
both unassigned, so the minimum is the optimal full matching of ``min(|X|, |Y|)`` pairs
on the cut distances ``min(|x_i - y_j|, c)^p`` (their Definition 1), which
:func:`scipy.optimize.linear_sum_assignment` finds; the pairs it matches at a cut distance
are counted as one missed and one false target (the same cost, ``c^p``).

:func:`gospa` returns the distance and its decomposition: ``localization`` (the sum of the
assigned pairs' ``|x_i - y_j|^p``), ``missed`` and ``false`` (``c^p / 2`` times their
counts), with ``distance = (localization + missed + false)^(1/p)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from activetrack.validation import FloatArray, as_finite, check_float


@dataclass(frozen=True)
class GOSPAResult:
    """A GOSPA distance and its decomposition (all terms in the ``p``-th power but
    ``distance``).

    Attributes:
        distance: ``(localization + missed + false)^(1/p)``.
        localization: sum over the assigned pairs of ``|x_i - y_j|^p``.
        missed: ``c^p / 2`` times the number of true targets left unassigned.
        false: ``c^p / 2`` times the number of estimates left unassigned.
        pairs: the assigned ``(i, j)`` (index into the truths, into the estimates),
            shape (n_pairs, 2), every pair at distance ``< c``.
        n_missed, n_false: the counts.
    """

    distance: float
    localization: float
    missed: float
    false: float
    pairs: np.ndarray
    n_missed: int
    n_false: int


def _points(name: str, value: ArrayLike, dim: int | None) -> FloatArray:
    """Return a set of points as an (n, d) float64 array (an empty set may be ``[]``)."""
    arr = as_finite(name, value)
    if arr.size == 0:
        return np.zeros((0, dim if dim is not None else 0))
    if arr.ndim != 2:
        raise ValueError(f"{name} must have shape (n, d) (one point a row), got {arr.shape}")
    return arr


def gospa(truths: ArrayLike, estimates: ArrayLike, c: float, p: float = 2.0) -> GOSPAResult:
    """Return the GOSPA distance (``alpha = 2``) between ``truths`` (n, d) and
    ``estimates`` (m, d) with cut-off ``c > 0`` and order ``p >= 1``, and its
    decomposition (:class:`GOSPAResult`); either set may be empty (``[]`` or shape (0, d)).
    The base distance is the Euclidean norm of the rows' difference."""
    c = check_float("c", c, 0.0, low_open=True)
    p = check_float("p", p, 1.0)
    X = _points("truths", truths, None)
    Y = _points("estimates", estimates, X.shape[1] if X.shape[0] else None)
    if X.shape[0] == 0 and Y.shape[0]:
        X = np.zeros((0, Y.shape[1]))
    if X.shape[0] and Y.shape[0] and X.shape[1] != Y.shape[1]:
        raise ValueError(
            f"truths and estimates must have points of one dimension, got {X.shape[1]} and "
            f"{Y.shape[1]}"
        )
    half = 0.5 * c**p
    pairs = np.zeros((0, 2), dtype=np.intp)
    loc = 0.0
    if X.shape[0] and Y.shape[0]:
        from scipy.optimize import linear_sum_assignment  # (scipy.optimize loads on first use)

        d = np.linalg.norm(X[:, None, :] - Y[None, :, :], axis=-1)
        rows, cols = linear_sum_assignment(np.minimum(d, c) ** p)
        near = d[rows, cols] < c  # matches at the cut-off: one missed and one false
        pairs = np.stack([rows[near], cols[near]], axis=1).astype(np.intp)
        loc = float(np.sum(d[rows[near], cols[near]] ** p))
    n_missed, n_false = X.shape[0] - len(pairs), Y.shape[0] - len(pairs)
    missed, false = half * n_missed, half * n_false
    return GOSPAResult(
        float((loc + missed + false) ** (1.0 / p)), loc, missed, false, pairs, n_missed, n_false
    )
