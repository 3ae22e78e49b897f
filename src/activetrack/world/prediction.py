"""The filter's full prediction that a planning problem may carry (eq. 2-3).

:class:`Prediction` holds ``x_hat(k+1|k)``, ``P(k+1|k)`` and the motion model ``Phi, Q``
of eq. (2), validated once; planners that look several steps ahead read it from
:attr:`activetrack.world.problem.PlanningProblem.prediction` (one per target in a
multi-target problem). The helpers below index, stack and read the position blocks of
predictions for :class:`~activetrack.world.problem.PlanningProblem`. :class:`Prediction`
is also importable from :mod:`activetrack.world.problem`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from activetrack.validation import FloatArray, as_finite, psd, spd

__all__ = ["Prediction"]


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
    """

    mean: FloatArray
    cov: FloatArray
    Phi: FloatArray
    Q: FloatArray

    def __post_init__(self) -> None:
        self._store_state(self.mean, self.cov)
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

    def _store_state(self, mean: ArrayLike, cov: ArrayLike) -> None:
        """Validate ``mean`` and ``cov`` and store them broadcast to their batch, read-only."""
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

    def with_state(self, mean: ArrayLike, cov: ArrayLike) -> Prediction:
        """Return the prediction ``mean``, ``cov`` (validated) of the same motion model.

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
        return out

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Return the batch axes, ``()`` for a single prediction."""
        return self.mean.shape[:-1]

    @property
    def dim(self) -> int:
        """Return the state dimension n."""
        return int(self.mean.shape[-1])

    def _trusted(self, mean: FloatArray, cov: FloatArray) -> Prediction:
        """Return the prediction of this model at already validated read-only arrays."""
        out = object.__new__(Prediction)
        for name, value in (("mean", mean), ("cov", cov), ("Phi", self.Phi), ("Q", self.Q)):
            object.__setattr__(out, name, value)
        return out


def indexed(pred: Prediction, index: Any) -> Prediction:
    """Return the prediction(s) at ``index`` of the batch axes (read-only copies)."""
    mean, cov = np.array(pred.mean[index]), np.array(pred.cov[index])
    mean.setflags(write=False)
    cov.setflags(write=False)
    return pred._trusted(mean, cov)


def stacked(preds: list[Prediction]) -> Prediction:
    """Return single predictions of one motion model stacked on a new batch axis."""
    first = preds[0]
    if any(
        q.Phi.shape != first.Phi.shape
        or not (np.array_equal(q.Phi, first.Phi) and np.array_equal(q.Q, first.Q))
        for q in preds
    ):
        raise ValueError("problems must all have the same prediction.Phi and prediction.Q")
    return first.with_state(np.stack([q.mean for q in preds]), np.stack([q.cov for q in preds]))


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
        pred = pred._trusted(mean, cov)
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
