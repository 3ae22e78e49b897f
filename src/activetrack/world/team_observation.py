"""Observations for decentralized agents: the scenario field ``team_observation``.

With a communication model (:mod:`activetrack.world.team_filters`) and
``team_observation=True``, agent ``i`` observes only what robot ``i`` has: its own
estimate and the messages it received at the last step, never the global state (which
stays available, unchanged, to centralized critics: :meth:`World.state`). Always in the
extended layout's units (:mod:`activetrack.world.observation`), in robot ``i``'s own frame:
the origin ``o_i`` is the centroid of *its* K predicted target positions. Agent ``i``'s
observation::

    own part        its K target blocks (7 entries each) from its own prediction
                    x_hat_i(k+1|k), P_i(k+1|k); then its own sensor block (12 + flags
                    entries: its position fix, its constants, its detection flags)
    neighbours      M - 1 blocks, one per other robot j in agent i's cyclic order
                    (i+1, ..., i+M-1 mod M), each 1 + (12 + flags) + 2K entries:
                      0       mask: 1 if i received j's message at the last step, else 0
                      1 ..    j's sensor block in i's frame (its fix, constants, flags)
                      ...     j's predicted target positions (x_hat_j - o_i) / L, K pairs
                    every entry 0 when the mask is 0
    own tail        its range-finder rays, route readings and kinematic features, as in
                    the world's observation (when the scenario has them)

The neighbour blocks are a set with a mask: a permutation-invariant model (a deep set,
attention with the mask) reads them as such; their fixed number, M - 1, gives the Box
space. A message carries the sender's fix, constants, detection flags and its predicted
target positions: what its measurements need (measurement sharing) and a summary of its
estimate (estimate sharing sends the whole estimate).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from activetrack.world import observation
from activetrack.world._observation_kernels import POSITION_MAX
from activetrack.world.observation import EXT_TARGET_DIM


def _layout(world: Any) -> observation.Layout:
    """Return the world's observation layout, extended (the paper's scenario has the
    paper's layout; a decentralized agent's is always the extended one)."""
    return replace(world.layout, extended=True)


def constants(world: Any) -> np.ndarray:
    """Return the extended layout's constant entries of every sensor block (M, 10)."""
    return _layout(world).sensor_constants(world.scenario, world.length_scale)


def sizes(world: Any) -> tuple[int, int, int, int]:
    """Return ``(own, block, tail, total)``: the entries of the own part, of one neighbour
    block, of the own tail and of the whole observation."""
    lay, k, m = _layout(world), world.n_targets, world.n_sensors
    sd = observation.EXT_SENSOR_DIM + lay.flags
    own = EXT_TARGET_DIM * k + sd
    block = 1 + sd + 2 * k
    tail = lay.rays + lay.route + lay.motion
    return own, block, tail, own + (m - 1) * block + tail


def bounds(world: Any) -> tuple[np.ndarray, np.ndarray]:
    """Return float32 ``(low, high)`` of one agent's decentralized observation."""
    lay, m = _layout(world), world.n_sensors
    low, high = lay.bounds(world.length_scale)  # the extended layout's (module docstring)
    td = lay.target_dim
    sd = lay.sensor_dim
    own, block, tail, _ = sizes(world)
    sensor = slice(td, td + sd)
    nb_lo = np.concatenate([[0.0], low[sensor], np.full(block - 1 - sd, -POSITION_MAX)])
    nb_hi = np.concatenate([[1.0], high[sensor], np.full(block - 1 - sd, POSITION_MAX)])
    tl = slice(len(low) - tail, len(low))
    lo = np.concatenate([low[:own], np.tile(nb_lo, m - 1), low[tl]])
    hi = np.concatenate([high[:own], np.tile(nb_hi, m - 1), high[tl]])
    return lo.astype(np.float32), hi.astype(np.float32)


def observe(world: Any, index: int | None = None, tail: np.ndarray | None = None) -> np.ndarray:
    """Return every agent's decentralized observation, float32 (N, M, D) or (M, D) for copy
    ``index``; ``tail`` (..., M, T) the agents' own tails (the world's observation's last
    entries), or None when the layout has none."""
    k_t, m, L = world.n_targets, world.n_sensors, world.length_scale
    x_preds = [world.team_get("x_pred", index, k) for k in range(k_t)]  # (..., M, n)
    P_preds = [world.team_get("P_pred", index, k) for k in range(k_t)]
    fixes = np.asarray(world.get("fixes", index), np.float64)  # (..., M, 2)
    lead = fixes.shape[:-2]
    fixes_i = np.broadcast_to(fixes[..., None, :, :], lead + (m, m, 2))  # seen by robot i
    detected = None
    if world.layout.flags:
        det = np.asarray(world.get("detected", index))  # (..., K, M)
        detected = np.broadcast_to(det[..., None, :, :], lead + (m,) + det.shape[-2:])
    target, sensor = observation.features(
        x_preds, P_preds, fixes_i, world._team_constants, world._dt, L, True, detected
    )  # (..., M, 7K), (..., M, M, SD): robot i's frame on axis -3 / -2
    pos = np.stack([x[..., :2] for x in x_preds], -2)  # (..., M, K, 2)
    origin = pos.mean(-2)  # (..., M, 2) each robot's own centroid
    rel = (pos[..., None, :, :, :] - origin[..., :, None, None, :]) / L  # (..., i, j, K, 2)
    rel = np.clip(rel, -POSITION_MAX, POSITION_MAX).reshape(lead + (m, m, 2 * k_t))
    links = world.links(index)  # (..., M, M) [i, j]: i received j
    order = observation.cyclic_order(m)
    own_i = np.arange(m)
    own, block, tl, total = sizes(world)
    out = np.zeros(lead + (m, total), np.float32)
    out[..., :, : EXT_TARGET_DIM * k_t] = target
    out[..., :, EXT_TARGET_DIM * k_t : own] = sensor[..., own_i, own_i, :]
    for slot in range(1, m):
        j = order[:, slot]  # robot i's slot-th neighbour, for every i
        got = links[..., own_i, j]  # (..., M)
        b = own + (slot - 1) * block
        blk = np.concatenate(
            [got[..., None].astype(np.float64), sensor[..., own_i, j, :], rel[..., own_i, j, :]], -1
        )
        out[..., :, b : b + block] = np.where(got[..., None], blk, 0.0)
    if tl:
        out[..., :, total - tl :] = tail
    return out
