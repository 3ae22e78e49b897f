"""The single-sensor solver for a batch of problems, vectorized over rows (Section IV-A).

The steps of :mod:`activetrack.solver_steps` with the :data:`~activetrack.solver_steps.ARRAY`
operations, one problem a row: all companion matrices of f3 (eq. 33) stacked and their
eigenvalues computed in one LAPACK sweep (:mod:`activetrack.companion`), or certified
warm-started roots (:mod:`activetrack.certified_roots`) when the caller passes the roots
of an earlier solve; candidates as columns, the best by ``argmin`` (first minimum);
Newton polishing of all starts at once. Inputs are validated by the caller
(:func:`activetrack.solver.solve_single_sensor_batch`).
"""

from __future__ import annotations

import numpy as np

from activetrack._coefficients import sylvester_gammas
from activetrack.certified_roots import CircleRoots, circle_roots
from activetrack.companion import accept_roots, accepted_first, monic
from activetrack.solver_results import BatchSolution
from activetrack.solver_scalar import solve_scalar
from activetrack.solver_steps import (
    ARRAY,
    FEAS_TOL,
    HALVINGS,
    N_POLISH,
    NEWTON_ITERS,
    SHARP,
    STEP_TOL,
    arc_ends,
    axis_points,
    circle_derivatives,
    circle_polynomial,
    eig_frame,
    f0,
    fallback_point,
    geometric_case,
    in_speed_disk,
    nearest_point,
    newton_step,
    normalize,
    root_candidates,
    to_eigen,
    to_original,
    value_at,
)
from activetrack.validation import FloatArray

SCALAR_ROWS = 8  # up to this many rows the scalar solver is faster than the vectorized


