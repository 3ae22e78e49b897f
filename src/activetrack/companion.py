"""Real roots of the Case-I polynomial f3 (eq. 33) from its companion matrix.

The critical points of f0 on the speed circle are the real roots of the 10th-order
Sylvester resultant f3 (eq. 33) in the scaled, centred variable ``X`` of
:mod:`activetrack._coefficients`; they are the real eigenvalues of f3's companion matrix.
This module builds the (stacked) companion matrices, computes their eigenvalues (one LAPACK
sweep for a stack; ``dgeev`` called directly for one polynomial) and applies the
acceptance rule: eigenvalues within ``IM_TOL`` of the real axis and ``RE_TOL`` of
``[-1, 1]`` (the circle is ``|X| <= 1``) are kept, real parts clipped onto ``[-1, 1]``.
Accepting a few spurious near-real roots is harmless: each only adds a candidate point.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import lapack

from activetrack.validation import FloatArray

IM_TOL = 1e-2  # accept eigenvalues this close to the real axis (extra candidates are harmless)
RE_TOL = 1e-2  # ... and this far outside [-1, 1] (clipped onto the circle)
_RE_BOUND = 1.0 + RE_TOL

_SHIFT = np.eye(10, k=-1)  # the companion matrix below its first row
_COMPANION_TEMPLATE = np.asfortranarray(np.eye(10, k=-1))


def monic(gam: FloatArray) -> FloatArray:
    """Return ``q`` (..., 10): f3 with coefficients ``gam`` (..., 11) is ``z^10 + sum q_k z^k``.

    The polynomial is first scaled by its largest coefficient; a vanishing leading
    coefficient (a root at infinity) is replaced by a tiny one, which only moves that
    root far outside the unit interval where no candidate is taken.
    """
    scale = np.max(np.abs(gam), axis=-1, keepdims=True)
    g = gam / np.where(scale > 0.0, scale, 1.0)
    lead = g[..., 10]
    lead = np.where(np.abs(lead) < 1e-15, np.where(lead < 0.0, -1e-15, 1e-15), lead)
    return g[..., :10] / lead[..., None]


def companion_monic(q: FloatArray) -> FloatArray:
    """Return the companion matrices (..., 10, 10) of ``z^10 + sum q_k z^k`` (``q`` (..., 10))."""
    comp = np.broadcast_to(_SHIFT, q.shape[:-1] + (10, 10)).copy()
    comp[..., 0, :] = -q[..., ::-1]
    return comp


def companion(gam: FloatArray) -> FloatArray:
    """Return the companion matrices (..., 10, 10) of f3 with coefficients ``gam`` (..., 11).

    Normalized as in :func:`monic` (scaled; a vanishing leading coefficient made tiny).
    """
    return companion_monic(monic(gam))


def accept(re, im):
    """Return whether roots with real parts ``re`` and imaginary parts ``im`` are accepted.

    Floats or arrays alike; NaN fails.
    """
    return (abs(im) <= IM_TOL) & (abs(re) <= _RE_BOUND)


def accept_roots(ev: np.ndarray) -> tuple[FloatArray, np.ndarray]:
    """Return ``(x, ok)``: real parts clipped to [-1, 1] and which eigenvalues qualify."""
    re = ev.real
    ok = accept(re, ev.imag) & np.isfinite(re)
    return np.clip(re, -1.0, 1.0), ok


def accepted_first(v: FloatArray, ok: np.ndarray) -> tuple[FloatArray, np.ndarray]:
    """Return ``(v, ok)`` cut to the accepted entries of each row, in order, (m, kmax).

    ``kmax`` is the most any row accepts; shorter rows are padded with ``ok = False``.
    """
    rows = np.arange(v.shape[0])
    rest = ok.copy()
    kmax = int(np.max(np.count_nonzero(ok, axis=1)))
    out_v = np.empty((v.shape[0], kmax))
    out_ok = np.empty((v.shape[0], kmax), dtype=bool)
    for j in range(kmax):
        first = np.argmax(rest, axis=1)  # the first accepted entry left (0 if none)
        out_v[:, j] = v[rows, first]
        out_ok[:, j] = rest[rows, first]
        rest[rows, first] = False
    return out_v, out_ok


def eigvals_stacked(comp: FloatArray) -> np.ndarray:
    """Return the eigenvalues of stacked matrices (n, 10, 10) in one LAPACK sweep.

    If QR fails to converge for some matrix (never seen), the stack is redone one matrix
    at a time and a failing matrix gets NaN eigenvalues (no root candidates).
    """
    try:
        return np.linalg.eigvals(comp)
    except np.linalg.LinAlgError:
        out = np.full(comp.shape[:-1], np.nan, dtype=complex)
        for i, m in enumerate(comp):
            try:
                out[i] = np.linalg.eigvals(m)
            except np.linalg.LinAlgError:
                pass
        return out


def real_roots_scalar(gam: tuple[float, ...]) -> list[float]:
    """Return the accepted roots of one f3 (coefficients ``gam``), clipped to [-1, 1].

    The one-polynomial form of :func:`companion` + :func:`eigvals_stacked` +
    :func:`accept_roots`, calling LAPACK ``dgeev`` directly (numpy's wrapper costs more
    than the 10x10 solve; ``dgeev`` balances the matrix, so no scaling is needed here).
    """
    lead = gam[10]
    if not (lead != 0.0 and math.isfinite(lead)):
        ev = np.linalg.eigvals(companion(np.nan_to_num(np.array(gam))))
        wr, wi = ev.real, ev.imag
    else:
        comp = _COMPANION_TEMPLATE.copy(order="F")
        comp[0, :] = [-gam[j] / lead for j in range(9, -1, -1)]
        # Positional (keywords cost more): no eigenvectors, lwork = 4 n (its default).
        wr, wi, _, _, info = lapack.dgeev(comp, 0, 0, 40, 1)
        if info != 0:  # QR failed to converge (never seen): numpy's driver instead
            ev = np.linalg.eigvals(companion(np.nan_to_num(np.array(gam))))
            wr, wi = ev.real, ev.imag
    # The rule of accept() written out (a call per root costs more than the test); NaN
    # fails it, so it is dropped.
    return [
        -1.0 if re < -1.0 else (1.0 if re > 1.0 else re)
        for re, im in zip(wr.tolist(), wi.tolist(), strict=True)
        if -IM_TOL <= im <= IM_TOL and -_RE_BOUND <= re <= _RE_BOUND
    ]
