"""The single-sensor solver, one problem, compiled (Section IV-A).

The steps of :mod:`activetrack.solvers._steps` on floats, the roots of f3 (eq. 33) from the
compiled companion-matrix QR (:func:`activetrack.solvers.companion.accepted_roots_from`; from a
nearby f3's roots where the caller keeps them, as GSR's sweeps do), candidates kept as
they come. :func:`solve_point` is the kernel; :func:`solve_rows` runs
it over a batch in compiled code (the batched solver), :func:`solve_checked` checks and
solves one problem from Python in one call (:func:`activetrack.solvers.analytic.solve_single_sensor`
names what it rejects). The other kernels take validated inputs.
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import kernel
from activetrack.solvers._coefficients import sylvester_gammas
from activetrack.solvers._inputs import accepted_point
from activetrack.solvers._steps import (
    FEAS_TOL,
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
from activetrack.solvers.companion import accepted_roots_from

MAX_STARTS = N_POLISH + 3  # Newton starts: the best critical root candidates, D, A, B
#: The roots kept by :func:`solve_point`: ``roots[:10]`` real parts, ``roots[10:20]``
#: imaginary parts, ``roots[ROOTS_TAG]`` which f3 they belong to (f3 in x or in y: the
#: ``swap`` of :func:`~activetrack.solvers._steps.circle_polynomial`), or none.
ROOTS_SIZE, ROOTS_TAG = 21, 20
NO_ROOTS, UNSWAPPED, SWAPPED = 0.0, 1.0, 2.0  # NO_ROOTS = 0: np.zeros is a fresh state
UNCHECKED = -1.0  # the ||c|| that tells solve_checked to skip the checks
assert N_POLISH == 2, "_two_best picks the polished root candidates"


@kernel
def polish(L1, L2, A, Bn, C1, C2, lo, f, x, y):
    """Return ``(f, x, y)`` after damped Newton on df0/dt from the speed-circle point (x, y).

    Steps from :func:`~activetrack.solvers._steps.newton_step`, halved until they lower
    ``f`` and stay feasible (``x^2 + y^2 >= lo``): sharp wells of f0 near the target
    (width ~ (||c|| - r) / r radians) are entered instead of jumped over.
    """
    t = math.atan2(y - C2, x - C1)
    for _ in range(NEWTON_ITERS):
        _, d1, d2 = circle_derivatives(L1, L2, A, Bn, C1, C2, math.cos(t), math.sin(t))
        step, go = newton_step(d1, d2, f)
        if not go:  # converged (or NaN)
            break
        moved = False
        while abs(step) >= STEP_TOL:
            tn = t + step
            xn, yn = C1 + math.cos(tn), C2 + math.sin(tn)
            if xn * xn + yn * yn >= lo:
                fn = f0(L1, L2, A, Bn, xn, yn)
                if fn < f:
                    t, f, x, y = tn, fn, xn, yn
                    moved = True
                    break
            step *= 0.5
        if not moved:
            break
    return f, x, y


@kernel
def _two_best(fs, xs, ys, n):
    """Return the indices ``(i, j)`` of the smallest and next smallest ``(f, x, y)`` among
    the first ``n`` (in that lexicographic order, as a sort of the tuples; -1: none)."""
    first = -1
    second = -1
    for k in range(n):
        key = (fs[k], xs[k], ys[k])
        if first < 0 or key < (fs[first], xs[first], ys[first]):
            second = first
            first = k
        elif second < 0 or key < (fs[second], xs[second], ys[second]):
            second = k
    return first, second


@kernel
def solve_point(p11, p12, p22, c1, c2, r, rho, sigma_d2, sigma_theta2, roots):
    """Return ``(sx, sy, value, case, feasible)`` for one validated problem.

    ``p11, p12, p22``: the symmetric prior information; ``c1, c2``: the sensor relative to
    the target; the rest as in :func:`activetrack.solvers.analytic.solve_single_sensor`.
    ``roots`` (:data:`ROOTS_SIZE`,) keeps f3's roots between solves: the real parts, the
    imaginary parts and a tag (:data:`NO_ROOTS`, or which variable f3 was in). Where the
    tag matches this problem's f3, the roots there are the starting point of
    :func:`activetrack.solvers.companion.accepted_roots_from`; this problem's roots (and tag)
    replace them. A fresh solve passes ``np.zeros(ROOTS_SIZE)``; a caller solving a
    sequence of nearby problems (GSR's sweeps) passes the same array each time, and gets
    the fresh solve's answer up to rounding.
    """
    cph, sph, l1, l2 = eig_frame(p11, p12, p22)
    a = 1.0 / sigma_d2
    b = 1.0 / sigma_theta2
    nc = math.hypot(c1, c2)
    case = geometric_case(nc, r, rho)

    if nc + r < rho or r == 0.0:
        # Infeasible (or nowhere to go): the reachable point farthest from the target.
        sx, sy = fallback_point(c1, c2, nc, r)
        ex, ey = to_eigen(sx, sy, cph, sph)
        return sx, sy, value_at(l1, l2, a, b, ex, ey), case, nc + r >= rho

    kappa, L1, L2, A, Bn, C1, C2, rh = normalize(l1, l2, a, b, c1, c2, cph, sph, r, rho)
    ncn = nc / r
    rh2 = rh * rh
    lo = rh2 * (1.0 - FEAS_TOL)

    best_f = math.inf
    bx = 0.0
    by = 0.0
    # Critical points on the speed circle (f, x, y), then the Newton starts.
    cf = np.empty(20)
    cx = np.empty(20)
    cy = np.empty(20)
    n_circle = 0
    sf = np.empty(MAX_STARTS)
    sx_ = np.empty(MAX_STARTS)
    sy_ = np.empty(MAX_STARTS)
    n_starts = 0

    on_speed_circle = ncn > 1.0 and rh2 < ncn * ncn - 1.0
    sharp = False
    if on_speed_circle:
        # Cases I and III: critical points on the speed circle (eq. 30-33).
        swap = abs(C1) > abs(C2)
        hk = circle_polynomial(L1, L2, A, Bn, C1, C2, swap)
        gam = np.array(sylvester_gammas(*hk))
        accepted = np.empty(10)
        tag = SWAPPED if swap else UNSWAPPED
        n_accepted, found = accepted_roots_from(
            gam, accepted, roots[:10], roots[10:20], roots[ROOTS_TAG] == tag
        )
        roots[ROOTS_TAG] = tag if found else NO_ROOTS
        for i in range(n_accepted):
            # Both points are candidates; the critical one(s) are also Newton starts.
            for x, y, crit in root_candidates(hk, accepted[i], C1, C2, swap):
                if x * x + y * y >= lo:
                    f = f0(L1, L2, A, Bn, x, y)
                    if f < best_f:
                        best_f, bx, by = f, x, y
                    if crit:
                        cf[n_circle], cx[n_circle], cy[n_circle] = f, x, y
                        n_circle += 1
        for k in _two_best(cf, cx, cy, n_circle):  # the N_POLISH = 2 best
            if k >= 0:
                sf[n_starts], sx_[n_starts], sy_[n_starts] = cf[k], cx[k], cy[k]
                n_starts += 1
        sharp = max(ncn - 1.0, rh) < SHARP
        if ncn - 1.0 >= rh:  # the nearest point D of the speed circle (case I)
            x, y = nearest_point(C1, C2, ncn)
            f = f0(L1, L2, A, Bn, x, y)
            if f < best_f:
                best_f, bx, by = f, x, y
            if sharp:
                sf[n_starts], sx_[n_starts], sy_[n_starts] = f, x, y
                n_starts += 1

    if rh >= ncn - 1.0:
        # Cases II, III and 4: the rho arc inside the speed disk (eq. 36-37) and its ends.
        for x, y in axis_points(rh):
            if in_speed_disk(x, y, C1, C2):
                f = f0(L1, L2, A, Bn, x, y)
                if f < best_f:
                    best_f, bx, by = f, x, y
        if ncn > 0.0 and rh >= abs(ncn - 1.0):
            for x, y in arc_ends(C1, C2, ncn, rh2):
                f = f0(L1, L2, A, Bn, x, y)
                if f < best_f:
                    best_f, bx, by = f, x, y
                if on_speed_circle and sharp:  # case III: the speed arcs end at A, B
                    sf[n_starts], sx_[n_starts], sy_[n_starts] = f, x, y
                    n_starts += 1

    # Polish on the speed circle: damped Newton on df0/dt (t: circle angle).
    for k in range(n_starts):
        f, x, y = polish(L1, L2, A, Bn, C1, C2, lo, sf[k], sx_[k], sy_[k])
        if f < best_f:
            best_f, bx, by = f, x, y

    sx, sy = to_original(bx * r, by * r, cph, sph)
    return sx, sy, best_f / kappa, case, True


@kernel
def solve_rows(P, c, r, rho, sigma_d2, sigma_theta2, s, value, case, feasible):
    """Solve the validated problems row by row into ``s`` (B, 2), ``value``, ``case``,
    ``feasible`` (B,); inputs (B, 2, 2), (B, 2) and (B,) x 4 (the prior symmetrized)."""
    roots = np.empty(ROOTS_SIZE)
    for i in range(P.shape[0]):
        p12 = 0.5 * (P[i, 0, 1] + P[i, 1, 0])
        roots[ROOTS_TAG] = NO_ROOTS  # rows are independent: each a fresh solve
        sx, sy, v, k, ok = solve_point(
            P[i, 0, 0], p12, P[i, 1, 1], c[i, 0], c[i, 1], r[i], rho[i], sigma_d2[i],
            sigma_theta2[i], roots,
        )  # fmt: skip
        s[i, 0] = sx
        s[i, 1] = sy
        value[i] = v
        case[i] = k
        feasible[i] = ok


@kernel
def solve_checked(p11, p12, p21, p22, c1, c2, nc, r, rho, sigma_d2, sigma_theta2):
    """Return ``(sx, sy, value, case, feasible, accepted)``: :func:`solve_point` of one
    problem given as floats (the prior's four entries; ``nc = ||c||`` for the range test),
    a fresh solve.

    The prior is symmetrized and the problem solved only when
    :func:`~activetrack.solvers._inputs.accepted_point` accepts it; otherwise ``accepted``
    is False (and the rest NaN, 0, False), for the caller to say why. ``nc =``
    :data:`UNCHECKED` (never a norm; a flag argument slowed the call from Python
    measurably) solves without checks, ``p12`` then the off-diagonal entry (``p21``
    unused).
    """
    if nc != UNCHECKED:  # NaN (a NaN in c) is checked, and refused
        if not accepted_point(p11, p12, p21, p22, c1, c2, nc, r, rho, sigma_d2, sigma_theta2):
            return math.nan, math.nan, math.nan, 0, False, False
        p12 = 0.5 * (p12 + p21)
    sx, sy, value, case, ok = solve_point(
        p11, p12, p22, c1, c2, r, rho, sigma_d2, sigma_theta2, np.zeros(ROOTS_SIZE)
    )
    return sx, sy, value, case, ok, True
