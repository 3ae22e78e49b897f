"""What the world's adapters read: its state, the planning problem, the observation.

:class:`WorldReaders` is the part of :class:`activetrack.world.World` that reads and does
not step: :meth:`~WorldReaders.get` and the state attributes, the planning problem of eq.
(15)-(17) the planners take, the agents' observations and the global state
(:mod:`activetrack.world.observation`), the occluders in force, the estimation errors and
an environment's per-copy infos. The world (:mod:`activetrack.world.world`) holds the
state and steps it; a world of one copy keeps its state unbatched, which the readers
return as it is (no leading axis) when asked for that copy.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from activetrack.estimation.ekf import position_nees
from activetrack.models.roadmap import route_readings
from activetrack.validation import FloatArray
from activetrack.world import _fast, observation, team_problem
from activetrack.world.prediction import Prediction
from activetrack.world.problem import PlanningProblem

#: The state fields every target has its own of.
_TARGET_FIELDS = ("x_true", "x_hat", "P", "x_pred", "P_pred")


class WorldReaders:
    """The reading half of :class:`activetrack.world.World` (see the module docstring)."""

    def get(self, name: str, index: int | None = None, target: int | None = None) -> Any:
        """Return state field ``name`` of copy ``index`` (unbatched), or of all copies (N, ...).

        Fields: ``x_true``, ``x_hat``, ``P``, ``x_pred``, ``P_pred`` (per target),
        ``sensors`` (true positions), ``fixes`` (the position fixes the team believes and
        plans from; the true positions when poses are known), ``k``, ``trace`` (the sum of
        the targets' posterior position traces), ``score`` (the objective, minus the
        reward; the trace for one target), ``projected``, ``n_projected``, ``terminated``,
        ``truncated``, ``detected`` (K, M): which sensor measured which target at the
        last step (all True with unlimited sensing; all False right after a reset),
        ``motion`` (M, S - 2): each sensor's state beyond its position when a kinematics
        carries one (a heading, a velocity; :mod:`activetrack.world._motion_state`). A
        per-target field is target ``target``'s; ``target=None`` gives
        the only target's (K = 1, shapes as in the paper) or all targets stacked on an
        axis after the copies' (K > 1, e.g. ``x_pred`` (N, K, n); their state dimensions
        must then agree). The attributes of the same names are ``get(name)``: read-only
        views, refreshed by every step (keep a copy, not a reference).
        """
        if name in _TARGET_FIELDS:
            if target is None:
                if self.n_targets > 1:
                    return self._stacked(name, index)
                v = self._t[0][name]
            else:
                if not isinstance(target, (int, np.integer)) or not 0 <= target < self.n_targets:
                    raise ValueError(
                        f"target must be an integer in [0, {self.n_targets - 1}], got {target!r}"
                    )
                v = self._t[target][name]
        elif name == "detected" and not self._limited:  # every sensor sees every target
            shape = (self.n_targets, self.n_sensors)
            v = np.ones(shape if self._one else (self.num_copies, *shape), dtype=bool)
        else:
            try:
                v = self._s[name]
            except KeyError:
                fields = sorted([*(k for k in self._s if k != "ended"), *_TARGET_FIELDS])
                raise ValueError(f"name must be one of {fields}, got {name!r}") from None
        if self._one:
            return v if index is not None else np.asarray(v)[None]
        return v if index is None else v[index]

    def _stacked(self, name: str, index: int | None) -> np.ndarray:
        """Return a per-target field of every target, stacked after the copies' axis."""
        parts = [self.get(name, index, k) for k in range(self.n_targets)]
        if len({np.shape(v) for v in parts}) != 1:
            raise ValueError(
                f"the targets' states differ in dimension: give target= (0 to "
                f"{self.n_targets - 1}) to read {name!r}"
            )
        return np.stack(parts, axis=0 if index is not None else 1)

    x_true = property(lambda self: self.get("x_true"), doc="True target states (N, n).")
    x_hat = property(lambda self: self.get("x_hat"), doc="Posterior means x_hat(k|k) (N, n).")
    P = property(lambda self: self.get("P"), doc="Posterior covariances (N, n, n).")
    x_pred = property(lambda self: self.get("x_pred"), doc="Predictions x_hat(k+1|k) (N, n).")
    P_pred = property(lambda self: self.get("P_pred"), doc="Predicted P(k+1|k) (N, n, n).")
    sensors = property(lambda self: self.get("sensors"), doc="Sensor positions (N, M, 2).")
    fixes = property(lambda self: self.get("fixes"), doc="Believed sensor positions (N, M, 2).")
    k = property(lambda self: self.get("k"), doc="Steps taken in each episode (N,).")
    trace = property(lambda self: self.get("trace"), doc="Posterior traces tr P_11 (N,).")
    score = property(lambda self: self.get("score"), doc="The objective at the posterior (N,).")
    projected = property(lambda self: self.get("projected"), doc="Moves pushed out of rho (N, M).")
    n_projected = property(lambda self: self.get("n_projected"), doc="Their count (N, M).")
    terminated = property(lambda self: self.get("terminated"), doc="Trace above max_trace (N,).")
    truncated = property(lambda self: self.get("truncated"), doc="Reached n_steps (N,).")
    detected = property(lambda self: self.get("detected"), doc="Who measured whom (N, K, M).")

    # What adapters read -----------------------------------------------------------------
    def planning_problem(self, index: int | None = None) -> PlanningProblem:
        """Return the planning problem of eq. (15)-(17) from the current prediction.

        ``index`` None: every copy (leading batch axis N); an int: that copy, unbatched.
        The problem carries the full prediction (:class:`~activetrack.world.problem.Prediction`:
        ``x_pred``, ``P_pred`` and the motion model ``Phi``, ``Q``; with an IMM also its
        predicted mixture mode by mode, ``Prediction.modes``); with K > 1 targets
        one per target (``multi_target``), whose positions and covariances are the
        problem's ``target`` and ``prior_cov``. The sensors are the position fixes; the sensors'
        models and the pose covariance the filter accounts for come along.
        """
        p = self.params
        extra = {
            "models": p.models,
            "pose_cov": p.filter_pose_cov,
            "objective": self.objective,
        }
        if self._team is not None:  # a kinematics that is not the built-in disk
            extra["kinematics"] = self._team.team
            if self._n_motion:  # a heading, a velocity: the kinematics see the whole state
                extra["sensor_states"] = self.sensor_states(index)
        if self._sep is not None:  # the team rule d_sep: the planners keep it too
            extra["d_sep"] = self.scenario.d_sep
        if p.sensor_objects is not None:  # a model of one's own: the planners ask the models
            extra["sensor_objects"] = p.sensor_objects
        if self._limited:  # the planners count each sensor's information at its expected value
            extra.update(
                p_detect=p.p_detect, max_range=p.max_range, occluders=self.occluders(index)
            )
        sensors = self.get("fixes" if self._pose else "sensors", index)
        models = self.__dict__.get("_prediction_models")
        if models is None:  # each target's Phi and Q are validated once
            models = self._prediction_models = [
                Prediction(self.get("x_pred", index, k), self.get("P_pred", index, k), tp.Phi, tp.Q)
                for k, tp in enumerate(p.targets)
            ]
        preds = [
            model.with_state(
                self.get("x_pred", index, k), self.get("P_pred", index, k),
                self._predicted_modes(index, k),
            )
            for k, model in enumerate(models)
        ]  # fmt: skip
        if self.n_targets > 1:
            problem = PlanningProblem(
                None, None, sensors, p.r, p.rho, p.sigma_d2, p.sigma_theta2,
                prediction=tuple(preds), multi_target=True, **extra,
            )  # fmt: skip
        else:
            problem = PlanningProblem.from_prediction(
                preds[0], sensors=sensors, r=p.r, rho=p.rho, sigma_d2=p.sigma_d2,
                sigma_theta2=p.sigma_theta2, **extra,
            )  # fmt: skip
        # A decentralized team's problem also carries each robot's prediction and the links.
        return team_problem.with_team(self, problem, index)

    def observe(self, index: int | None = None) -> np.ndarray:
        """Return every agent's observation, float32 (N, M, D), or (M, D) for one copy.

        The layout is :mod:`activetrack.world.observation`'s (``self.layout``; ``D = 5 + 6M`` in
        the paper): the prediction and the team as seen from each agent's seat.
        """
        if self._team_obs:  # each agent its own estimate and messages (team_observation)
            return self._team_observe(index)
        rays, fused = self.layout.rays, self._fused and not self.layout.route
        if self._one and fused and (index is None or (type(index) is int and index == 0)):
            return _fast.observe_one(self)[None] if index is None else _fast.observe_one(self)
        if fused and index is None:  # every copy of a batched fused world
            return _fast.observe_batch(self)
        out = observation.encode(*self._feature_args(index), self._order, rays)
        if rays:  # written straight into the observation (float32): no float64 temporary
            observation.ray_readings(
                self.get("sensors", index), self.occluders(index), out[..., -rays:]
            )
        more = [a for a in (self._route(index), self._motion_features(index),
                            self._track_flags(index)) if a is not None]  # fmt: skip
        if more:  # each agent's own route readings, heading or velocity, last
            out = np.concatenate([out, *(a.astype(np.float32) for a in more)], -1)
        return out

    def _team_observe(self, index: int | None) -> np.ndarray:
        """Return :func:`activetrack.world.team_observation.observe` with the agents' own
        rays, route readings and kinematic features as its tail."""
        from activetrack.world import team_observation  # noqa: PLC0415 (its own option)

        tail = []
        if self.layout.rays:
            tail.append(observation.ray_readings(self.get("sensors", index), self.occluders(index)))
        tail += [a for a in (self._route(index), self._motion_features(index)) if a is not None]
        tail = np.concatenate(tail, -1) if tail else None
        return team_observation.observe(self, index, tail)

    def state(self, index: int | None = None) -> np.ndarray:
        """Return the global state, float32 (N, D + 1) or (D + 1,) for one copy."""
        target, sensor = observation.features(*self._feature_args(index))
        elapsed = self.get("k", index) / self._n_steps
        return observation.global_state(
            target, sensor, elapsed, self._rays(index), self._motion_features(index),
            self._route(index), self._track_flags(index),
        )  # fmt: skip

    def _rays(self, index: int | None) -> FloatArray | None:
        """Return every agent's range-finder readings (..., M, RAYS), or None (no occluders)."""
        if not self.layout.rays:
            return None
        return observation.ray_readings(self.get("sensors", index), self.occluders(index))

    def _track_flags(self, index: int | None) -> FloatArray | None:
        """Return every agent's track flags (..., M, K), 1 where the team holds a track,
        or None (no ``births``)."""
        if self._births is None:
            return None
        held = self._tracked if index is None else self._tracked[index]
        shape = held.shape[:-1] + (self.n_sensors, self.n_targets)
        return np.broadcast_to(held[..., None, :], shape).astype(np.float64)

    def _route(self, index: int | None) -> FloatArray | None:
        """Return every agent's route readings (..., M, 3K), or None (no
        ``route_observation``: :func:`activetrack.models.roadmap.route_readings`)."""
        if not self.layout.route:
            return None
        goals = np.stack([self.get("x_pred", index, k)[..., :2] for k in range(self.n_targets)], -2)
        return route_readings(self.get("sensors", index), goals, self.occluders(index))

    def occluders(
        self, index: int | None = None
    ):  # -> activetrack.models.occluders.Occluders | None
        """Return the occluders in force (None: an open plane).

        ``index`` None: every copy's (with random layouts an
        :class:`~activetrack.models.occluders.Occluders` batched over the copies, else the
        scenario's fixed set, shared); an int: copy ``index``'s layout, unbatched.
        """
        if index is not None and (
            isinstance(index, (bool, np.bool_))
            or not isinstance(index, (int, np.integer))
            or not 0 <= index < self.num_copies
        ):
            raise ValueError(
                f"index must be None or an integer in [0, {self.num_copies - 1}], got {index!r}"
            )
        occ = self._occ
        if occ is None or index is None or self._one:
            return occ
        return occ[index]

    def _feature_args(self, index: int | None) -> tuple:
        """Return :func:`activetrack.world.observation.features`' arguments for copy ``index``
        (None: every copy): the predictions, the sensors' fixes (their positions in the
        paper's layout), the constant entries, ``dt``, ``L``, the layout, the flags."""
        if self._one and index is not None:  # the single env: no get() calls
            x_preds = [t["x_pred"] for t in self._t]
            P_preds = [t["P_pred"] for t in self._t]
            fixes = self._s["fixes" if self._extended else "sensors"]
        else:
            K = self.n_targets
            x_preds = [self.get("x_pred", index, k) for k in range(K)]
            P_preds = [self.get("P_pred", index, k) for k in range(K)]
            fixes = self.get("fixes" if self._extended else "sensors", index)
        detected = self.get("detected", index) if self._limited else None
        return (x_preds, P_preds, fixes, self._constants, self._dt, self.length_scale,
                self._extended, detected)  # fmt: skip

    def position_error(self, index: int | None = None, per_target: bool = False) -> FloatArray:
        """Return ``||p_T(k) - p_hat_T(k|k)||`` (m) per copy, or of copy ``index``.

        With K > 1 targets: the root mean square over the targets (``per_target``: each
        target's, on a last axis of K); with ``births``, over the present targets whose
        slot holds a track (0 when none does; ``per_target``: NaN for the others).
        """
        if self.n_targets > 1:
            err = np.stack(
                [self._error(self.get("x_true", index, k), self.get("x_hat", index, k))
                 for k in range(self.n_targets)], -1,
            )  # fmt: skip
            if self._births is not None:  # the tracks held of the targets present
                held = self._held(index)
                if per_target:
                    return np.where(held, err, np.nan)
                n = np.maximum(held.sum(-1), 1)
                return np.sqrt(np.sum(np.where(held, err * err, 0.0), axis=-1) / n)
            return err if per_target else np.sqrt(np.mean(err * err, axis=-1))
        if self._one and index is not None:
            x, h = self._t[0]["x_true"], self._t[0]["x_hat"]
        else:
            x, h = self.get("x_true", index), self.get("x_hat", index)
        if index is not None:  # one copy: Python numbers (NumPy calls cost microseconds)
            (x0, x1, *_), (h0, h1, *_) = x.tolist(), h.tolist()
            err = np.float64(math.hypot(x0 - h0, x1 - h1))
            return err[None] if per_target else err
        err = self._error(x, h)
        return err[..., None] if per_target else err

    @staticmethod
    def _error(x: FloatArray, h: FloatArray) -> FloatArray:
        d = x[..., :2] - h[..., :2]
        return np.hypot(d[..., 0], d[..., 1])

    def copy_info(self, index: int) -> tuple[int, float, float, list[bool], list[int]]:
        """Return copy ``index``'s ``(k, trace, position_error, projected, n_projected)`` as
        Python values (lists per sensor): what an environment's infos report."""
        get = self._s.__getitem__ if self._one else (lambda key: self._s[key][index])
        if self.n_targets == 1:
            t = self._t[0]
            x, h = (
                (t["x_true"], t["x_hat"]) if self._one else (t["x_true"][index], t["x_hat"][index])
            )
            (x0, x1, *_), (h0, h1, *_) = x.tolist(), h.tolist()
            err = math.hypot(x0 - h0, x1 - h1)  # position_error(index), without a call
        else:  # the root mean square over the targets: position_error's own arithmetic, so
            # that a serial episode's infos equal its batched copy's bit for bit
            err = float(self.position_error(index))
        return (
            int(get("k")),
            float(get("trace")),
            err,
            get("projected").tolist(),
            get("n_projected").tolist(),
        )

    def position_nees(self, index: int | None = None, per_target: bool = False) -> FloatArray:
        """Return the position NEES ``e^T P_11^{-1} e`` per copy, or of copy ``index``.

        With K > 1 targets: the mean over the targets (``per_target``: each target's, on a
        last axis of K); each is chi-square with 2 degrees of freedom for a consistent filter.
        With ``births``: over the present targets whose slot holds a track (NaN for the
        others, and the mean NaN when none does).
        """
        nees = np.stack(
            [position_nees(self.get("x_true", index, k), self.get("x_hat", index, k),
                           self.get("P", index, k)) for k in range(self.n_targets)], -1,
        )  # fmt: skip
        if self._births is not None:  # the tracks held of the targets present
            nees = np.where(self._held(index), nees, np.nan)
            if per_target:
                return nees
            with np.errstate(invalid="ignore"):
                n = np.sum(~np.isnan(nees), -1)
                return np.where(n > 0, np.nansum(nees, -1) / np.maximum(n, 1), np.nan)
        return nees if per_target else np.mean(nees, axis=-1)

    def _held(self, index: int | None) -> np.ndarray:
        """Return which slots hold a track of a present target, (K,) or (N, K)."""
        held = self._present & self._tracked
        return held if index is None else held[index]
