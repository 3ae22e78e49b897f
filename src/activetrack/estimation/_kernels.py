"""Compiled EKF update of eq. (11) in square-root form, one filter at a time.

The kernels behind :func:`activetrack.estimation.ekf.update` (whose module docstring derives the
square-root form, the zero-distance rule and the iterated EKF):
:func:`range_bearing_terms` is the measurement information ``Y = sum_i H_i^T R_i^{-1}
H_i`` (eq. 12) and the gradient term ``b = H^T R^{-1} nu`` of a team of sensors with
weights ``(w_d, w_theta)`` (zero for a component a sensor does not measure or a sensor
that did not measure); :func:`posterior_into` is eq. (11)'s posterior from ``(Y, b)``;
:func:`relinearize_into` one more linearization of the iterated EKF; :func:`update_rows`
the whole update of a batch of filters, every filter iterating until its own position
settles. A filter's arrays are rows of C-contiguous float64 arrays; per-sensor arrays
(B', M) with B' = 1 (shared by the batch) or B.
"""

from __future__ import annotations

import math

from activetrack._jit import inline_kernel, kernel
from activetrack.models.measurement import INFORMATION_RATIO_MAX, ZERO_DISTANCE2

#: Floor of the conditional variance ``p11 - p01^2 / p00`` of a prior's position block,
#: relative to ``p11``: the rounding level of the stored entries, so the 2x2 Cholesky factor
#: of a prior that is positive definite in floating point is never singular.
FLOOR = 1e-15
#: The iterated EKF stops when the position moves less than this (times 1 + |position|).
ITERATION_TOL = 1e-10
_TWO_PI = 2.0 * math.pi


@kernel
def wrap(a):
    """Return the angle ``a`` wrapped to ``[-pi, pi)`` (as :func:`measurement.wrap_angle`)."""
    if abs(a) < math.pi:
        return a
    return a - _TWO_PI * math.floor((a + math.pi) / _TWO_PI)


@kernel
def range_bearing_terms(tx, ty, z, sensors, wd, wt, orientation, mask, near):
    """Return ``(Y_xx, Y_xy, Y_yy, b_x, b_y)`` linearized at the target position (tx, ty).

    A sensor at zero distance, or nearer than its bearing information allows (``w_theta
    near > d^2``, ``near = tr(P11) / INFORMATION_RATIO_MAX``: :func:`near_scale`), gives no
    terms (the zero- and near-distance rules of :mod:`activetrack.estimation.ekf`).

    ``z``, ``sensors`` (M, 2): the measurements and the sensors' positions; ``wd``, ``wt``,
    ``orientation`` (M,) weights and orientations; ``mask`` (M,) bool, the sensors that
    measured. With ``p = p_S - p_T_hat``, ``h = w_theta / |p|^2``: ``Y = sum_i g_i p p^T +
    (sum_i h_i) I`` with ``g = (w_d - h) / |p|^2`` (since ``p p^T + (J p)(J p)^T = |p|^2
    I``), and ``b = sum_i e_i d + f_i J^T d`` with ``d = -p``, ``e = w_d nu_d / |p|``,
    ``f = h nu_theta`` (eq. 9, 12).
    """
    s_h = 0.0
    s_wd = 0.0
    g_re = 0.0
    g_im = 0.0
    b_re = 0.0
    b_im = 0.0
    for i in range(sensors.shape[0]):
        if not mask[i]:  # no measurement: no terms (adding zeros would change nothing)
            continue
        dx, dy = tx - sensors[i, 0], ty - sensors[i, 1]
        n2 = dx * dx + dy * dy  # (no hypot: distances far from overflow, 4x cheaper)
        dist = math.sqrt(n2)
        w_d = wd[i]
        w_t = wt[i]
        if n2 < ZERO_DISTANCE2 or w_t * near > n2:  # no information at (near) zero distance
            dist = 1.0
            n2 = 1.0
            w_d = 0.0
            w_t = 0.0
        nu_t = wrap(z[i, 1] - math.atan2(dy, dx) + orientation[i])
        h = w_t / n2
        s_h += h
        s_wd += w_d
        g = (w_d - h) / n2
        g_re += g * (dx * dx - dy * dy)
        g_im += g * (dx * dy + dy * dx)
        e = w_d * (z[i, 0] - dist) / dist
        f = h * nu_t
        b_re += e * dx - f * dy
        b_im += e * dy + f * dx
    half = 0.5 * (s_wd + s_h)
    return half + 0.5 * g_re, 0.5 * g_im, half - 0.5 * g_re, b_re, b_im


