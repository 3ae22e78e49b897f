"""Compiled unicycle steps: a team's actions to its next states, and which moves end
inside a target's ``rho`` disk (:meth:`activetrack.Unicycle.team_step`).

The arithmetic is :class:`activetrack.Unicycle`'s (``commands`` then ``integrate``, the
heading wrapped as ``np.pi - np.mod(np.pi - a, 2 pi)``), operation for operation in the
same order, so the compiled step gives the NumPy methods' numbers bit for bit (the sines
and cosines are the C library's on both sides; ``tests/extensions/test_robot_fused.py``
checks it). Arrays are C-contiguous float64 rows: actions (B, M, 2), states (B, M, 3),
targets (B, K, 2), ``rho`` (B, M).
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import inline_kernel, kernel


@kernel
def np_mod(a, b):
    """Return NumPy's ``np.mod(a, b)`` of floats (``fmod``, then the divisor's sign)."""
    mod = np.fmod(a, b)  # (exact: no rounding)
    if mod != 0.0:
        if (b < 0.0) != (mod < 0.0):
            mod += b
    else:
        mod = math.copysign(0.0, b)
    return mod


@inline_kernel
def arc_step(a0, a1, x, y, th, v_min, v_max, w_max, dt):
    """Return one sensor's next state ``(x, y, theta)`` after its normalized action
    ``(a0, a1)`` (clipped to [-1, 1]: ``v = v_min + (a_0 + 1) (v_max - v_min) / 2``,
    ``w = a_1 w_max``, held for ``dt``, the exact arc) from ``(x, y, th)``."""
    a0 = min(max(a0, -1.0), 1.0)
    a1 = min(max(a1, -1.0), 1.0)
    v = v_min + 0.5 * (a0 + 1.0) * (v_max - v_min)
    w = a1 * w_max
    phi = 0.5 * w * dt
    s = math.sin(phi) / phi if phi != 0.0 else 1.0
    chord = v * dt * s
    ang = th + phi
    return (
        x + chord * math.cos(ang),
        y + chord * math.sin(ang),
        math.pi - np_mod(math.pi - (th + 2.0 * phi), 2.0 * math.pi),
    )


@kernel
def team_step_rows(actions, states, v_min, v_max, w_max, dt, targets, rho_inside, out, inside):
    """Write each sensor's :func:`arc_step` into ``out`` (B, M, 3), and into ``inside``
    (B, M) whether the new position is closer than ``rho_inside`` (B, M) to one of
    ``targets``."""
    for b in range(actions.shape[0]):
        for i in range(actions.shape[1]):
            x, y, th = arc_step(
                actions[b, i, 0], actions[b, i, 1], states[b, i, 0], states[b, i, 1],
                states[b, i, 2], v_min, v_max, w_max, dt,
            )  # fmt: skip
            out[b, i, 0] = x
            out[b, i, 1] = y
            out[b, i, 2] = th
            hit = False
            for k in range(targets.shape[1]):
                if math.hypot(x - targets[b, k, 0], y - targets[b, k, 1]) < rho_inside[b, i]:
                    hit = True
            inside[b, i] = hit
