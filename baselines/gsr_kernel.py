"""GSR's plain sweeps compiled (Section IV-B, eq. 38), one problem at a time.

:func:`relax_point` is :class:`activetrack.baselines.gsr.Relaxation`'s ``relax`` from a
feasible warm start without pattern moves (what ``GSR()`` runs): Gauss-Seidel sweeps over
the free sensors, each solving its exact single-sensor problem (Section IV-A,
:func:`activetrack.solver_scalar.solve_point`) given the others' information, an update
kept only if it lowers ``tr(Y^{-1})``, a sensor re-solved only when another one moved,
until a sweep improves by at most ``tol`` (relative), nothing is left to re-solve, or
``max_sweeps``. :func:`relax_rows` runs it over a batch in compiled code, so a batch row
equals the single problem's plan bit for bit. The restarts and the pattern moves
(``GSR(restarts=True)``, ``GSR(accelerate=True)``) run the Python ``Relaxation``.
"""

from __future__ import annotations

import numpy as np

from activetrack._jit import kernel
from activetrack.objective import information_entries, trace_of_inverse
from activetrack.solver_scalar import solve_point


@kernel
def _total(pa, pb, pc, ia, ib, ic):
    """Return the entries of ``prior + sum_i info_i`` (the sensors summed first)."""
    sa, sb, sc = ia[0], ib[0], ic[0]
    for i in range(1, ia.shape[0]):
        sa += ia[i]
        sb += ib[i]
        sc += ic[i]
    return pa + sa, pb + sb, pc + sc


@kernel
def _sweep(pa, pb, pc, s, ia, ib, ic, c, r, rho, sd2, st2, free, stale):
    """Run one sweep in place (``s``, the entries ``ia``, ``ib``, ``ic``, ``stale``); return
    the objective after it and the number of single-sensor solves."""
    ta, tb, tc = _total(pa, pb, pc, ia, ib, ic)  # rebuilt every sweep: no drift
    cur = trace_of_inverse(ta, tb, tc)
    solves = 0
    for k in range(free.shape[0]):
        if not stale[k]:
            continue
        i = free[k]
        oa, ob, oc = ta - ia[i], tb - ib[i], tc - ic[i]
        sx, sy, _, _, _ = solve_point(oa, ob, oc, c[i, 0], c[i, 1], r[i], rho[i], sd2[i], st2[i])
        solves += 1
        stale[k] = False
        na, nb, nc = information_entries(sx, sy, sd2[i], st2[i])
        ca, cb, cc = oa + na, ob + nb, oc + nc
        val = trace_of_inverse(ca, cb, cc)
        if val < cur:
            changed = sx != s[i, 0] or sy != s[i, 1]
            s[i, 0], s[i, 1] = sx, sy
            ia[i], ib[i], ic[i] = na, nb, nc
            ta, tb, tc, cur = ca, cb, cc, val
            if changed:  # every other sensor now faces a new problem
                stale[:] = True
                stale[k] = False
    return cur, solves


@kernel
def relax_point(pa, pb, pc, c, r, rho, sd2, st2, free, s, tol, max_sweeps):
    """Relax the feasible configuration ``s`` (M, 2, relative to the target) in place.

    ``(pa, pb, pc)`` the prior information's entries, ``c`` (M, 2) the sensors relative to
    the target, ``free`` the indices of the sensors to optimize. Returns ``(value,
    start_value, sweeps, solves, converged)``.
    """
    m = s.shape[0]
    ia, ib, ic = np.empty(m), np.empty(m), np.empty(m)
    for i in range(m):
        ia[i], ib[i], ic[i] = information_entries(s[i, 0], s[i, 1], sd2[i], st2[i])
    start = trace_of_inverse(*_total(pa, pb, pc, ia, ib, ic))
    if free.shape[0] == 0:
        return start, start, 0, 0, True
    stale = np.ones(free.shape[0], np.bool_)
    f0 = start
    f1, solves = _sweep(pa, pb, pc, s, ia, ib, ic, c, r, rho, sd2, st2, free, stale)
    sweeps = 1
    while sweeps < max_sweeps and stale.any() and not f0 - f1 <= tol * f0:
        f0 = f1
        f1, n = _sweep(pa, pb, pc, s, ia, ib, ic, c, r, rho, sd2, st2, free, stale)
        solves += n
        sweeps += 1
    return f1, start, sweeps, solves, (f0 - f1 <= tol * f0) or not stale.any()


@kernel
def relax_rows(prior, c, r, rho, sd2, st2, free, s, tol, max_sweeps, value, sweeps, solves):
    """Run :func:`relax_point` on every row of a batch: ``prior`` (B, 2, 2), ``c``, ``s``
    (B, M, 2), ``r``, ``rho``, ``sd2``, ``st2``, ``free`` (B, M); writes ``s`` in place and
    ``value``, ``sweeps``, ``solves`` (B,)."""
    for b in range(s.shape[0]):
        idx = np.flatnonzero(free[b])
        v, _, n_sweeps, n_solves, _ = relax_point(
            prior[b, 0, 0], prior[b, 0, 1], prior[b, 1, 1], c[b], r[b], rho[b], sd2[b], st2[b],
            idx, s[b], tol, max_sweeps,
        )  # fmt: skip
        value[b], sweeps[b], solves[b] = v, n_sweeps, n_solves