@kernel
def posterior_into(x, P, yxx, yxy, yyy, bx, by, x_out, P_out, cov):
    """Write eq. (11)'s posterior from ``(Y, b)`` into ``x_out``, ``P_out`` (without
    ``cov``: only the position ``x_out[:2]``).

    ``P11 = L L^T``, ``I + L^T Y L = M M^T``; ``P+ = Z Z^T + blockdiag(0, S22)`` with
    ``Z = P[:, :2] L^{-T} M^{-T}`` and ``S22`` the prior's Schur complement: a sum of
    two positive semidefinite terms, exactly symmetric. The clamps only round quantities
    that are nonnegative in exact arithmetic.
    """
    factored_into(x, P, prior_factor(P), yxx, yxy, yyy, bx, by, x_out, P_out, cov)


@kernel
def prior_factor(P):
    """Return ``(l00, l10, l11, t00, t01, t11)``: the prior's position block ``P11 = L L^T``
    (lower triangular) and ``T = L^{-T}``, what every linearization of one update shares."""
    p00, p01, p11 = P[0, 0], P[0, 1], P[1, 1]
    s = p11 - p01 * p01 / p00
    s = s if s > FLOOR * p11 else FLOOR * p11
    l00, l11 = math.sqrt(p00), math.sqrt(s)
    l10 = p01 / l00
    t00, t11 = 1.0 / l00, 1.0 / l11
    return l00, l10, l11, t00, -l10 * t00 * t11, t11


@inline_kernel
def factored_into(x, P, factor, yxx, yxy, yyy, bx, by, x_out, P_out, cov):
    """:func:`posterior_into` with the prior's :func:`prior_factor` given; without ``cov``
    only the position of ``x_out`` is written (what an iteration needs)."""
    l00, l10, l11, t00, t01, t11 = factor
    yl00, yl10 = yxx * l00 + yxy * l10, yxy * l00 + yyy * l10  # Y L, first column
    k00 = l00 * yl00 + l10 * yl10
    m00 = math.sqrt(1.0 + k00) if k00 > 0.0 else 1.0
    m10 = l11 * yl10 / m00
    e = l11 * l11 * yyy - m10 * m10
    m11 = math.sqrt(1.0 + e) if e > 0.0 else 1.0
    # T = L^{-T} (given) and U = M^{-T}, both upper triangular.
    u00, u11 = 1.0 / m00, 1.0 / m11
    u01 = -m10 * u00 * u11
    # The correction K nu = P[:, :2] T (I + K)^{-1} L^T b, (I + K)^{-1} = U U^T.
    c0, c1 = l00 * bx + l10 * by, l11 * by
    w0, w1 = u00 * c0, u01 * c0 + u11 * c1
    v0, v1 = u00 * w0 + u01 * w1, u11 * w1
    z00, z10, z11 = t00 * u00, t00 * u01 + t01 * u11, t11 * u11
    g0, g1 = t00 * v0 + t01 * v1, t11 * v1
    if not cov:
        for i in range(2):
            x_out[i] = x[i] + (g0 * P[0, i] + g1 * P[1, i])
        return
    for i in range(x.shape[0]):
        r0i, r1i = P[0, i], P[1, i]
        x_out[i] = x[i] + (g0 * r0i + g1 * r1i)
        za, zb = z00 * r0i, z10 * r0i + z11 * r1i
        fa, fb = t00 * r0i, t01 * r0i + t11 * r1i
        for j in range(i + 1):
            r0j, r1j = P[0, j], P[1, j]
            v = za * (z00 * r0j) + zb * (z10 * r0j + z11 * r1j)
            if i >= 2 and j >= 2:  # the Schur complement of the unobserved block
                v += (P[i, j] - fa * (t00 * r0j)) - fb * (t01 * r0j + t11 * r1j)
            P_out[i, j] = v
            P_out[j, i] = v


@kernel
def relinearized_b(x, lin0, lin1, yxx, yxy, yyy, bx, by):
    """Return the gradient term of the iterated EKF linearized at ``lin`` (its terms
    ``(Y, b)`` there): ``nu_i = z - h(lin) - H (x - lin)`` gives ``b - Y (p - lin)``."""
    d0, d1 = x[0] - lin0, x[1] - lin1
    return bx - (yxx * d0 + yxy * d1), by - (yxy * d0 + yyy * d1)


