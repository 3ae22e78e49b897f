"""Real roots of the Case-I polynomial f3 (eq. 33) from its companion matrix.

The critical points of f0 on the speed circle are the real roots of the 10th-order
Sylvester resultant f3 (eq. 33) in the scaled, centred variable ``X`` of
:mod:`activetrack.solvers._coefficients`; they are the real eigenvalues of f3's companion matrix.
This module normalizes f3 to a monic polynomial, builds its companion matrix and takes the
eigenvalues with the compiled QR of :mod:`activetrack.solvers.hessenberg_qr` (a stack of
polynomials in one kernel call; one polynomial inside the compiled solver), and applies
the acceptance rule: eigenvalues within ``IM_TOL`` of the real axis and ``RE_TOL`` of
``[-1, 1]`` (the circle is ``|X| <= 1``) are kept, real parts clipped onto ``[-1, 1]``.
Accepting a few spurious near-real roots is harmless: each only adds a candidate point.

A solve that knows the roots of a nearby f3 (GSR's later sweeps: the sensor's problem
moved a little since its last solve) starts from them instead
(:func:`accepted_roots_from`): Aberth-Ehrlich steps (Bini 1996), each root frozen once
``|f3|`` there is within the rounding bound of Horner's rule, then an inclusion test
(Carstensen 1991): with ``W_k = f3(z_k) / prod_{j != k} (z_k - z_j)``, ``f3`` is the
characteristic polynomial of ``diag(z) - 1 W^T``, whose Gerschgorin column disks
``D(z_k - W_k, (n - 1)|W_k|)`` lie in ``D(z_k, n |W_k|)``; where those (with ``|f3(z_k)|``
enlarged by its rounding bound) are pairwise disjoint, each holds exactly one root, so
every root is within its disk's radius of its approximation. Otherwise (a cluster, a
root moving far, ``WARM_ITERS`` steps without convergence) the companion-matrix QR
decides, as for a fresh problem.
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import kernel
from activetrack.solvers.hessenberg_qr import balance_factor, hqr
from activetrack.validation import FloatArray

IM_TOL = 1e-2  # accept eigenvalues this close to the real axis (extra candidates are harmless)
RE_TOL = 1e-2  # ... and this far outside [-1, 1] (clipped onto the circle)
_RE_BOUND = 1.0 + RE_TOL
WARM_ITERS = 8  # Aberth sweeps from a warm start before the QR takes over
_N = 10  # f3's degree
# Horner's rule in complex arithmetic on a degree-10 polynomial: |computed - exact| at z
# is below (2 sqrt(2) + 1) n eps sum_k |q_k| |z|^k (|q_10| = 1) to first order. A root is
# taken as found where |p| is below _HORNER_ERR times that sum; the certificate bounds the
# exact |p| by the computed one plus twice that (a margin over the first-order bound).
_HORNER_ERR = 4.0 * _N * 2.220446049250313e-16
_TINY = 1e-290  # products below this (near the subnormals) have lost their relative precision


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

    :func:`activetrack.solvers.hessenberg_qr.balance` of the companion matrix (first row
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

    The eigenvalues of the companion matrices by :mod:`activetrack.solvers.hessenberg_qr`; a row
    that is not finite, or where QR fails to converge (not seen), gets NaN roots (no
    candidates).
    """
    return _roots_rows(np.ascontiguousarray(q, dtype=np.float64))


@kernel
def _horner(q: FloatArray, x: float, y: float) -> tuple[float, float, float, float]:
    """Return ``(Re p, Im p, Re p', Im p')`` of ``p = z^10 + sum q_k z^k`` at ``x + iy``."""
    pr, pi = 1.0, 0.0
    dr, di = 0.0, 0.0
    for j in range(_N - 1, -1, -1):
        dr, di = dr * x - di * y + pr, dr * y + di * x + pi
        pr, pi = pr * x - pi * y + q[j], pr * y + pi * x
    return pr, pi, dr, di


@kernel
def _abs_sum(aq: FloatArray, a: float) -> float:
    """Return ``a^10 + sum aq_k a^k`` (``aq = |q|``): Horner's rounding scale at ``|z| = a``."""
    b = 1.0
    for j in range(_N - 1, -1, -1):
        b = b * a + aq[j]
    return b


@kernel
def _separated(err: FloatArray, zr: FloatArray, zi: FloatArray) -> bool:
    """Return whether the inclusion disks ``D(z_k, n err_k / prod_{j != k} |z_k - z_j|)``
    (``err_k``: a bound on ``|p(z_k)|``) are pairwise disjoint: then each holds exactly
    one root (module docstring)."""
    rad = np.empty(_N)
    for k in range(_N):
        m2 = 1.0
        for j in range(_N):
            if j != k:
                ur, ui = zr[k] - zr[j], zi[k] - zi[j]
                m2 *= ur * ur + ui * ui
        if not (m2 > _TINY and math.isfinite(m2)):  # coincident, or too near to tell
            return False
        rad[k] = _N * err[k] / math.sqrt(m2) * (1.0 + 1e-6)  # 1e-6: the product's rounding
    for k in range(_N):
        for j in range(k):
            ur, ui = zr[k] - zr[j], zi[k] - zi[j]
            s = rad[k] + rad[j]
            if ur * ur + ui * ui <= s * s:
                return False
    return True