def polish_rows(
    sub: tuple[FloatArray, ...], f: FloatArray, x: FloatArray, y: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return ``(f, x, y)`` after damped Newton on df0/dt, the rows' form of the scalar
    :func:`activetrack.solver_scalar.polish`.

    ``sub`` holds ``(L1, L2, A, Bn, C1, C2, lo)`` per row; rows drop out once converged,
    so the cost is set by the few rows that need many steps.
    """
    f, x, y = f.copy(), x.copy(), y.copy()
    L1, L2, A, Bn, C1, C2, lo = sub
    t = np.arctan2(y - C2, x - C1)
    act = np.flatnonzero(np.isfinite(f))
    for _ in range(NEWTON_ITERS):
        if act.size == 0:
            break
        ta = t[act]
        _, d1, d2 = circle_derivatives(
            L1[act], L2[act], A[act], Bn[act], C1[act], C2[act], np.cos(ta), np.sin(ta)
        )
        with np.errstate(over="ignore"):  # f'' = 0: see newton_step
            step, keep = newton_step(d1, d2, f[act], ARRAY)  # keep: False when converged
        act, step = act[keep], step[keep]
        moved = np.zeros(t.shape, dtype=bool)
        pend = np.arange(act.size)  # positions in act still looking for a decrease
        for _ in range(HALVINGS):
            if pend.size == 0:
                break
            rows = act[pend]
            tn = t[rows] + step[pend]
            xn = C1[rows] + np.cos(tn)
            yn = C2[rows] + np.sin(tn)
            fn = f0(L1[rows], L2[rows], A[rows], Bn[rows], xn, yn)
            ok = (xn * xn + yn * yn >= lo[rows]) & (fn < f[rows])
            good = rows[ok]
            t[good], f[good], x[good], y[good] = tn[ok], fn[ok], xn[ok], yn[ok]
            moved[good] = True
            pend = pend[~ok]
            step[pend] *= 0.5
            pend = pend[np.abs(step[pend]) >= STEP_TOL]
        act = act[moved[act]]
    return f, x, y


def solve_rows_scalar(
    P: FloatArray,
    c: FloatArray,
    r: FloatArray,
    rho: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
) -> tuple[BatchSolution, CircleRoots]:
    """Return the scalar solver's solutions of a few rows, in the batch layout.

    Each row is :func:`activetrack.solver_scalar.solve_scalar` (the same method; a
    vectorized call costs ~1 ms of numpy overhead whatever its size). No roots are
    returned (NaN).
    """
    n = P.shape[0]
    sols = [
        solve_scalar(
            float(P[i, 0, 0]),
            0.5 * float(P[i, 0, 1] + P[i, 1, 0]),
            float(P[i, 1, 1]),
            float(c[i, 0]),
            float(c[i, 1]),
            float(r[i]),
            float(rho[i]),
            float(sigma_d2[i]),
            float(sigma_theta2[i]),
        )
        for i in range(n)
    ]
    sol = BatchSolution(
        s=np.array([q[0] for q in sols]).reshape(n, 2),
        value=np.array([q[1] for q in sols], dtype=np.float64),
        case=np.array([q[2] for q in sols], dtype=np.int64),
        feasible=np.array([q[3] for q in sols], dtype=bool),
    )
    roots = CircleRoots(
        np.full((n, 10), np.nan, dtype=np.complex128),
        np.zeros(n, dtype=bool),
        np.zeros(n, dtype=bool),
    )
    return sol, roots


def _circle_candidates(frame, idx, lo, guess, roots_out, swap_out, certified):
    """Return ``(X, Y, F, crit)`` (len(idx), k): candidates on the speed circle (eq. 30-33).

    ``frame = (L1, L2, A, Bn, C1, C2)`` of all rows; rows ``idx`` need the circle. The
    roots of f3 per row go to ``roots_out``, ``swap_out``, ``certified`` (by ``idx``).
    ``F`` is ``inf`` where a candidate is not one (rejected root, infeasible point).
    """
    L1i, L2i, Ai, Bi, C1i, C2i = (q[idx] for q in frame)
    swap = np.abs(C1i) > np.abs(C2i)
    hk = circle_polynomial(L1i, L2i, Ai, Bi, C1i, C2i, swap, ARRAY)
    gam = np.stack(sylvester_gammas(*hk), axis=-1)
    bad = ~np.all(np.isfinite(gam), axis=-1)
    gam[bad] = 0.0
    gam[bad, 10] = 1.0  # no finite polynomial: all roots at zero, masked below
    q = monic(gam)
    ev = circle_roots(q, swap, bad, guess, idx, certified)
    roots_out[idx] = np.where(bad[:, None], np.nan, ev)
    swap_out[idx] = swap
    v, ok = accept_roots(ev)
    ok &= ~bad[:, None]
    # Only the accepted roots matter (most rows accept 2 of the 10): keep their columns.
    v, ok = accepted_first(v, ok)
    # Both points of each root are candidates; the critical one(s) are also Newton starts.
    plus, minus = root_candidates(
        [h[:, None] for h in hk], v, C1i[:, None], C2i[:, None], swap[:, None], ARRAY
    )
    X, Y, crit = (np.concatenate(pair, axis=1) for pair in zip(plus, minus, strict=True))
    ok2 = np.concatenate([ok, ok], axis=1)
    ok2 &= X * X + Y * Y >= lo[idx, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        F = f0(L1i[:, None], L2i[:, None], Ai[:, None], Bi[:, None], X, Y)
    F = np.where(ok2 & np.isfinite(F), F, np.inf)
    return X, Y, F, crit


def _arc_candidates(frame, ncn, rh, need_arc):
    """Return blocks ``[(x, y, f)]`` (n, 4) and (n, 2): the ``rho`` arc's axis points
    inside the speed disk (eq. 36-37) and its ends A, B; ``f = inf`` where not candidates."""
    L1, L2, A, Bn, C1, C2 = (q[:, None] for q in frame)
    n = ncn.shape[0]
    pts = axis_points(rh)
    ax = np.stack([np.broadcast_to(p[0], (n,)) for p in pts], axis=1)
    ay = np.stack([np.broadcast_to(p[1], (n,)) for p in pts], axis=1)
    inside = in_speed_disk(ax, ay, C1, C2)
    meet = need_arc & (ncn > 0.0) & (rh >= np.abs(ncn - 1.0))
    (xa, ya), (xb, yb) = arc_ends(C1[:, 0], C2[:, 0], np.where(ncn > 0.0, ncn, 1.0), rh * rh, ARRAY)
    blocks = []
    for x_, y_, ok_ in (
        (ax, ay, inside & need_arc[:, None]),
        (np.stack([xa, xb], axis=1), np.stack([ya, yb], axis=1), np.stack([meet, meet], axis=1)),
    ):
        f_ = f0(L1, L2, A, Bn, x_, y_)
        blocks.append((x_, y_, np.where(ok_ & np.isfinite(f_), f_, np.inf)))
    return blocks


def _polish_starts(xs, ys, fs, idx, crit, n_circle, d_col, ab_cols, sharp):
    """Return the Newton starts (starts, len(idx)) as candidate columns (-1: none).

    From D and, in case III, A and B where the speed arc passes near the target
    (``sharp``); then the ``N_POLISH`` best critical root candidates.
    """
    starts = []
    if np.any(sharp):
        for col_j in (d_col, *ab_cols):
            starts.append(np.where(sharp, col_j, -1))
    if n_circle:
        fcrit = np.where(crit, fs[idx, :n_circle], np.inf)
        rows_i = np.arange(idx.size)
        for _ in range(min(N_POLISH, n_circle)):  # the best, then the next best
            jm = np.argmin(fcrit, axis=1)
            starts.append(np.where(np.isfinite(fcrit[rows_i, jm]), jm, -1))
            fcrit[rows_i, jm] = np.inf
    return starts


def solve_batch(
    P: FloatArray,
    c: FloatArray,
    r: FloatArray,
    rho: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    guess: CircleRoots | None = None,
) -> tuple[BatchSolution, CircleRoots]:
    """Return the batched solution for validated arrays of shapes (B,2,2), (B,2), (B,)x4.

    Also returns the roots of f3 used per row (NaN off the speed circle). Without
    ``guess`` the roots are the companion-matrix eigenvalues. With it (the roots returned
    by an earlier call on nearby problems, row by row) rows may take certified roots
    instead, as :func:`activetrack.certified_roots.circle_roots` says; the result is the
    same to rounding; and a call of up to ``SCALAR_ROWS`` rows is solved row by row by
    the scalar kernel (faster there; no roots returned). The public batch solver passes
    no ``guess``, so its answers never depend on the batch size.
    """
    n = P.shape[0]
    if guess is not None and n <= SCALAR_ROWS:
        return solve_rows_scalar(P, c, r, rho, sigma_d2, sigma_theta2)
    p12 = 0.5 * (P[:, 0, 1] + P[:, 1, 0])
    cph, sph, l1, l2 = eig_frame(P[:, 0, 0], p12, P[:, 1, 1], ARRAY)
    a = 1.0 / sigma_d2
    b = 1.0 / sigma_theta2
    c1, c2 = c[:, 0], c[:, 1]
    nc = np.hypot(c1, c2)
    case = geometric_case(nc, r, rho).astype(np.int64)
    feasible = nc + r >= rho
    special = ~feasible | (r == 0.0)

    # Normalized eigenframe quantities (rows with r == 0 get a dummy r = 1).
    rr = np.where(r > 0.0, r, 1.0)
    kappa, *frame, rh = normalize(l1, l2, a, b, c1, c2, cph, sph, rr, rho, ARRAY)
    C1, C2 = frame[4], frame[5]
    ncn = nc / rr
    lo = rh * rh * (1.0 - FEAS_TOL)

    need_circle = ~special & (ncn > 1.0) & (rh * rh < ncn * ncn - 1.0)
    need_arc = ~special & (rh >= ncn - 1.0)

    roots_out = np.full((n, 10), np.nan, dtype=np.complex128)
    swap_out = np.zeros(n, dtype=bool)
    certified = np.zeros(n, dtype=bool)
    # Candidate blocks (x, y, f0 or inf where not a candidate), each (n, k), joined below.
    blocks = []
    idx = np.flatnonzero(need_circle)
    n_circle = 0
    crit = None
    if idx.size:
        X, Y, F, crit = _circle_candidates(frame, idx, lo, guess, roots_out, swap_out, certified)
        n_circle = X.shape[1]
        if idx.size == n:  # GSR's usual batch: no row needs scattering
            blocks.append((X, Y, F))
        else:
            xs = np.zeros((n, n_circle))
            ys = np.zeros((n, n_circle))
            fs = np.full((n, n_circle), np.inf)
            xs[idx], ys[idx], fs[idx] = X, Y, F
            blocks.append((xs, ys, fs))
    d_col = n_circle
    with np.errstate(divide="ignore", invalid="ignore"):
        # Nearest point D of the speed circle (case I).
        dx, dy = nearest_point(C1, C2, np.where(ncn > 0.0, ncn, 1.0))
        fd = f0(*frame[:4], dx, dy)
        ok_d = need_circle & (ncn - 1.0 >= rh) & np.isfinite(fd)
        blocks.append((dx[:, None], dy[:, None], np.where(ok_d, fd, np.inf)[:, None]))
        if np.any(need_arc):
            # rho-arc candidates (cases II, III, 4), then the arc ends A, B.
            blocks += _arc_candidates(frame, ncn, rh, need_arc)

    xs, ys, fs = (np.concatenate(parts, axis=1) for parts in zip(*blocks, strict=True))
    rows = np.arange(n)
    j = np.argmin(fs, axis=1)
    best_f = fs[rows, j]
    bx, by = xs[rows, j], ys[rows, j]

    # Polish on the speed circle (damped Newton on df0/dt), rows in idx only: from the
    # best root candidates, from D and, in case III, from the arc ends A, B. All starts
    # run in one batch; their results are then taken in order (strictly better wins).
    if idx.size:
        sharp = np.maximum(ncn[idx] - 1.0, rh[idx]) < SHARP
        ab = (xs.shape[1] - 2, xs.shape[1] - 1) if np.any(need_arc) else ()
        starts = _polish_starts(xs, ys, fs, idx, crit, n_circle, d_col, ab, sharp)
        if starts:
            jj = np.stack(starts)  # (starts, rows of idx); -1: no start there
            ii = np.broadcast_to(idx, jj.shape)
            f0s = np.where(jj >= 0, fs[ii, jj], np.inf).ravel()
            sub = tuple(np.tile(q[idx], len(starts)) for q in (*frame, lo))
            f, x, y = polish_rows(sub, f0s, xs[ii, jj].ravel(), ys[ii, jj].ravel())
            f, x, y = (q.reshape(jj.shape) for q in (f, x, y))
            bfi, bxi, byi = best_f[idx], bx[idx], by[idx]
            for k in range(len(starts)):
                win = f[k] < bfi
                bfi = np.where(win, f[k], bfi)
                bxi = np.where(win, x[k], bxi)
                byi = np.where(win, y[k], byi)
            best_f[idx], bx[idx], by[idx] = bfi, bxi, byi

    s = np.stack(to_original(bx * rr, by * rr, cph, sph), axis=1)
    value = best_f / kappa

    if np.any(special):
        # Infeasible (or nowhere to go): the reachable point farthest from the target.
        k = np.flatnonzero(special)
        sx, sy = fallback_point(c1[k], c2[k], nc[k], r[k], ARRAY)
        s[k, 0], s[k, 1] = sx, sy
        ex, ey = to_eigen(sx, sy, cph[k], sph[k])
        with np.errstate(divide="ignore", invalid="ignore"):
            value[k] = value_at(l1[k], l2[k], a[k], b[k], ex, ey, ARRAY)
    sol = BatchSolution(s=s, value=value, case=case, feasible=feasible)
    return sol, CircleRoots(roots_out, swap_out, certified)