@kernel
def relinearize_into(x, P, lin0, lin1, yxx, yxy, yyy, bx, by, x_out, P_out, cov):
    """Write the posterior of the iterated EKF linearized at ``lin`` (its terms ``(Y, b)``
    there; :func:`relinearized_b`) into ``x_out``, ``P_out`` (as :func:`posterior_into`)
    from the same prior ``x``, ``P``; return whether the position moved less than
    :data:`ITERATION_TOL` (relative to ``1 + |lin|``)."""
    cx, cy = relinearized_b(x, lin0, lin1, yxx, yxy, yyy, bx, by)
    posterior_into(x, P, yxx, yxy, yyy, cx, cy, x_out, P_out, cov)
    return settled(x_out, lin0, lin1)


@kernel
def settled(x_out, lin0, lin1):
    """Return whether the position ``x_out[:2]`` is within :data:`ITERATION_TOL` (relative
    to ``1 + |lin|``) of the linearization point ``lin``."""
    step = max(abs(x_out[0] - lin0), abs(x_out[1] - lin1))
    return step <= ITERATION_TOL * (1.0 + max(abs(lin0), abs(lin1)))


@kernel
def near_scale(P):
    """Return ``tr(P11) / INFORMATION_RATIO_MAX``: a sensor whose bearing information
    ``w_theta / d^2`` exceeds ``1 / near_scale`` is too near (:func:`range_bearing_terms`)."""
    return (P[0, 0] + P[1, 1]) * (1.0 / INFORMATION_RATIO_MAX)


@inline_kernel
def update_row(x, P, z, sensors, wd, wt, orientation, mask, iterations, x_out, P_out):
    """Write one filter's EKF posterior (``x`` (n,), ``P`` (n, n), ``z``, ``sensors`` (M, 2),
    per-sensor ``wd``, ``wt``, ``orientation``, ``mask`` (M,)) into ``x_out``, ``P_out``:
    eq. (11), then up to ``iterations - 1`` relinearizations (the covariance once, at the
    last linearization: the iterations need only the mean)."""
    f = prior_factor(P)
    near = near_scale(P)
    yxx, yxy, yyy, bx, by = range_bearing_terms(
        x[0], x[1], z, sensors, wd, wt, orientation, mask, near
    )
    factored_into(x, P, f, yxx, yxy, yyy, bx, by, x_out, P_out, iterations == 1)
    if iterations == 1:
        return
    for _ in range(iterations - 1):
        lin0, lin1 = x_out[0], x_out[1]
        yxx, yxy, yyy, bx, by = range_bearing_terms(
            lin0, lin1, z, sensors, wd, wt, orientation, mask, near
        )
        cx, cy = relinearized_b(x, lin0, lin1, yxx, yxy, yyy, bx, by)
        factored_into(x, P, f, yxx, yxy, yyy, cx, cy, x_out, P_out, False)
        if settled(x_out, lin0, lin1):
            break
    factored_into(x, P, f, yxx, yxy, yyy, cx, cy, x_out, P_out, True)  # the same position


@kernel
def update_rows(x, P, z, sensors, wd, wt, orientation, mask, iterations, x_out, P_out):
    """Write the EKF posteriors (:func:`update_row`) of B filters (``x`` (B, n), ``P``
    (B, n, n), ``z``, ``sensors`` (B, M, 2), per-sensor ``wd``, ``wt``, ``orientation``,
    ``mask`` (B', M)) into ``x_out``, ``P_out``."""
    for b in range(x.shape[0]):
        update_row(
            x[b], P[b], z[b], sensors[b], wd[b if wd.shape[0] > 1 else 0],
            wt[b if wt.shape[0] > 1 else 0], orientation[b if orientation.shape[0] > 1 else 0],
            mask[b if mask.shape[0] > 1 else 0], iterations, x_out[b], P_out[b],
        )  # fmt: skip


@kernel
def posterior_rows(x, P, terms, active, iterate, x_out, P_out):
    """For the filters ``active`` (indices) with their terms (len(active), 5) ``(Y_xx,
    Y_xy, Y_yy, b_x, b_y)``: write eq. (11)'s posterior (``iterate`` False; the terms at
    the prior mean) or one more linearization at the last posterior's position
    (``iterate`` True) into ``x_out``, ``P_out``; return the mask of those not settled."""
    out = active >= 0
    for k in range(active.shape[0]):
        b = active[k]
        yxx, yxy, yyy, bx, by = terms[k, 0], terms[k, 1], terms[k, 2], terms[k, 3], terms[k, 4]
        if iterate:
            lin0, lin1 = x_out[b, 0], x_out[b, 1]
            out[k] = not relinearize_into(
                x[b], P[b], lin0, lin1, yxx, yxy, yyy, bx, by, x_out[b], P_out[b], True
            )
        else:
            posterior_into(x[b], P[b], yxx, yxy, yyy, bx, by, x_out[b], P_out[b], True)
    return out
