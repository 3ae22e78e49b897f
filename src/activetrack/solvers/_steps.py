"""The steps of the single-sensor solver (Section IV-A), as compiled scalar kernels.

Every function here is an :func:`activetrack._jit.kernel` on floats: the solver
(:mod:`activetrack.solvers._scalar`) runs them compiled, one problem at a time, and the
batched solver loops over problems in compiled code, so one copy of each step serves
both.

The steps, in the order the solver uses them:

- :func:`eig_frame` (and :func:`eigenvalues`): Lemma 2,
  ``L' = C(phi0) diag(l1, l2) C(-phi0)``.
- :func:`normalize`: the eigenframe problem in units (lengths in ``r``, information in
  ``kappa = max(l1, 1/sigma_d^2, 1/(sigma_theta^2 r^2))``) that keep the polynomials of
  :mod:`activetrack.solvers._coefficients` well scaled.
- :func:`geometric_case`: the case (1-4) of Fig. 3.
- :func:`f0` (eq. 22 in the eigenframe, eq. 18) and :func:`circle_derivatives`
  (``f0`` and its first two derivatives along the speed circle, eq. 30-31).
- :func:`circle_polynomial`: f1 reduced to the speed circle (eq. 30-32), whose Sylvester
  resultant is f3 (eq. 33); :func:`root_candidates`: the two circle points of a root of
  f3 and which of them is critical.
- :func:`nearest_point` (D), :func:`axis_points` (eq. 36-37: ``x y = 0`` on the ``rho``
  arc), :func:`in_speed_disk`, :func:`arc_ends` (A, B): the other candidates (Lemma 3).
- :func:`newton_step`: the damped Newton step on ``d f0 / d theta`` that polishes.
- :func:`fallback_point`, :func:`value_at`: the infeasible and ``r = 0`` answer.
- :func:`to_eigen`, :func:`to_original`: the rotations of Lemma 2.
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import kernel
from activetrack.solvers._coefficients import alpha_beta, circle_reduction

RHO_FLOOR = 1e-9  # minimum rho / r used internally (see the solver's module docstring)
FEAS_TOL = 1e-12  # relative slack of the feasibility tests of candidates
SIGN_RATIO = 10.0  # a sign of the eliminated coordinate is "critical" unless the other fits
# f1 10x better; both signs are always evaluated, this only picks where Newton starts
NEWTON_ITERS = 12  # damped Newton iterations per start (most starts converge in 1-2)
HALVINGS = 40  # backtracking: step, step/2, ..., until f decreases
GAIN_TOL = 1e-16  # stop when the predicted decrease |f' step| is below this * f
MAX_STEP = 0.5  # radians per Newton step
N_POLISH = 2  # polish this many of the best speed-circle candidates (plus D, A, B)
STEP_TOL = 1e-13  # Newton steps below this (radians) are converged
# Polish also from D, A, B when the feasible speed arc passes within SHARP * r of the
# target: f0 then has a well of angular width ~ distance / r, the roots of f3 crowd there
# and lose accuracy (a nearly multiple root), and the root candidates may miss the well.
SHARP = 0.25


@kernel
def eigenvalues(p11, p12, p22):
    """Return ``(l1, l2)``, the eigenvalues of ``[[p11, p12], [p12, p22]]`` (``l1 >= l2``)."""
    # np.hypot: also on arrays (the batched input check calls this kernel on columns).
    l1 = 0.5 * (p11 + p22) + np.hypot(0.5 * (p11 - p22), p12)
    # det / l1 is positive whenever the matrix is (validated) positive definite.
    return l1, (p11 * p22 - p12 * p12) / l1


@kernel
def eig_frame(p11, p12, p22):
    """Return ``(cos phi0, sin phi0, l1, l2)`` of Lemma 2 (``l1 >= l2 > 0``), closed form."""
    phi0 = 0.5 * math.atan2(2.0 * p12, p11 - p22)
    l1, l2 = eigenvalues(p11, p12, p22)
    return math.cos(phi0), math.sin(phi0), l1, l2


@kernel
def to_eigen(x, y, cph, sph):
    """Return ``C(-phi0) (x, y)``: a point of the original frame in the eigenframe."""
    return cph * x + sph * y, -sph * x + cph * y


@kernel
def to_original(x, y, cph, sph):
    """Return ``C(phi0) (x, y)``: an eigenframe point in the original frame."""
    return cph * x - sph * y, sph * x + cph * y


@kernel
def normalize(l1, l2, a, b, c1, c2, cph, sph, r, rho):
    """Return ``(kappa, L1, L2, A, Bn, C1, C2, rh)``: the problem in normalized units.

    Lengths in units of ``r > 0`` and information in units of
    ``kappa = max(l1, a, b / r^2)`` (``a = 1/sigma_d^2``, ``b = 1/sigma_theta^2``), so the
    largest of ``L1, A, Bn`` is 1; ``(C1, C2)`` is ``c / r`` in the eigenframe and
    ``rh = max(rho / r, RHO_FLOOR)``. ``f0`` in these units is ``kappa f0``.
    """
    kappa = max(max(l1, a), b / (r * r))
    big_c1, big_c2 = to_eigen(c1, c2, cph, sph)
    return (
        kappa,
        l1 / kappa,
        l2 / kappa,
        a / kappa,
        b / (r * r * kappa),
        big_c1 / r,
        big_c2 / r,
        max(rho / r, RHO_FLOOR),
    )


@kernel
def geometric_case(nc, r, rho):
    """Return the geometric case (1-4) of Fig. 3 for ``||c|| = nc`` (4: ``||c|| <= r``)."""
    if nc <= r:
        return 4
    if rho <= nc - r:
        return 1
    return 2 if rho * rho >= nc * nc - r * r else 3


@kernel
def f0(l1, l2, a, b, x, y):
    """Return f0 of eq. (22) for diagonal prior ``diag(l1, l2)``: ``tr(M) / det(M)``.

    ``a = 1/sigma_d^2``, ``b = 1/sigma_theta^2``. Written as ``P / Q`` with
    ``P = D ((l1 + l2 + a) D + b)``, ``Q = l1 l2 D^2 + a D (l1 y^2 + l2 x^2)
    + b (a D + l1 x^2 + l2 y^2)``, ``D = x^2 + y^2``: all terms positive, no cancellation.
    """
    xx = x * x
    yy = y * y
    d = xx + yy
    return (d * ((l1 + l2 + a) * d + b)) / (
        l1 * l2 * d * d + a * d * (l1 * yy + l2 * xx) + b * (a * d + l1 * xx + l2 * yy)
    )


@kernel
def circle_derivatives(l1, l2, a, b, c1, c2, co, si):
    """Return ``(f0, df0/dt, d2f0/dt2)`` at ``s = c + (cos t, sin t)`` (unit circle, eq. 30)."""
    x = c1 + co
    y = c2 + si
    # x' = -sin t, y' = cos t, x'' = -cos t, y'' = -sin t.
    d = x * x + y * y
    dp = 2.0 * (y * co - x * si)
    dpp = 2.0 * (1.0 - x * co - y * si)
    e = l1 * y * y + l2 * x * x
    ep = 2.0 * (l1 * y * co - l2 * x * si)
    epp = 2.0 * (l1 * (co * co - y * si) + l2 * (si * si - x * co))
    fp = 2.0 * (l2 * y * co - l1 * x * si)
    fpp = 2.0 * (l1 * (si * si - x * co) + l2 * (co * co - y * si))
    big_a = l1 + l2 + a
    w = 2.0 * big_a * d + b
    p = d * (big_a * d + b)
    pp = w * dp
    ppp = 2.0 * big_a * dp * dp + w * dpp
    k = 2.0 * l1 * l2 * d + a * b + a * e
    q = l1 * l2 * d * d + a * d * e + b * (a * d + l1 * x * x + l2 * y * y)
    qp = k * dp + a * d * ep + b * fp
    qpp = 2.0 * l1 * l2 * dp * dp + 2.0 * a * dp * ep + k * dpp + a * d * epp + b * fpp
    num = pp * q - p * qp
    f = p / q
    f1 = num / (q * q)
    f2 = (ppp * q - p * qpp) / (q * q) - 2.0 * qp * num / (q * q * q)
    return f, f1, f2


@kernel
def circle_polynomial(L1, L2, A, Bn, C1, C2, swap):
    """Return ``(h0..h5, k0..k4)``: f1 (eq. 32) on the speed circle is ``g0(v) + g1(v) w``.

    ``g0 = sum h_i v^i``, ``g1 = sum k_i v^i``; ``v`` is the offset from ``c`` (units of
    ``r``) along x, or along y where ``swap`` (then the mirrored problem: x <-> y,
    ``L1 <-> L2``), and ``w = +-sqrt(1 - v^2)`` the other one. The Sylvester resultant of
    ``g0 + g1 w`` and the circle (eq. 30) is f3 (eq. 33):
    :func:`activetrack.solvers._coefficients.sylvester_gammas` of these.
    """
    m1, m2, q1, q2 = (L2, L1, C2, C1) if swap else (L1, L2, C1, C2)
    return circle_reduction(*alpha_beta(m1, m2, A, Bn, q1, q2), q1, q2)


@kernel
def root_candidates(hk, v, C1, C2, swap):
    """Return ``((x+, y+, crit+), (x-, y-, crit-))``: the speed-circle points of roots ``v``.

    A root ``v`` in [-1, 1] of f3 (eq. 33) is the offset from ``c / r`` along x (along y
    where ``swap``); the other offset is ``+-w``, ``w = sqrt(1 - v^2)``. f1 (eq. 32) on the
    circle is ``g0(v) + g1(v) (+-w)`` (``hk`` from :func:`circle_polynomial`; Horner's
    rule); a sign is critical (a Newton start) unless f1
    there is ``SIGN_RATIO`` times that at the other. Both points are candidates.
    """
    w = math.sqrt(max(0.0, 1.0 - v * v))
    g0 = ((((hk[5] * v + hk[4]) * v + hk[3]) * v + hk[2]) * v + hk[1]) * v + hk[0]
    g1w = ((((hk[10] * v + hk[9]) * v + hk[8]) * v + hk[7]) * v + hk[6]) * w
    ep, em = abs(g0 + g1w), abs(g0 - g1w)
    dxp, dxm, dyp, dym = (w, -w, v, v) if swap else (v, v, w, -w)
    return (
        (C1 + dxp, C2 + dyp, ep <= SIGN_RATIO * em),
        (C1 + dxm, C2 + dym, em <= SIGN_RATIO * ep),
    )


@kernel
def nearest_point(C1, C2, ncn):
    """Return D, the speed circle's point nearest the target (``ncn = ||c|| / r > 0``)."""
    t = 1.0 - 1.0 / ncn
    return C1 * t, C2 * t


