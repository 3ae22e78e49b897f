"""The world's compiled fast paths: one copy, and the fused step.

:class:`activetrack.world.World` runs the general batched loop; when the scenario's
capabilities say so (:attr:`Capabilities.fused_step
<activetrack.world.capabilities.Capabilities.fused_step>`: one target, known sensor
positions, every sensor measures, the EKF of eq. 11) a whole step is one compiled call
(:mod:`activetrack.world._loop_kernels`), and a world of one copy keeps its state
unbatched so that its step, its store and its observation cost microseconds. This module
holds that code; the world calls it at its dispatch points (construction, step, store,
observe). Each function takes the world as its first argument and reads and writes its
private state directly: a single environment's step is measured in microseconds, so no
wrapper or check is repeated here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from activetrack._jit import as_rows
from activetrack.kinematics import sensor_motion
from activetrack.models.objective import combined
from activetrack.world import _loop_kernels as loop_kernels
from activetrack.world import _observation_kernels as observation_kernels
from activetrack.world import observation

if TYPE_CHECKING:
    from activetrack.validation import FloatArray
    from activetrack.world.world import World


def prepare(w: World) -> None:
    """Set the fused kernels' constant arguments on world ``w`` (built with ``w._fused``):
    the sensors' table and the target's matrices of the step, the observation's
    constants, and one copy's work arrays."""
    p, m, K = w.params, w.n_sensors, w.n_targets
    t0 = p.targets[0]
    table = np.empty((m, loop_kernels.TABLE_COLUMNS))
    table[:, loop_kernels.R], table[:, loop_kernels.RHO] = p.r, p.rho
    if w._team is not None:  # the team moves first (team_moves): the kernel keeps its points
        table[:, loop_kernels.R], table[:, loop_kernels.RHO] = np.inf, 0.0
    table[:, loop_kernels.ORIENTATION] = p.orientation
    table[:, loop_kernels.STD_D : loop_kernels.STD_T + 1] = p.noise_std
    table[:, loop_kernels.USE_D : loop_kernels.USE_T + 1] = p.uses
    table[:, loop_kernels.W_D], table[:, loop_kernels.W_T] = p.weights
    w._fused_args = (table, np.stack([t0.Phi, t0.noise_factor, t0.Q]))
    n0 = t0.dim  # one copy's work arrays: P Phi^T, the measurements, all sensors
    w._fused_work = (np.empty((n0, n0)), np.empty((m, 2)), np.ones(m, bool))
    w._arcs = arcs_args(w._team, p.rho, m)
    constants = np.ascontiguousarray(w._constants, np.float64)
    td = observation.EXT_TARGET_DIM * K if w._extended else observation.TARGET_DIM
    w._obs_args = (constants, float(w._dt), float(w.length_scale), w._extended)
    # The kernel's observation: the layout without the kinematic features (with_motion).
    w._fused_obs_shape = (m, w._obs_shape[1] - w.layout.motion)
    w._obs_work = (np.zeros((1, m), bool), np.empty(td),
                   np.empty((m, 2 + constants.shape[1])), w._order)  # fmt: skip


