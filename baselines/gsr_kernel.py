"""GSR's plain sweeps compiled (Section IV-B, eq. 38), one problem at a time.

:func:`relax_point` is :class:`activetrack.baselines.gsr.Relaxation`'s ``relax`` from a
feasible warm start without pattern moves (what ``GSR()`` runs): Gauss-Seidel sweeps over
the free sensors, each solving its exact single-sensor problem (Section IV-A,
:func:`activetrack.solvers._scalar.solve_point`) given the others' information, an update
kept only if it lowers ``tr(Y^{-1})``, a sensor re-solved only when another one moved
(from the roots of its previous solve, kept in an array per sensor), until a sweep
improves by at most ``tol`` (relative), nothing is left to re-solve, or ``max_sweeps``.
:func:`relax_rows` runs it over a batch in compiled code, so a batch row equals the
single problem's plan bit for bit. The restarts and the pattern moves
(``GSR(restarts=True)``, ``GSR(accelerate=True)``) run the Python ``Relaxation``.
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import kernel
from activetrack.kinematics._kernels import fallback_point, project_feasible_point
from activetrack.models.objective import information_entries, trace_of_inverse
from activetrack.solvers._scalar import NO_ROOTS, ROOTS_SIZE, ROOTS_TAG, solve_point

#: Sensor status of :func:`modes_row`: fine, a fixed sensor exactly on the target (no
#: bearing), a free sensor with ``rho <= 0`` that can reach the target (no minimum; the
#: first to report).
OK, ON_TARGET, DEGENERATE = 0, 1, 2


@kernel
def modes_row(c, r, rho, free, fixed, status):
    """Write each sensor's mode (``c`` (M, 2) relative to the target): ``free`` (``r > 0``
    and the feasible set not empty), ``fixed`` (the current position, or for a sensor that
    cannot leave the ``rho`` disk the reachable point farthest from the target) and
    ``status`` (:data:`OK`, :data:`DEGENERATE`, :data:`ON_TARGET`); return the worst."""
    worst = OK
    for i in range(c.shape[0]):
        nc = math.hypot(c[i, 0], c[i, 1])
        stay = r[i] <= 0.0
        unreachable = not stay and nc + r[i] < rho[i]
        free[i] = not stay and not unreachable
        if unreachable:
            fixed[i, 0], fixed[i, 1] = fallback_point(c[i, 0], c[i, 1], r[i])
        else:
            fixed[i, 0], fixed[i, 1] = c[i, 0], c[i, 1]
        status[i] = OK
        if free[i] and rho[i] <= 0.0 and nc <= r[i]:
            status[i] = DEGENERATE
        elif not free[i] and math.hypot(fixed[i, 0], fixed[i, 1]) == 0.0:
            status[i] = ON_TARGET
        worst = max(worst, status[i])
    return worst


@kernel
def warm_row(c, r, rho, free, fixed, s, inside):
    """Write GSR's warm start into ``s`` (M, 2): ``fixed``, except a free sensor inside its
    ``rho`` disk (marked in ``inside`` (M,)), which starts from its nearest feasible point;
    return whether one did."""
    any_inside = False
    for i in range(c.shape[0]):
        inside[i] = free[i] and math.hypot(c[i, 0], c[i, 1]) < rho[i]
        if inside[i]:
            s[i, 0], s[i, 1] = project_feasible_point(
                c[i, 0], c[i, 1], c[i, 0], c[i, 1], r[i], rho[i]
            )
            any_inside = True
        else:
            s[i, 0], s[i, 1] = fixed[i, 0], fixed[i, 1]
    return any_inside


@kernel
def modes_rows(c, r, rho, free, fixed, status):
    """Run :func:`modes_row` on every row (``c``, ``fixed`` (B, M, 2), the others (B, M))."""
    for b in range(c.shape[0]):
        modes_row(c[b], r[b], rho[b], free[b], fixed[b], status[b])


@kernel
def warm_rows(c, r, rho, free, fixed, s, inside):
    """Run :func:`warm_row` on every row (``inside`` (B, M))."""
    for b in range(c.shape[0]):
        warm_row(c[b], r[b], rho[b], free[b], fixed[b], s[b], inside[b])


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
def _sweep(pa, pb, pc, s, ia, ib, ic, c, r, rho, sd2, st2, free, stale, roots):
    """Run one sweep in place (``s``, the entries ``ia``, ``ib``, ``ic``, ``stale``, each
    sensor's f3 roots ``roots`` (M, ROOTS_SIZE)); return the objective after it and the
    number of single-sensor solves."""
    ta, tb, tc = _total(pa, pb, pc, ia, ib, ic)  # rebuilt every sweep: no drift
    cur = trace_of_inverse(ta, tb, tc)
    solves = 0
    for k in range(free.shape[0]):
        if not stale[k]:
            continue
        i = free[k]
        oa, ob, oc = ta - ia[i], tb - ib[i], tc - ic[i]
        sx, sy, _, _, _ = solve_point(
            oa, ob, oc, c[i, 0], c[i, 1], r[i], rho[i], sd2[i], st2[i], roots[i]
        )
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
    roots = np.empty((m, ROOTS_SIZE))
    roots[:, ROOTS_TAG] = NO_ROOTS
    f0 = start
    f1, solves = _sweep(pa, pb, pc, s, ia, ib, ic, c, r, rho, sd2, st2, free, stale, roots)
    sweeps = 1
    while sweeps < max_sweeps and stale.any() and not f0 - f1 <= tol * f0:
        f0 = f1
        f1, n = _sweep(pa, pb, pc, s, ia, ib, ic, c, r, rho, sd2, st2, free, stale, roots)
        solves += n
        sweeps += 1
    return f1, start, sweeps, solves, (f0 - f1 <= tol * f0) or not stale.any()


@kernel
def plan_point(pa, pb, pc, c, r, rho, sd2, st2, tol, max_sweeps, free, fixed, status, s, inside):
    """GSR's plan of one problem: the sensors' modes (:func:`modes_row`, into ``free``,
    ``fixed``, ``status``), the warm start (:func:`warm_row`, into ``s``, ``inside``) and
    :func:`relax_point` from it. Returns ``(status, value, start_value, sweeps, solves,
    converged)``; a status other than :data:`OK` stops before the relaxation."""
    worst = modes_row(c, r, rho, free, fixed, status)
    if worst != OK:
        return worst, np.nan, np.nan, 0, 0, False
    warm_row(c, r, rho, free, fixed, s, inside)
    v, start, sweeps, solves, converged = relax_point(
        pa, pb, pc, c, r, rho, sd2, st2, np.flatnonzero(free), s, tol, max_sweeps
    )
    return OK, v, start, sweeps, solves, converged


@kernel
def plan_single(pa, pb, pc, c, r, rho, sd2, st2, tol, max_sweeps, s):
    """:func:`plan_point` with its own scratch arrays, the plan into ``s`` (M, 2). Returns
    ``(status, value, start_value, sweeps, solves, converged, warm_feasible)``."""
    m = c.shape[0]
    free, fixed, inside = np.empty(m, np.bool_), np.empty((m, 2)), np.empty(m, np.bool_)
    status = np.empty(m, np.int64)
    worst, v, start, sweeps, solves, converged = plan_point(
        pa, pb, pc, c, r, rho, sd2, st2, tol, max_sweeps, free, fixed, status, s, inside
    )
    return worst, v, start, sweeps, solves, converged, not inside.any()


@kernel
def relax_rows(prior, c, r, rho, sd2, st2, tol, max_sweeps, s, status, value, sweeps, solves):
    """Run :func:`plan_point` on every row of a batch: ``prior`` (B, 2, 2), ``c``, ``s``
    (B, M, 2), ``r``, ``rho``, ``sd2``, ``st2`` (B, M); writes the plans into ``s``, the
    sensors' ``status`` (B, M) and ``value``, ``sweeps``, ``solves`` (B,)."""
    m = c.shape[1]
    free, fixed, inside = np.empty(m, np.bool_), np.empty((m, 2)), np.empty(m, np.bool_)
    for b in range(s.shape[0]):
        _, v, _, n_sweeps, n_solves, _ = plan_point(
            prior[b, 0, 0], prior[b, 0, 1], prior[b, 1, 1], c[b], r[b], rho[b], sd2[b], st2[b],
            tol, max_sweeps, free, fixed, status[b], s[b], inside,
        )  # fmt: skip
        value[b], sweeps[b], solves[b] = v, n_sweeps, n_solves
