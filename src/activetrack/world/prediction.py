"""The filter's full prediction that a planning problem may carry (eq. 2-3).

:class:`Prediction` holds ``x_hat(k+1|k)``, ``P(k+1|k)`` and the motion model ``Phi, Q``
of eq. (2), validated once; planners that look several steps ahead read it from
:attr:`activetrack.world.problem.PlanningProblem.prediction` (one per target in a
multi-target problem). With an IMM filter (the scenario field ``estimator``) a prediction
also carries the predicted mixture mode by mode (:class:`ModePredictions`), whose moments
are its ``mean`` and ``cov``: a planner may plan from one mode's prediction alone
(:mod:`activetrack.world.planning_prediction`). The helpers below index, stack and read
the position blocks of predictions for :class:`~activetrack.world.problem.PlanningProblem`.
:class:`Prediction` is also importable from :mod:`activetrack.world.problem`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from activetrack.estimation import imm
from activetrack.validation import FloatArray, as_finite, psd, spd

__all__ = ["ModePredictions", "Prediction"]

#: How far (relative to the components' scale) a prediction's mean and covariance may be
#: from the moments of the mode predictions it carries.
MOMENTS_RTOL = 1e-8


@dataclass(frozen=True, eq=False)
class ModePredictions:
    """An IMM filter's predicted mixture mode by mode: ``sum_j c_j N(x_j(k+1|k),
    P_j(k+1|k))`` (:mod:`activetrack.estimation.imm`: mixing, then eq. 3 with each mode's
    model).

    Arrays are float64, validated on creation and stored read-only; all three may carry
    the same leading batch axes ``...`` (or axes that broadcast to them).

    Attributes:
        weights: the predicted mode probabilities ``c_j`` (..., r), >= 0, summing to 1.
        means: the mode-matched predictions ``x_j(k+1|k)`` (..., r, n), position first.
        covs: their covariances ``P_j(k+1|k)`` (..., r, n, n), symmetric positive definite.
    """

    weights: FloatArray
    means: FloatArray
    covs: FloatArray

    def __post_init__(self) -> None:
        w = as_finite("prediction.modes.weights", self.weights)
        if w.ndim < 1 or w.shape[-1] < 1:
            raise ValueError(
                f"prediction.modes.weights must have shape (..., r) with r >= 1, got {w.shape}"
            )
        r = w.shape[-1]
        if np.any(w < 0.0) or np.any(np.abs(w.sum(axis=-1) - 1.0) > 1e-9):
            raise ValueError(
                "prediction.modes.weights must be probabilities >= 0 summing to 1 (one per "
                f"mode), got {self.weights!r}"
            )
        means = as_finite("prediction.modes.means", self.means)
        if means.ndim < 2 or means.shape[-2] != r or means.shape[-1] < 2:
            raise ValueError(
                f"prediction.modes.means must have shape (..., {r}, n) with n >= 2, "
                f"got {means.shape}"
            )
        n = means.shape[-1]
        covs = spd("prediction.modes.covs", self.covs)
        if covs.ndim < 3 or covs.shape[-3:] != (r, n, n):
            raise ValueError(
                f"prediction.modes.covs must have shape (..., {r}, {n}, {n}), got {covs.shape}"
            )
        batch = broadcast_batches(
            {
                "prediction.modes.weights": w.shape[:-1],
                "prediction.modes.means": means.shape[:-2],
                "prediction.modes.covs": covs.shape[:-3],
            }
        )
        for name, value, tail in (("weights", w, 1), ("means", means, 2), ("covs", covs, 3)):
            object.__setattr__(self, name, _read_only(value, batch, tail))

    @property
    def n_modes(self) -> int:
        """Return the number of modes r."""
        return int(self.weights.shape[-1])

    @property
    def dim(self) -> int:
        """Return the state dimension n."""
        return int(self.means.shape[-1])

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Return the batch axes, ``()`` for a single prediction."""
        return self.weights.shape[:-1]

    def moments(self) -> tuple[FloatArray, FloatArray]:
        """Return the mixture's mean (..., n) and covariance (..., n, n)."""
        return imm.combine(self.weights, self.means, self.covs)

    def _trusted(self, weights: FloatArray, means: FloatArray, covs: FloatArray) -> ModePredictions:
        """Return mode predictions at already validated arrays (made read-only copies)."""
        out = object.__new__(ModePredictions)
        for name, value in (("weights", weights), ("means", means), ("covs", covs)):
            value = np.array(value)
            value.setflags(write=False)
            object.__setattr__(out, name, value)
        return out

    def _broadcast(self, batch: tuple[int, ...]) -> ModePredictions:
        """Return these mode predictions broadcast to the batch axes ``batch``."""
        if self.batch_shape == batch:
            return self
        r, n = self.n_modes, self.dim
        return self._trusted(
            np.broadcast_to(self.weights, batch + (r,)),
            np.broadcast_to(self.means, batch + (r, n)),
            np.broadcast_to(self.covs, batch + (r, n, n)),
        )


