"""Real roots of the Case-I polynomial f3 (eq. 33) from its companion matrix.

The critical points of f0 on the speed circle are the real roots of the 10th-order
Sylvester resultant f3 (eq. 33) in the scaled, centred variable ``X`` of
:mod:`activetrack._coefficients`; they are the real eigenvalues of f3's companion matrix.
This module normalizes f3 to a monic polynomial, builds its companion matrix and takes the
eigenvalues with the compiled QR of :mod:`activetrack.hessenberg_qr` (a stack of
polynomials in one kernel call; one polynomial inside the compiled solver), and applies
the acceptance rule: eigenvalues within ``IM_TOL`` of the real axis and ``RE_TOL`` of
``[-1, 1]`` (the circle is ``|X| <= 1``) are kept, real parts clipped onto ``[-1, 1]``.
Accepting a few spurious near-real roots is harmless: each only adds a candidate point.
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import kernel
from activetrack.hessenberg_qr import balance_factor, hqr
from activetrack.validation import FloatArray

IM_TOL = 1e-2  # accept eigenvalues this close to the real axis (extra candidates are harmless)
RE_TOL = 1e-2  # ... and this far outside [-1, 1] (clipped onto the circle)
_RE_BOUND = 1.0 + RE_TOL


@kernel
def _monic_into(gam: FloatArray, q: FloatArray) -> None:
    """Write ``q`` (10,): f3 with coefficients ``gam`` (11,) is ``z^10 + sum q_k z^k``
    (normalized as in :func:`monic`; NaN if a coefficient is not finite)."""
    scale = 0.0
    for k in range(11):
        if not math.isfinite(gam[k]):
            q[:] = np.nan
            return
        scale = max(scale, abs(gam[k]))
    if scale == 0.0:
        scale = 1.0
    lead = gam[10] / scale
    if abs(lead) < 1e-15:
        lead = -1e-15 if lead < 0.0 else 1e-15
    for k in range(10):
        q[k] = gam[k] / scale / lead


@kernel
def _monic_rows(gam: FloatArray) -> FloatArray:
    """Return :func:`monic` of the rows of ``gam`` (m, 11)."""
    q = np.empty((gam.shape[0], 10))
    for i in range(gam.shape[0]):
        _monic_into(gam[i], q[i])
    return q


def monic(gam: FloatArray) -> FloatArray:
    """Return ``q`` (..., 10): f3 with coefficients ``gam`` (..., 11) is ``z^10 + sum q_k z^k``.

    The polynomial is first scaled by its largest coefficient; a vanishing leading
    coefficient (a root at infinity) is replaced by a tiny one, which only moves that
    root far outside the unit interval where no candidate is taken. Rows with a
    coefficient that is not finite give NaN.
    """
    gam = np.asarray(gam, dtype=np.float64)
    rows = np.ascontiguousarray(gam.reshape(-1, 11))
    return _monic_rows(rows).reshape(gam.shape[:-1] + (10,))


@kernel
def _balanced_companion_into(q: FloatArray, a: FloatArray) -> None:
    """Write the balanced companion matrix of ``z^n + sum q_k z^k`` into ``a`` (n, n).

    :func:`activetrack.hessenberg_qr.balance` of the companion matrix (first row
    ``-q`` reversed, ones below the diagonal), bit for bit, in O(n) a pass instead of
    O(n^2): a diagonal similarity keeps the sparsity, so only the first row ``top`` and
    the subdiagonal ``sub`` are stored, and each row or column sum runs over its nonzero
    entries in the general loop's order.
    """
    n = q.shape[0]
    top = np.empty(n)
    sub = np.ones(n)  # sub[i] = a[i, i - 1] (sub[0] unused)
    for j in range(n):
        top[j] = -q[n - 1 - j]
    done = False
    while not done:
        done = True
        for i in range(n):
            c = 0.0  # column i without the diagonal: a[0, i], a[i + 1, i]
            if i != 0:
                c += abs(top[i])
            if i + 1 < n:
                c += abs(sub[i + 1])
            r = 0.0  # row i without the diagonal
            if i == 0:
                for j in range(1, n):
                    r += abs(top[j])
            else:
                r = abs(sub[i])
            if c == 0.0 or r == 0.0:
                continue
            f = balance_factor(c, r)
            if f != 1.0:
                done = False
                if i == 0:
                    for j in range(n):
                        top[j] /= f
                    top[0] *= f
                else:
                    sub[i] /= f
                    top[i] *= f
                if i + 1 < n:
                    sub[i + 1] *= f
    a[:, :] = 0.0
    for j in range(n):
        a[0, j] = top[j]
    for i in range(1, n):
        a[i, i - 1] = sub[i]


@kernel
def _roots_into(q: FloatArray, wr: FloatArray, wi: FloatArray) -> bool:
    """Return whether the roots of monic ``q`` (10,) were found (into ``wr + 1j wi``);
    NaN roots if ``q`` is not finite or QR fails.

    Exact zero roots (``q_0 = ... = q_{z-1} = 0``) are taken out first: QR finds a
    multiple root at 0 only to ~eps^(1/z), and the symmetric problems that give them
    (the target on an eigen-axis) are common.
    """
    for k in range(10):
        if not math.isfinite(q[k]):
            wr[:] = np.nan
            wi[:] = np.nan
            return False
    z = 0
    while z < 10 and q[z] == 0.0:
        wr[z] = 0.0
        wi[z] = 0.0
        z += 1
    if z == 10:
        return True
    n = 10 - z
    a = np.empty((n, n))  # contiguous: QR's indexing compiles to fixed strides
    _balanced_companion_into(q[z:], a)
    if not hqr(a, wr[z:], wi[z:]):
        wr[:] = np.nan
        wi[:] = np.nan
        return False
    return True


@kernel
def _roots_rows(q: FloatArray) -> np.ndarray:
    """Return the roots (m, 10) of the monic polynomials ``q`` (m, 10) (NaN rows: none)."""
    m = q.shape[0]
    wr = np.empty(10)
    wi = np.empty(10)
    out = np.empty((m, 10), dtype=np.complex128)
    for i in range(m):
        _roots_into(q[i], wr, wi)
        for k in range(10):
            out[i, k] = complex(wr[k], wi[k])
    return out


def monic_roots(q: FloatArray) -> np.ndarray:
    """Return the roots (m, 10) of ``z^10 + sum q_k z^k`` for each row of ``q`` (m, 10).

    The eigenvalues of the companion matrices by :mod:`activetrack.hessenberg_qr`; a row
    that is not finite, or where QR fails to converge (not seen), gets NaN roots (no
    candidates).
    """
    return _roots_rows(np.ascontiguousarray(q, dtype=np.float64))


@kernel
def accepted_roots_into(gam: FloatArray, out: FloatArray) -> int:
    """Return how many roots of one f3 (coefficients ``gam`` (11,)) are accepted; they go,
    clipped to [-1, 1], to the front of ``out`` (10,) in the order found.

    :func:`monic` + :func:`monic_roots` for one polynomial, then the acceptance rule of
    the module docstring (NaN fails it).
    """
    q = np.empty(10)
    wr = np.empty(10)
    wi = np.empty(10)
    _monic_into(gam, q)
    n = 0
    if _roots_into(q, wr, wi):
        for k in range(10):
            re = wr[k]
            if -IM_TOL <= wi[k] <= IM_TOL and -_RE_BOUND <= re <= _RE_BOUND:
                out[n] = min(1.0, max(-1.0, re))
                n += 1
    return n


def real_roots_scalar(gam: tuple[float, ...]) -> list[float]:
    """Return the accepted roots of one f3 (coefficients ``gam``), clipped to [-1, 1]."""
    out = np.empty(10)
    n = accepted_roots_into(np.array(gam, dtype=np.float64), out)
    return out[:n].tolist()
