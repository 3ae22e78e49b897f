"""The IMM filter as the world's estimator: the scenario field ``estimator``.

``estimator`` is ``"ekf"`` (the default: each target's EKF on its motion model, eq. 3 and
11; the world is what it always was, bit for bit) or an :class:`IMMSpec`: the mode set
(linear motion models of the target's state), the modes' Markov transition matrix and the
initial mode probabilities of an interacting multiple model filter
(:mod:`activetrack.estimation.imm`), the same for every target.

With an IMM the world keeps, per copy and target, the predicted mode probabilities ``c``
(r,), the mode-matched predicted means (r, n) and covariances (r, n, n). At reset every
mode starts at the prior ``N(x0_hat, P0)`` with probabilities ``initial``, then the IMM
predicts (mix, mode-matched prediction, combination). Each step:

1. *update*: every mode with the step's measurements, the same sensors as the EKF would
   take (the detections mask of limited sensing; :func:`activetrack.estimation.imm.update`),
   and the mode probabilities from the modes' likelihoods;
2. *combine*: ``x_hat``/``P`` (the world's posterior: the score, the reward, the NEES)
   are the moments of the posterior mixture;
3. *mix, predict, combine*: ``x_pred``/``P_pred`` (what the sensors keep ``rho`` from, the
   observation, the planning problem and so every planner read) are the moments of the
   predicted mixture ``sum_j c_j N(x_j(k+1|k), P_j(k+1|k))``: the planners plan against
   the uncertainty the filter actually has. The planning problem's prediction carries the
   mixture mode by mode too (``Prediction.modes``), so a policy may plan from one mode's
   prediction alone instead (the policies' ``prediction``,
   :mod:`activetrack.world.planning_prediction`).

The IMM draws no random numbers, so a world with an IMM consumes the same normals as with
the EKF: runs of the two estimators from the same seeds are paired. Every operation acts on
each copy's rows alone, so a world of N copies equals N worlds of one bit for bit. A
look-ahead beyond the next step extrapolates with the scenario's motion model (the
planning problem's), not with the IMM's modes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from activetrack.estimation import imm
from activetrack.models.behaviour import distribution, stochastic_matrix
from activetrack.models.motion import LinearMotionModel
from activetrack.validation import FloatArray
from activetrack.world.prediction import ModePredictions

_WHAT = "estimator must be 'ekf', 'imm' or an activetrack.IMMSpec"


class IMMSpec:
    """An IMM filter's mode set, for the scenario field ``estimator``.

    ``models``: the modes' :class:`~activetrack.LinearMotionModel` (a non-empty sequence,
    one state dimension, that of the targets' motion model); ``transition`` (r, r)
    row-stochastic, ``Pi[i, j] = P(m_k = j | m_{k-1} = i)``; ``initial`` (r,) the mode
    probabilities of the prior (default uniform). :meth:`from_behaviour` takes them from a
    :class:`~activetrack.Maneuvering` (or :class:`~activetrack.StopAndGo`) behaviour: the
    filter that knows the target's jump Markov model. Compared by value.
    """

    def __init__(
        self,
        models: Sequence[LinearMotionModel],
        transition: ArrayLike,
        initial: ArrayLike | None = None,
    ) -> None:
        models = tuple(models) if isinstance(models, (list, tuple)) else ()
        if not models or not all(isinstance(m, LinearMotionModel) for m in models):
            raise ValueError(
                "estimator: IMMSpec models must be a non-empty sequence of "
                "activetrack.LinearMotionModel"
            )
        dims = [m.dim for m in models]
        if any(d != dims[0] for d in dims):
            raise ValueError(
                f"estimator: IMMSpec models must share one state dimension, got {dims}"
            )
        r = len(models)
        self.models = models
        self.transition = stochastic_matrix("estimator: IMMSpec transition", transition, r)
        first = np.full(r, 1.0 / r) if initial is None else initial
        self.initial = distribution("estimator: IMMSpec initial", first, r)

    @classmethod
    def from_behaviour(cls, behaviour: Any, initial: ArrayLike | None = None) -> IMMSpec:
        """Return the spec of a behaviour's jump Markov model: its ``models`` (a
        :class:`~activetrack.Maneuvering`'s; a :class:`~activetrack.StopAndGo`'s moving
        and stopped models), its ``transition`` and its ``initial`` distribution (or
        ``initial`` if given)."""
        models = getattr(behaviour, "models", None)
        if models is None and hasattr(behaviour, "stopped_model"):
            models = (behaviour.moving_model, behaviour.stopped_model)
        if models is None or not hasattr(behaviour, "transition"):
            raise ValueError(
                "estimator: IMMSpec.from_behaviour needs a behaviour with a mode set "
                f"(models and transition, e.g. activetrack.Maneuvering), got {behaviour!r}"
            )
        if initial is None:
            initial = getattr(behaviour, "initial", np.eye(len(models))[0])
        return cls(models, behaviour.transition, initial)

    @property
    def n_modes(self) -> int:
        """Return the number of modes r."""
        return len(self.models)

    @property
    def dim(self) -> int:
        """Return the modes' state dimension n."""
        return self.models[0].dim

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented if isinstance(other, IMMSpec) else False
        return (
            self.n_modes == other.n_modes
            and np.array_equal(self.transition, other.transition)
            and np.array_equal(self.initial, other.initial)
            and all(
                np.array_equal(a.Phi, b.Phi) and np.array_equal(a.Q, b.Q) and a.dt == b.dt
                for a, b in zip(self.models, other.models, strict=True)
            )
        )

    def __hash__(self) -> int:
        return hash((type(self), self.n_modes))

    def __repr__(self) -> str:
        names = [m.name for m in self.models]
        return f"IMMSpec(models={names}, transition={self.transition.tolist()})"


