"""The path a sensor actually travels within one step, and tests along it.

The world's team rules (:mod:`activetrack.kinematics.path_rule`) check a move along the
path the sensor's kinematics makes it travel, not along the chord from its old position
to its new one. :func:`path` samples that path at ``n + 1`` evenly spaced instants of the
step (the first sample the old position, the last the new one, exactly):

- :class:`~activetrack.kinematics.unicycle.Unicycle`: the arc of the command
  :meth:`~activetrack.kinematics.unicycle.Unicycle.command` gives for the end point (speed
  ``v`` and turn rate ``w`` held over the step);
- :class:`~activetrack.kinematics.double_integrator.DoubleIntegrator`: the parabola
  ``p + v t + a t^2 / 2`` of the acceleration its ``command`` gives;
- a kinematics with a method ``path(points, state, n)`` (same contract): that method (the
  hook of a new kinematics whose moves are not straight);
- any other (the paper's :class:`~activetrack.kinematics.disk.Disk` among them): the
  straight segment, at constant speed.

**Between the samples.** A path piece between two samples deviates from the straight
piece joining them (at the same instant) by at most ``max |p''| h^2 / 8`` (``h`` the
sample spacing in time; for an arc and a parabola, whose second differences are
constant in size, this is ``|p_{k+1} - 2 p_k + p_{k-1}| / 8``): :func:`slack` returns that
bound (enlarged by 1%), which the distance tests subtract, so a path that passes them
keeps its distances everywhere, not just at the samples. For occluders,
:func:`hull_segments` returns, for each piece, its chord and the two sides of the
triangle made with the control point ``c = 2 m - (p_k + p_{k+1}) / 2`` (``m`` the piece's
midpoint sample; for a parabola the quadratic Bezier control point, so the piece lies in
the triangle; for an arc the same to fourth order in the piece's turn): a polygon meeting
the piece crosses one of these segments (unless it lies wholly inside a triangle, of
width ``h^2 |p''| / 4``), so no blocked triangle side means no occluder along the path.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.kinematics._path_kernels import path_point_rows
from activetrack.kinematics.double_integrator import DoubleIntegrator
from activetrack.kinematics.unicycle import Unicycle, _sinc
from activetrack.validation import FloatArray

#: The pieces a step's path is checked in (33 samples).
N_PATH = 32
_SLACK = 1.01  # the deviation bound's safety factor (rounding)


def path(kin: Any, points: FloatArray, state: FloatArray, n: int = N_PATH) -> FloatArray:
    """Return the positions (..., n + 1, 2) of a sensor moving by ``kin`` from ``state``
    (..., S) to the reachable ``points`` (..., 2) at the instants ``k / n`` of the step
    (module docstring): the first is the position, the last ``points`` exactly."""
    q, st = np.asarray(points, np.float64), np.asarray(state, np.float64)
    lead = np.broadcast_shapes(q.shape[:-1], st.shape[:-1])
    q, st = np.broadcast_to(q, lead + (2,)), np.broadcast_to(st, lead + st.shape[-1:])
    s = np.arange(n + 1) / n  # (n + 1,)
    p0 = st[..., None, :2]
    hook = getattr(kin, "path", None)
    if callable(hook):
        out = np.array(hook(q, st, n), dtype=np.float64)
    elif isinstance(kin, Unicycle):
        v, w = kin.commands(kin.command(q, st))
        dt = kin._dt()
        phi = 0.5 * w[..., None] * dt * s
        chord = v[..., None] * dt * s * _sinc(phi)
        ang = st[..., 2, None] + phi
        out = p0 + chord[..., None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    elif isinstance(kin, DoubleIntegrator):
        u = kin.command(q, st)
        c_a, r_a, _, _ = kin.disks(st)
        vel = c_a - st[..., :2]  # v dt
        out = p0 + s[:, None] * vel[..., None, :] + (r_a * s * s)[:, None] * u[..., None, :]
    else:
        out = p0 + s[:, None] * (q - st[..., :2])[..., None, :]
    out = np.array(np.broadcast_to(out, lead + (n + 1, 2)))
    out[..., 0, :] = st[..., :2]
    out[..., -1, :] = q
    return out


def slack(samples: FloatArray) -> FloatArray:
    """Return the bound (...) on the distance between the path and the straight pieces
    joining its ``samples`` (..., n + 1, 2) at the same instants (module docstring)."""
    p = np.asarray(samples, np.float64)
    if p.shape[-2] < 3:
        return np.zeros(p.shape[:-2])
    d2 = p[..., 2:, :] - 2.0 * p[..., 1:-1, :] + p[..., :-2, :]
    return _SLACK * np.max(np.hypot(d2[..., 0], d2[..., 1]), axis=-1) / 8.0


def hull_segments(kin: Any, points: FloatArray, state: FloatArray, n: int = N_PATH):
    """Return ``(a, b)`` (..., 3 n, 2): segments whose union with no occluder crossing
    them means the path (:func:`path`) meets no occluder (module docstring)."""
    return hull_of(path(kin, points, state, 2 * n))


def hull_of(fine: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Return :func:`hull_segments` from the path sampled at ``2 n + 1`` instants (the
    pieces' ends at the even ones, their midpoints at the odd ones)."""
    p, m = fine[..., ::2, :], fine[..., 1::2, :]
    c = 2.0 * m - 0.5 * (p[..., :-1, :] + p[..., 1:, :])
    a = np.concatenate([p[..., :-1, :], p[..., :-1, :], c], -2)
    b = np.concatenate([p[..., 1:, :], c, p[..., 1:, :]], -2)
    return a, b


def point_distances(samples: FloatArray, points: FloatArray) -> FloatArray:
    """Return the distance (..., J) from the path through ``samples`` (..., n + 1, 2) to
    each of ``points`` (..., J, 2), less the path's :func:`slack` (a lower bound)."""
    p = np.asarray(samples, np.float64)
    q = np.asarray(points, np.float64)
    lead = np.broadcast_shapes(p.shape[:-2], q.shape[:-2])
    rows_p = np.ascontiguousarray(np.broadcast_to(p, lead + p.shape[-2:])).reshape(
        -1, *p.shape[-2:]
    )
    rows_q = np.ascontiguousarray(np.broadcast_to(q, lead + q.shape[-2:])).reshape(
        -1, *q.shape[-2:]
    )
    d = np.empty(rows_q.shape[:2])
    path_point_rows(rows_p, rows_q, d)  # (segment_distance's arithmetic, compiled)
    return d.reshape(lead + q.shape[-2:-1]) - slack(p)[..., None]
