"""Certified warm-started roots of f3 (eq. 33): the batched solver's shortcut.

The companion-matrix eigenvalues (:mod:`activetrack.companion`) are the method of record
for the roots of the Case-I polynomial f3 (eq. 33). When a nearby problem was solved
before (the same sensor one Gauss-Seidel step earlier in the batched GSR), its roots are
a good start: Weierstrass (Durand-Kerner) steps refine them, and a row's result replaces
the eigenvalues only when it is *certified* to be the same roots:

- Gerschgorin inclusion disks of all 10 roots (rounding included) each lie entirely
  inside or entirely outside the acceptance region of
  :func:`activetrack.companion.accept` (``|imag| <= IM_TOL``, ``|real| <= 1 + RE_TOL``),
  and the inside ones are pairwise disjoint, so the region holds exactly one root per
  inside disk;
- each accepted root is pinned to within ``1e-10`` (units of ``r``) by a Newton
  inclusion disk lying in its own.

Rows without a start of their own can be seeded from the eigenvalues of a similar row of
the same batch (nearest in log-coefficient distance, k-d tree). :func:`circle_roots` is
the entry point; rows not certified take the eigenvalues.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from activetrack.companion import (
    IM_TOL,
    RE_TOL,
    monic_roots,
)
from activetrack.validation import FloatArray


@dataclass(frozen=True)
class CircleRoots:
    """The roots of f3 (eq. 33) behind a batch of solutions, for warm starts.

    Attributes:
        roots: (B, 10) complex roots in the polynomial's scaled, centred variable; NaN in
            rows without a speed-circle polynomial.
        swap: (B,) bool, which coordinate the variable is (the ``swap`` of the solver).
        certified: (B,) bool, rows whose roots came from the certified warm start
            (ignored in a guess).
    """

    roots: np.ndarray
    swap: np.ndarray
    certified: np.ndarray


_WARM_ITERS = 6  # Weierstrass steps from a warm start before falling back to eigvals
# A round of Weierstrass steps costs ~0.1 ms plus ~1 us a row, an eigenvalue solve ~25 us
# a row: fewer rows than these are cheaper by eigenvalues (to start, to go on).
_WARM_MIN_ROWS = 32
_WARM_MIN_LEFT = 16
_WARM_RADIUS = 1e-10  # an accepted root must be certified to within this
_PIN_ITERS = 3  # Newton steps that pin the roots inside the acceptance box
# Rounding (Higham, Accuracy and Stability, 2nd ed., Sec. 5.1, and Lemma 3.5: a complex
# multiply errs by at most sqrt(2) gamma_2): Horner's rule on n = 10 complex steps errs
# by at most ~3.9 n eps sum |q_k| |z|^k = 4.3e-15 sum |q_k| |z|^k (_HORNER_ERR, 2.3x
# that), its derivative recurrence by at most twice that times sum k |q_k| |z|^(k-1).
# The product of 9 differences errs by ~32 eps relative, each radius formula by a few
# eps (_PROD_ERR). The comparisons with the box get an absolute slack of
# _BOX_ERR (1 + |z|) for the rounding of |Re z| +- radius.
_HORNER_ERR = 1e-14
_PROD_ERR = 1e-13
_BOX_ERR = 1e-15


def _weierstrass(q: FloatArray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(p(z_i), prod_{j != i} (z_i - z_j))``, each (n, m), for ``z`` (n, m).

    Layout: one polynomial per column, ``p = z^n + sum_k q[k] z^k`` with ``q`` (n, m).
    Their ratio is the Weierstrass correction ``W_i``.
    """
    n = z.shape[0]
    p = _horner(q, z)
    z2 = np.concatenate([z, z])  # z2[s:s + n] is z rolled by s
    prod = z - z2[1 : n + 1]
    diff = np.empty_like(z)
    for shift in range(2, n):
        np.subtract(z, z2[shift : shift + n], out=diff)
        prod *= diff
    return p, prod


