"""Observation and global-state encoding of the tracking loop (pure, batched).

At step k every agent sees what the planners of Section IV see (eq. 15-17): the
prediction ``x_hat(k+1|k)``, ``P(k+1|k)`` (only its position block matters, Lemma 1), all
sensors' current positions and all their parameters. Everything is made dimensionless
with one length scale ``L`` (:func:`length_scale`, 23.1 m in the paper's scenario) and
variances go through logarithms, so the entries are O(1) and the map is invertible
(:func:`decode_target`, :func:`decode_sensors`).

Target block (5 entries), shared by all agents::

    0  ln(sigma_x / L)         sigma_x^2 = P(k+1|k)[0, 0]
    1  ln(sigma_y / L)         sigma_y^2 = P(k+1|k)[1, 1]
    2  corr = P[0, 1] / (sigma_x sigma_y)       in (-1, 1)
    3  v_x dt / L              predicted target velocity x_hat(k+1|k)[2:4] as the
    4  v_y dt / L              displacement per step (0 for a position-only model)

Sensor block of sensor j (6 entries)::

    0  (x_S_j(k) - x_hat_T(k+1|k)) / L      the c_j of eq. (15) over L
    1  (y_S_j(k) - y_hat_T(k+1|k)) / L
    2  ln(sigma_d_j / L)                    sigma_d_j^2 = range noise variance (m^2)
    3  ln(sigma_theta_j)                    sigma_theta_j^2 = bearing noise variance (rad^2)
    4  r_j / L                              reach per step, vmax_j dt (eq. 13)
    5  rho_j / L                            minimum distance to the predicted target (eq. 14)

Agent i's observation is the target block, then the sensor blocks of sensors
``i, i+1, ..., i+M-1 (mod M)``: its own block first, the others in cyclic order, so
every agent sees the team from its own seat. Size ``5 + 6M``. The global state is the
target block, the sensor blocks of sensors ``0..M-1`` and the elapsed fraction
``k / n_steps`` of the episode. Size ``6 + 6M``.

**Extended layout** (any scenario that is not one target seen by range-and-bearing sensors
at known positions: several targets, other sensor models, uncertain poses). The frame's
origin is the centroid ``o`` of the K predicted target positions. Target block of target
k (7 entries)::

    0  (x_hat_k - o_x) / L      predicted position x_hat_k(k+1|k) relative to the centroid
    1  (y_hat_k - o_y) / L
    2  ln(sigma_x / L)          as entries 0-4 of the paper's target block
    3  ln(sigma_y / L)
    4  corr
    5  v_x dt / L
    6  v_y dt / L

Sensor block of sensor j (12 entries)::

    0  (x_j - o_x) / L          the sensor's position fix relative to the centroid
    1  (y_j - o_y) / L
    2  ln(sigma_d_j / L)        0 for a sensor that does not measure range
    3  ln(sigma_theta_j)        0 for a sensor that does not measure bearing
    4  r_j / L
    5  rho_j / L
    6  1 if range and bearing   one-hot sensor model
    7  1 if range only
    8  1 if bearing only
    9  sqrt(Sigma_11) / L       the sensor's pose covariance (0, 0, 0 when known)
    10 sqrt(Sigma_22) / L
    11 corr(Sigma)              0 when a variance is 0

Agent i's observation: the K target blocks (target order), then the sensor blocks in
agent i's cyclic order; size ``7K + 12M``; the global state adds ``k / n_steps``.

**Limited sensing** (a finite ``max_range``, ``p_detect < 1`` or occluders: the extended
layout always). Each sensor block gains K entries after entry 11: ``12 + k`` is 1 if sensor
j measured target k at the last step, else 0 (0 after a reset). With occluders each agent's
observation ends with its own :data:`RAYS` range-finder readings: rays at the angles
``2 pi r / RAYS`` (world frame) from the sensor's true position, the distance to the first
occluder edge over :data:`RAY_MAX` (1: nothing within ``RAY_MAX`` m). Sizes: sensor
block ``12 + K``, observation ``7K + (12 + K) M (+ RAYS)``; the global state holds every
agent's rays (``M RAYS``) before ``k / n_steps``.

**Route readings** (``route_observation``): after the rays, each agent's way round the
occluders to each target's prediction, 3 entries per target: the unit direction (world
frame) of the way's first leg and the detour ratio, straight distance over the way's
length, in (0, 1] (:func:`activetrack.models.roadmap.route_readings`); the global state
holds every agent's (``3 K M``) after the rays.

**A state beyond the position** (a kinematics with ``n_features > 0``:
:mod:`activetrack.world._motion_state`). Each agent's observation (either layout) ends
with its own F kinematic features (``Layout.motion``: a unicycle's heading as ``(cos,
sin)``, a double integrator's velocity over its top speed; zero-padded to the team's
largest F), in [-1, 1]; the global state holds every agent's (``M F``) after the rays and
before ``k / n_steps``.

**Targets that appear and leave** (``births``): each agent's observation ends with K
entries, 1 if the team holds a track in slot k, else 0 (a slot without one shows a search
point in its target block: :mod:`activetrack.world.track_management`); the global state
holds every agent's (``M K``) last before ``k / n_steps``.
:class:`Layout` says which layout a scenario uses and its sizes and bounds.

**Bounds** (:meth:`Layout.bounds`, the spaces' boxes). Bounded by definition: the
correlations (in [-1, 1]), the one-hot and detection entries and the rays (in [0, 1]), the
elapsed fraction of the global state (in [0, 1]), ``r / L`` and ``rho / L`` (in [0, 1]:
``L >= rho_i + r_i``, :func:`length_scale`), and the other sensor constants by the ranges
a scenario accepts (:mod:`activetrack.world.scenarios`): ``ln(sigma_d / L)`` by
``SIGMA_D2_RANGE``, ``ln(sigma_theta)`` by ``SIGMA_THETA2_RANGE``, the pose standard
deviations over ``L`` by ``POSE_COV_MAX`` (each range widened to hold 0, the entry of a
sensor without that quantity). Unbounded by nature: a target that outruns the team takes
the relative positions and the velocity anywhere, and a lost target's standard deviations
grow without limit. These are clipped: positions and displacements per step over ``L``
to +-:data:`POSITION_MAX` (1e6: a sensor moves at most ``r <= L`` a step, so its own
motion takes a million steps to get there), ``ln(sigma / L)`` to +-:data:`LOG_STD_MAX`
(50: ``sigma`` between 2e-22 L and 5e21 L). Far beyond any tracking, the clips change no
value of a working episode; the inverse maps (:func:`decode_target`,
:func:`decode_sensors`) hold inside them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from activetrack._jit import as_rows
from activetrack.models.roadmap import ROUTE_DIM, route_bounds
from activetrack.validation import FloatArray
from activetrack.world import _observation_kernels as obk
from activetrack.world._observation_kernels import LOG_STD_MAX, POSITION_MAX
from activetrack.world._scenario_fields import POSE_COV_MAX, SIGMA_D2_RANGE, SIGMA_THETA2_RANGE
from activetrack.world.scenarios import Scenario

TARGET_DIM = 5
SENSOR_DIM = 6
#: Block sizes of the extended layout.
EXT_TARGET_DIM = 7
EXT_SENSOR_DIM = 12
#: Range-finder rays per agent with occluders, and their maximum distance (m).
RAYS = 16
RAY_MAX = 10.0
#: The rays' unit directions (RAYS, 2).
RAY_DIRECTIONS = np.stack(
    [np.cos(2 * np.pi * np.arange(RAYS) / RAYS), np.sin(2 * np.pi * np.arange(RAYS) / RAYS)], -1
)


@dataclass(frozen=True)
class Layout:
    """Which observation layout a scenario uses, and its sizes.

    Attributes:
        extended: False for the paper's layout (one target, range-and-bearing sensors at
            known positions: ``5 + 6M``), True for the extended one (``7K + 12M``).
        n_targets: K.
        n_sensors: M.
        flags: detection flags per sensor block (K with limited sensing, else 0).
        rays: range-finder rays per agent (:data:`RAYS` with occluders, else 0).
        motion: the kinematic features per agent (the largest ``n_features`` of the
            team's kinematics: a heading's ``(cos, sin)``, a velocity over the top speed),
            in [-1, 1], at the end of its observation; the global state holds every agent's
            after the rays.
        route: the route readings per agent (:data:`ROUTE_DIM` per target with
            ``route_observation``, else 0; :func:`route_readings`), after the rays; the
            global state holds every agent's after the rays.
        tracks: the track flags per agent (K with ``births``, else 0), last.
    """

    extended: bool
    n_targets: int
    n_sensors: int
    flags: int = 0
    rays: int = 0
    motion: int = 0
    route: int = 0
    tracks: int = 0

    @property
    def target_dim(self) -> int:
        """Return the entries of all target blocks."""
        return EXT_TARGET_DIM * self.n_targets if self.extended else TARGET_DIM

    @property
    def sensor_dim(self) -> int:
        """Return the entries of one sensor block."""
        return EXT_SENSOR_DIM + self.flags if self.extended else SENSOR_DIM

    @property
    def obs_dim(self) -> int:
        """Return the size of one agent's observation."""
        return (
            self.target_dim + self.sensor_dim * self.n_sensors + self.rays + self.route
            + self.motion + self.tracks
        )  # fmt: skip

    @property
    def state_dim(self) -> int:
        """Return the size of the global state."""
        per_agent = self.rays + self.route + self.motion + self.tracks
        return self.target_dim + self.sensor_dim * self.n_sensors + per_agent * self.n_sensors + 1

    def sensor_constants(self, sc: Scenario, L: float) -> FloatArray:
        """Return the constant entries of every sensor block: (M, 4) or (M, 10)."""
        sd2, st2 = sc.per_sensor("sigma_d2"), sc.per_sensor("sigma_theta2")
        base = sensor_constants(sd2, st2, sc.r, sc.per_sensor("rho"), L)
        if not self.extended:
            return base
        # Each model's slots (M, 2): which noise entries it has. The one-hot is its built-in
        # code, or for a model of one's own that of the built-in filling the same slots.
        uses = np.array([m.slots for m in sc.sensor_objects], dtype=bool).reshape(-1, 2)
        base[:, :2] = np.where(uses, base[:, :2], 0.0)
        onehot = np.eye(3)[sc.sensor_models]
        cov = sc.pose_covariances
        pose = np.zeros((sc.n_sensors, 3))
        if cov is not None:
            sx, sy = np.sqrt(cov[:, 0, 0]), np.sqrt(cov[:, 1, 1])
            both = (sx > 0) & (sy > 0)
            pose[:, 0], pose[:, 1] = sx / L, sy / L
            pose[:, 2] = np.where(both, cov[:, 0, 1] / np.where(both, sx * sy, 1.0), 0.0)
        return np.concatenate([base, onehot, pose], -1)

    def bounds(self, length_scale: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Return float32 ``(low, high)`` of one agent's observation (module docstring,
        "Bounds"); without the ``length_scale`` L the log noise entries and the pose
        standard deviations are left unbounded (their bounds scale with L)."""
        if self.tracks:  # the track flags, last, in [0, 1]
            low, high = replace(self, tracks=0).bounds(length_scale)
            one = np.ones(self.tracks, dtype=np.float32)
            return np.concatenate([low, 0.0 * one]), np.concatenate([high, one])
        if self.motion:  # the agent's kinematic features, last, in [-1, 1]
            low, high = replace(self, motion=0).bounds(length_scale)
            one = np.ones(self.motion, dtype=np.float32)
            return np.concatenate([low, -one]), np.concatenate([high, one])
        if self.route:  # the route readings, after the rays
            low, high = replace(self, route=0).bounds(length_scale)
            lo, hi = route_bounds(self.route // ROUTE_DIM)
            return np.concatenate([low, lo]), np.concatenate([high, hi])
        if not self.extended:
            return observation_bounds(self.n_sensors, length_scale)
        low = np.full(self.obs_dim, -np.inf, dtype=np.float32)
        high = np.full(self.obs_dim, np.inf, dtype=np.float32)
        for k in range(self.n_targets):
            b = EXT_TARGET_DIM * k
            _clipped(low, high, [b, b + 1, b + 5, b + 6], POSITION_MAX)
            _clipped(low, high, [b + 2, b + 3], LOG_STD_MAX)
            low[b + 4], high[b + 4] = -1.0, 1.0
        for j in range(self.n_sensors):
            b = self.target_dim + self.sensor_dim * j
            _clipped(low, high, [b, b + 1], POSITION_MAX)
            _sensor_constant_bounds(low, high, b, length_scale, with_zero=True)
            low[b + 6 : b + 11] = 0.0  # one-hot, pose standard deviations
            high[b + 6 : b + 9] = 1.0
            if length_scale is not None:
                high[b + 9 : b + 11] = np.sqrt(POSE_COV_MAX) / length_scale
            low[b + 11], high[b + 11] = -1.0, 1.0
            low[b + 12 : b + 12 + self.flags] = 0.0  # detection flags
            high[b + 12 : b + 12 + self.flags] = 1.0
        if self.rays:
            low[-self.rays :], high[-self.rays :] = 0.0, 1.0
        return low, high

    def state_bounds(self, length_scale: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Return float32 ``(low, high)`` of the global state (:meth:`bounds`, every
        agent's rays and kinematic features, and the elapsed fraction in [0, 1])."""
        low, high = replace(self, motion=0, route=0, tracks=0).bounds(length_scale)
        if self.rays:  # every agent's rays instead of one agent's
            extra = np.float32(np.ones(self.rays * (self.n_sensors - 1)))
            low = np.concatenate([low, 0.0 * extra]).astype(np.float32)
            high = np.concatenate([high, extra]).astype(np.float32)
        if self.route:  # every agent's route readings
            lo, hi = route_bounds(self.route // ROUTE_DIM)
            low = np.concatenate([low, np.tile(lo, self.n_sensors)])
            high = np.concatenate([high, np.tile(hi, self.n_sensors)])
        if self.motion:
            one = np.ones(self.motion * self.n_sensors, dtype=np.float32)
            low, high = np.concatenate([low, -one]), np.concatenate([high, one])
        if self.tracks:
            one = np.ones(self.tracks * self.n_sensors, dtype=np.float32)
            low, high = np.concatenate([low, 0.0 * one]), np.concatenate([high, one])
        return np.append(low, np.float32(0.0)), np.append(high, np.float32(1.0))


def _clipped(low: np.ndarray, high: np.ndarray, idx: list[int], bound: float) -> None:
    """Set the bounds of the clipped entries ``idx`` to ``[-bound, bound]``."""
    low[idx], high[idx] = -bound, bound


def _sensor_constant_bounds(
    low: np.ndarray, high: np.ndarray, b: int, L: float | None, with_zero: bool
) -> None:
    """Set the bounds of entries 2-5 of the sensor block at ``b``: ``ln(sigma_d / L)`` and
    ``ln(sigma_theta)`` by the ranges a scenario accepts (with 0 if ``with_zero``: the
    extended layout's entry of a sensor without that measurement; float32 of the float64
    ends, which hold every float32 entry rounded from a value between them), ``r / L`` and
    ``rho / L`` in [0, 1]."""
    if L is not None:
        lo_d, hi_d = (0.5 * np.log(v / L**2) for v in SIGMA_D2_RANGE)
        lo_t, hi_t = (0.5 * np.log(v) for v in SIGMA_THETA2_RANGE)
        if with_zero:
            lo_d, hi_d, lo_t, hi_t = min(lo_d, 0), max(hi_d, 0), min(lo_t, 0), max(hi_t, 0)
        low[b + 2 : b + 4] = np.float32([lo_d, lo_t])
        high[b + 2 : b + 4] = np.float32([hi_d, hi_t])
    low[b + 4 : b + 6], high[b + 4 : b + 6] = 0.0, 1.0


def layout_of(sc: Scenario) -> Layout:
    """Return the layout of scenario ``sc``: the paper's when its capabilities say so
    (``paper_observation``), else the extended one, with detection flags unless sensing
    is unlimited and range-finder rays when there are occluders."""
    caps = sc.capabilities
    motion = 0 if sc.kinematics is None else max(k.n_features for k in sc.kinematics_models)
    return Layout(
        not caps.paper_observation, sc.n_targets, sc.n_sensors,
        0 if caps.unlimited_sensing else sc.n_targets, 0 if caps.no_occluders else RAYS,
        int(motion), ROUTE_DIM * sc.n_targets if sc.route_observation else 0,
        0 if sc.births is None else sc.n_targets,
    )  # fmt: skip


def features(
    x_preds: list[FloatArray],
    P_preds: list[FloatArray],
    fixes: FloatArray,
    constants: FloatArray,
    dt: float,
    L: float,
    extended: bool,
    detected: np.ndarray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Return the target blocks (..., TD) and sensor blocks (..., M, SD) of either layout
    (``extended``; the paper's takes one prediction and the sensors' positions as
    ``fixes``), float64 (:func:`activetrack.world._observation_kernels.features_rows`)."""
    fixes, constants = np.asarray(fixes, np.float64), np.asarray(constants, np.float64)
    args, batch = _kernel_args(x_preds, P_preds, fixes, constants, detected)
    x, m = args[0], fixes.shape[-2]
    td = EXT_TARGET_DIM * x.shape[1] if extended else TARGET_DIM
    target = np.empty((x.shape[0], td))
    sensor = np.empty((x.shape[0], m, 2 + constants.shape[-1] + args[-1]))
    obk.features_rows(*args[:4], float(dt), float(L), extended, *args[4:], target, sensor)
    return target.reshape(batch + (td,)), sensor.reshape(batch + sensor.shape[1:])


def encode(
    x_preds: list[FloatArray],
    P_preds: list[FloatArray],
    fixes: FloatArray,
    constants: FloatArray,
    dt: float,
    L: float,
    extended: bool,
    detected: np.ndarray | None,
    order: np.ndarray,
    n_rays: int = 0,
) -> np.ndarray:
    """Return every agent's observation, float32 (..., M, D): :func:`observations` of
    :func:`features` in one compiled pass, with room for ``n_rays`` range-finder readings
    last that the caller fills (:func:`ray_readings` with ``out=``)."""
    fixes, constants = np.asarray(fixes, np.float64), np.asarray(constants, np.float64)
    order = _checked_order(order, fixes.shape[-2])
    args, batch = _kernel_args(x_preds, P_preds, fixes, constants, detected)
    x, m = args[0], fixes.shape[-2]
    td = EXT_TARGET_DIM * x.shape[1] if extended else TARGET_DIM
    d = td + (2 + constants.shape[-1] + args[-1]) * m + n_rays
    out = np.empty((x.shape[0], m, d), dtype=np.float32)
    obk.observe_rows(*args[:4], float(dt), float(L), extended, *args[4:], order, out)
    return out.reshape(batch + (m, d))


def _checked_order(order: np.ndarray, m: int) -> np.ndarray:
    """Return ``order`` as the kernels' (M, M) int64 table, or raise ValueError: the
    kernels index with it unchecked."""
    if order is _CYCLIC.get(m):  # the tables cyclic_order hands out: read-only, valid
        return order
    table = np.asarray(order)
    if table.shape != (m, m) or not np.issubdtype(table.dtype, np.integer):
        raise ValueError(
            f"order must be an ({m}, {m}) integer table, got {table.dtype} {table.shape}"
        )
    table = np.ascontiguousarray(table, np.int64)
    if m and (table.min() < 0 or table.max() >= m):
        raise ValueError(f"order must hold sensor indices in [0, {m - 1}]")
    return table


def _kernel_args(
    x_preds: list[FloatArray],
    P_preds: list[FloatArray],
    fixes: FloatArray,
    constants: FloatArray,
    detected: np.ndarray | None,
) -> tuple[tuple, tuple[int, ...]]:
    """Return the kernels' ``(x, P, fixes, constants, detected, flags)`` and the batch
    shape of ``fixes``: the predictions stacked (B, K, n), a target with a shorter state
    padded with zeros (only its position block and velocity are read)."""
    batch = fixes.shape[:-2]
    m, K = fixes.shape[-2], len(x_preds)
    dims = [x.shape[-1] for x in x_preds]
    if K == 1:  # views, no copies
        x = as_rows(x_preds[0], batch, (dims[0],))[:, None]
        P = as_rows(P_preds[0], batch, (dims[0], dims[0]))[:, None]
    else:
        n = max(dims)
        x, P = np.zeros(batch + (K, n)), np.zeros(batch + (K, n, n))
        for k, (xk, Pk) in enumerate(zip(x_preds, P_preds, strict=True)):
            x[..., k, : dims[k]] = xk
            P[..., k, : dims[k], : dims[k]] = Pk
        x, P = x.reshape(-1, K, n), P.reshape(-1, K, n, n)
    f = as_rows(fixes, batch, (m, 2))
    c = as_rows(constants, constants.shape[:1], constants.shape[1:])
    if detected is None:
        return (x, P, f, c, np.zeros((1, K, m), bool), 0), batch
    return (x, P, f, c, as_rows(detected, batch, (K, m), np.bool_), K), batch


def obs_dim(n_sensors: int) -> int:
    """Return the size of one agent's observation, ``5 + 6M``."""
    return TARGET_DIM + SENSOR_DIM * n_sensors


def state_dim(n_sensors: int) -> int:
    """Return the size of the global state, ``6 + 6M``."""
    return TARGET_DIM + SENSOR_DIM * n_sensors + 1


def length_scale(sc: Scenario) -> float:
    """Return ``L``: the farthest a sensor can start from the estimated target.

    ``L = ||sensor_center - x0_hat[:2]|| + sensor_radius`` (23.1 m for ``paper``; with K
    targets measured from their estimates' centroid, plus the farthest estimate from it), at least
    ``max(rho_i + r_i)`` and at least 1e-6 m so that it is never zero.
    """
    starts = np.array([x[:2] for x in sc.target_states("x0_hat")])
    centroid = starts.mean(axis=0)
    d = float(np.hypot(*(np.asarray(sc.sensor_center) - centroid)))
    spread = float(np.max(np.hypot(*(starts - centroid).T)))  # 0 for one target
    floor = float(np.max(sc.per_sensor("rho") + sc.r))
    return max(d + sc.sensor_radius + spread, floor, 1e-6)


def sensor_constants(
    sigma_d2: FloatArray, sigma_theta2: FloatArray, r: FloatArray, rho: FloatArray, L: float
) -> FloatArray:
    """Return the constant entries 2..5 of every sensor block, shape (M, 4)."""
    return np.stack([0.5 * np.log(sigma_d2 / L**2), 0.5 * np.log(sigma_theta2), r / L, rho / L], -1)


def target_features(x_pred: FloatArray, P_pred: FloatArray, dt: float, L: float) -> FloatArray:
    """Return the target block from the prediction ``(x_hat(k+1|k), P(k+1|k))``, (..., 5)."""
    x_pred, P_pred = np.asarray(x_pred, np.float64), np.asarray(P_pred, np.float64)
    batch = np.broadcast_shapes(x_pred.shape[:-1], P_pred.shape[:-2])
    one = np.zeros(batch + (1, 2))  # a sensor, whose block is not returned
    return features([x_pred], [P_pred], one, np.zeros((1, 4)), dt, L, False)[0]


def sensor_features(
    sensors: FloatArray, target_pos: FloatArray, constants: FloatArray, L: float
) -> FloatArray:
    """Return every sensor's block, shape (..., M, 6)."""
    sensors, target_pos = np.asarray(sensors, np.float64), np.asarray(target_pos, np.float64)
    batch = np.broadcast_shapes(sensors.shape[:-2], target_pos.shape[:-1])
    sensors = np.broadcast_to(sensors, batch + sensors.shape[-2:])
    unit = np.broadcast_to(np.eye(2), batch + (2, 2))  # (the target block is not returned)
    constants = np.asarray(constants, np.float64)
    return features([target_pos], [unit], sensors, constants, 1.0, L, False)[1]


def cyclic_order(n_sensors: int) -> np.ndarray:
    """Return the (M, M) index table whose row i is ``i, i+1, ..., i+M-1 (mod M)``
    (read-only, one per M)."""
    table = _CYCLIC.get(n_sensors)
    if table is None:
        idx = np.arange(n_sensors)
        table = _CYCLIC[n_sensors] = (idx[:, None] + idx[None, :]) % n_sensors
        table.flags.writeable = False
    return table


#: The tables of :func:`cyclic_order`, by M.
_CYCLIC: dict[int, np.ndarray] = {}


def observations(
    target: FloatArray, sensor: FloatArray, order: np.ndarray, n_rays: int = 0
) -> np.ndarray:
    """Return all agents' observations, float32 of shape (..., M, TD + M SD), from the
    target blocks (..., TD) and sensor blocks (..., M, SD): agent ``i`` sees the sensor
    blocks in the order ``order[i]`` (:func:`cyclic_order`); with room for ``n_rays``
    range-finder readings last that the caller fills (:func:`ray_readings` with ``out=``)."""
    m, td, sd = sensor.shape[-2], target.shape[-1], sensor.shape[-1]
    batch = sensor.shape[:-2]
    full = np.empty(batch + (m, td + sd * m + n_rays), dtype=np.float32)
    obk.windows_rows(
        as_rows(target, batch, (td,)), as_rows(sensor, batch, (m, sd)),
        _checked_order(order, m), full.reshape(-1, m, full.shape[-1]),
    )  # fmt: skip
    return full


def global_state(
    target: FloatArray,
    sensor: FloatArray,
    elapsed: FloatArray | float,
    rays: FloatArray | None = None,
    motion: FloatArray | None = None,
    route: FloatArray | None = None,
    tracks: FloatArray | None = None,
) -> np.ndarray:
    """Return the global state, float32 of shape (..., 6 + 6M): the target and sensor
    blocks, then every agent's ``rays`` (..., M, R), ``route`` readings (..., M, 3K),
    kinematic features ``motion`` (..., M, F) and track flags ``tracks`` (..., M, K), each
    if given, then the elapsed fraction."""
    m, td, sd = sensor.shape[-2], target.shape[-1], sensor.shape[-1]
    per_agent = [a for a in (rays, route, motion, tracks) if a is not None]
    extra = sum(a.shape[-1] * m for a in per_agent)
    out = np.empty(sensor.shape[:-2] + (td + sd * m + extra + 1,), dtype=np.float32)
    out[..., :td] = target
    out[..., td : td + sd * m] = sensor.reshape(sensor.shape[:-2] + (m * sd,))
    at = td + sd * m
    for a in per_agent:
        n = a.shape[-1] * m
        out[..., at : at + n] = a.reshape(a.shape[:-2] + (n,))
        at += n
    out[..., -1] = elapsed
    return out


def ray_readings(positions: FloatArray, occ: object, out: np.ndarray | None = None) -> FloatArray:
    """Return the range-finder readings (..., M, RAYS) in [0, 1] from sensors at
    ``positions`` (..., M, 2) among the occluders ``occ``
    (:func:`activetrack.models.occluders.ray_distances` over :data:`RAY_MAX`), written into
    ``out`` if given (float64 or float32, e.g. the observation's rays: no temporary)."""
    from activetrack.models import occluders  # noqa: PLC0415 (occluded scenarios only)

    positions = np.asarray(positions, np.float64)
    shape = positions.shape[:-1] + (RAYS,)
    if out is None:
        out = np.empty(shape)
    elif out.shape != shape or out.dtype not in (np.float32, np.float64):
        raise ValueError(
            f"out must be a float32 or float64 array of shape {shape}, got {out.dtype} {out.shape}"
        )
    return occluders._rays_into(positions, RAY_DIRECTIONS, occ, RAY_MAX, RAY_MAX, out)


def observation_bounds(
    n_sensors: int, length_scale: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Return float32 ``(low, high)`` of one agent's observation in the paper's layout.

    The correlation in [-1, 1]; the relative positions, velocity and log standard
    deviations clipped; ``r / L`` and ``rho / L`` in [0, 1]; the log noise entries by the
    ranges a scenario accepts, given the ``length_scale`` L, else unbounded (module
    docstring, "Bounds").
    """
    low = np.full(obs_dim(n_sensors), -np.inf, dtype=np.float32)
    high = np.full(obs_dim(n_sensors), np.inf, dtype=np.float32)
    _clipped(low, high, [0, 1], LOG_STD_MAX)
    low[2], high[2] = -1.0, 1.0  # correlation coefficient
    _clipped(low, high, [3, 4], POSITION_MAX)
    for j in range(n_sensors):
        b = TARGET_DIM + SENSOR_DIM * j
        _clipped(low, high, [b, b + 1], POSITION_MAX)
        _sensor_constant_bounds(low, high, b, length_scale, with_zero=False)
    return low, high


def state_bounds(
    n_sensors: int, length_scale: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Return float32 ``(low, high)`` of the global state in the paper's layout."""
    low, high = observation_bounds(n_sensors, length_scale)
    return np.append(low, np.float32(0.0)), np.append(high, np.float32(1.0))


def decode_target(target: FloatArray, dt: float, L: float) -> tuple[FloatArray, FloatArray]:
    """Return ``(P11, v)``: the 2x2 position covariance and velocity of a target block."""
    target = np.asarray(target, dtype=np.float64)
    sx, sy = L * np.exp(target[..., 0]), L * np.exp(target[..., 1])
    pxy = target[..., 2] * sx * sy
    P = np.stack([np.stack([sx * sx, pxy], -1), np.stack([pxy, sy * sy], -1)], -2)
    return P, target[..., 3:5] * (L / dt)


def decode_sensors(sensor: FloatArray, L: float) -> dict[str, FloatArray]:
    """Return the physical quantities of sensor blocks (..., M, 6) as a dict of arrays.

    Keys: ``rel`` (positions relative to the predicted target, m), ``sigma_d2``,
    ``sigma_theta2``, ``r``, ``rho``.
    """
    s = np.asarray(sensor, dtype=np.float64)
    return {
        "rel": s[..., :2] * L,
        "sigma_d2": (L * np.exp(s[..., 2])) ** 2,
        "sigma_theta2": np.exp(s[..., 3]) ** 2,
        "r": s[..., 4] * L,
        "rho": s[..., 5] * L,
    }