def converted(value: object, sc: Any) -> Any:
    """Return the scenario field ``estimator`` checked: ``"ekf"`` or an :class:`IMMSpec`
    whose modes have every target's state dimension and the scenario's ``dt``
    (``sc``: the scenario, its other fields converted); ``"imm"`` is the spec of the
    scenario's ``target_behaviour`` (:meth:`IMMSpec.from_behaviour`; one behaviour with a
    mode set for every target). Else a ValueError naming the field."""
    if isinstance(value, str) and value == "ekf":
        return "ekf"
    if isinstance(value, str) and value == "imm":
        b = sc.target_behaviour
        if b is None or isinstance(b, tuple) or not hasattr(b, "transition"):
            raise ValueError(
                "estimator='imm' needs one target_behaviour with a mode set for every target "
                f"(activetrack.Maneuvering or StopAndGo), got target_behaviour={b!r}; "
                "give an activetrack.IMMSpec instead"
            )
        value = IMMSpec.from_behaviour(b)
    if not isinstance(value, IMMSpec):
        raise ValueError(f"{_WHAT}, got {value!r}")
    dims = [m.dim for m in sc.target_models]
    if any(d != value.dim for d in dims):
        raise ValueError(
            f"estimator: the IMM's modes have state dimension {value.dim}, the targets' "
            f"motion models {dims}"
        )
    for j, m in enumerate(value.models):
        if not math.isclose(float(m.dt), sc.dt, rel_tol=1e-12):
            raise ValueError(
                f"estimator: the IMM's mode {j} has time step {float(m.dt):g}, the scenario's "
                f"dt is {sc.dt:g}; build the modes with dt={sc.dt:g}"
            )
    return value


def record(value: Any) -> Any:
    """Return the field's JSON-friendly record: ``"ekf"``, or the IMM's mode names,
    transition matrix and initial probabilities."""
    if not isinstance(value, IMMSpec):
        return value
    return {
        "name": "imm",
        "models": [m.name for m in value.models],
        "transition": value.transition.tolist(),
        "initial": value.initial.tolist(),
    }


