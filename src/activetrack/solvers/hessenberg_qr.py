"""Eigenvalues of small real upper-Hessenberg matrices: balancing and Francis QR, compiled.

The roots of the Case-I polynomial f3 (eq. 33) are the eigenvalues of its 10x10
companion matrix (:mod:`activetrack.solvers.companion`), which is upper Hessenberg. For a matrix
this small, LAPACK's ``dgeev`` spends most of its time in the call itself; these kernels
do the same two steps without it:

- :func:`balance`: diagonal similarity by powers of 2 (exact in floating point) until
  every row and column have comparable norms (Parlett and Reinsch; LAPACK ``dgebal``'s
  scaling), which keeps the QR iteration accurate for coefficients of very different
  sizes;
- :func:`hqr`: the implicit double-shift (Francis) QR iteration on the Hessenberg form,
  deflating at negligible subdiagonal entries (EISPACK ``hqr``; Numerical Recipes 11.6),
  with exceptional shifts every 10 iterations and at most ``MAX_ITS`` per eigenvalue
  (double roots, which converge linearly, take up to about 70).

Both are backward stable: the eigenvalues are those of a matrix within a few units of
rounding of the balanced one, as LAPACK's are.
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import kernel

MAX_ITS = 300  # QR iterations per eigenvalue before giving up: LAPACK dlahqr's 30 max(10, n)


@kernel
def balance_factor(c: float, r: float) -> float:
    """Return the power of 2 by which balancing divides a row and multiplies its column
    (``c``, ``r``: the column's and the row's off-diagonal 1-norms, both > 0), or 1.0
    when that would not lower ``c + r`` by 5%."""
    s = c + r
    f = 1.0
    g = r / 2.0
    while c < g:
        f *= 2.0
        c *= 4.0
    g = r * 2.0
    while c > g:
        f /= 2.0
        c /= 4.0
    return f if (c + r) / f < 0.95 * s else 1.0


@kernel
def balance(a: np.ndarray) -> None:
    """Balance the square matrix ``a`` in place by a diagonal similarity of powers of 2."""
    n = a.shape[0]
    done = False
    while not done:
        done = True
        for i in range(n):
            c = 0.0
            r = 0.0
            for j in range(n):
                if j != i:
                    c += abs(a[j, i])
                    r += abs(a[i, j])
            if c == 0.0 or r == 0.0:
                continue
            f = balance_factor(c, r)
            if f != 1.0:
                done = False
                for j in range(n):
                    a[i, j] /= f
                for j in range(n):
                    a[j, i] *= f


@kernel
def hqr(a: np.ndarray, wr: np.ndarray, wi: np.ndarray) -> bool:
    """Return whether the QR iteration converged; the eigenvalues of the upper-Hessenberg
    ``a`` (destroyed) go to ``wr + 1j wi``, complex pairs adjacent (``wi`` of the pair
    ``-z, +z``)."""
    n = a.shape[0]
    anorm = 0.0
    for i in range(n):
        for j in range(max(i - 1, 0), n):
            anorm += abs(a[i, j])
    nn = n - 1
    t = 0.0  # the exceptional shifts so far
    while nn >= 0:
        its = 0
        while True:
            # The last negligible subdiagonal entry a[l, l-1] (l = 0 if none).
            low = 0
            for ll in range(nn, 0, -1):
                s = abs(a[ll - 1, ll - 1]) + abs(a[ll, ll])
                if s == 0.0:
                    s = anorm
                if abs(a[ll, ll - 1]) + s == s:
                    a[ll, ll - 1] = 0.0
                    low = ll
                    break
            x = a[nn, nn]
            if low == nn:  # a 1x1 block: one real eigenvalue
                wr[nn] = x + t
                wi[nn] = 0.0
                nn -= 1
                break
            y = a[nn - 1, nn - 1]
            w = a[nn, nn - 1] * a[nn - 1, nn]
            if low == nn - 1:  # a 2x2 block: two real eigenvalues or a complex pair
                p = 0.5 * (y - x)
                q = p * p + w
                z = math.sqrt(abs(q))
                x += t
                if q >= 0.0:
                    z = p + math.copysign(z, p)
                    wr[nn - 1] = x + z
                    wr[nn] = x - w / z if z != 0.0 else x + z
                    wi[nn - 1] = 0.0
                    wi[nn] = 0.0
                else:
                    wr[nn - 1] = x + p
                    wr[nn] = x + p
                    wi[nn - 1] = -z
                    wi[nn] = z
                nn -= 2
                break
            if its == MAX_ITS:
                return False
            if its % 10 == 0 and its > 0:  # exceptional shift (breaks a cycle)
                t += x
                for i in range(nn + 1):
                    a[i, i] -= x
                s = abs(a[nn, nn - 1]) + abs(a[nn - 1, nn - 2])
                x = 0.75 * s
                y = x
                w = -0.4375 * s * s
            its += 1
            # The first column of (A - s1)(A - s2) at the top of the active block: the bulge
            # starts at m = low. (EISPACK also looks for two small subdiagonal entries in a
            # row to start lower; at n = 10 such a pair is rare, and the search costs two
            # divisions per row in every sweep.)
            m = low
            z = a[m, m]
            r = x - z
            s = y - z
            p = (r * s - w) / a[m + 1, m] + a[m, m + 1]
            q = a[m + 1, m + 1] - z - r - s
            r = a[m + 2, m + 1]
            s = 1.0 / (abs(p) + abs(q) + abs(r))  # a reciprocal: divisions are slow
            p *= s
            q *= s
            r *= s
            for i in range(m + 2, nn + 1):
                a[i, i - 2] = 0.0
                if i != m + 2:
                    a[i, i - 3] = 0.0
            # Chase the bulge: Householder reflections on rows and columns m..nn.
            for k in range(m, nn):
                if k != m:
                    p = a[k, k - 1]
                    q = a[k + 1, k - 1]
                    r = a[k + 2, k - 1] if k != nn - 1 else 0.0
                    x = abs(p) + abs(q) + abs(r)
                    if x != 0.0:
                        inv = 1.0 / x
                        p *= inv
                        q *= inv
                        r *= inv
                s = math.copysign(math.sqrt(p * p + q * q + r * r), p)
                if s == 0.0:
                    continue
                if k != m:
                    a[k, k - 1] = -s * x
                p += s
                inv = 1.0 / s
                x = p * inv
                y = q * inv
                z = r * inv
                inv = 1.0 / p
                q *= inv
                r *= inv
                # The reflection on rows k..k+2 (columns k..nn), then columns k..k+2;
                # a 2-vector one at the last step. The two loops are written out (not one
                # loop with a branch inside) so that each compiles branch-free.
                if k != nn - 1:
                    for j in range(k, nn + 1):
                        p = a[k, j] + q * a[k + 1, j] + r * a[k + 2, j]
                        a[k + 2, j] -= p * z
                        a[k + 1, j] -= p * y
                        a[k, j] -= p * x
                    for i in range(low, min(nn, k + 3) + 1):
                        p = x * a[i, k] + y * a[i, k + 1] + z * a[i, k + 2]
                        a[i, k + 2] -= p * r
                        a[i, k + 1] -= p * q
                        a[i, k] -= p
                else:
                    for j in range(k, nn + 1):
                        p = a[k, j] + q * a[k + 1, j]
                        a[k + 1, j] -= p * y
                        a[k, j] -= p * x
                    for i in range(low, nn + 1):
                        p = x * a[i, k] + y * a[i, k + 1]
                        a[i, k + 1] -= p * q
                        a[i, k] -= p
    return True


@kernel
def hessenberg_eigvals(a: np.ndarray, wr: np.ndarray, wi: np.ndarray) -> bool:
    """Return whether QR converged; the eigenvalues of upper-Hessenberg ``a`` (destroyed,
    balanced first) go to ``wr + 1j wi``."""
    balance(a)
    return hqr(a, wr, wi)