def step_one(w: World, absolute: bool, moves: Any, name: str) -> tuple[Any, Any, bool]:
    """Return ``(reward, terminated, truncated)`` of ``World._step`` of a fused world of
    one copy: one compiled call (:func:`activetrack.world._loop_kernels.advance_observe_row`)
    on its unbatched arrays, which also makes the observation :func:`observe_one` returns
    next."""
    st, t = w._s, w._t[0]
    if st["ended"]:
        w._not_running(0)
    moves = w._moves_array(moves, name, 0)
    sensors, x_true, P_pred = st["sensors"], t["x_true"], t["P_pred"]
    if w._team is not None:
        moves, team_projected = team_moves(w, absolute, moves, sensors, t["x_pred"], ...)
        absolute = True
    noise = w._noise_of(0, False)
    new_sensors, projected = np.empty(sensors.shape), np.empty(sensors.shape[0], bool)
    x_next_true, x_post, x_pred = (
        np.empty(x_true.shape),
        np.empty(x_true.shape),
        np.empty(x_true.shape),
    )
    P_post, P_next = np.empty(P_pred.shape), np.empty(P_pred.shape)
    obs = np.empty(w._fused_obs_shape, np.float32)
    trace, count = loop_kernels.advance_observe_row.dispatcher(  # (no wrapper call)
        moves, absolute, sensors, x_true, t["x_pred"], P_pred, noise, *w._fused_args,
        new_sensors, projected, x_next_true, x_post, P_post, x_pred, P_next,
        *w._fused_work, *w._obs_args, *w._obs_work, obs,
    )  # fmt: skip
    t["x_true"], t["x_hat"], t["P"], t["x_pred"], t["P_pred"] = (
        x_next_true, x_post, P_post, x_pred, P_next)  # fmt: skip
    if w._team is not None:  # the team's rule said which moves it projected
        projected, count = team_projected, int(np.count_nonzero(team_projected))
        obs = with_motion(w, obs, new_sensors, w._motion_next)
    w._obs_cache = obs
    trace = np.float64(trace)
    score = trace if w._plain else combined(
        w.objective, np.stack([w.objective.of_covariance(P_post)], -1)
    )  # fmt: skip
    terminated = trace > w._max_trace
    new = {"sensors": new_sensors, "fixes": new_sensors, "projected": projected,
           "trace": trace, "score": score, "terminated": terminated}  # fmt: skip
    if w._team is not None:
        w._motion_store(new, 0, False)
    return -w._scale * score, terminated, store_one(w, new, count > 0)


def store_one(w: World, new: dict[str, Any], projected: bool) -> bool:
    """Store a step's results ``new`` in world ``w`` of one copy (``projected``: whether a
    move was pushed out of a ``rho`` disk): by rebinding, no NumPy indexing; return
    ``truncated``."""
    st = w._s
    k = st["k"] + 1
    truncated = k >= w.episode_steps
    if projected:
        st["n_projected"] = st["n_projected"] + new["projected"]
    st.update(new, k=k, truncated=truncated, ended=bool(new["terminated"]) or truncated)
    return truncated


def advance_fused(
    w: World, moves: FloatArray, absolute: bool, noise: FloatArray, calc: Any
) -> tuple[FloatArray, np.ndarray, tuple[Any, ...]]:
    """Return ``(sensors, projected, (x_true, x_post, P_post, x_pred, P_pred, trace))``
    of one compiled step (:func:`activetrack.world._loop_kernels.advance_rows`) of the
    copies ``calc`` of a batched fused world ``w``."""
    st, t = w._s, w._t[0]
    sensors, x_true = st["sensors"][calc], t["x_true"][calc]
    x_pred, P_pred = t["x_pred"][calc], t["P_pred"][calc]
    n, m = x_true.shape[-1], w.n_sensors
    batch = x_true.shape[:-1]
    if w._team is not None:
        if w._arcs is not None and not absolute and w._rule is None:
            done = advance_arcs(w, moves, noise, calc)
            if done is not None:
                return done
        moves, team_projected = team_moves(w, absolute, moves, sensors, x_pred, calc)
        absolute = True
    out = (
        np.empty(sensors.shape), np.empty(sensors.shape[:-1], bool), np.empty(x_true.shape),
        np.empty(x_true.shape), np.empty(P_pred.shape), np.empty(x_true.shape),
        np.empty(P_pred.shape), np.empty(batch),
    )  # fmt: skip
    loop_kernels.advance_rows(  # (its count of projected moves: the caller's rows only)
        as_rows(moves, batch, (m, 2)), absolute, as_rows(sensors, batch, (m, 2)),
        as_rows(x_true, batch, (n,)), as_rows(x_pred, batch, (n,)),
        as_rows(P_pred, batch, (n, n)), as_rows(noise, batch, (w._n_noise,)),
        *w._fused_args, *out,
    )  # fmt: skip
    return out[0], out[1] if w._team is None else team_projected, out[2:]


