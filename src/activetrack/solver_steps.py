"""The steps of the single-sensor solver (Section IV-A), written once for floats and arrays.

Every function here works on Python floats (the scalar path, one problem) and on NumPy
arrays (the batched path, one problem a row) alike, with the same operations in the same
order on both, so each path gives the results it gave as its own code. The arithmetic is
``+ - * /``, ``abs`` and comparisons; the few operations whose float and array forms
differ come from an ``ops`` namespace, :data:`SCALAR` (``math``, builtins, conditional
expressions) or :data:`ARRAY` (NumPy): ``atan2``, ``hypot``, ``cos``, ``sin``, ``sqrt``,
``maximum``, ``minimum``, ``copysign``, ``where(cond, x, y)`` and
``swap2(cond, x, y)`` (``(y, x)`` where ``cond``, else ``(x, y)``). The scalar forms
evaluate both branches, so callers keep both finite (e.g. a safe divisor).

The steps, in the order the solver uses them:

- :func:`eig_frame` (and :func:`eigenvalues`): Lemma 2,
  ``L' = C(phi0) diag(l1, l2) C(-phi0)``.
- :func:`normalize`: the eigenframe problem in units (lengths in ``r``, information in
  ``kappa = max(l1, 1/sigma_d^2, 1/(sigma_theta^2 r^2))``) that keep the polynomials of
  :mod:`activetrack._coefficients` well scaled.
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
from types import SimpleNamespace

import numpy as np

from activetrack._coefficients import alpha_beta, circle_reduction

SCALAR = SimpleNamespace(
    atan2=math.atan2,
    hypot=math.hypot,
    cos=math.cos,
    sin=math.sin,
    sqrt=math.sqrt,
    maximum=max,
    minimum=min,
    where=lambda cond, x, y: x if cond else y,
    swap2=lambda cond, x, y: (y, x) if cond else (x, y),
    copysign=math.copysign,
)
ARRAY = SimpleNamespace(
    atan2=np.arctan2,
    hypot=np.hypot,
    cos=np.cos,
    sin=np.sin,
    sqrt=np.sqrt,
    maximum=np.maximum,
    minimum=np.minimum,
    where=np.where,
    swap2=lambda cond, x, y: (np.where(cond, y, x), np.where(cond, x, y)),
    copysign=np.copysign,
)

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


def eigenvalues(p11, p12, p22, ops):
    """Return ``(l1, l2)``, the eigenvalues of ``[[p11, p12], [p12, p22]]`` (``l1 >= l2``)."""
    l1 = 0.5 * (p11 + p22) + ops.hypot(0.5 * (p11 - p22), p12)
    # det / l1 is positive whenever the matrix is (validated) positive definite.
    return l1, (p11 * p22 - p12 * p12) / l1


def eig_frame(p11, p12, p22, ops):
    """Return ``(cos phi0, sin phi0, l1, l2)`` of Lemma 2 (``l1 >= l2 > 0``), closed form."""
    phi0 = 0.5 * ops.atan2(2.0 * p12, p11 - p22)
    l1, l2 = eigenvalues(p11, p12, p22, ops)
    return ops.cos(phi0), ops.sin(phi0), l1, l2


def to_eigen(x, y, cph, sph):
    """Return ``C(-phi0) (x, y)``: a point of the original frame in the eigenframe."""
    return cph * x + sph * y, -sph * x + cph * y


def to_original(x, y, cph, sph):
    """Return ``C(phi0) (x, y)``: an eigenframe point in the original frame."""
    return cph * x - sph * y, sph * x + cph * y


def normalize(l1, l2, a, b, c1, c2, cph, sph, r, rho, ops):
    """Return ``(kappa, L1, L2, A, Bn, C1, C2, rh)``: the problem in normalized units.

    Lengths in units of ``r > 0`` and information in units of
    ``kappa = max(l1, a, b / r^2)`` (``a = 1/sigma_d^2``, ``b = 1/sigma_theta^2``), so the
    largest of ``L1, A, Bn`` is 1; ``(C1, C2)`` is ``c / r`` in the eigenframe and
    ``rh = max(rho / r, RHO_FLOOR)``. ``f0`` in these units is ``kappa f0``.
    """
    kappa = ops.maximum(ops.maximum(l1, a), b / (r * r))
    big_c1, big_c2 = to_eigen(c1, c2, cph, sph)
    return (
        kappa,
        l1 / kappa,
        l2 / kappa,
        a / kappa,
        b / (r * r * kappa),
        big_c1 / r,
        big_c2 / r,
        ops.maximum(rho / r, RHO_FLOOR),
    )


def geometric_case(nc, r, rho):
    """Return the geometric case (1-4) of Fig. 3 for ``||c|| = nc`` (4: ``||c|| <= r``).

    ``4 if nc <= r else 1 if rho <= nc - r else 2 if rho^2 >= nc^2 - r^2 else 3``, by
    arithmetic on the three tests (bools or bool arrays; the result int or int array).
    """
    case = 3 - (rho * rho >= nc * nc - r * r)
    case = case - (case - 1) * (rho <= nc - r)
    return case + (4 - case) * (nc <= r)


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


def circle_polynomial(L1, L2, A, Bn, C1, C2, swap, ops):
    """Return ``(h0..h5, k0..k4)``: f1 (eq. 32) on the speed circle is ``g0(v) + g1(v) w``.

    ``g0 = sum h_i v^i``, ``g1 = sum k_i v^i``; ``v`` is the offset from ``c`` (units of
    ``r``) along x, or along y where ``swap`` (then the mirrored problem: x <-> y,
    ``L1 <-> L2``), and ``w = +-sqrt(1 - v^2)`` the other one. The Sylvester resultant of
    ``g0 + g1 w`` and the circle (eq. 30) is f3 (eq. 33):
    :func:`activetrack._coefficients.sylvester_gammas` of these.
    """
    m1, m2 = ops.swap2(swap, L1, L2)
    q1, q2 = ops.swap2(swap, C1, C2)
    return circle_reduction(*alpha_beta(m1, m2, A, Bn, q1, q2), q1, q2)


def root_candidates(hk, v, C1, C2, swap, ops):
    """Return ``((x+, y+, crit+), (x-, y-, crit-))``: the speed-circle points of roots ``v``.

    A root ``v`` in [-1, 1] of f3 (eq. 33) is the offset from ``c / r`` along x (along y
    where ``swap``); the other offset is ``+-w``, ``w = sqrt(1 - v^2)``. f1 (eq. 32) on the
    circle is ``g0(v) + g1(v) (+-w)`` (``hk`` from :func:`circle_polynomial`, entries
    broadcasting with ``v``; Horner's rule); a sign is critical (a Newton start) unless f1
    there is ``SIGN_RATIO`` times that at the other. Both points are candidates.
    """
    w = ops.sqrt(ops.maximum(0.0, 1.0 - v * v))
    g0 = ((((hk[5] * v + hk[4]) * v + hk[3]) * v + hk[2]) * v + hk[1]) * v + hk[0]
    g1w = ((((hk[10] * v + hk[9]) * v + hk[8]) * v + hk[7]) * v + hk[6]) * w
    ep, em = abs(g0 + g1w), abs(g0 - g1w)
    (dxp, dxm), (dyp, dym) = ops.swap2(swap, (v, v), (w, -w))
    return (
        (C1 + dxp, C2 + dyp, ep <= SIGN_RATIO * em),
        (C1 + dxm, C2 + dym, em <= SIGN_RATIO * ep),
    )


def nearest_point(C1, C2, ncn):
    """Return D, the speed circle's point nearest the target (``ncn = ||c|| / r > 0``)."""
    t = 1.0 - 1.0 / ncn
    return C1 * t, C2 * t


def axis_points(rh):
    """Return the four candidates ``(+-rh, 0), (0, +-rh)`` of the ``rho`` arc (eq. 36-37)."""
    return ((rh, 0.0), (-rh, 0.0), (0.0, rh), (0.0, -rh))


def in_speed_disk(x, y, C1, C2):
    """Return whether ``(x, y)`` lies in the speed disk ``|(x, y) - c / r| <= 1`` (with slack)."""
    return (x - C1) ** 2 + (y - C2) ** 2 <= 1.0 + FEAS_TOL


def arc_ends(C1, C2, ncn, rh2, ops):
    """Return the arc ends A, B ``((xa, ya), (xb, yb))``: where the two circles meet.

    ``ncn = ||c|| / r > 0`` (callers pass a safe value where it is 0), ``rh2 = (rho/r)^2``.
    """
    along = (rh2 - 1.0 + ncn * ncn) / (2.0 * ncn)
    h = ops.sqrt(ops.maximum(0.0, rh2 - along * along))
    ux, uy = C1 / ncn, C2 / ncn
    return (along * ux - h * uy, along * uy + h * ux), (along * ux + h * uy, along * uy - h * ux)


def newton_step(d1, d2, f, ops):
    """Return ``(step, go)``: the damped Newton step on ``d f0 / d theta`` and whether to
    take it (the step and its predicted gain ``|f' step|`` exceed rounding; NaN: not).

    The step is ``-f'/|f''|`` (a descent direction even where f0 is concave) clipped to
    ``+-MAX_STEP``. Where ``f'' = 0`` the divisor is the smallest subnormal instead, so
    ``-f'/divisor`` is beyond ``MAX_STEP`` (or infinite) for every ``f' != 0``: the full
    ``MAX_STEP`` downhill (arrays: the caller ignores the overflow).
    """
    step = -d1 / (abs(d2) + (d2 == 0.0) * 5e-324)
    step = ops.maximum(-MAX_STEP, ops.minimum(MAX_STEP, step))
    return step, (abs(step) >= STEP_TOL) & (abs(d1 * step) > GAIN_TOL * f)


def fallback_point(c1, c2, nc, r, ops):
    """Return ``c + r c / ||c||`` (the x axis if ``c = 0``): the reachable point farthest
    from the target, the answer when infeasible (``||c|| + r < rho``) or ``r = 0``."""
    away = nc > 0.0
    safe = ops.where(away, nc, 1.0)
    ux = ops.where(away, c1 / safe, 1.0)
    uy = ops.where(away, c2 / safe, 0.0)
    return c1 + r * ux, c2 + r * uy


def value_at(l1, l2, a, b, x, y, ops):
    """Return f0 at eigenframe point (x, y); at ``s = 0`` its infimum ``1 / (l1 + a)``."""
    origin = (x == 0.0) & (y == 0.0)
    return ops.where(origin, 1.0 / (l1 + a), f0(l1, l2, a, b, ops.where(origin, 1.0, x), y))
