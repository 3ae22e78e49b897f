"""Compiled observation encoding: the feature blocks and the agents' cyclic views.

The kernels behind :mod:`activetrack.world.observation`, whose module docstring defines the
blocks (the paper's layout, ``5 + 6M``, and the extended one, ``7K + (12 + flags) M``).
:func:`target_block` is the paper's target block of one prediction; :func:`features_row`
both layouts' target and sensor blocks of one copy; :func:`features_rows` those of a batch
(float64); :func:`windows_row` every agent's float32 view of one copy's blocks (the target
blocks, then the sensor blocks in the agent's order, its own first);
:func:`observe_rows` the observations of a batch in one pass.

Arrays: predictions ``x`` (B, K, n) and ``P`` (B, K, n, n) (a target with a shorter state
padded with zeros: only the position block and the velocity are read), position fixes
(B, M, 2), the constant sensor entries (M, C) (:meth:`Layout.sensor_constants`), detection
flags (B', K, M) bool with B' = 1 (none: zeros) or B.
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import kernel

#: The clip of the entries that have no bound by nature (:mod:`activetrack.world.observation`,
#: "Bounds"): positions and displacements per step over ``L`` to [-POSITION_MAX,
#: POSITION_MAX], log standard deviations ``ln(sigma / L)`` to [-LOG_STD_MAX, LOG_STD_MAX].
POSITION_MAX = 1.0e6
LOG_STD_MAX = 50.0


@kernel
def clip(v, bound):
    """Return ``v`` clipped to ``[-bound, bound]``."""
    return min(max(v, -bound), bound)


@kernel
def target_block(x, P, dt, L, out, o):
    """Write the paper's target block of prediction ``x`` (n,), ``P`` (n, n) into
    ``out[o:o + 5]``: log standard deviations and correlation of the position, velocity
    times ``dt / L`` (0 for a state without velocity), the unbounded entries clipped
    (:data:`LOG_STD_MAX`, :data:`POSITION_MAX`)."""
    pxx, pyy, pxy = P[0, 0], P[1, 1], P[0, 1]
    out[o] = clip(0.5 * math.log(pxx / L**2), LOG_STD_MAX)
    out[o + 1] = clip(0.5 * math.log(pyy / L**2), LOG_STD_MAX)
    out[o + 2] = pxy / math.sqrt(pxx * pyy)
    if x.shape[0] >= 4:
        out[o + 3] = clip(x[2] * (dt / L), POSITION_MAX)
        out[o + 4] = clip(x[3] * (dt / L), POSITION_MAX)
    else:
        out[o + 3] = 0.0
        out[o + 4] = 0.0


@kernel
def features_row(x, P, fixes, constants, dt, L, extended, detected, flags, target, sensor):
    """Write one copy's target blocks ``target`` (TD,) and sensor blocks ``sensor``
    (M, 2 + C + flags) (``x`` (K, n), ``P`` (K, n, n), ``fixes`` (M, 2); ``detected``
    (K, M) gives the ``flags`` detection entries, none for 0); relative positions clipped
    to :data:`POSITION_MAX`."""
    K, M, C = x.shape[0], fixes.shape[0], constants.shape[1]
    if extended:  # positions relative to the targets' centroid
        ox, oy = x[0, 0], x[0, 1]
        for k in range(1, K):
            ox += x[k, 0]
            oy += x[k, 1]
        ox *= 1.0 / K
        oy *= 1.0 / K
        for k in range(K):
            target[7 * k] = clip((x[k, 0] - ox) * (1.0 / L), POSITION_MAX)
            target[7 * k + 1] = clip((x[k, 1] - oy) * (1.0 / L), POSITION_MAX)
            target_block(x[k], P[k], dt, L, target, 7 * k + 2)
    else:  # relative to the predicted target
        ox, oy = x[0, 0], x[0, 1]
        target_block(x[0], P[0], dt, L, target, 0)
    for j in range(M):
        sensor[j, 0] = clip((fixes[j, 0] - ox) / L, POSITION_MAX)
        sensor[j, 1] = clip((fixes[j, 1] - oy) / L, POSITION_MAX)
        for c in range(C):
            sensor[j, 2 + c] = constants[j, c]
        for k in range(flags):
            sensor[j, 2 + C + k] = 1.0 if detected[k, j] else 0.0


@kernel
def features_rows(x, P, fixes, constants, dt, L, extended, detected, flags, target, sensor):
    """Fill ``target`` (B, TD) and ``sensor`` (B, M, SD) with :func:`features_row` of each
    copy."""
    for b in range(x.shape[0]):
        det = detected[b if detected.shape[0] > 1 else 0]
        features_row(
            x[b], P[b], fixes[b], constants, dt, L, extended, det, flags, target[b], sensor[b]
        )  # fmt: skip


@kernel
def windows_row(target, sensor, order, out):
    """Write every agent's view (M, TD + M SD) float32 into ``out``: the target blocks, then
    the sensor blocks in agent ``i``'s order ``order[i]``, each entry rounded once."""
    TD, M, SD = target.shape[0], sensor.shape[0], sensor.shape[1]
    for i in range(M):
        for c in range(TD):
            out[i, c] = target[c]
        for j in range(M):
            s = order[i, j]
            for c in range(SD):
                out[i, TD + j * SD + c] = sensor[s, c]


@kernel
def windows_rows(target, sensor, order, out):
    """Fill ``out`` (B, M, D) with :func:`windows_row` of each copy's blocks."""
    for b in range(target.shape[0]):
        windows_row(target[b], sensor[b], order, out[b])


@kernel
def observe_rows(x, P, fixes, constants, dt, L, extended, detected, flags, order, out):
    """Fill ``out`` (B, M, D) float32 with every agent's observation of each copy: the
    blocks of :func:`features_row` in the views of :func:`windows_row`; the entries after
    ``TD + M SD`` (range-finder readings) are left to the caller."""
    M = fixes.shape[1]
    target = np.empty(7 * x.shape[1] if extended else 5)
    sensor = np.empty((M, 2 + constants.shape[1] + flags))
    for b in range(x.shape[0]):
        det = detected[b if detected.shape[0] > 1 else 0]
        features_row(
            x[b], P[b], fixes[b], constants, dt, L, extended, det, flags, target, sensor
        )  # fmt: skip
        windows_row(target, sensor, order, out[b])


@kernel
def headings_into(motion, out, col):
    """Write every agent's heading ``theta = motion[b, i, 0]`` as ``(cos theta, sin
    theta)`` into ``out[b, i, col:col + 2]`` (``out`` (B, M, D) float32, each entry rounded
    once): :meth:`activetrack.Unicycle.features`, the observation's last entries."""
    for b in range(motion.shape[0]):
        for i in range(motion.shape[1]):
            th = motion[b, i, 0]
            out[b, i, col] = math.cos(th)
            out[b, i, col + 1] = math.sin(th)
