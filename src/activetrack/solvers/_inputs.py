"""The single-sensor solver's accepted inputs, one problem, compiled.

The bounds of the accepted scale range (documented in :mod:`activetrack.solvers.analytic`) and
:func:`accepted_point`, the test a checked scalar solve runs on its ten floats before
solving (in the same compiled call, :func:`activetrack.solvers._scalar.solve_checked`);
:func:`accepted_rows` runs it over a batch for the checked batched solve, so both accept
exactly the same problems. A rejected problem is handed to the Python checks of
:mod:`activetrack.solvers.analytic`, which name the offending parameter and its allowed range; this
module only decides.
"""

from __future__ import annotations

import math

from activetrack._jit import kernel
from activetrack.solvers._steps import RHO_FLOOR, eigenvalues
from activetrack.validation import SYMMETRY_TOL

MIN_SCALE = 1e-50  # smallest nonzero magnitude accepted (see activetrack.solvers.analytic)
MAX_SCALE = 1e50  # largest magnitude accepted
MAX_DISTANCE_RATIO = 1e5  # largest ||c|| / r accepted
MAX_PRIOR_CONDITION = 1e8  # largest condition number l1 / l2 of prior_info accepted
MIN_INFORMATION_RATIO = 1e-30  # of the two largest of l1, 1/sigma_d2, 1/(sigma_theta2 r^2)


@kernel
def informative(l1: float, a: float, b_r2: float) -> bool:
    """Return whether the two largest information scales are within the ratio."""
    least = MIN_INFORMATION_RATIO * max(l1, a, b_r2)
    # Counted with ints: NumPy booleans (plain-Python runs) add as a logical or.
    return int(l1 >= least) + int(a >= least) + int(b_r2 >= least) >= 2


@kernel
def _spd2(p11: float, p12: float, p21: float, p22: float) -> bool:
    """Return whether ``[[p11, p12], [p21, p22]]`` is finite, within ``MAX_SCALE``,
    symmetric and positive definite (the rule of ``validation.spd2_entries``)."""
    if not (
        math.isfinite(p11) and math.isfinite(p12) and math.isfinite(p21) and math.isfinite(p22)
    ):
        return False
    scale = max(abs(p11), abs(p22), abs(p12))
    if scale > MAX_SCALE or abs(p21) > MAX_SCALE:
        return False
    if abs(p12 - p21) > SYMMETRY_TOL * max(scale, 1e-300):
        return False
    return p11 > 0.0 and p11 * p22 - p12 * p21 > 0.0


@kernel
def accepted_point(p11, p12, p21, p22, c1, c2, nc, r, rho, sigma_d2, sigma_theta2) -> bool:
    """Return whether one problem (the prior's four entries, ``c``, ``nc = ||c||`` as the
    caller's named checks compute it, ``r``, ``rho``, the two noise variances; floats) is
    inside the accepted range of :mod:`activetrack.solvers.analytic`."""
    if not _spd2(p11, p12, p21, p22):
        return False
    if not (math.isfinite(c1) and math.isfinite(c2)):
        return False
    # Finite and >= 0 (r, rho) or > 0 (the variances); NaN fails every comparison.
    if not (0.0 <= r < math.inf and 0.0 <= rho < math.inf):
        return False
    if not (0.0 < sigma_d2 < math.inf and 0.0 < sigma_theta2 < math.inf):
        return False
    l1, l2 = eigenvalues(p11, 0.5 * (p12 + p21), p22)
    lo, hi = MIN_SCALE, MAX_SCALE
    return (
        lo <= l2
        and l1 <= hi
        and l1 <= MAX_PRIOR_CONDITION * l2
        and lo <= sigma_d2 <= hi
        and lo <= sigma_theta2 <= hi
        and (lo <= rho <= hi or rho == 0.0)
        and (lo <= nc <= hi or nc == 0.0)
        and (
            r == 0.0
            or lo <= r <= hi
            and nc <= MAX_DISTANCE_RATIO * r
            and (rho >= RHO_FLOOR * r or rho == 0.0)
            and informative(l1, 1.0 / sigma_d2, 1.0 / (sigma_theta2 * r * r))
        )
    )


@kernel
def accepted_rows(P, c, nc, r, rho, sigma_d2, sigma_theta2, out) -> bool:
    """Write :func:`accepted_point` of each row into ``out`` (B,) (``P`` (B, 2, 2), ``c``
    (B, 2), the rest (B,)); return whether every row is accepted."""
    every = True
    for i in range(P.shape[0]):
        out[i] = accepted_point(
            P[i, 0, 0], P[i, 0, 1], P[i, 1, 0], P[i, 1, 1], c[i, 0], c[i, 1], nc[i], r[i],
            rho[i], sigma_d2[i], sigma_theta2[i],
        )  # fmt: skip
        every = every and out[i]
    return every
