"""The planning problem of one time step, eq. (15)-(17), and the planner protocol.

At step k every planner sees the predicted target position ``p_T(k+1|k)`` with its 2x2 covariance,
the sensors' current positions and their parameters, and returns the sensors' next absolute
positions minimizing the objective of eq. (17) (by default the trace of the posterior position
covariance, :data:`activetrack.models.objective.TRACE`) subject to the reach (eq. 15) and the
minimum distance (eq. 16).

A :class:`PlanningProblem` holds one such problem or a batch of independent ones (an optional
leading batch axis on every array, e.g. the copies of a batched environment); planners return next
positions of shape ``batch_shape + (M, 2)``.

A problem may also carry the filter's full :class:`Prediction` (eq. 3: ``x_hat(k+1|k)`` with the
velocity, the whole ``P(k+1|k)`` and the motion model ``Phi, Q`` of eq. 2), which planners that look
several steps ahead need; ``prior_cov`` and ``target`` are then its position blocks
(:meth:`PlanningProblem.from_prediction` derives them).

Beyond the paper a problem may have K targets (``multi_target``: ``prior_cov`` (..., K, 2, 2),
``target`` (..., K, 2); every sensor keeps ``rho`` from every predicted target; the objective
combines the targets' values), sensors of other measurement models (``models``,
:mod:`activetrack.models.sensor_models`) and uncertain position fixes (``pose_cov``):
:meth:`PlanningProblem.score` then sums the effective information ``J_eff`` of
:func:`activetrack.models.sensor_models.team_entries` per target. :attr:`PlanningProblem.is_paper`
says whether the paper's exact single-sensor solve (Section IV-A) applies.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from functools import cached_property
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from activetrack.estimation import generic
from activetrack.kinematics import separation, team
from activetrack.linalg2 import inv2
from activetrack.models import sensor_models
from activetrack.models.objective import TRACE, Objective, is_trace, total_information
from activetrack.models.sensor import check_team
from activetrack.solvers._inputs import MAX_SCALE, MIN_SCALE
from activetrack.validation import FloatArray, as_finite, positive, real_array, spd
from activetrack.world import capabilities as _capabilities
from activetrack.world.prediction import (
    Prediction,
    attach,
    broadcast_batches,
    indexed,
    stacked,
    target_blocks,
    target_predictions,
)

#: The per-sensor parameters and whether 0 is allowed.
_PER_SENSOR = (("r", True), ("rho", True), ("sigma_d2", False), ("sigma_theta2", False))
#: The accepted range of the noise variances and of both eigenvalues of ``prior_cov``: the
#: single-sensor solver's own (:mod:`activetrack.solvers.analytic`, ``MIN_SCALE``, ``MAX_SCALE``),
#: inside which every planner (GSR with or without restarts, GBES, RM, the look-ahead)
#: answers feasible finite positions; beyond it the information overflows float64.
SCALE_RANGE = (MIN_SCALE, MAX_SCALE)


def _check_scale(name: str, value: FloatArray, what: str = "") -> None:
    """Raise ``ValueError`` naming ``name`` unless every entry of ``value`` lies in
    :data:`SCALE_RANGE`."""
    lo, hi = SCALE_RANGE
    out = ~((value >= lo) & (value <= hi))  # NaN (an overflowed eigenvalue) is out
    if np.any(out):
        bad = value[out]
        raise ValueError(
            f"{name}{what} must lie in [{lo:g}, {hi:g}] (the planners' scale range), "
            f"got {float(bad.flat[0])!r}"
        )


def _eigenvalues2(cov: FloatArray) -> FloatArray:
    """Return both eigenvalues (..., 2) of symmetric 2x2 matrices (..., 2, 2), closed form
    in units of the largest entry (no overflow or underflow before scaling back)."""
    s = np.max(np.abs(cov), axis=(-2, -1))
    u = cov / np.where(s > 0, s, 1.0)[..., None, None]
    a, b, c = u[..., 0, 0], 0.5 * (u[..., 0, 1] + u[..., 1, 0]), u[..., 1, 1]
    big = 0.5 * (a + c) + np.hypot(0.5 * (a - c), b)
    # The small one from the determinant (no cancellation): a c - b^2 = big * small.
    small = (a * c - b * b) / np.where(big > 0, big, 1.0)
    return np.stack([small, big], axis=-1) * s[..., None]


#: What a missing optional field of a problem stands for when problems are stacked.
_FILLS: dict[str, Any] = {
    "models": lambda p: np.zeros(p.n_sensors, np.int8),  # range and bearing
    "pose_cov": lambda p: np.zeros((p.n_sensors, 2, 2)),  # known positions
    "p_detect": lambda p: np.full(p.n_sensors, 1.0),  # always
    "max_range": lambda p: np.full(p.n_sensors, np.inf),  # unlimited
    "sensor_states": None,  # (no default)
}


@dataclass(frozen=True, eq=False)
class PlanningProblem:
    """What every planner needs at one step (arrays are float64, validated on creation).

    Every array may carry the same leading batch axes ``...`` (or axes that broadcast to
    them): then the object holds ``batch_shape`` independent problems with the same number
    of sensors M. Arrays are stored broadcast to the batch shape, read-only.

    Attributes:
        prior_cov: predicted target position covariance ``P(k+1|k)_11``, (..., 2, 2),
            both eigenvalues in :data:`SCALE_RANGE` ``[1e-50, 1e50]``.
        target: predicted target position ``p_T(k+1|k)``, (..., 2).
        sensors: current sensor positions ``p_S_i(k)``, (..., M, 2).
        r: per-sensor reach ``vmax_i dt``, (..., M) (a scalar or (M,) broadcasts).
        rho: per-sensor minimum distance to the predicted target, (..., M).
        sigma_d2: range noise variances, (..., M), in :data:`SCALE_RANGE`.
        sigma_theta2: bearing noise variances, (..., M), in :data:`SCALE_RANGE`.
        objective: the function of the total information that planners minimize, an
            :class:`activetrack.Objective` (:data:`activetrack.models.objective.TRACE`,
            eq. 17, by default).
        prediction: the filter's full :class:`Prediction` (``None``: not known), stored
            broadcast to the batch shape. With a prediction, ``prior_cov`` and ``target``
            are its position blocks ``cov[..., :2, :2]`` and ``mean[..., :2]``: ``None``
            derives them (:meth:`from_prediction`), given values must equal them exactly.
            A ``multi_target`` problem carries a tuple of K predictions, one per target
            (their state dimensions may differ), whose blocks are target k's.
        models: per-sensor model codes (..., M) int8 (0 range and bearing, 1 range only,
            2 bearing only; names accepted), or None: all range and bearing.
        pose_cov: per-sensor covariance of the position fix (..., M, 2, 2), PSD, or None:
            positions known exactly.
        multi_target: whether ``prior_cov`` and ``target`` carry a targets axis K (after
            the batch axes). A prediction is only carried for one target.
        p_detect: per-sensor detection probability in [0, 1] (..., M), or None: 1.
        max_range: per-sensor sensing range (..., M), > 0 (inf: unlimited), or None:
            unlimited. With either, a sensor's information counts at its expected value
            (:func:`activetrack.models.sensor_models.detection_factor` at the predicted targets).
        occluders: an :class:`activetrack.models.occluders.Occluders` (one layout shared by the
            batch, or one per entry of the first batch axis: ``Occluders.stack``) or None:
            a sensor counts no information about a predicted target it cannot see.
        sensor_objects: each sensor's :class:`activetrack.SensorModel` (a tuple of M shared
            by the batch) when one is a model of one's own, or None (the built-in models
            of ``models``). The planners then ask the models for the information
            (:meth:`information_entries`), never the paper's arithmetic.
        kinematics: each sensor's :class:`activetrack.Kinematics` (a tuple of M, shared by
            the batch; ``r`` is then each one's radius), or None: the disks of radius ``r``.
        sensor_states: the sensors' states (..., M, S) when a kinematics carries more than the
            position (:func:`activetrack.kinematics.team.checked_states`), or None.
        d_sep: the team rule's minimum separation (the scenario's field, shared by the batch:
            :mod:`activetrack.kinematics.separation`), or None: no rule.
    """

    prior_cov: FloatArray
    target: FloatArray
    sensors: FloatArray
    r: FloatArray
    rho: FloatArray
    sigma_d2: FloatArray
    sigma_theta2: FloatArray
    objective: Objective = TRACE
    prediction: Prediction | tuple[Prediction, ...] | None = None
    models: np.ndarray | None = None
    pose_cov: FloatArray | None = None
    multi_target: bool = False
    p_detect: FloatArray | None = None
    max_range: FloatArray | None = None
    occluders: Any = None
    sensor_objects: tuple | None = None
    kinematics: tuple | None = None
    sensor_states: FloatArray | None = None
    d_sep: Any = None

    def __post_init__(self) -> None:
        if self.sensor_objects is not None:
            check_team("sensor_objects", self.sensor_objects, np.shape(self.sensors)[-2])
        sensors = as_finite("sensors", self.sensors)
        if sensors.ndim < 2 or sensors.shape[-1] != 2 or sensors.shape[-2] < 1:
            raise ValueError(
                f"sensors must have shape (..., M, 2) with M >= 1, got {sensors.shape}"
            )
        m = sensors.shape[-2]
        multi = self.multi_target
        if not isinstance(multi, (bool, np.bool_)):
            raise ValueError(f"multi_target must be True or False, got {multi!r}")
        multi = bool(multi)
        object.__setattr__(self, "multi_target", multi)
        pred = self.prediction
        if multi and pred is not None:
            pred = target_predictions(pred)
            object.__setattr__(self, "prediction", pred)
        elif pred is not None and not isinstance(pred, Prediction):
            raise ValueError(
                f"prediction must be an activetrack.world.problem.Prediction or None, got {pred!r}"
            )
        # A prior taken from a prediction is a block of its validated SPD covariance.
        derived = pred is not None and self.prior_cov is None
        if derived:
            prior_cov = target_blocks(pred, lambda q: q.cov[..., :2, :2], 2)
        else:
            prior_cov = spd("prior_cov", self.prior_cov)
        if prior_cov.shape[-2:] != (2, 2):
            raise ValueError(f"prior_cov must have shape (..., 2, 2), got {prior_cov.shape}")
        _check_scale("prior_cov", _eigenvalues2(prior_cov), " eigenvalues")
        derived_target = pred is not None and self.target is None
        if derived_target:
            target = target_blocks(pred, lambda q: q.mean[..., :2], 1)
        else:
            target = as_finite("target", self.target)
        if target.ndim < 1 or target.shape[-1] != 2:
            raise ValueError(f"target must have shape (..., 2), got {target.shape}")
        kk = 0
        if multi:
            if target.ndim < 2 or prior_cov.ndim < 3 or target.shape[-2] != prior_cov.shape[-3]:
                raise ValueError(
                    "a multi_target problem needs target (..., K, 2) and prior_cov "
                    f"(..., K, 2, 2), got {target.shape} and {prior_cov.shape}"
                )
            kk = target.shape[-2]
            if pred is not None and len(pred) != kk:
                raise ValueError(
                    f"prediction must hold one Prediction per target ({kk}), got {len(pred)}"
                )
        values = {"prior_cov": prior_cov, "target": target, "sensors": sensors}
        tail = 1 if multi else 0
        batch_of = {
            "prior_cov": prior_cov.shape[: prior_cov.ndim - 2 - tail],
            "target": target.shape[: target.ndim - 1 - tail],
            "sensors": sensors.shape[:-2],
        }
        for name, allow_zero in _PER_SENSOR:
            arr = positive(name, getattr(self, name), allow_zero=allow_zero)
            if arr.ndim > 0 and arr.shape[-1] != m:
                raise ValueError(
                    f"{name} must be a scalar or have shape (..., {m}) (one entry per sensor), "
                    f"got {arr.shape}"
                )
            if not allow_zero:  # the noise variances
                _check_scale(name, arr)
            values[name] = arr
            batch_of[name] = arr.shape[:-1]
        if pred is not None:
            for k, q in enumerate(pred if multi else (pred,)):
                batch_of[f"prediction[{k}]" if multi else "prediction"] = q.batch_shape
        batch = broadcast_batches(batch_of)
        if not isinstance(self.objective, Objective):
            raise ValueError(
                f"objective must be an activetrack.Objective instance (such as "
                f"activetrack.TRACE), got {self.objective!r}"
            )
        if self.models is not None:
            codes = sensor_models.SensorTeam(self.models, 1.0, 1.0).models
            if codes.shape[-1] != m:
                raise ValueError(f"models must have shape (..., {m}), got {codes.shape}")
            batch_of["models"] = codes.shape[:-1]
            values["models"] = codes
        if self.pose_cov is not None:
            cov = sensor_models.SensorTeam([0], 1.0, 1.0, self.pose_cov).pose_cov
            if cov.shape[-3] != m:
                raise ValueError(f"pose_cov must have shape (..., {m}, 2, 2), got {cov.shape}")
            batch_of["pose_cov"] = cov.shape[:-3]
            values["pose_cov"] = cov
        for name in ("p_detect", "max_range"):
            value = getattr(self, name)
            if value is None:
                continue
            arr = real_array(name, value, finite=False)
            bad = np.isnan(arr) | (arr > 1.0) | (arr < 0.0) if name == "p_detect" else (
                np.isnan(arr) | (arr <= 0.0))  # fmt: skip
            if np.any(bad):
                allowed = "[0, 1]" if name == "p_detect" else "(0, inf]"
                raise ValueError(f"{name} must lie in {allowed}, got {value!r}")
            if arr.ndim > 0 and arr.shape[-1] != m:
                raise ValueError(
                    f"{name} must be a scalar or have shape (..., {m}) (one entry per sensor), "
                    f"got {arr.shape}"
                )
            batch_of[name] = arr.shape[:-1]
            values[name] = arr
        if self.occluders is not None:
            from activetrack.models.occluders import Occluders  # noqa: PLC0415

            if not isinstance(self.occluders, Occluders):
                raise ValueError(
                    "occluders must be an activetrack.models.occluders.Occluders or None, got "
                    f"{type(self.occluders).__name__}"
                )
        if self.kinematics is not None:
            object.__setattr__(self, "kinematics", team.converted(tuple(self.kinematics), m))
        if self.d_sep is not None:
            object.__setattr__(self, "d_sep", separation.converted(self.d_sep, m))
        if self.sensor_states is not None:
            states = team.checked_states(self.sensor_states, sensors, self.kinematics)
            values["sensor_states"], batch_of["sensor_states"] = states, states.shape[:-2]
            batch = broadcast_batches(batch_of)
        k_axis = (kk,) if multi else ()
        trailing = {
            "prior_cov": (*k_axis, 2, 2),
            "target": (*k_axis, 2),
            "sensors": (m, 2),
            "models": (m,),
            "pose_cov": (m, 2, 2),
            "sensor_states": np.shape(values.get("sensor_states", np.zeros((m, 2))))[-2:],
        }
        for name, value in values.items():
            shape = batch + trailing.get(name, (m,))
            if value.ndim == 0:
                value = np.full(shape, float(value))
            elif name == "models":
                value = np.array(np.broadcast_to(value, shape))
            else:  # a copy the caller cannot change
                value = np.array(np.broadcast_to(value, shape) if value.shape != shape else value)
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        occ = self.occluders
        if occ is not None and occ.batched and (not batch or batch[0] != occ.n_layouts):
            raise ValueError(
                f"occluders holds {occ.n_layouts} layouts (one per copy): the problem's first "
                f"batch axis must have that length, got batch shape {batch}"
            )
        if pred is not None and multi:
            held = tuple(
                attach(self, q, batch, not derived, not derived_target, k)
                for k, q in enumerate(pred)
            )
            object.__setattr__(self, "prediction", held)
        elif pred is not None:
            pred = attach(self, pred, batch, not derived, not derived_target)
            object.__setattr__(self, "prediction", pred)

    @property
    def predictions(self) -> tuple[Prediction, ...] | None:
        """Return every target's :class:`Prediction` (K of them; one for a single-target
        problem), or None when the problem carries none."""
        pred = self.prediction
        if pred is None:
            return None
        return pred if self.multi_target else (pred,)

    @classmethod
    def from_prediction(
        cls,
        prediction: Prediction,
        sensors: ArrayLike,
        r: ArrayLike,
        rho: ArrayLike,
        sigma_d2: ArrayLike,
        sigma_theta2: ArrayLike,
        objective: Objective = TRACE,
        models: ArrayLike | None = None,
        pose_cov: ArrayLike | None = None,
        p_detect: ArrayLike | None = None,
        max_range: ArrayLike | None = None,
        occluders: Any = None,
        sensor_objects: tuple | None = None,
        kinematics: tuple | None = None,
        sensor_states: ArrayLike | None = None,
        d_sep: Any = None,
    ) -> PlanningProblem:
        """Return the problem at ``prediction`` (``prior_cov`` and ``target`` its position
        blocks); the other arguments are the fields of the same names."""
        return cls(
            None, None, sensors, r, rho, sigma_d2, sigma_theta2, objective, prediction,
            models, pose_cov, p_detect=p_detect, max_range=max_range, occluders=occluders,
            sensor_objects=sensor_objects, kinematics=kinematics, sensor_states=sensor_states,
            d_sep=d_sep,
        )  # fmt: skip

    @classmethod
    def _validated(cls, **values: Any) -> PlanningProblem:
        """Return a problem from already validated, converted arrays (no checks, no copies)."""
        out = object.__new__(cls)
        for name, value in values.items():
            object.__setattr__(out, name, value)
        return out

    @classmethod
    def stack(cls, problems: Sequence[PlanningProblem]) -> PlanningProblem:
        """Return the batch (B,) of single problems with the same M and objective.

        Their predictions are stacked too: all problems carry one (of the same motion
        model) or none does. Their occluders: one shared object stays shared; different
        layouts (same polygon sizes) are stacked, one per problem (``Occluders.stack``).
        """
        if not problems:
            raise ValueError("problems must hold at least one problem")
        objective = problems[0].objective
        if any(p.objective != objective for p in problems):
            raise ValueError("problems must all have the same objective")
        multi = problems[0].multi_target
        if any(p.multi_target != multi for p in problems):
            raise ValueError("problems must all be multi_target, or none")
        occ = problems[0].occluders
        if any((p.occluders is None) != (occ is None) for p in problems):
            raise ValueError("problems must all have occluders, or none")
        if any(p.occluders is not None and p.occluders.batched for p in problems):
            raise ValueError("problems must be single problems to stack (unbatched occluders)")
        if any(p.occluders is not occ for p in problems):  # each its own layout
            occ = type(occ).stack([p.occluders for p in problems])
        arrays: dict[str, Any] = {"multi_target": multi, "occluders": occ}
        for f in fields(cls):
            if f.name in ("objective", "prediction", "multi_target", "occluders", "kinematics",
                          "d_sep"):  # fmt: skip
                continue
            if f.name == "sensor_objects":
                if any(p.sensor_objects != problems[0].sensor_objects for p in problems):
                    raise ValueError("problems must all have the same sensor_objects")
                arrays[f.name] = problems[0].sensor_objects
                continue
            vals = [getattr(p, f.name) for p in problems]
            if f.name in _FILLS:  # None in some problems: filled with the default's value
                if all(v is None for v in vals):
                    arrays[f.name] = None
                    continue
                if _FILLS[f.name] is None and any(v is None for v in vals):
                    raise ValueError(f"problems must all carry {f.name}, or none")
                vals = [_FILLS[f.name](p) if v is None else v
                        for v, p in zip(vals, problems, strict=True)]  # fmt: skip
            arrays[f.name] = np.stack(vals)
        all_preds = [p.predictions for p in problems]
        prediction: Any = None
        if any(q is not None for q in all_preds):
            if any(q is None for q in all_preds):
                raise ValueError("problems must all carry a prediction, or none")
            per_target = [stacked([q[k] for q in all_preds]) for k in range(len(all_preds[0]))]
            prediction = tuple(per_target) if multi else per_target[0]
        kin, d_sep = problems[0].kinematics, problems[0].d_sep
        if any(p.kinematics != kin or p.d_sep != d_sep for p in problems):
            raise ValueError("problems must all have the same kinematics and d_sep")
        return cls(**arrays, objective=objective, prediction=prediction, kinematics=kin,
                   d_sep=d_sep)  # fmt: skip

    def __getitem__(self, index: Any) -> PlanningProblem:
        """Return the problem(s) at ``index`` of the batch axes (``problem[i]``: copy ``i``)."""
        if not self.batch_shape:
            raise TypeError("a single planning problem (batch_shape ()) cannot be indexed")
        np.empty(self.batch_shape, dtype=bool)[index]  # IndexError for indices past the batch
        values = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "prediction":
                if isinstance(value, tuple):
                    value = tuple(indexed(q, index) for q in value)
                elif value is not None:
                    value = indexed(value, index)
            elif f.name == "occluders" and value is not None:  # the layouts of the first axis
                value = value[index[0] if isinstance(index, tuple) else index]
            elif f.name not in (
                "objective",
                "multi_target",
                "sensor_objects",
                "kinematics",
                "d_sep",
            ) and (value is not None):
                value = np.array(value[index])
                value.setflags(write=False)
            values[f.name] = value
        return self._validated(**values)

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """Return the batch axes, ``()`` for a single problem."""
        return self.target.shape[: -2 if self.multi_target else -1]

    @property
    def n_targets(self) -> int:
        """Return K (1 unless ``multi_target``)."""
        return int(self.target.shape[-2]) if self.multi_target else 1

    @property
    def is_paper(self) -> bool:
        """Return whether the paper's problem holds: one target, range-and-bearing sensors
        at known positions, the trace objective, every sensor always measures (Section
        IV-A's exact solve applies): :func:`activetrack.world.capabilities.paper_problem`,
        the rule a scenario's ``capabilities.paper_problem`` applies, on this problem's
        arrays."""
        return _capabilities.paper_problem(
            not self.multi_target,
            (self.models is None or not np.any(self.models)) and self.sensor_objects is None,
            self.pose_cov is None,
            self.p_detect is None and self.max_range is None and self.occluders is None,
            is_trace(self.objective),
            self.kinematics is None or team.all_disks(self.kinematics),
        )

    @cached_property
    def detect(self) -> tuple[FloatArray, FloatArray] | None:
        """Return ``(p_detect, max_range**2)`` (..., M) for the expected information, or
        None when every sensor always measures."""
        if self.p_detect is None and self.max_range is None and self.occluders is None:
            return None
        shape = self.sensors.shape[:-1]
        p = np.ones(shape) if self.p_detect is None else self.p_detect
        r2 = np.full(shape, np.inf) if self.max_range is None else self.max_range**2
        return p, r2

    @property
    def targets(self) -> FloatArray:
        """Return the predicted target positions with a targets axis, (..., K, 2)."""
        return self.target if self.multi_target else self.target[..., None, :]

    @property
    def prior_infos(self) -> FloatArray:
        """Return every target's prior information with a targets axis, (..., K, 2, 2)."""
        info = self.prior_info
        return info if self.multi_target else info[..., None, :, :]

    @cached_property
    def weights(self) -> tuple[FloatArray, FloatArray]:
        """Return the component weights ``(w_d, w_theta)`` (..., M), 0 for unused ones
        (with ``sensor_objects``: ``1/sigma^2`` for each slot, what
        :meth:`information_entries` turns back into the models' variances)."""
        if self.sensor_objects is not None:
            return 1.0 / self.sigma_d2, 1.0 / self.sigma_theta2
        models = 0 if self.models is None else self.models
        return sensor_models.weights(models, self.sigma_d2, self.sigma_theta2)

    @property
    def n_sensors(self) -> int:
        """Return M."""
        return int(self.sensors.shape[-2])

    @cached_property
    def prior_info(self) -> FloatArray:
        """Return the prior position information ``P(k+1|k)_11^{-1}``, (..., 2, 2), read-only."""
        info = inv2(self.prior_cov)
        info.setflags(write=False)
        return info

    @property
    def rel_sensors(self) -> FloatArray:
        """Return the current sensor positions relative to the predicted target (the ``c_i``),
        (..., M, 2); with K targets relative to each of them, (..., K, M, 2)."""
        if self.multi_target:
            return self.sensors[..., None, :, :] - self.target[..., :, None, :]
        return self.sensors - self.target[..., None, :]

    def score(self, next_positions: ArrayLike) -> FloatArray:
        """Return the objective of eq. (17) at absolute next positions (..., M, 2).

        The batch axes of ``next_positions`` (just before ``(M, 2)``) match the problem's;
        any further leading axes (candidates) broadcast. Shape: the leading axes.
        """
        pos = np.asarray(next_positions, dtype=np.float64)
        if self.is_paper:  # the paper's arithmetic, unchanged
            rel = pos - self.target[..., None, :]
            info = total_information(self.prior_info, rel, self.sigma_d2, self.sigma_theta2)
            return self.objective.of_information(info)
        # Every target k: Y_k = P11_k^{-1} + sum_i J_eff_i(p_i - t_k); objective over k.
        rel = pos[..., None, :, :] - self.targets[..., :, None, :]  # (..., K, M, 2)
        w_d, w_t = self.weights
        cov = None if self.pose_cov is None else self.pose_cov[..., None, :, :, :]
        det = None if self.detect is None else tuple(d[..., None, :] for d in self.detect)
        if self.occluders is not None:
            det = (*det, self.line_of_sight(pos))
        a, b, c = self.information_entries(rel, w_d[..., None, :], w_t[..., None, :], cov, det)
        prior = self.prior_infos
        a, b, c = (prior[..., 0, 0] + a.sum(-1), prior[..., 0, 1] + b.sum(-1),
                   prior[..., 1, 1] + c.sum(-1))  # fmt: skip
        return self.objective.of_targets(a, b, c)

    def information_entries(
        self,
        rel: FloatArray,
        w_d: FloatArray,
        w_t: FloatArray,
        pose_cov: FloatArray | None = None,
        detect: tuple | None = None,
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return each sensor's information entries ``(a, b, c)`` (..., M) at offsets
        ``rel = p_S - p_T`` (..., M, 2), the sensor axis last: the planners' one entry
        point. Built-in models: :func:`activetrack.models.sensor_models.information_entries`
        on the weights ``(w_d, w_t)`` (:attr:`weights`, broadcast as the caller needs);
        ``sensor_objects``: each model's :meth:`activetrack.SensorModel.information`
        (:func:`activetrack.estimation.generic.entries`) with variances ``1 / w``."""
        if self.sensor_objects is None:
            return sensor_models.information_entries(rel, w_d, w_t, pose_cov, detect)
        return generic.entries(self.sensor_objects, rel, 1.0 / w_d, 1.0 / w_t, pose_cov, detect)

    def line_of_sight(self, positions: ArrayLike) -> np.ndarray:
        """Return whether sensors at ``positions`` (..., M, 2) see each predicted target,
        (..., K, M) bool (all True without occluders)."""
        pos = np.asarray(positions, dtype=np.float64)
        if self.occluders is None:
            return np.ones(pos.shape[:-2] + (self.n_targets, pos.shape[-2]), dtype=bool)
        from activetrack.models.occluders import line_of_sight  # noqa: PLC0415

        return line_of_sight(pos, self.targets, self.occluders)

    def trace(self, next_positions: ArrayLike) -> FloatArray:
        """Return :meth:`score` (the name from when the trace was the only objective)."""
        return self.score(next_positions)

    def violation(self, next_positions: ArrayLike) -> FloatArray:
        """Return each sensor's largest constraint violation (0 when feasible), shape (..., M)."""
        p = np.asarray(next_positions, dtype=np.float64)
        step = np.linalg.norm(p - self.sensors, axis=-1) - self.r
        if self.kinematics is not None and not team.all_disks(self.kinematics):
            # A kinematics of its own: the distance to its reach set (its clip).
            s = self.sensors if self.sensor_states is None else self.sensor_states
            gap = [p[..., i, :] - k.clip(p[..., i, :], team.state_of(k, s[..., i, :]))
                   for i, k in enumerate(self.kinematics)]  # fmt: skip
            step = np.stack([np.hypot(g[..., 0], g[..., 1]) for g in gap], -1)
        near = np.linalg.norm(p[..., None, :, :] - self.targets[..., :, None, :], axis=-1)
        dist = self.rho - near.min(axis=-2)  # the nearest target
        return np.maximum(np.maximum(step, dist), 0.0)


@runtime_checkable
class Planner(Protocol):
    """Anything that maps a :class:`PlanningProblem` to next absolute positions.

    The result has shape ``problem.batch_shape + (M, 2)``.
    """

    def plan(self, problem: PlanningProblem, rng: np.random.Generator) -> FloatArray: ...