def _read_only(value: FloatArray, batch: tuple[int, ...], tail: int) -> FloatArray:
    """Return a read-only copy of ``value`` broadcast to the batch axes ``batch`` before its
    ``tail`` trailing axes."""
    shape = batch + value.shape[value.ndim - tail :]
    value = np.array(np.broadcast_to(value, shape) if value.shape != shape else value)
    value.setflags(write=False)
    return value


@dataclass(frozen=True, eq=False)
class Prediction:
    """The filter's prediction ``x_hat(k+1|k), P(k+1|k)`` and its motion model (eq. 2-3).

    Arrays are float64, validated on creation and stored read-only; ``mean`` and ``cov``
    may carry the same leading batch axes ``...`` (or axes that broadcast to them).

    Attributes:
        mean: the predicted state ``x_hat(k+1|k)``, (..., n), position first (n >= 2).
        cov: its covariance ``P(k+1|k)``, (..., n, n), symmetric positive definite.
        Phi: the transition matrix of eq. (2), (n, n), shared by the batch.
        Q: the process noise covariance of eq. (3), (n, n), symmetric positive
            semidefinite, shared by the batch.
        modes: with an IMM filter, its predicted mixture mode by mode
            (:class:`ModePredictions`, broadcast to the batch, whose moments ``mean`` and
            ``cov`` must be within :data:`MOMENTS_RTOL`), or None: a single model's.
    """

    mean: FloatArray
    cov: FloatArray
    Phi: FloatArray
    Q: FloatArray
    modes: ModePredictions | None = None

    def __post_init__(self) -> None:
        self._store_state(self.mean, self.cov, self.modes)
        n = self.dim
        Phi = as_finite("prediction.Phi", self.Phi)
        if Phi.shape != (n, n):
            raise ValueError(f"prediction.Phi must have shape ({n}, {n}), got {Phi.shape}")
        Q = psd("prediction.Q", self.Q)
        if Q.shape != (n, n):
            raise ValueError(f"prediction.Q must have shape ({n}, {n}), got {Q.shape}")
        for name, value in (("Phi", Phi), ("Q", Q)):
            value = np.array(value)  # a copy the caller cannot change
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    def _store_state(
        self, mean: ArrayLike, cov: ArrayLike, modes: ModePredictions | None = None
    ) -> None:
        """Validate ``mean``, ``cov`` and ``modes`` and store them broadcast to their batch,
        read-only."""
        mean = as_finite("prediction.mean", mean)
        if mean.ndim < 1 or mean.shape[-1] < 2:
            raise ValueError(
                f"prediction.mean must have shape (..., n) with n >= 2, got {mean.shape}"
            )
        n = mean.shape[-1]
        cov = spd("prediction.cov", cov)
        if cov.shape[-1] != n:
            raise ValueError(f"prediction.cov must have shape (..., {n}, {n}), got {cov.shape}")
        batch = broadcast_batches(
            {"prediction.mean": mean.shape[:-1], "prediction.cov": cov.shape[:-2]}
        )
        for name, value, trailing in (("mean", mean, (n,)), ("cov", cov, (n, n))):
            shape = batch + trailing
            # A copy the caller cannot change.
            value = np.array(np.broadcast_to(value, shape) if value.shape != shape else value)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        if modes is not None:
            modes = self._checked_modes(modes)
        object.__setattr__(self, "modes", modes)

    def _checked_modes(self, modes: object) -> ModePredictions:
        """Return ``modes`` broadcast to this prediction's batch, or raise naming the field
        (not mode predictions, another state or batch, moments that are not this mean's
        and covariance)."""
        if not isinstance(modes, ModePredictions):
            raise ValueError(
                "prediction.modes must be an activetrack.world.prediction.ModePredictions or "
                f"None, got {type(modes).__name__}"
            )
        if modes.dim != self.dim:
            raise ValueError(
                f"prediction.modes.means must have shape (..., r, {self.dim}) (the "
                f"prediction's state), got {modes.means.shape}"
            )
        batch = self.batch_shape
        common = broadcast_batches({"prediction": batch, "prediction.modes": modes.batch_shape})
        if common != batch:
            raise ValueError(
                f"the batch axes of prediction.modes {modes.batch_shape} must broadcast to "
                f"the prediction's {batch}"
            )
        modes = modes._broadcast(batch)
        x, P = modes.moments()
        for name, mine, theirs, parts in (
            ("mean", self.mean, x, modes.means),
            ("cov", self.cov, P, modes.covs),
        ):
            scale = max(float(np.max(np.abs(parts))), float(np.max(np.abs(theirs))), 1e-300)
            if np.max(np.abs(mine - theirs)) > MOMENTS_RTOL * scale:
                raise ValueError(
                    f"prediction.{name} must be the moments of prediction.modes (the "
                    f"mixture's {name}, to a relative {MOMENTS_RTOL:g})"
                )
        return modes

    def with_state(
        self, mean: ArrayLike, cov: ArrayLike, modes: ModePredictions | None = None
    ) -> Prediction:
        """Return the prediction ``mean``, ``cov`` (validated; with the mode predictions
        ``modes`` of an IMM, or None) of the same motion model.

        ``Phi`` and ``Q`` were validated once, with this prediction, and are shared, not
        checked again: the cheap way to make the prediction of every step of one model.
        """
        out = object.__new__(Prediction)
        out._store_state(mean, cov)
        if out.dim != self.dim:
            raise ValueError(
                f"prediction.mean must have shape (..., {self.dim}) (the model's state), "
                f"got {out.mean.shape}"
            )
        object.__setattr__(out, "Phi", self.Phi)
        object.__setattr__(out, "Q", self.Q)
        if modes is not None:
            object.__setattr__(out, "modes", out._checked_modes(modes))
        return out

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Return the batch axes, ``()`` for a single prediction."""
        return self.mean.shape[:-1]

    @property
    def dim(self) -> int:
        """Return the state dimension n."""
        return int(self.mean.shape[-1])

    def _trusted(
        self, mean: FloatArray, cov: FloatArray, modes: ModePredictions | None = None
    ) -> Prediction:
        """Return the prediction of this model at already validated read-only arrays."""
        out = object.__new__(Prediction)
        for name, value in (("mean", mean), ("cov", cov), ("Phi", self.Phi), ("Q", self.Q),
                            ("modes", modes)):  # fmt: skip
            object.__setattr__(out, name, value)
        return out


def indexed(pred: Prediction, index: Any) -> Prediction:
    """Return the prediction(s) at ``index`` of the batch axes (read-only copies)."""
    mean, cov = np.array(pred.mean[index]), np.array(pred.cov[index])
    mean.setflags(write=False)
    cov.setflags(write=False)
    m = pred.modes
    modes = None if m is None else m._trusted(m.weights[index], m.means[index], m.covs[index])
    return pred._trusted(mean, cov, modes)


def stacked(preds: list[Prediction]) -> Prediction:
    """Return single predictions of one motion model stacked on a new batch axis."""
    first = preds[0]
    if any(
        q.Phi.shape != first.Phi.shape
        or not (np.array_equal(q.Phi, first.Phi) and np.array_equal(q.Q, first.Q))
        for q in preds
    ):
        raise ValueError("problems must all have the same prediction.Phi and prediction.Q")
    modes = None
    if any(q.modes is not None for q in preds):
        if any(q.modes is None or q.modes.n_modes != first.modes.n_modes for q in preds):
            raise ValueError("problems must all carry prediction.modes of as many modes, or none")
        modes = ModePredictions(
            *(np.stack([getattr(q.modes, f) for q in preds]) for f in ("weights", "means", "covs"))
        )
    return first.with_state(
        np.stack([q.mean for q in preds]), np.stack([q.cov for q in preds]), modes
    )


def target_predictions(value: Any) -> tuple[Prediction, ...]:
    """Return a multi-target problem's predictions as a tuple, or raise naming the field."""
    if not isinstance(value, (tuple, list)) or not all(isinstance(q, Prediction) for q in value):
        raise ValueError(
            "prediction of a multi_target problem must be a tuple of "
            f"activetrack.world.problem.Prediction (one per target) or None, got {value!r}"
        )
    return tuple(value)


