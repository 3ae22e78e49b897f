"""Covariance intersection: fusing estimates whose errors are correlated by an unknown amount.

Robots that share their *estimates* (not their raw measurements) over limited links
(issue 37; the paper's motivation: "limitations on the robots' processing and
communication resources") cannot know how correlated their errors are: they may have used
the same measurements, or each other's earlier estimates. The Kalman (information) fusion
``P^{-1} = sum_i P_i^{-1}`` then double counts and is over-confident. Covariance
intersection (Julier & Uhlmann, "A non-divergent estimation algorithm in the presence of
unknown correlations", ACC 1997) fuses ``n`` estimates ``(x_i, P_i)`` as::

    P^{-1} = sum_i w_i P_i^{-1},    P^{-1} x = sum_i w_i P_i^{-1} x_i,

with weights ``w`` on the simplex (``w_i >= 0``, ``sum w_i = 1``). For *any* joint error
covariance whose diagonal blocks are (at most) the ``P_i``, ``P`` bounds the fused error's
covariance: ``P - E[e e^T]`` is positive semidefinite (the estimate is never
over-confident). The weights are chosen to minimize ``tr P`` (``"trace"``) or
``log det P`` (``"logdet"``), both convex in ``w``: for two estimates a bounded scalar
minimization (:func:`scipy.optimize.minimize_scalar`), for more a minimization over the
simplex (:func:`scipy.optimize.minimize`, SLSQP). ``P`` is SPD by construction (a convex
combination of SPD information matrices, inverted).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from activetrack.validation import FloatArray, as_finite, spd

__all__ = ["CIResult", "covariance_intersection", "information_fusion"]

CRITERIA = ("trace", "logdet")


class CIResult(NamedTuple):
    """A fused estimate: ``mean`` (d,), ``covariance`` (d, d) SPD, ``weights`` (n,) on the
    simplex (the estimates' shares of the fused information)."""

    mean: FloatArray
    covariance: FloatArray
    weights: FloatArray


def _checked(means: ArrayLike, covariances: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Return ``(means (n, d), covariances (n, d, d))`` checked: finite, SPD, n >= 1."""
    x = as_finite("means", means)
    if x.ndim != 2 or x.shape[0] < 1 or x.shape[1] < 1:
        raise ValueError(f"means must have shape (n, d) with n, d >= 1, got {x.shape}")
    n, d = x.shape
    P = spd("covariances", covariances)
    if P.shape != (n, d, d):
        raise ValueError(f"covariances must have shape ({n}, {d}, {d}) (means: {x.shape}), "
                         f"got {P.shape}")  # fmt: skip
    return x, 0.5 * (P + np.swapaxes(P, -1, -2))


def _fused(info: FloatArray, info_x: FloatArray, w: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Return the fused ``(mean, covariance)`` of weights ``w`` (unchecked)."""
    Y = np.einsum("i,ijk->jk", w, info)
    P = np.linalg.inv(Y)
    P = 0.5 * (P + P.T)
    return P @ np.einsum("i,ij->j", w, info_x), P


def information_fusion(means: ArrayLike, covariances: ArrayLike) -> CIResult:
    """Return the Kalman (information) fusion of independent estimates:
    ``P^{-1} = sum_i P_i^{-1}``, ``P^{-1} x = sum_i P_i^{-1} x_i`` (``weights`` all 1).
    Exact for independent errors, over-confident for correlated ones."""
    x, P = _checked(means, covariances)
    info = np.linalg.inv(P)
    mean, cov = _fused(info, np.einsum("ijk,ik->ij", info, x), np.ones(len(x)))
    return CIResult(mean, cov, np.ones(len(x)))


def covariance_intersection(
    means: ArrayLike, covariances: ArrayLike, criterion: str = "trace"
) -> CIResult:
    """Return the covariance-intersection fusion (module docstring) of ``n`` estimates,
    ``means`` (n, d) and ``covariances`` (n, d, d) SPD, with the weights minimizing the
    fused covariance's trace (``criterion="trace"``) or log-determinant (``"logdet"``).

    One estimate is returned unchanged (weight 1). The weights are found to about ``1e-8``
    for two estimates (Brent's bounded method: ``xatol`` ``1e-10`` plus ``sqrt(eps)``
    times the weight), to SLSQP's ``ftol`` ``1e-12`` on the criterion for more; the fused
    covariance is consistent for any weights on the simplex, so the tolerance affects only
    how small it is, never its consistency.
    """
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {list(CRITERIA)}, got {criterion!r}")
    x, P = _checked(means, covariances)
    n = len(x)
    if n == 1:
        return CIResult(x[0].copy(), P[0].copy(), np.ones(1))
    info = np.linalg.inv(P)
    info = 0.5 * (info + np.swapaxes(info, -1, -2))
    info_x = np.einsum("ijk,ik->ij", info, x)
    # Scale-free objective: the criterion of P relative to the first estimate's scale, so
    # the optimizers' absolute tolerances mean the same for metres and millimetres.
    scale = float(np.trace(P[0])) / P.shape[-1]

    def objective(w: FloatArray) -> float:
        Y = np.einsum("i,ijk->jk", w, info) * scale
        if criterion == "trace":
            return float(np.trace(np.linalg.inv(Y)))
        sign, logdet = np.linalg.slogdet(Y)
        return float(-logdet) if sign > 0 else np.inf

    if n == 2:
        from scipy.optimize import minimize_scalar

        res = minimize_scalar(
            lambda a: objective(np.array([a, 1.0 - a])),
            bounds=(0.0, 1.0),
            method="bounded",
            options={"xatol": 1e-10},
        )
        a = float(np.clip(res.x, 0.0, 1.0))
        w = np.array([a, 1.0 - a])
        # The bounded method never evaluates the ends exactly: an estimate that dominates
        # (weight 0 or 1) is kept if it is better.
        for end in (np.array([1.0, 0.0]), np.array([0.0, 1.0])):
            if objective(end) < objective(w):
                w = end
    else:
        from scipy.optimize import minimize

        w0 = np.full(n, 1.0 / n)
        best = min(range(n), key=lambda i: objective(np.eye(n)[i]))
        res = minimize(
            objective,
            w0,
            method="SLSQP",
            bounds=[(0.0, 1.0)] * n,
            constraints=[{"type": "eq", "fun": lambda w: np.sum(w) - 1.0}],
            options={"ftol": 1e-12, "maxiter": 500},
        )
        w = np.clip(res.x, 0.0, None)
        w = w / w.sum()
        if not np.isfinite(objective(w)) or objective(np.eye(n)[best]) < objective(w):
            w = np.eye(n)[best]  # a vertex (one estimate alone) is the optimum
    mean, cov = _fused(info, info_x, w)
    return CIResult(mean, cov, w)
