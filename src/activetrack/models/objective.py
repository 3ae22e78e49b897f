"""The planning objective: trace of the posterior position covariance, eq. (12), (17)-(19).

By Lemma 1 the posterior position covariance after all sensors measure is
``(P11^{-1} + sum_i H_i^T R_i^{-1} H_i)^{-1}`` (eq. 12), where each sensor at relative
position ``p_i = p_S_i - p_T_hat`` contributes the information
``p p^T / (sigma_d^2 p^T p) + J p p^T J^T / (sigma_theta^2 (p^T p)^2)`` (eq. 17).
Lemma 2 rotates the prior information into its eigenbasis (eq. 18).

Every function is vectorized over a leading batch axis of relative positions
(shape (..., M, 2)): exhaustive search evaluates millions of candidate configurations.

:class:`Objective` is the objective as one piece, the public base every planner calls
(through :attr:`activetrack.world.problem.PlanningProblem.objective`) to score a candidate
configuration, and the world calls for its score and reward: a function of each target's
total information ``Y`` (eq. 12, 17), combined over the targets. :class:`TraceObjective`
(:data:`TRACE`, the paper's), :class:`WorstTraceObjective` and :class:`LogDetObjective` are
its built-in subclasses. A new objective subclasses :class:`Objective` in any module,
defines :meth:`Objective.of_entries` and a ``name``, and is passed as ``objective=`` to
:func:`activetrack.make_scenario` (or to a :class:`~activetrack.PlanningProblem`).
Planners that rely on the form of ``tr(Y^{-1})`` (GSR's exact single-sensor step of
Section IV-A) apply only to :class:`TraceObjective` itself (:func:`is_trace`).
"""

from __future__ import annotations

import abc

import numpy as np
from numpy.typing import ArrayLike

from activetrack._jit import kernel
from activetrack.linalg2 import inv2, rotation, trace_inv2
from activetrack.validation import (
    ComparedByValue,
    FloatArray,
    as_finite,
    check_trailing_shape,
    positive,
    spd,
)


@kernel
def information_entries(x, y, sigma_d2, sigma_theta2):
    """Return ``(a, b, c)``: the entries ``[[a, b], [b, c]]`` of the information of a sensor
    at relative position ``(x, y)`` (eq. 17). A kernel on floats, and (its ``py_func``,
    the same source) elementwise on arrays, real or complex."""
    xx, xy, yy = x * x, x * y, y * y
    n2 = xx + yy
    wd = 1.0 / (sigma_d2 * n2)
    wt = 1.0 / (sigma_theta2 * n2 * n2)
    return wd * xx + wt * yy, (wd - wt) * xy, wd * yy + wt * xx


@kernel
def trace_of_inverse(a, b, c):
    """Return ``tr([[a, b], [b, c]]^{-1}) = (a + c) / (ac - b^2)`` (a kernel on floats; its
    ``py_func`` elementwise on arrays)."""
    return (a + c) / (a * c - b * b)


def sensor_information(
    rel: FloatArray, sigma_d2: FloatArray, sigma_theta2: FloatArray
) -> FloatArray:
    """Return each sensor's position information ``H_i^T R_i^{-1} H_i`` (eq. 17), (..., M, 2, 2).

    Unchecked kernel: ``rel`` must be non-zero and finite, variances positive.
    """
    a, b, c = information_entries.py_func(rel[..., 0], rel[..., 1], sigma_d2, sigma_theta2)
    # Filled in place: three np.stack calls cost ~10x more on GSR's single (2,) sensors.
    out = np.empty(np.shape(a) + (2, 2), dtype=np.result_type(a, b, c))  # complex steps too
    out[..., 0, 0] = a
    out[..., 0, 1] = b
    out[..., 1, 0] = b
    out[..., 1, 1] = c
    return out