class IMMTracking:
    """The part of :class:`activetrack.world.World` that runs the IMM (module docstring);
    it reads the world's ``scenario``, ``params``, ``_t`` and copy layout."""

    def _init_imm(self) -> None:
        """Set up every copy's IMM state at the prior (placeholders until the copies'
        first reset; None with the EKF)."""
        spec = self.scenario.estimator
        self._imm = spec if isinstance(spec, IMMSpec) else None
        if self._imm is None:
            return
        self._imm_team = self.scenario.sensor_objects
        self._imm_state: list[dict[str, FloatArray]] = []
        for k in range(self.n_targets):
            state, _ = self._imm_prior(k)
            if not self._one:
                state = {
                    key: np.broadcast_to(v, (self.num_copies, *v.shape)).copy()
                    for key, v in state.items()
                }
            self._imm_state.append(state)
        self._reset_imm(slice(None) if not self._one else 0)

    def _imm_prior(self, k: int) -> tuple[dict[str, FloatArray], tuple[FloatArray, FloatArray]]:
        """Return target ``k``'s IMM state after the prior's prediction (every mode at
        ``N(x0_hat, P0)``, probabilities ``initial``) and the predicted mixture's moments."""
        spec, r = self._imm, self._imm.n_modes
        x0, P0 = self._x0_hats[k], self._P0s[k]
        xs, Ps = np.tile(x0, (r, 1)), np.tile(P0, (r, 1, 1))
        mu = spec.initial.copy()
        c, xm, Pm = imm.mix(mu, spec.transition, xs, Ps)
        xs, Ps = imm.predict(spec.models, xm, Pm)
        return {"mu": mu, "c": c, "x": xs, "P": Ps}, imm.combine(c, xs, Ps)

    def _reset_imm(self, sel: Any) -> None:
        """Start the IMM of the copies ``sel`` at the prior; their ``x_pred``/``P_pred``
        become the predicted mixture's."""
        if self._imm is None:
            return
        for k in range(self.n_targets):
            state, (x_pred, P_pred) = self._imm_prior(k)
            state.update(x_pred=x_pred, P_pred=P_pred)
            for key, value in state.items():
                store = self._t[k] if key in ("x_pred", "P_pred") else self._imm_state[k]
                if self._one:
                    store[key] = value
                else:
                    store[key][sel] = value

    def _imm_step(
        self,
        k: int,
        z: FloatArray,
        fixes: FloatArray,
        seen: np.ndarray | None,
        sel: Any,
        calc: Any,
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Return target ``k``'s ``(x_post, P_post, x_pred, P_pred)`` for the copies
        ``calc`` after the IMM's update with the measurements ``z`` (..., M, 2) of the
        sensors ``seen`` (..., M; None: all) believed at ``fixes``, then its mix, predict
        and combine; the copies ``sel`` keep the new IMM state."""
        spec, p, st = self._imm, self.params, self._imm_state[k]
        mask = np.ones(fixes.shape[:-1], dtype=bool) if seen is None else seen
        xs, Ps, ll = imm.update(
            self._imm_team, st["x"][calc], st["P"][calc], z, fixes, p.sigma_d2,
            p.sigma_theta2, p.orientation, mask, p.filter_pose_cov, p.filter_iterations,
        )  # fmt: skip
        mu = imm.mode_probabilities(st["c"][calc], ll)
        x_post, P_post = imm.combine(mu, xs, Ps)
        c, xm, Pm = imm.mix(mu, spec.transition, xs, Ps)
        xs, Ps = imm.predict(spec.models, xm, Pm)
        new = {"mu": mu, "c": c, "x": xs, "P": Ps}
        if isinstance(sel, np.ndarray):  # a subset: computed with all, kept alone
            for key, value in new.items():
                st[key][sel] = value[sel]
        else:
            st.update(new)
        return (x_post, P_post, *imm.combine(c, xs, Ps))

    def _predicted_modes(self, index: int | None, k: int) -> ModePredictions | None:
        """Return target ``k``'s predicted mixture mode by mode (what ``x_pred``/``P_pred``
        are the moments of) for copy ``index`` (unbatched) or every copy (None), or None
        when the estimator is the EKF."""
        if self._imm is None:
            return None
        st = self._imm_state[k]
        parts = [st[key] for key in ("c", "x", "P")]
        if self._one:
            parts = [v if index is not None else v[None] for v in parts]
        elif index is not None:
            parts = [v[index] for v in parts]
        return ModePredictions(*parts)

    @property
    def mode_probabilities(self) -> list[FloatArray] | None:
        """Return every target's posterior mode probabilities ((N, r) each, a copy; (r,)
        for a world of one copy), or None when the estimator is the EKF."""
        if self._imm is None:
            return None
        return [st["mu"].copy() for st in self._imm_state]
