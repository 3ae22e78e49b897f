"""The single-sensor solver for one problem, on Python floats (Section IV-A).

The steps of :mod:`activetrack.solver_steps` with the :data:`~activetrack.solver_steps.SCALAR`
operations: Python floats throughout (a NumPy scalar operation costs ~10x a float one),
the roots of f3 (eq. 33) from one direct LAPACK call
(:func:`activetrack.companion.real_roots_scalar`), candidates kept as they come. Inputs are
validated by the caller (:func:`activetrack.solver.solve_single_sensor`).
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._coefficients import sylvester_gammas
from activetrack.companion import real_roots_scalar
from activetrack.solver_steps import (
    FEAS_TOL,
    N_POLISH,
    NEWTON_ITERS,
    SCALAR,
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

Point = tuple[float, float, float]  # (f0, x, y)


def polish(L1, L2, A, Bn, C1, C2, lo, f, x, y) -> Point:
    """Return ``(f, x, y)`` after damped Newton on df0/dt from the speed-circle point (x, y).

    Steps from :func:`~activetrack.solver_steps.newton_step`, halved until they lower
    ``f`` and stay feasible (``x^2 + y^2 >= lo``): sharp wells of f0 near the target
    (width ~ (||c|| - r) / r radians) are entered instead of jumped over.
    """
    t = math.atan2(y - C2, x - C1)
    for _ in range(NEWTON_ITERS):
        _, d1, d2 = circle_derivatives(L1, L2, A, Bn, C1, C2, math.cos(t), math.sin(t))
        step, go = newton_step(d1, d2, f, SCALAR)
        if not go:  # converged (or NaN)
            break
        while abs(step) >= STEP_TOL:
            tn = t + step
            xn, yn = C1 + math.cos(tn), C2 + math.sin(tn)
            if xn * xn + yn * yn >= lo:
                fn = f0(L1, L2, A, Bn, xn, yn)
                if fn < f:
                    t, f, x, y = tn, fn, xn, yn
                    break
            step *= 0.5
        else:
            break
    return f, x, y


def solve_scalar(
    p11: float,
    p12: float,
    p22: float,
    c1: float,
    c2: float,
    r: float,
    rho: float,
    sigma_d2: float,
    sigma_theta2: float,
) -> tuple[np.ndarray, float, int, bool]:
    """Return ``(s, value, case, feasible)`` for validated float inputs.

    ``p11, p12, p22``: the symmetric prior information; ``c1, c2``: the sensor relative to
    the target; the rest as in :func:`activetrack.solver.solve_single_sensor`.
    """
    cph, sph, l1, l2 = eig_frame(p11, p12, p22, SCALAR)
    a = 1.0 / sigma_d2
    b = 1.0 / sigma_theta2
    nc = math.hypot(c1, c2)
    case = geometric_case(nc, r, rho)

    if nc + r < rho or r == 0.0:
        # Infeasible (or nowhere to go): the reachable point farthest from the target.
        sx, sy = fallback_point(c1, c2, nc, r, SCALAR)
        ex, ey = to_eigen(sx, sy, cph, sph)
        return np.array([sx, sy]), value_at(l1, l2, a, b, ex, ey, SCALAR), case, nc + r >= rho

    kappa, L1, L2, A, Bn, C1, C2, rh = normalize(l1, l2, a, b, c1, c2, cph, sph, r, rho, SCALAR)
    ncn = nc / r
    rh2 = rh * rh
    lo = rh2 * (1.0 - FEAS_TOL)

    best_f = math.inf
    best = (0.0, 0.0)
    circle: list[Point] = []  # critical points on the speed circle
    starts: list[Point] = []  # where to polish on the speed circle

    on_speed_circle = ncn > 1.0 and rh2 < ncn * ncn - 1.0
    sharp = False
    if on_speed_circle:
        # Cases I and III: critical points on the speed circle (eq. 30-33).
        swap = abs(C1) > abs(C2)
        hk = circle_polynomial(L1, L2, A, Bn, C1, C2, swap, SCALAR)
        for v in real_roots_scalar(sylvester_gammas(*hk)):
            # Both points are candidates; the critical one(s) are also Newton starts.
            for x, y, crit in root_candidates(hk, v, C1, C2, swap, SCALAR):
                if x * x + y * y >= lo:
                    f = f0(L1, L2, A, Bn, x, y)
                    if f < best_f:
                        best_f, best = f, (x, y)
                    if crit:
                        circle.append((f, x, y))
        circle.sort()
        starts = circle[:N_POLISH]
        sharp = max(ncn - 1.0, rh) < SHARP
        if ncn - 1.0 >= rh:  # the nearest point D of the speed circle (case I)
            x, y = nearest_point(C1, C2, ncn)
            f = f0(L1, L2, A, Bn, x, y)
            if f < best_f:
                best_f, best = f, (x, y)
            if sharp:
                starts.append((f, x, y))

    if rh >= ncn - 1.0:
        # Cases II, III and 4: the rho arc inside the speed disk (eq. 36-37) and its ends.
        for x, y in axis_points(rh):
            if in_speed_disk(x, y, C1, C2):
                f = f0(L1, L2, A, Bn, x, y)
                if f < best_f:
                    best_f, best = f, (x, y)
        if ncn > 0.0 and rh >= abs(ncn - 1.0):
            for x, y in arc_ends(C1, C2, ncn, rh2, SCALAR):
                f = f0(L1, L2, A, Bn, x, y)
                if f < best_f:
                    best_f, best = f, (x, y)
                if on_speed_circle and sharp:  # case III: the speed arcs end at A, B
                    starts.append((f, x, y))

    # Polish on the speed circle: damped Newton on df0/dt (t: circle angle).
    for f, x, y in starts:
        f, x, y = polish(L1, L2, A, Bn, C1, C2, lo, f, x, y)
        if f < best_f:
            best_f, best = f, (x, y)

    sx, sy = to_original(best[0] * r, best[1] * r, cph, sph)
    return np.array([sx, sy]), best_f / kappa, case, True