@kernel
def axis_points(rh):
    """Return the four candidates ``(+-rh, 0), (0, +-rh)`` of the ``rho`` arc (eq. 36-37)."""
    return ((rh, 0.0), (-rh, 0.0), (0.0, rh), (0.0, -rh))


@kernel
def in_speed_disk(x, y, C1, C2):
    """Return whether ``(x, y)`` lies in the speed disk ``|(x, y) - c / r| <= 1`` (with slack)."""
    return (x - C1) ** 2 + (y - C2) ** 2 <= 1.0 + FEAS_TOL


@kernel
def arc_ends(C1, C2, ncn, rh2):
    """Return the arc ends A, B ``((xa, ya), (xb, yb))``: where the two circles meet.

    ``ncn = ||c|| / r > 0`` (callers pass a safe value where it is 0), ``rh2 = (rho/r)^2``.
    """
    along = (rh2 - 1.0 + ncn * ncn) / (2.0 * ncn)
    h = math.sqrt(max(0.0, rh2 - along * along))
    ux, uy = C1 / ncn, C2 / ncn
    return (along * ux - h * uy, along * uy + h * ux), (along * ux + h * uy, along * uy - h * ux)


@kernel
def newton_step(d1, d2, f):
    """Return ``(step, go)``: the damped Newton step on ``d f0 / d theta`` and whether to
    take it (the step and its predicted gain ``|f' step|`` exceed rounding; NaN: not).

    The step is ``-f'/|f''|`` (a descent direction even where f0 is concave) clipped to
    ``+-MAX_STEP``. Where ``f'' = 0`` it is the full ``MAX_STEP`` downhill.
    """
    if d2 == 0.0:
        step = -MAX_STEP if d1 > 0.0 else (MAX_STEP if d1 < 0.0 else 0.0)
    else:
        step = max(-MAX_STEP, min(MAX_STEP, -d1 / abs(d2)))
    return step, abs(step) >= STEP_TOL and abs(d1 * step) > GAIN_TOL * f


@kernel
def fallback_point(c1, c2, nc, r):
    """Return ``c + r c / ||c||`` (the x axis if ``c = 0``): the reachable point farthest
    from the target, the answer when infeasible (``||c|| + r < rho``) or ``r = 0``."""
    if nc > 0.0:
        return c1 + r * (c1 / nc), c2 + r * (c2 / nc)
    return c1 + r, c2


@kernel
def value_at(l1, l2, a, b, x, y):
    """Return f0 at eigenframe point (x, y); at ``s = 0`` its infimum ``1 / (l1 + a)``."""
    if x == 0.0 and y == 0.0:
        return 1.0 / (l1 + a)
    return f0(l1, l2, a, b, x, y)