def target_blocks(preds: tuple[Prediction, ...] | Prediction, block: Any, tail: int) -> FloatArray:
    """Return ``block`` of one prediction, or those of K stacked on a targets axis before
    their ``tail`` trailing axes (broadcast to the predictions' common batch)."""
    if isinstance(preds, Prediction):
        return block(preds)
    batch = broadcast_batches({f"prediction[{k}]": q.batch_shape for k, q in enumerate(preds)})
    parts = [block(q) for q in preds]
    return np.stack([np.broadcast_to(v, batch + v.shape[-tail:]) for v in parts], -tail - 1)


def broadcast_batches(batch_of: dict[str, tuple[int, ...]]) -> tuple[int, ...]:
    """Return the broadcast of the fields' batch shapes, or raise naming them all."""
    shapes = list(batch_of.values())
    if all(sh == shapes[0] for sh in shapes):  # the common case, without numpy's helper
        return shapes[0]
    try:
        return np.broadcast_shapes(*shapes)
    except ValueError:
        listed = ", ".join(f"{k} {v}" for k, v in batch_of.items())
        raise ValueError(f"the batch axes of the fields do not broadcast: {listed}") from None


def attach(
    self: Any,
    pred: Prediction,
    batch: tuple[int, ...],
    check_cov: bool,
    check_target: bool,
    k: int | None = None,
) -> Prediction:
    """Return ``pred`` broadcast to ``batch``, checking (where given rather than derived)
    that its position blocks are the planning problem ``self``'s ``prior_cov`` and
    ``target`` (target ``k``'s)."""
    prior_cov = self.prior_cov if k is None else self.prior_cov[..., k, :, :]
    target = self.target if k is None else self.target[..., k, :]
    if pred.batch_shape != batch:
        n = pred.dim
        mean = np.array(np.broadcast_to(pred.mean, batch + (n,)))
        cov = np.array(np.broadcast_to(pred.cov, batch + (n, n)))
        mean.setflags(write=False)
        cov.setflags(write=False)
        modes = None if pred.modes is None else pred.modes._broadcast(batch)
        pred = pred._trusted(mean, cov, modes)
    if check_cov and not np.array_equal(pred.cov[..., :2, :2], prior_cov):
        raise ValueError(
            "prior_cov must equal prediction.cov[..., :2, :2] (the predicted position "
            "covariance); pass prior_cov=None, or use PlanningProblem.from_prediction"
        )
    if check_target and not np.array_equal(pred.mean[..., :2], target):
        raise ValueError(
            "target must equal prediction.mean[..., :2] (the predicted position); pass "
            "target=None, or use PlanningProblem.from_prediction"
        )
    return pred