def arcs_args(team: Any, rho: Any, m: int) -> tuple | None:
    """Return the constants of :func:`advance_arcs` for a team of ``m`` sensors that all
    move by one :class:`activetrack.Unicycle` (the class itself, with a reach): ``(kin,
    (v_min, v_max, w_max, dt), rho (1 - TOL), rho)`` (``rho`` (M,), the scenario's), else
    None."""
    from activetrack.kinematics.base import TOL  # noqa: PLC0415
    from activetrack.kinematics.unicycle import Unicycle  # noqa: PLC0415

    kin = None if team is None else team.shared
    if type(kin) is not Unicycle or team.state_dim != 3 or not kin.radius > 0.0:
        return None
    rho = np.broadcast_to(np.asarray(rho, np.float64), (m,))
    # (TeamMotion's test of a move into a rho disk: closer than rho (1 - TOL))
    inside = np.ascontiguousarray(rho * (1.0 - TOL))
    return kin, (kin.v_min, kin.v_max, kin.w_max, kin.dt), inside, rho


def advance_arcs(
    w: World, actions: FloatArray, noise: FloatArray, calc: Any
) -> tuple[FloatArray, np.ndarray, tuple[Any, ...]] | None:
    """Return :func:`advance_fused` of the actions of a team of unicycles (``w._arcs``; no
    team rule), the move and the step of every copy in one compiled call
    (:func:`activetrack.world._loop_kernels.advance_unicycle_rows`) but for the few copies
    with a move that ends inside the ``rho`` disk: those moves projected
    (:meth:`activetrack.kinematics.pieces.PiecewiseReach.project`, the next heading that of
    :meth:`~activetrack.Unicycle.command` reaching the point), then those copies advanced
    (:func:`activetrack.world._loop_kernels.advance_listed_rows`). The numbers of
    :func:`team_moves` then the compiled step, bit for bit. Keeps the next ``motion`` for
    ``World._motion_store``. None when a new position is not finite (the caller's path
    then raises)."""
    kin, arc, rho_inside, rho = w._arcs
    st, t = w._s, w._t[0]
    sensors, motion = st["sensors"][calc], st["motion"][calc]
    x_true, x_pred, P_pred = t["x_true"][calc], t["x_pred"][calc], t["P_pred"][calc]
    n, m = x_true.shape[-1], w.n_sensors
    batch = x_true.shape[:-1]
    ins = (
        as_rows(sensors, batch, (m, 2)), as_rows(motion, batch, (m, 1)),
        as_rows(x_true, batch, (n,)), as_rows(x_pred, batch, (n,)),
        as_rows(P_pred, batch, (n, n)), as_rows(noise, batch, (w._n_noise,)),
        *w._fused_args,
    )  # fmt: skip
    out = (
        np.empty(sensors.shape), np.empty(sensors.shape[:-1], bool), np.empty(x_true.shape),
        np.empty(x_true.shape), np.empty(P_pred.shape), np.empty(x_true.shape),
        np.empty(P_pred.shape), np.empty(batch),
    )  # fmt: skip
    heading, pending = np.empty(motion.shape), np.empty(batch, bool)
    count = loop_kernels.advance_unicycle_rows(
        as_rows(actions, batch, (m, 2)), *ins, *arc, rho_inside, *out, heading, pending
    )
    if count < 0:
        return None
    if count:  # (rare: a move into a rho disk) the team rule's projection, then the step
        rows = np.flatnonzero(pending)
        positions, projected = out[0], out[1]
        hit = projected[rows]
        states = np.concatenate([sensors[rows], motion[rows]], -1)[hit]  # (H, 3), in order
        want = positions[rows][hit]
        moved = np.array(want)
        copies, agents = np.nonzero(hit)
        for j, (b, i) in enumerate(zip(rows[copies].tolist(), agents.tolist(), strict=True)):
            moved[j] = kin.project(want[j], states[j], x_pred[b, None, :2], rho[i])
        if not np.isfinite(moved).all():
            return None
        sub = positions[rows]
        sub[hit] = moved
        positions[rows] = sub
        nxt = heading[rows]
        nxt[hit] = kin.advance(kin.command(moved, states), states)[..., 2:]
        heading[rows] = nxt
        loop_kernels.advance_listed_rows(rows, *ins[2:], positions, *out[2:])
    w._motion_next = heading
    return out[0], out[1], out[2:]