@kernel
def _aberth_into(q: FloatArray, zr: FloatArray, zi: FloatArray) -> bool:
    """Return whether Aberth steps from ``zr + 1j zi`` (10,) found every root of monic
    ``q`` (10,), certified by :func:`_separated`; the approximations are updated in place
    (meaningless if not). Gauss-Seidel order: each step uses the others' newest values."""
    aq = np.empty(_N)
    for k in range(_N):
        aq[k] = abs(q[k])
    done = np.zeros(_N, np.bool_)
    err = np.empty(_N)
    for _ in range(WARM_ITERS):
        moved = False
        for k in range(_N):
            if done[k]:
                continue
            x, y = zr[k], zi[k]
            pr, pi, dr, di = _horner(q, x, y)
            bound = _HORNER_ERR * _abs_sum(aq, math.sqrt(x * x + y * y))
            # |p| at rounding level: a root. Squares where the bound's cannot underflow (else
            # both sides could be 0 and any point would pass); hypot below that.
            b2 = bound * bound
            if b2 > _TINY:
                ap2 = pr * pr + pi * pi
                found = ap2 <= b2
                ap = math.sqrt(ap2)
            else:
                ap = math.hypot(pr, pi)
                found = ap <= bound
            if found:
                done[k] = True
                err[k] = ap + 2.0 * bound
                continue
            d2 = dr * dr + di * di
            if not d2 > 0.0:  # p' = 0 (or NaN): no Newton step
                return False
            nr, ni = (pr * dr + pi * di) / d2, (pi * dr - pr * di) / d2  # p / p'
            sr, si = 0.0, 0.0  # sum_j 1 / (z_k - z_j)
            for j in range(_N):
                if j != k:
                    ur, ui = x - zr[j], y - zi[j]
                    u2 = ur * ur + ui * ui
                    if not u2 > 0.0:  # two approximations coincide
                        return False
                    sr += ur / u2
                    si -= ui / u2
            er, ei = 1.0 - (nr * sr - ni * si), -(nr * si + ni * sr)  # 1 - (p / p') s
            e2 = er * er + ei * ei
            if not e2 > 0.0:
                return False
            zr[k] = x - (nr * er + ni * ei) / e2
            zi[k] = y - (ni * er - nr * ei) / e2
            moved = True
        if not moved:
            return _separated(err, zr, zi)
    return False


@kernel
def accepted_roots_from(
    gam: FloatArray, out: FloatArray, zr: FloatArray, zi: FloatArray, warm: bool
) -> tuple[int, bool]:
    """Return ``(n, found)``: how many roots of one f3 (coefficients ``gam`` (11,)) are
    accepted (into the front of ``out`` (10,), clipped to [-1, 1], in the order found) and
    whether its roots were found (into ``zr + 1j zi`` (10,)).

    With ``warm``, ``zr + 1j zi`` holds the roots of a nearby f3 to start from
    (:func:`_aberth_into`, module docstring); else, or where that fails, and for an f3
    with an exact root at 0, the companion QR (:func:`_roots_into`).
    """
    q = np.empty(10)
    _monic_into(gam, q)
    found = warm and q[0] != 0.0 and _aberth_into(q, zr, zi)
    if not found:
        found = _roots_into(q, zr, zi)
    n = 0
    if found:
        for k in range(10):
            re = zr[k]
            if -IM_TOL <= zi[k] <= IM_TOL and -_RE_BOUND <= re <= _RE_BOUND:
                out[n] = min(1.0, max(-1.0, re))
                n += 1
    return n, found


@kernel
def accepted_roots_into(gam: FloatArray, out: FloatArray) -> int:
    """Return how many roots of one f3 (coefficients ``gam`` (11,)) are accepted; they go,
    clipped to [-1, 1], to the front of ``out`` (10,) in the order found.

    :func:`monic` + :func:`monic_roots` for one polynomial, then the acceptance rule of
    the module docstring (NaN fails it).
    """
    n, _ = accepted_roots_from(gam, out, np.empty(10), np.empty(10), False)
    return n


def real_roots_scalar(gam: tuple[float, ...]) -> list[float]:
    """Return the accepted roots of one f3 (coefficients ``gam``), clipped to [-1, 1]."""
    out = np.empty(10)
    n = accepted_roots_into(np.array(gam, dtype=np.float64), out)
    return out[:n].tolist()