def total_information(
    prior_info: FloatArray, rel: FloatArray, sigma_d2: FloatArray, sigma_theta2: FloatArray
) -> FloatArray:
    """Return the posterior position information ``P11^{-1} + sum_i info_i`` (..., 2, 2)."""
    return prior_info + sensor_information(rel, sigma_d2, sigma_theta2).sum(axis=-3)


#: Central-difference step of :meth:`Objective.tangent`'s default, relative to the least
#: eigenvalue of ``Y``: ``eps^(1/3)`` balances truncation (``h^2``) and rounding
#: (``eps / h``) errors, both then ``~eps^(2/3)`` (``~4e-11``) relative.
TANGENT_STEP = float(np.finfo(np.float64).eps ** (1.0 / 3.0))


class Objective(ComparedByValue, abc.ABC):
    """The score of a configuration: a function ``phi_k(Y_k)`` of each target's total
    position information ``Y_k = P11_k^{-1} + sum_i info_ik`` (2x2 symmetric positive
    definite, eq. 12, 17), combined over the K targets (:meth:`combine`). Planners minimize
    it; the world's score is it at the posterior, and its reward minus that.

    A subclass implements :meth:`of_entries` (one target's value from the entries
    ``a = Y11``, ``b = Y12``, ``c = Y22``, elementwise over arrays of any broadcastable
    shapes, as numpy's operators are) and sets the class attribute ``name``. Everything
    else has a default derived from it, which a subclass may override with a closed form:

    - :meth:`combine`: the sum over targets (a maximum, ``np.max``, is the other form GBES
      bounds);
    - :meth:`of_covariance`: :meth:`of_entries` of the information ``P11^{-1}``;
    - :meth:`tangent`: the value and central differences of :meth:`of_entries` in
      ``(a, b, c)`` with the step ``TANGENT_STEP`` times the least eigenvalue of ``Y``
      (which keeps the stencil positive definite; relative error ``~1e-10``);
    - :meth:`of_targets`, :meth:`of_covariances`, :meth:`of_information`,
      :meth:`gradient`: from the above.

    Two class attributes declare properties planners may rely on (declare them only when
    true): ``convex`` (each ``phi_k`` is convex in ``Y_k`` on positive definite matrices,
    so its tangent plane is a lower bound everywhere: GBES's branch and bound refuses an
    objective without it) and ``nonnegative`` (values are never negative: GSR's relative
    stopping tolerance is then taken on the value itself, otherwise on ``max(|f|, 1)``).
    """

    #: Whether each target's value is convex in its information ``Y`` (see the class doc).
    convex: bool = False
    #: Whether every value is >= 0 (see the class doc).
    nonnegative: bool = False

    @property
    def name(self) -> str:
        """Return the objective's name (scenario records, messages): a subclass sets the
        class attribute ``name``; without one, its class name."""
        return type(self).__name__

    @abc.abstractmethod
    def of_entries(self, a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
        """Return one target's value at ``Y = [[a, b], [b, c]]`` (elementwise, broadcast)."""

    def combine(self, values: FloatArray, axis: int = -1) -> FloatArray:
        """Return the per-target values (the ``axis`` over targets) combined: their sum."""
        return np.sum(values, axis=axis)

    def of_targets(self, a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
        """Return the objective of K targets' information entries (..., K), combined: (...)."""
        return self.combine(self.of_entries(a, b, c))

    def of_covariances(self, P: FloatArray) -> FloatArray:
        """Return the objective of K targets' position covariances (..., K, n, n): (...)."""
        return self.combine(self.of_covariance(P))

    def of_information(self, Y: FloatArray) -> FloatArray:
        """Return one target's value at total information matrices ``Y`` (..., 2, 2).

        Reads ``Y[..., 0, 1]`` as the off-diagonal entry (``Y`` is symmetric).
        """
        return self.of_entries(Y[..., 0, 0], Y[..., 0, 1], Y[..., 1, 1])

    def of_covariance(self, P: FloatArray) -> FloatArray:
        """Return one target's value at position covariances: :meth:`of_entries` of the
        information ``P11^{-1}``.

        ``P`` (..., n, n) is ``P11`` itself (n = 2) or a whole state covariance whose
        top-left 2x2 block is the position's; ``P[..., 0, 1]`` is read as its off-diagonal.
        """
        p, q, s = P[..., 0, 0], P[..., 0, 1], P[..., 1, 1]
        det = p * s - q * q
        return self.of_entries(s / det, -q / det, p / det)

    def tangent(
        self, a: FloatArray, b: FloatArray, c: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Return ``(phi, ga, gb, gc)`` at ``Y = [[a, b], [b, c]]``: value and entry gradient.

        ``phi(Y + dY) ~ phi + ga da + gb db + gc dc`` for ``dY = [[da, db], [db, dc]]``
        (``gb`` is the derivative in ``b``, which stands in both off-diagonal places). This
        default: central differences of :meth:`of_entries` (see the class doc), all seven
        points in one call.
        """
        a, b, c = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (a, b, c)))
        lam_max = 0.5 * (a + c) + np.hypot(0.5 * (a - c), b)
        # The least eigenvalue from the determinant: a perturbation of the entries by h moves
        # the eigenvalues by at most h, so Y stays positive definite at every stencil point.
        h = TANGENT_STEP * ((a * c - b * b) / lam_max)
        z = np.zeros_like(h)
        v = self.of_entries(
            a + np.stack([z, h, -h, z, z, z, z]),
            b + np.stack([z, z, z, h, -h, z, z]),
            c + np.stack([z, z, z, z, z, h, -h]),
        )
        two_h = 2.0 * h
        return v[0], (v[1] - v[2]) / two_h, (v[3] - v[4]) / two_h, (v[5] - v[6]) / two_h

    def gradient(self, Y: FloatArray) -> FloatArray:
        """Return ``d phi / dY`` (symmetric, (..., 2, 2)) for symmetric ``Y`` (..., 2, 2):
        ``[[ga, gb / 2], [gb / 2, gc]]`` of :meth:`tangent`."""
        _, ga, gb, gc = self.tangent(Y[..., 0, 0], Y[..., 0, 1], Y[..., 1, 1])
        half = 0.5 * gb
        return np.stack([np.stack([ga, half], -1), np.stack([half, gc], -1)], -2)

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


class TraceObjective(Objective):
    """The objective of eq. (17), ``phi(Y) = tr(Y^{-1})``, of the total information ``Y``.

    ``Y = P11^{-1} + sum_i info_i`` is 2x2 symmetric positive definite. Methods take
    either the matrices (..., 2, 2) or their independent entries ``a = Y11``, ``b = Y12``,
    ``c = Y22`` (arrays of any broadcastable shapes): exhaustive search adds the entries of
    per-sensor candidates by broadcasting and never forms matrices. ``phi`` is convex on
    positive definite matrices, so its tangent plane (:meth:`tangent`) is a lower bound
    everywhere (GBES's branch and bound relies on that).
    """

    name = "trace"
    convex = True
    nonnegative = True

    def of_entries(self, a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
        """Return ``tr([[a, b], [b, c]]^{-1}) = (a + c) / (ac - b^2)``."""
        return trace_of_inverse.py_func(a, b, c)

    def of_covariance(self, P: FloatArray) -> FloatArray:
        """Return the objective of position covariances: the trace of ``P11``.

        ``P`` (..., n, n) is ``P11`` itself (n = 2) or a whole state covariance whose
        top-left 2x2 block is the position's (read in place, no slice).
        """
        return P[..., 0, 0] + P[..., 1, 1]

    def tangent(
        self, a: FloatArray, b: FloatArray, c: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Return ``(phi, ga, gb, gc)`` at ``Y = [[a, b], [b, c]]``: value and entry gradient.

        ``phi(Y + dY) ~ phi + ga da + gb db + gc dc`` for ``dY = [[da, db], [db, dc]]``:
        the gradient of ``tr(Y^{-1})`` with respect to ``Y`` is ``G = -Y^{-2}``, and
        ``<G, dY> = G11 da + 2 G12 db + G22 dc``, so ``gb = 2 G12``.
        """
        det = a * c - b * b
        # Y^{-1} = [[c, -b], [-b, a]] / det; the gradient is minus its square.
        p, q, s = c / det, -b / det, a / det
        return (a + c) / det, -(p * p + q * q), -2.0 * q * (p + s), -(s * s + q * q)

    def __repr__(self) -> str:
        return "TRACE"


#: The trace objective of eq. (17), the default of every planning problem; with K targets
#: the sum of their traces.
TRACE = TraceObjective()


class WorstTraceObjective(TraceObjective):
    """The largest of the targets' posterior position traces (``max_k tr(Y_k^{-1})``).

    Per target the same function as :class:`TraceObjective`; only :meth:`combine` differs.
    For K = 1 it equals :data:`TRACE`.
    """

    name = "worst_trace"

    def combine(self, values: FloatArray, axis: int = -1) -> FloatArray:
        """Return the largest per-target value."""
        return np.max(values, axis=axis)

    def __repr__(self) -> str:
        return "WORST_TRACE"


class LogDetObjective(TraceObjective):
    """The sum over targets of ``log det P_k = -log det Y_k`` (D-optimality).

    Invariant to the length unit up to a constant, and the log-volume of each target's
    uncertainty ellipse; convex in ``Y_k``.
    """

    name = "logdet"
    nonnegative = False

    def of_entries(self, a: FloatArray, b: FloatArray, c: FloatArray) -> FloatArray:
        """Return ``-log det([[a, b], [b, c]]) = -log(ac - b^2)``."""
        return -np.log(a * c - b * b)

    def of_covariance(self, P: FloatArray) -> FloatArray:
        """Return ``log det P11`` of position covariances (or whole state covariances)."""
        return np.log(P[..., 0, 0] * P[..., 1, 1] - P[..., 0, 1] * P[..., 1, 0])

    def tangent(
        self, a: FloatArray, b: FloatArray, c: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Return ``(phi, ga, gb, gc)``; ``d(-log det Y) = -tr(Y^{-1} dY)``."""
        det = a * c - b * b
        return -np.log(det), -c / det, 2.0 * b / det, -a / det

    def __repr__(self) -> str:
        return "LOGDET"


#: The largest target's trace.
WORST_TRACE = WorstTraceObjective()
#: The sum of the targets' log-determinants.
LOGDET = LogDetObjective()
#: The objectives by name (:attr:`activetrack.Scenario.objective`).
OBJECTIVES: dict[str, Objective] = {o.name: o for o in (TRACE, WORST_TRACE, LOGDET)}


def combined(objective: Objective, values: FloatArray) -> FloatArray:
    """Return ``objective.combine(values)`` over the last axis (the targets), the world's
    score; a ``ValueError`` naming the objective if it is NaN or inf (a new objective that
    passed the scenario's probe may still fail on an episode's covariances: said, not a
    silent NaN reward)."""
    out = objective.combine(values)
    if not np.all(np.isfinite(values)) or not np.all(np.isfinite(out)):
        raise ValueError(
            f"objective {objective.name!r} ({type(objective).__name__}) returned NaN or inf"
            " on this step's posterior covariances (positive definite)"
        )
    return out


def is_trace(objective: Objective) -> bool:
    """Return whether ``objective`` is the paper's trace itself (a :class:`TraceObjective`,
    not a subclass, which may change any method): Section IV-A's exact solve applies."""
    return type(objective) is TraceObjective


def as_objective(value: object, field: str = "objective") -> Objective:
    """Return ``value`` as an :class:`Objective`: a name of :data:`OBJECTIVES` or an instance.

    Raises:
        ValueError: naming ``field``, for anything else (a class rather than an instance
            included).
    """
    if isinstance(value, Objective):
        return value
    if isinstance(value, str) and value in OBJECTIVES:
        return OBJECTIVES[value]
    raise ValueError(
        f"{field} must be one of {list(OBJECTIVES)} or an activetrack.Objective instance, "
        f"got {value!r}"
    )


def _check(prior_cov: ArrayLike, rel: ArrayLike, sigma_d2: ArrayLike, sigma_theta2: ArrayLike):
    prior_cov = check_trailing_shape("prior_cov", spd("prior_cov", prior_cov), (2, 2))
    rel = check_trailing_shape("rel_positions", as_finite("rel_positions", rel), (2,))
    if rel.ndim < 2:
        raise ValueError(f"rel_positions must have shape (..., M, 2), got {rel.shape}")
    if np.any(np.hypot(rel[..., 0], rel[..., 1]) == 0.0):
        raise ValueError(
            "rel_positions must be non-zero: a sensor exactly on the target has no bearing"
        )
    m = rel.shape[-2]
    sd2 = positive("sigma_d2", sigma_d2)
    st2 = positive("sigma_theta2", sigma_theta2)
    for name, s in (("sigma_d2", sd2), ("sigma_theta2", st2)):
        if s.ndim > 0 and s.shape[-1] != m:
            raise ValueError(
                f"{name} must be a scalar or have {m} entries (one per sensor), got {s.shape}"
            )
    return prior_cov, rel, sd2, st2


def posterior_position_covariance(
    prior_cov: ArrayLike, rel_positions: ArrayLike, sigma_d2: ArrayLike, sigma_theta2: ArrayLike
) -> FloatArray:
    """Return the posterior position covariance of eq. (12)/(17), shape (..., 2, 2).

    Args:
        prior_cov: predicted position covariance ``P(k+1|k)_11``, shape (2, 2) or (..., 2, 2).
        rel_positions: next sensor positions minus the predicted target position, (..., M, 2).
        sigma_d2: range noise variances, scalar or (M,).
        sigma_theta2: bearing noise variances, scalar or (M,).
    """
    prior_cov, rel, sd2, st2 = _check(prior_cov, rel_positions, sigma_d2, sigma_theta2)
    return inv2(total_information(inv2(prior_cov), rel, sd2, st2))


def posterior_trace(
    prior_cov: ArrayLike, rel_positions: ArrayLike, sigma_d2: ArrayLike, sigma_theta2: ArrayLike
) -> FloatArray:
    """Return the objective of eq. (17): the trace of :func:`posterior_position_covariance`."""
    prior_cov, rel, sd2, st2 = _check(prior_cov, rel_positions, sigma_d2, sigma_theta2)
    return trace_inv2(total_information(inv2(prior_cov), rel, sd2, st2))


def lemma2_rotation(prior_info: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Return ``(phi0, lambdas)`` with ``prior_info = C(phi0) diag(l1, l2) C(-phi0)``, l1 >= l2.

    Lemma 2: in the frame ``s = C(-phi0) p`` the prior information is diagonal and the
    objective keeps its form (eq. 18). Batched over leading axes.
    """
    A = np.asarray(prior_info, dtype=np.float64)
    a, b, c = A[..., 0, 0], A[..., 0, 1], A[..., 1, 1]
    phi0 = 0.5 * np.arctan2(2.0 * b, a - c)  # eigenvector angle of the larger eigenvalue
    mean = 0.5 * (a + c)
    rad = np.hypot(0.5 * (a - c), b)
    return phi0, np.stack([mean + rad, mean - rad], axis=-1)


def to_eigenframe(phi0: FloatArray | float, p: FloatArray) -> FloatArray:
    """Return ``s = C(-phi0) p`` for points ``p`` of shape (..., 2)."""
    return np.einsum("...ij,...j->...i", rotation(-np.asarray(phi0)), p)


def from_eigenframe(phi0: FloatArray | float, s: FloatArray) -> FloatArray:
    """Return ``p = C(phi0) s`` for points ``s`` of shape (..., 2)."""
    return np.einsum("...ij,...j->...i", rotation(np.asarray(phi0)), s)