def team_moves(
    w: World, absolute: bool, moves: FloatArray, sensors: FloatArray, x_pred: FloatArray,
    calc: Any,
) -> tuple[FloatArray, np.ndarray]:  # fmt: skip
    """Return ``(positions, projected)`` of the sensors of a fused world ``w`` whose team
    moves by its kinematics (``w._team``): the generic path's move
    (``World._move_sensors``, which keeps the next ``motion``), from the sensors (known
    positions) about the predicted target ``x_pred[..., :2]``. The compiled step then takes
    the positions as they are (its table's reach infinite and ``rho`` zero: no clip, no
    projection), so the step's numbers are the generic path's."""
    move = sensor_motion.move_to if absolute else sensor_motion.apply_actions
    positions, projected = w._move_sensors(move, moves, sensors, sensors, x_pred[..., :2], calc)
    return np.ascontiguousarray(positions, np.float64), projected


def with_motion(w: World, obs: np.ndarray, sensors: FloatArray, motion: FloatArray) -> np.ndarray:
    """Return one copy's observation ``obs`` (M, D) with each agent's kinematic features
    last (what ``World.observe`` appends on the generic path)."""
    if not w._team.n_features:
        return obs
    features = w._team.features(w._team.states(sensors, motion))
    return np.concatenate([obs, features.astype(np.float32)], -1)


def observe_one(w: World) -> np.ndarray:
    """``World.observe`` of a fused world of one copy: the observation its last step made,
    or the kernel's (:func:`activetrack.world._observation_kernels.observe_rows`) on
    views of the world's own arrays, unchecked."""
    out = w._obs_cache
    if out is not None:  # handed out once: a second call makes a new array
        w._obs_cache = None
        return out
    t = w._t[0]
    x, P = t["x_pred"], t["P_pred"]
    n, (m, d) = x.shape[0], w._fused_obs_shape
    detected, target, sensor, order = w._obs_work
    out = np.empty((m, d), np.float32)
    observation_kernels.observe_rows.dispatcher(
        x.reshape(1, 1, n), P.reshape(1, 1, n, n), w._s["sensors"].reshape(1, m, 2),
        *w._obs_args, detected.reshape(1, 1, m), 0, order, out.reshape(1, m, d),
    )  # fmt: skip
    if w._team is not None:
        st = w._s
        out = with_motion(w, out, st["sensors"], st.get("motion"))
    return out


def observe_batch(w: World) -> np.ndarray:
    """``World.observe`` of every copy of a batched fused world ``w``: one compiled call
    (:func:`activetrack.world._observation_kernels.observe_rows`) on views of the world's
    own arrays, unchecked, into an array with room for the team's kinematic features,
    written last (a team of unicycles: compiled too,
    :func:`activetrack.world._observation_kernels.headings_into`)."""
    t, st = w._t[0], w._s
    x, P = t["x_pred"], t["P_pred"]
    n, (m, d) = x.shape[-1], w._fused_obs_shape
    N = x.shape[0]
    features = 0 if w._team is None else w._team.n_features
    out = np.empty((N, m, d + features), np.float32)
    detected, _, _, order = w._obs_work
    observation_kernels.observe_rows(
        as_rows(x, (N,), (n,))[:, None], as_rows(P, (N,), (n, n))[:, None],
        as_rows(st["sensors"], (N,), (m, 2)), *w._obs_args, detected.reshape(1, 1, m), 0,
        order, out,
    )  # fmt: skip
    if w._arcs is not None:
        observation_kernels.headings_into(as_rows(st["motion"], (N,), (m, 1)), out, d)
    elif features:
        out[..., d:] = w._team.features(w._team.states(st["sensors"], st.get("motion")))
    return out