def _horner(q: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Return ``p(x)`` for ``p = z^n + sum_k q[k] z^k`` (``q`` (n, ...) broadcasts with ``x``)."""
    n = q.shape[0]
    p = x + q[n - 1]
    for k in range(n - 2, -1, -1):
        p *= x
        p += q[k]
    return p


def _inclusion_radii(
    abs_q: FloatArray, z: np.ndarray, w: np.ndarray, prod: np.ndarray
) -> FloatArray:
    """Return radii ``R_i >= n |W_i|`` (n, m) that also cover rounding.

    ``w = p / prod`` and ``prod`` as from :func:`_weierstrass` at ``z``; ``abs_q`` (n, m)
    is ``|q|`` (for Horner's rounding error scale).
    """
    n = z.shape[0]
    # Horner's rounding error scale sum_k |q_k| |z|^k.
    radius = _horner(abs_q, np.abs(z))
    radius *= _HORNER_ERR
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        radius /= np.abs(prod)
        radius += np.abs(w)
    radius *= n * (1.0 + _PROD_ERR)
    return radius


def _classify(z: np.ndarray, radius: FloatArray) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(ok, inside)`` for the disks ``|x - z_i| <= radius_i`` (n, m).

    ``inside`` (n, m): the disk lies in the acceptance box of :func:`~activetrack.companion.accept`
    (``|imag| <= IM_TOL``, ``|real| <= 1 + RE_TOL``). ``ok`` (m,): every disk of the
    column lies entirely inside or entirely outside the box and the inside ones are
    pairwise disjoint (an inside and an outside disk cannot meet). NaN fails.
    """
    n = z.shape[0]
    are, aim = np.abs(z.real), np.abs(z.imag)
    # Signed excess over the box: inside iff <= -radius, outside iff > radius.
    excess = np.maximum(aim - IM_TOL, are - (1.0 + RE_TOL))
    are += aim
    are += 1.0
    are *= _BOX_ERR
    radius = radius + are  # slack for the rounding of the comparisons
    inside = excess <= -radius
    settled = excess > radius
    settled |= inside
    ok = np.all(settled, axis=0)
    count = inside.sum(axis=0)
    # Two inside disks must not meet. Most columns have two: compare first and last.
    two = np.flatnonzero(ok & (count == 2))
    if two.size:
        first = np.argmax(inside[:, two], axis=0)
        last = n - 1 - np.argmax(inside[::-1, two], axis=0)
        gap = np.abs(z[first, two] - z[last, two])
        ok[two] = gap > radius[first, two] + radius[last, two]
    # More: all pairs (i, i + s mod n), s = 1..n/2.
    cols = np.flatnonzero(ok & (count > 2))
    if cols.size:
        zc, rc, ic = z[:, cols], radius[:, cols], inside[:, cols]
        z2 = np.concatenate([zc, zc])
        r2 = np.concatenate([rc, rc])
        i2 = np.concatenate([ic, ic])
        meet = np.zeros(zc.shape, dtype=bool)
        for shift in range(1, n // 2 + 1):
            sl = slice(shift, shift + n)
            meet |= (np.abs(zc - z2[sl]) <= rc + r2[sl]) & i2[sl]
        ok[cols] = ~np.any(meet & ic, axis=0)
    return ok, inside


def _horner_with_derivative(q: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(p(x), p'(x))`` for ``p = z^n + sum_k q[k] z^k`` (``q`` (n, ...), Horner)."""
    n = q.shape[0]
    p = x + q[n - 1]
    dp = np.ones_like(p)
    for k in range(n - 2, -1, -1):
        dp *= x
        dp += p
        p *= x
        p += q[k]
    return p, dp


def _pin(
    q: FloatArray, x: np.ndarray, centre: np.ndarray, radius: FloatArray
) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(x, ok)``: Newton-refined roots (K,) and whether each is pinned.

    Root ``k`` of polynomial ``q[:, k]`` (``z^n + sum_j q[j, k] z^j``, ``q`` (n, K)) is
    known to be the only root in the disk ``|x - centre_k| <= radius_k``. Since
    ``p'/p (x) = sum_j 1 / (x - r_j)``, some root lies within ``n |p(x) / p'(x)|`` of any
    ``x``; when that disk (with rounding) fits in the known one, it holds that root. ``ok``
    when it does and is no wider than ``_WARM_RADIUS``; up to ``_PIN_ITERS`` Newton steps.
    The returned root is within ``1.1 _WARM_RADIUS`` of the true one.
    """
    n = q.shape[0]
    # Error scales sum |q_k| a^k and sum k |q_k| a^(k-1) at a = |centre| + radius, which
    # bound those at any x in the known disk (the only x that can be accepted).
    bp, bd = _horner_with_derivative(np.abs(q), np.abs(centre) + radius)
    err_p, err_d = _HORNER_ERR * bp, (2.0 * _HORNER_ERR) * bd
    ok = np.zeros(x.shape, dtype=bool)
    x = x.copy()
    act = np.arange(x.size)
    xa, qa, ca, ra = x, q, centre, radius
    for it in range(_PIN_ITERS):
        p, dp = _horner_with_derivative(qa, xa)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            # n |p / p'| with |p| bounded above and |p'| below, rounding included.
            den = np.abs(dp) - err_d
            rho = (n * (1.0 + _PROD_ERR)) * (np.abs(p) + err_p) / den
            step = p / dp
        inner = (np.abs(xa - ca) + rho) * (1.0 + _PROD_ERR) <= ra
        good = (den > 0.0) & (rho <= _WARM_RADIUS) & inner
        # The root is within rho of xa; xa - step (|step| <= rho / n) is within 1.1 rho
        # of it and still in the known disk.
        x[act[good]] = xa[good] - step[good]
        ok[act[good]] = True
        keep = ~good
        if it == _PIN_ITERS - 1 or not keep.any():
            break
        act, xa, qa = act[keep], xa[keep] - step[keep], qa.compress(keep, axis=1)
        ca, ra, err_p, err_d = ca[keep], ra[keep], err_p[keep], err_d[keep]
    return x, ok


def certified_roots(q: FloatArray, guess: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return ``(z, ok)``: the roots (m, 10) of ``z^10 + sum q_k z^k`` (``q`` (m, 10)).

    From ``guess`` (m, 10), e.g. the roots of a nearby polynomial, Weierstrass (Durand-
    Kerner) steps ``z_i <- z_i - W_i`` run (quadratic convergence near simple roots) until
    a row is certified, at most ``_WARM_ITERS`` steps (fewer once under
    ``_WARM_MIN_LEFT`` rows are left). The certificate, in two parts:

    1. Which roots are accepted. With the Weierstrass corrections
       ``W_i = p(z_i) / prod_{j != i} (z_i - z_j)``, Lagrange interpolation gives
       ``p(x) = prod_j (x - z_j) (1 + sum_i W_i / (x - z_i))``, the characteristic
       polynomial of ``diag(z) - W 1^T``; by Gerschgorin's theorem every root of ``p``
       lies in a disk ``|x - z_i + W_i| <= (n - 1) |W_i|``, hence in ``|x - z_i| <= R_i``
       (:func:`_inclusion_radii`: ``R_i >= n |W_i|`` with rounding), and a union of k
       disks disjoint from the others holds exactly k roots. When every disk lies
       entirely inside or outside the acceptance box of
       :func:`~activetrack.companion.accept` and the inside ones are disjoint
       (:func:`_classify`), the box holds exactly one root per inside disk.
    2. Where they are: each inside root is within ``R_i`` of ``z_i``; where ``R_i`` is
       wider than ``_WARM_RADIUS`` it is pinned by :func:`_pin` (Newton from
       ``z_i - W_i``, an inclusion disk inside ``R_i``).

    Then the returned ``z`` (the pinned roots; ``z_i - W_i`` outside the box) classify as
    the true roots do. Rows not ``ok`` hold garbage.
    """
    qt = q_all = np.ascontiguousarray(q.T)
    abs_qt = np.abs(qt)
    z = np.ascontiguousarray(guess.T, dtype=np.complex128)
    out = np.empty_like(z)
    ok = np.zeros(z.shape[1], dtype=bool)
    act = np.arange(z.shape[1])
    to_pin = []  # (column, root row, centre, radius) of accepted roots wider than wanted
    for it in range(_WARM_ITERS + 1):
        p, prod = _weierstrass(qt, z)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            w = p / prod
        radius = _inclusion_radii(abs_qt, z, w, prod)
        good, inside = _classify(z, radius)
        cols = np.flatnonzero(good)
        if cols.size:
            ri, ci = np.nonzero(inside[:, cols] & (radius[:, cols] > _WARM_RADIUS))
            col = cols[ci]
            to_pin.append((act[col], ri, z[ri, col], radius[ri, col]))
        z -= w
        if cols.size:
            out[:, act[cols]] = z[:, cols]
            ok[act[cols]] = True
        keep = ~good & np.all(np.isfinite(z), axis=0)
        if it == _WARM_ITERS or np.count_nonzero(keep) < _WARM_MIN_LEFT:
            break
        if not keep.all():
            act = act[keep]
            z, qt, abs_qt = (a.compress(keep, axis=1) for a in (z, qt, abs_qt))
    if to_pin:
        # All at once: Newton from z_i - W_i (now in out), within the known disks.
        col, ri, centre, radius = (np.concatenate(v) for v in zip(*to_pin, strict=True))
        x, pinned = _pin(q_all[:, col], out[ri, col], centre, radius)
        out[ri, col] = x
        ok[col[~pinned]] = False  # a column is done when all its inside roots are pinned
    return out.T, ok


_SEED_MIN_ROWS = 256  # rows without a guess needed before seeding them from the batch
_SEED_EVERY = 8  # of those, one in this many takes eigenvalues and seeds its neighbours
_SEED_PROBE = 64  # seeded rows tried first; the rest only if at least
_SEED_PROBE_OK = 0.5  # this fraction of them is certified


def nearest_seed(
    q: FloatArray, swap: np.ndarray, seeds: np.ndarray, rows: np.ndarray
) -> np.ndarray:
    """Return, for each of ``rows``, the nearest of ``seeds`` with the same ``swap`` (or -1).

    Distance: Euclidean in ``sign(q) log(1 + |q|)`` (the monic coefficients, (m, 10)),
    where nearby polynomials have nearby roots; k-d tree search.
    """
    from scipy.spatial import cKDTree  # here: importing scipy.spatial costs ~0.1 s

    feat = np.sign(q) * np.log1p(np.abs(q))
    out = np.full(rows.size, -1, dtype=np.int64)
    for value in (False, True):
        have = seeds[swap[seeds] == value]
        need = np.flatnonzero(swap[rows] == value)
        if have.size and need.size:
            _, k = cKDTree(feat[have]).query(feat[rows[need]])
            out[need] = have[k]
    return out


def circle_roots(
    q: FloatArray,
    swap: np.ndarray,
    bad: np.ndarray,
    guess: CircleRoots | None,
    idx: np.ndarray,
    certified: np.ndarray,
) -> np.ndarray:
    """Return the roots (m, 10) of the monic f3 ``q`` (m, 10) of rows ``idx``.

    Without ``guess``: the companion-matrix eigenvalues, the method of record. With it,
    rows with a usable guess (finite, same variable ``swap``) try
    :func:`certified_roots`; when at least ``_SEED_MIN_ROWS`` rows have none, one in
    ``_SEED_EVERY`` of them takes the eigenvalues and the others start from their
    nearest such seed's roots (:func:`nearest_seed`), if the first ``_SEED_PROBE`` of
    them certify well enough (a batch of dissimilar problems makes poor seeds). Certified
    rows are marked in ``certified`` (length B, by ``idx``); all others take the
    eigenvalues.
    """
    if guess is None:
        return monic_roots(q)
    m = q.shape[0]
    ev = np.empty(q.shape, dtype=np.complex128)
    done = np.zeros(m, dtype=bool)
    start = guess.roots[idx]
    warm = (guess.swap[idx] == swap) & ~bad & np.all(np.isfinite(start), axis=1)
    cold = np.flatnonzero(~warm & ~bad)
    if cold.size >= _SEED_MIN_ROWS:
        seeds = cold[::_SEED_EVERY]
        ev[seeds] = monic_roots(q[seeds])
        done[seeds] = True
        rows = np.setdiff1d(cold, seeds, assume_unique=True)
        near = nearest_seed(q, swap, seeds, rows)
        keep = near >= 0
        keep[keep] = np.all(np.isfinite(ev[near[keep]]), axis=1)
        rows, near = rows[keep], near[keep]
        start[rows] = ev[near]
        # Seeds are only as good as the batch is homogeneous: try a few rows first.
        probe = rows[:_SEED_PROBE]
        if probe.size:
            z, ok = certified_roots(q[probe], start[probe])
            ev[probe[ok]] = z[ok]
            done[probe[ok]] = True
            certified[idx[probe[ok]]] = True
            if ok.mean() >= _SEED_PROBE_OK:
                warm[rows[_SEED_PROBE:]] = True
    use = np.flatnonzero(warm)
    if use.size >= _WARM_MIN_ROWS:
        z, ok = certified_roots(q[use], start[use])
        ev[use[ok]] = z[ok]
        done[use[ok]] = True
        certified[idx[use[ok]]] = True
    rest = np.flatnonzero(~done)
    if rest.size:
        ev[rest] = monic_roots(q[rest])
    return ev
