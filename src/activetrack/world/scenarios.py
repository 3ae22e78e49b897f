"""Scenario configuration.

:class:`Scenario` is the one frozen configuration shared by the simulation runner and the
environments: team, noise, kinematics, target model, initial conditions and episode
length. :func:`make_scenario` picks a named preset (:data:`PRESETS`, in
``world/presets.py``: ``paper`` is the setup of Section V exactly, ``homogeneous`` M
identical sensors, :data:`TASKS` the tasks beyond the paper) and overrides any field by
keyword. Each field's accepted range and conversion is in ``world/_scenario_fields.py``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from activetrack.kinematics import separation, team
from activetrack.models import births
from activetrack.models.motion import LinearMotionModel, make_model
from activetrack.models.objective import Objective
from activetrack.models.sensor import SensorModel, as_sensor_model, record, slot_code
from activetrack.validation import FloatArray, UnexpectedKeywordError
from activetrack.world import behaviours, imm_tracking, team_filters
from activetrack.world._scenario_fields import (
    _PER_SENSOR,
    CHOICES,
    DT_RANGE,
    INFORMATION_RATIO_MAX,
    LENGTH_MAX,
    MAX_TRACE_RANGE,
    N_SENSORS_MAX,
    N_STEPS_MAX,
    N_TARGETS_MAX,
    OBJECTIVE_NAMES,
    ORIENTATION_MAX,
    P0_RANGE,
    POSE_COV_MAX,
    Q_MAX,
    REWARD_SCALE_RANGE,
    SENSOR_MODELS,
    SIGMA_D2_RANGE,
    SIGMA_THETA2_RANGE,
    SPEED_MAX,
    STATE_MAX,
    _converted_models,
    _converted_motion,
    _converted_objective,
    _converted_occluders,
    _converted_p0,
    _converted_pose_cov,
    _converted_random_occluders,
    _count_field,
    _per_target_p0,
    _per_target_states,
    _real_field,
    _sensor_field,
    _vector_field,
)
from activetrack.world.capabilities import Capabilities
from activetrack.world.presets import EXTENSIONS, PRESETS, TASKS

#: The public names, re-exported from their modules: the fields' accepted ranges
#: (``world/_scenario_fields.py``) and the presets (``world/presets.py``).
__all__ = [
    "DT_RANGE",
    "EXTENSIONS",
    "INFORMATION_RATIO_MAX",
    "LENGTH_MAX",
    "MAX_TRACE_RANGE",
    "N_SENSORS_MAX",
    "N_STEPS_MAX",
    "N_TARGETS_MAX",
    "OBJECTIVE_NAMES",
    "ORIENTATION_MAX",
    "P0_RANGE",
    "POSE_COV_MAX",
    "PRESETS",
    "Q_MAX",
    "REWARD_SCALE_RANGE",
    "SENSOR_MODELS",
    "SIGMA_D2_RANGE",
    "SIGMA_THETA2_RANGE",
    "SPEED_MAX",
    "STATE_MAX",
    "TASKS",
    "Scenario",
    "make_scenario",
]


@dataclass(frozen=True)
class Scenario:
    """A tracking scenario (all lengths in metres, times in seconds, angles in radians).

    Every field is converted and validated once, at construction, and stored converted:
    counts as ``int``, scalars as ``float``, per-sensor fields as a ``float`` (the same for
    every sensor) or a tuple of M floats, vectors as tuples of floats, ``P0`` as a tuple
    (its diagonal) or a tuple of tuples. An invalid value raises a ``ValueError`` naming
    the field and its accepted range; strings, bools, ``None``, complex numbers, NaN and
    inf are rejected wherever a number is expected. Accepted ranges are in brackets.

    Attributes:
        name: label of the preset it came from (a string).
        n_sensors: team size M [1, 10000].
        sigma_d2, sigma_theta2: per-sensor range (m^2) [1e-8, 1e8] and bearing (rad^2)
            [1e-10, 1e2] noise variances; a scalar applies to every sensor.
        vmax: per-sensor maximum speed [0, 1e9]; the reach per step ``r = vmax dt``
            (eq. 13) must also be at most 1e9.
        rho: per-sensor minimum distance to the predicted target (eq. 14) [0, 1e9].
        orientation: per-sensor heading ``phi_i`` subtracted from the bearing (eq. 4),
            magnitude at most 1e3.
        dt: time step [1e-6, 1e4].
        motion: ``"cv"`` (eq. 39), ``"ca"``, or any :class:`LinearMotionModel` (its state
            dimension n is then the model's).
        q: continuous process noise intensity of the ``"cv"``/``"ca"`` models [0, 1e10].
        x0: true initial target state; x0_hat: initial estimate (n entries, magnitudes at
            most 1e9); P0: its covariance, the diagonal (n entries) or a full symmetric
            positive definite n x n matrix, diagonal entries in [1e-8, 1e16].
        target_init: ``"fixed"`` uses x0 and x0_hat as given; ``"gaussian"`` draws the true
            state from ``N(x0_hat, P0)`` so the filter starts consistent.
        sensor_center, sensor_radius: sensors start uniformly (by area) in this disk
            (coordinates magnitude at most 1e9, radius [0, 1e9]).
        n_steps: episode length in time steps [1, 1e9]; ``make_scenario`` also accepts
            PettingZoo's name for it, ``max_cycles``.
        max_trace: optional early termination when the posterior trace exceeds it
            [1e-300, 1e300], or None.
        reward_scale: the reward is ``-reward_scale`` times the objective (1 = the paper)
            [1e-12, 1e12].
        n_targets: number of targets K [1, 100]. With K > 1, ``motion`` and ``q`` may be
            per target (a tuple of K), ``x0`` and ``x0_hat`` are per target (K rows, each
            of its model's state dimension), and ``P0`` is shared (a diagonal of n
            entries) or per target (K diagonals or K matrices). Every target has its own
            EKF; measurements are labelled by target (known data association).
        sensor_model: per-sensor measurement model, ``"range_bearing"`` (eq. 4),
            ``"range"`` or ``"bearing"``, or an :class:`activetrack.SensorModel` (a name
            or model for every sensor or a tuple of M); a built-in's instance is stored as
            its name. The variance of a component a sensor does not measure is unused.
        pose_cov: covariance of each sensor's position fix (m^2): 0 (known exactly, the
            paper), a variance s >= 0 for every sensor (``s I``), M variances, one 2x2
            matrix for every sensor, or M 2x2 matrices (symmetric positive semidefinite,
            entries at most 1e8). Stored as a float or nested tuples.
        account_pose: whether the filter accounts for the pose uncertainty in its
            measurement noise (``R + H_s Sigma H_s^T``); False gives a filter that
            ignores it (for studies of that error).
        objective: ``"trace"`` (sum of the targets' posterior position traces, eq. 17),
            ``"worst_trace"`` (the largest) or ``"logdet"`` (sum of log-determinants),
            or an :class:`activetrack.Objective` instance (a new objective: a subclass with
            a ``name`` of its own); the reward is minus it at the posterior. A built-in
            objective's instance (``activetrack.TRACE``...) is stored as its name.
        max_range: per-sensor sensing range (m) [1e-6, 1e9], or None (unlimited, the
            paper): a sensor farther than it from a target does not measure it that step.
        p_detect: per-sensor detection probability within range [0, 1] (1, the paper): each
            step each sensor detects each target in range independently with it; a sensor
            that does not detect a target contributes no measurement of it that step.
        occluders: polygons (each a sequence of at least 3 (x, y) vertices, simple, of
            non-zero area; at most 4096 vertices in all with the random rectangles',
            :data:`activetrack.models.occluders.MAX_VERTICES`) that block the line of sight
            (no measurement through them) and the sensors' straight moves; stored as
            tuples of (x, y) tuples. Empty: an open plane (the paper).
        random_occluders: rectangles drawn afresh for every episode from its seed [0, 100]
            (0: none), added to ``occluders``: side lengths uniform in ``occluder_size``,
            orientation uniform, each inside ``occluder_bounds``, none within
            ``sensor_radius`` of the sensors' start centre or of a target's initial
            estimate ``x0_hat`` (:func:`activetrack.models.occluders.random_layout`;
            :meth:`draw_occluders`). For studies of generalization over layouts.
        occluder_bounds: ``(xmin, ymin, xmax, ymax)`` of the random rectangles (m), finite,
            at most 1e9 in magnitude, min < max.
        occluder_size: ``(lo, hi)`` of the random rectangles' side lengths (m),
            1e-6 <= lo <= hi <= 1e9.
        filter_iterations: linearizations of the filter's measurement update [1, 100]: 1
            is the EKF of eq. (11) (the paper); more is the iterated EKF
            (:func:`activetrack.estimation.ekf.update`), which stays consistent where a target is
            measured again after a long gap, its prediction meters off.
        kinematics: how each sensor moves in one step: None (the paper's
            :class:`activetrack.kinematics.disk.Disk` of radius ``vmax_i dt``), an
            :class:`activetrack.Kinematics` for every sensor, or a tuple of M; with one
            given, the reach ``r`` is its ``radius`` and ``vmax`` is unused.
        target_behaviour: how the true targets move: None (their filter's own model, eq.
            2), an :class:`activetrack.TargetBehaviour` for every target, or a tuple of K
            (:mod:`activetrack.world.behaviours`); the filter keeps its model.
        estimator: ``"ekf"`` (each target's EKF on its motion model), ``"imm"`` (the IMM
            of ``target_behaviour``'s mode set) or an :class:`activetrack.IMMSpec` (an IMM's
            modes, of the targets' state and ``dt``; :mod:`activetrack.world.imm_tracking`).
        d_sep: the team rule of a minimum separation (:mod:`activetrack.kinematics.separation`):
            0 (none, the paper), a distance [0, 1e9] every pair keeps, or M radii (a pair
            keeps ``d_i + d_j``); the world enforces it, and it must fit the start disk.
        route_observation: whether each agent also observes its route to each target's
            prediction around the occluders (direction and detour:
            :func:`activetrack.world.observation.route_readings`); False (the default).
        communication: None (one central filter, the paper's team) or an
            :class:`activetrack.CommunicationModel`: who hears whom each step; the world
            then keeps a filter per robot too (:mod:`activetrack.world.team_filters`).
        team_fusion: how a robot uses what it hears: ``"measurements"`` (its neighbours'
            measurements, the default) or ``"covariance_intersection"`` (their estimates).
        team_observation: whether each agent observes only its own estimate and its
            neighbours' messages (:mod:`activetrack.world.team_observation`); False.
        births: None (every target there throughout) or an :class:`activetrack.BirthProcess`:
            the K targets are slots that targets enter and leave, and the team tracks those
            it has detected (:mod:`activetrack.world.track_management`).

    One coupled limit: the first predicted position variance (from P0, the model and q)
    may be at most 1e10 times the smallest range variance, so that one update never
    shrinks the position covariance beyond what float64 represents.
    """

    name: str = "paper"
    n_sensors: int = 3
    sigma_d2: float | tuple[float, ...] = (2.0, 4.0, 4.0)
    sigma_theta2: float | tuple[float, ...] = (0.25, 0.5, 0.5)
    vmax: float | tuple[float, ...] = 10.0
    rho: float | tuple[float, ...] = 2.0
    orientation: float | tuple[float, ...] = 0.0
    dt: float = 0.1
    motion: str | LinearMotionModel = "cv"
    q: float = 10.0
    x0: tuple[float, ...] = (0.0, 0.0, -8.0, 6.0)
    x0_hat: tuple[float, ...] = (2.0, -2.0, 0.0, 0.0)
    P0: tuple[float, ...] | tuple[tuple[float, ...], ...] = (4.0, 4.0, 100.0, 100.0)
    target_init: str = "fixed"
    sensor_center: tuple[float, float] = (20.0, 0.0)
    sensor_radius: float = 5.0
    n_steps: int = 50
    max_trace: float | None = None
    reward_scale: float = 1.0
    n_targets: int = 1
    sensor_model: str | SensorModel | tuple[str | SensorModel, ...] = "range_bearing"
    pose_cov: float | tuple = 0.0
    account_pose: bool = True
    objective: str | Objective = "trace"
    max_range: float | tuple[float, ...] | None = None
    p_detect: float | tuple[float, ...] = 1.0
    occluders: tuple = ()
    random_occluders: int = 0
    occluder_bounds: tuple[float, float, float, float] = (-20.0, -20.0, 20.0, 20.0)
    occluder_size: tuple[float, float] = (2.0, 6.0)
    filter_iterations: int = 1
    kinematics: Any = None
    target_behaviour: Any = None
    estimator: Any = "ekf"
    d_sep: float | tuple[float, ...] = 0.0
    route_observation: bool = False
    communication: Any = None
    team_fusion: str = "measurements"
    team_observation: bool = False
    births: Any = None
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        def put(name: str, value: object) -> None:
            object.__setattr__(self, name, value)

        if not isinstance(self.name, str):
            raise ValueError(f"name must be a string, got {self.name!r}")
        m = _count_field("n_sensors", self.n_sensors)
        put("n_sensors", m)
        put("n_steps", _count_field("n_steps", self.n_steps))
        for key in ("dt", "sensor_radius", "reward_scale"):
            put(key, _real_field(key, getattr(self, key)))
        if self.max_trace is not None:
            put("max_trace", _real_field("max_trace", self.max_trace))
        if not isinstance(self.target_init, str) or self.target_init not in CHOICES["target_init"]:
            raise ValueError(f"target_init must be 'fixed' or 'gaussian', got {self.target_init!r}")
        kk = _count_field("n_targets", self.n_targets)
        put("n_targets", kk)
        put("motion", _converted_motion(self.motion, kk))
        if kk > 1 and isinstance(self.q, (tuple, list, np.ndarray)):
            put("q", _vector_field("q", self.q, kk, why=" (one per target)"))
        else:
            put("q", _real_field("q", self.q))
        put("objective", _converted_objective(self.objective))
        if not isinstance(self.account_pose, (bool, np.bool_)):
            raise ValueError(f"account_pose must be True or False, got {self.account_pose!r}")
        put("account_pose", bool(self.account_pose))
        if not isinstance(self.route_observation, (bool, np.bool_)):
            raise ValueError(
                f"route_observation must be True or False, got {self.route_observation!r}"
            )
        put("route_observation", bool(self.route_observation))
        put("sensor_model", _converted_models(self.sensor_model, m))
        put("pose_cov", _converted_pose_cov(self.pose_cov, m))
        if self.max_range is not None:
            put("max_range", _sensor_field("max_range", self.max_range, m))
        put("p_detect", _sensor_field("p_detect", self.p_detect, m))
        occluders, occ = _converted_occluders(self.occluders)
        if occ is not None:
            self._cache["occluders"] = occ
        put("occluders", occluders)
        put("sensor_center", _vector_field("sensor_center", self.sensor_center, 2))
        count, bounds, size = _converted_random_occluders(
            self.random_occluders, self.occluders, self.occluder_bounds, self.occluder_size
        )
        put("random_occluders", count)
        put("occluder_bounds", bounds)
        put("occluder_size", size)
        put("filter_iterations", _count_field("filter_iterations", self.filter_iterations))
        put("kinematics", team.converted(self.kinematics, m, self.dt))
        for key in _PER_SENSOR:
            put(key, _sensor_field(key, getattr(self, key), m))
        reach = np.asarray(self.vmax) * self.dt
        if np.any(reach > LENGTH_MAX):
            raise ValueError(
                f"vmax * dt (the reach r of eq. 13) must be at most {LENGTH_MAX:g}, "
                f"got vmax={self.vmax!r}, dt={self.dt!r}"
            )
        if kk == 1:
            n = self.model.dim
            why = f" (the state of motion={getattr(self.motion, 'name', self.motion)!r})"
            for key in ("x0", "x0_hat"):
                value = getattr(self, key)
                put(key, _vector_field(key, value, n, why=why))
            put("P0", _converted_p0(self.P0, n, self.motion))
        else:
            dims = [mdl.dim for mdl in self.target_models]
            for key in ("x0", "x0_hat"):
                put(key, _per_target_states(key, getattr(self, key), dims))
            put("P0", _per_target_p0(self.P0, dims))
        put("target_behaviour", behaviours.converted(self.target_behaviour, self))
        put("estimator", imm_tracking.converted(self.estimator, self))
        put("births", births.converted(self.births, self))
        self._check_information_ratio()
        put("d_sep", separation.converted(self.d_sep, m))
        separation.check_scenario(self)
        team_filters.check_fields(self, put)
        if self.random_occluders:  # a layout can be drawn (the reset would fail otherwise)
            self.draw_occluders(np.random.default_rng(0))

    def draw_occluders(self, rng: np.random.Generator):  # -> activetrack.models.occluders.Occluders
        """Return an episode's occluders: the fixed ``occluders`` and ``random_occluders``
        rectangles drawn from ``rng`` (:func:`activetrack.models.occluders.random_layout`).

        Raises ``ValueError`` naming the fields when the rectangles cannot be placed, and
        ``TypeError`` for an ``rng`` that is not a ``numpy.random.Generator``.
        """
        return self.draw_occluder_batch([rng])[0]

    def draw_occluder_batch(self, rngs: Any):  # -> Occluders, batched
        """Return the batched occluders of episodes drawn from ``rngs`` (one layout each, as
        :meth:`draw_occluders`; :func:`activetrack.models.occluder_layouts.layout_batch`)."""
        from activetrack.models.occluder_layouts import layout_batch  # noqa: PLC0415

        return layout_batch(self, rngs)

    def _check_information_ratio(self) -> None:
        """Check the coupled limit of the class docstring (one update's variance reduction)."""
        ratio = max(
            float(np.max(np.diag(mdl.predict(np.zeros(mdl.dim), P0)[1])[:2]))
            for mdl, P0 in zip(self.target_models, self.initial_covs, strict=True)
        ) / float(np.min(self.per_sensor("sigma_d2")))
        if not ratio <= INFORMATION_RATIO_MAX:
            raise ValueError(
                "sigma_d2 is too small for the predicted position variance "
                f"({ratio:.3g} times larger; at most {INFORMATION_RATIO_MAX:g}): "
                "raise sigma_d2 or lower q, dt or P0"
            )

    # Derived arrays -------------------------------------------------------------------
    @property
    def model(self) -> LinearMotionModel:
        """Return the target motion model (the first target's when K > 1; built once)."""
        return self.target_models[0]

    @property
    def target_models(self) -> tuple[LinearMotionModel, ...]:
        """Return every target's motion model (K of them; built once)."""
        if "models" not in self._cache:
            kk = self.n_targets
            motions = self.motion if isinstance(self.motion, tuple) else (self.motion,) * kk
            qs = self.q if isinstance(self.q, tuple) else (self.q,) * kk
            self._cache["models"] = tuple(
                mo if isinstance(mo, LinearMotionModel) else make_model(mo, q, self.dt)
                for mo, q in zip(motions, qs, strict=True)
            )
        return self._cache["models"]

    @property
    def initial_cov(self) -> FloatArray:
        """Return P0 as a full matrix (the first target's when K > 1; a fresh copy)."""
        return self.initial_covs[0].copy()

    @property
    def initial_covs(self) -> tuple[FloatArray, ...]:
        """Return every target's P0 as a full matrix (validated once; do not modify)."""
        if "P0" not in self._cache:

            def full(p: object) -> FloatArray:
                arr = np.asarray(p, dtype=np.float64)
                return np.diag(arr) if arr.ndim == 1 else arr

            kk = self.n_targets
            shared = kk == 1 or not isinstance(self.P0[0], tuple)
            covs = (full(self.P0),) * kk if shared else tuple(full(p) for p in self.P0)
            self._cache["P0"] = covs
        return self._cache["P0"]

    def target_states(self, key: str) -> tuple[FloatArray, ...]:
        """Return ``x0`` or ``x0_hat`` as K float64 vectors (one per target)."""
        if key not in ("x0", "x0_hat"):
            raise ValueError(f"key must be 'x0' or 'x0_hat', got {key!r}")
        v = getattr(self, key)
        rows = (v,) if self.n_targets == 1 else v
        return tuple(np.asarray(r, dtype=np.float64) for r in rows)

    @property
    def sensor_models(self) -> np.ndarray:
        """Return the per-sensor model codes (M,) int8 (0 range-bearing, 1 range, 2 bearing)."""
        # (a model of one's own: the code of the built-in filling the same slots)
        return np.array([slot_code(s) for s in self.sensor_objects], dtype=np.int8)

    @property
    def sensor_objects(self) -> tuple[SensorModel, ...]:
        """Return each sensor's :class:`activetrack.SensorModel` (M,)."""
        names = self.sensor_model
        names = names if isinstance(names, tuple) else (names,) * self.n_sensors
        return tuple(as_sensor_model(n) for n in names)

    @property
    def pose_covariances(self) -> FloatArray | None:
        """Return the per-sensor pose covariances (M, 2, 2), or None when all are zero."""
        arr = np.asarray(self.pose_cov, dtype=np.float64)
        if not np.any(arr):
            return None
        m = self.n_sensors
        if arr.ndim <= 1:
            return np.broadcast_to(arr, (m,))[:, None, None] * np.eye(2)
        return np.array(np.broadcast_to(arr, (m, 2, 2)))

    @property
    def occluder_set(self):  # -> activetrack.models.occluders.Occluders | None
        """Return the occluders as an :class:`activetrack.models.occluders.Occluders`, or None."""
        if not self.occluders:
            return None
        occ = self._cache.get("occluders")
        if occ is None:
            from activetrack.models.occluders import Occluders  # noqa: PLC0415

            occ = self._cache["occluders"] = Occluders.from_polygons(self.occluders)
        return occ

    @property
    def max_ranges(self) -> FloatArray | None:
        """Return the per-sensor sensing ranges (M,), or None when unlimited."""
        if self.max_range is None:
            return None
        return np.broadcast_to(
            np.asarray(self.max_range, dtype=np.float64), (self.n_sensors,)
        ).copy()

    @property
    def detection_probs(self) -> FloatArray | None:
        """Return the per-sensor detection probabilities (M,), or None when all are 1."""
        p = np.broadcast_to(np.asarray(self.p_detect, dtype=np.float64), (self.n_sensors,))
        return None if np.all(p == 1.0) else p.copy()

    @property
    def limited_sensing(self) -> bool:
        """Return whether a sensor may miss a target (a finite range, p_detect < 1 or
        occluders)."""
        return self.max_range is not None or self.detection_probs is not None or self.has_occluders

    @property
    def has_occluders(self) -> bool:
        """Return whether episodes have occluders (fixed or random)."""
        return bool(self.occluders) or self.random_occluders > 0

    @property
    def capabilities(self) -> Capabilities:
        """Return which of the paper's special cases this scenario is in
        (:class:`activetrack.world.capabilities.Capabilities`): what decides the world's,
        the observation's and the planners' fast paths."""
        caps = self._cache.get("capabilities")
        if caps is None:
            caps = self._cache["capabilities"] = Capabilities.of(self)
        return caps

    @property
    def is_paper_model(self) -> bool:
        """Return whether this is the paper's measurement setup: one target, every sensor
        range-and-bearing, poses known, unlimited sensing, the trace objective, the EKF
        (today's arithmetic applies; ``capabilities.paper_model``)."""
        return self.capabilities.paper_model

    def per_sensor(self, name: str) -> FloatArray:
        """Return the per-sensor parameter ``name`` as an (M,) array."""
        if name not in _PER_SENSOR:
            raise ValueError(f"name must be one of {list(_PER_SENSOR)}, got {name!r}")
        values = np.asarray(getattr(self, name), dtype=np.float64)
        return np.broadcast_to(values, (self.n_sensors,)).copy()

    @property
    def r(self) -> FloatArray:
        """Return the per-sensor reach ``r_i = vmax_i dt`` (eq. 13), or each kinematics'
        radius when ``kinematics`` is given."""
        if self.kinematics is not None:
            return team.radii(self.kinematics, self.n_sensors)
        return self.per_sensor("vmax") * self.dt

    @property
    def kinematics_models(self) -> tuple:  # tuple[activetrack.Kinematics, ...]
        """Return each sensor's kinematics (M,): ``Disk(vmax_i dt)`` unless given."""
        return team.models(self.kinematics, self.r)

    def replace(self, **overrides: Any) -> Scenario:
        """Return a copy with fields overridden (validated)."""
        return make_scenario(self, **overrides)

    def to_dict(self) -> dict[str, Any]:
        """Return the fields as JSON-friendly values (a custom motion model by name, a new
        objective as ``{"name": its name, "class": "module.QualifiedName"}``).

        The fields beyond the paper's (:data:`EXTENSIONS`) appear only when they differ
        from their defaults, so a paper-like scenario's record is what it always was.
        """
        out = {}
        for f in dataclasses.fields(self):
            if f.name.startswith("_"):
                continue
            v = getattr(self, f.name)
            if f.name in EXTENSIONS and _same(v, f.default):
                continue
            if isinstance(v, tuple) and any(isinstance(e, LinearMotionModel) for e in v):
                v = tuple(e.name if isinstance(e, LinearMotionModel) else e for e in v)
            if isinstance(v, SensorModel) or (
                isinstance(v, tuple) and any(isinstance(e, SensorModel) for e in v)
            ):  # a record of which model, as for an objective
                v = record(v)
            if isinstance(v, Objective):  # a record of which objective, not its code
                cls = type(v)
                v = {"name": v.name, "class": f"{cls.__module__}.{cls.__qualname__}"}
            if f.name == "kinematics":  # a record of which kinematics, not its code
                v = [{"name": k.name, "class": f"{type(k).__module__}.{type(k).__qualname__}",
                      "radius": k.radius} for k in self.kinematics_models]  # fmt: skip
            if f.name == "target_behaviour":  # a record of which behaviours, not their code
                v = behaviours.record(v)
            v = imm_tracking.record(v) if f.name == "estimator" else v
            v = team_filters.record(v) if f.name == "communication" else v
            v = repr(v) if f.name == "births" and v is not None else v
            out[f.name] = v.name if isinstance(v, LinearMotionModel) else v
        return out


def _same(a: object, b: object) -> bool:
    """Return whether ``a == b`` is plainly true (False for arrays and incomparable values)."""
    try:
        return bool(a == b)
    except (TypeError, ValueError):
        return False


#: The per-sensor fields :func:`make_scenario` repeats for a new team size.
_TEAM_FIELDS = (*_PER_SENSOR, "sensor_model", "pose_cov", "max_range", "p_detect", "kinematics",
                "d_sep")  # fmt: skip


def _per_sensor_tuple(key: str, value: object) -> bool:
    """Return whether ``value`` of field ``key`` holds one entry per sensor (a tuple or
    list; for ``pose_cov`` of variances or of 2x2 matrices, not one matrix)."""
    if not isinstance(value, (tuple, list)) or not value:
        return False
    if key == "pose_cov":
        try:
            return np.asarray(value, dtype=np.float64).ndim in (1, 3)
        except (TypeError, ValueError):
            return False  # Scenario names the field
    return True


def make_scenario(scenario: str | Scenario = "paper", **overrides: Any) -> Scenario:
    """Return the named preset (or a given scenario) with ``overrides`` applied.

    A new team size repeats the team (every preset alike): when ``n_sensors`` changes,
    each per-sensor field the base holds as a tuple of its L sensors (``sigma_d2``,
    ``sigma_theta2``, ``vmax``, ``rho``, ``orientation``, ``sensor_model``, ``pose_cov``,
    ``max_range``, ``p_detect``) and that is not overridden gives sensor ``i`` the value of
    the base's sensor ``i mod L``: ``make_scenario("paper", n_sensors=6)`` is the paper's
    team twice, ``make_scenario("mixed", n_sensors=2)`` its first two sensors. Fields given
    as one value for every sensor stay so. ``max_cycles`` (PettingZoo's
    episode-length keyword) is accepted as ``n_steps``. An unknown keyword raises
    :class:`~activetrack.validation.UnexpectedKeywordError` (a ``TypeError`` worded like
    Python's, and a ``ValueError``).
    """
    if isinstance(scenario, Scenario):
        base = {f.name: getattr(scenario, f.name) for f in dataclasses.fields(Scenario) if f.init}
    elif isinstance(scenario, str) and scenario in PRESETS:
        base = {f.name: f.default for f in dataclasses.fields(Scenario) if f.init}
        base.update(PRESETS[scenario])
    else:
        raise ValueError(
            f"scenario must be one of {sorted(PRESETS)} or a Scenario, got {scenario!r}"
        )
    if "max_cycles" in overrides:
        cycles = overrides.pop("max_cycles")
        if "n_steps" in overrides and not _same(overrides["n_steps"], cycles):
            raise ValueError(
                f"max_cycles is n_steps: give one of them, got max_cycles={cycles!r} "
                f"and n_steps={overrides['n_steps']!r}"
            )
        overrides["n_steps"] = cycles
    for key in overrides:
        if key not in base:
            raise UnexpectedKeywordError(
                f"make_scenario() got an unexpected keyword argument {key!r}; "
                f"valid scenario fields: {sorted(base)} (and max_cycles for n_steps)"
            )
    m = overrides.get("n_sensors", base["n_sensors"])
    if isinstance(m, (int, np.integer)) and not isinstance(m, (bool, np.bool_)):
        for key in _TEAM_FIELDS:  # (an invalid n_sensors: Scenario says)
            val = base[key]
            if key not in overrides and _per_sensor_tuple(key, val) and len(val) != m:
                base[key] = tuple(val[i % len(val)] for i in range(min(m, N_SENSORS_MAX)))
    base.update(overrides)
    return Scenario(**base)
