"""Compiled distances from sampled paths to points (:func:`activetrack.kinematics.paths.
point_distances`).

The arithmetic is :func:`activetrack.kinematics.separation.segment_distance`'s, operation
for operation in the same order (the sums of two terms left to right, ``np.clip`` as
``min(max(t, 0), 1)``, ``np.hypot``: the C library's when compiled, and NumPy's, not
Python's ``math.hypot``, as plain Python), so the kernel gives the NumPy expression's
numbers bit for bit (``tests/core/test_path_kernels.py`` checks it, also as plain
Python). Arrays are C-contiguous float64 rows: samples (R, S, 2), points (R, J, 2).
"""

from __future__ import annotations

import math

import numpy as np

from activetrack._jit import kernel


@kernel
def path_point_rows(p, q, out):
    """Write into ``out`` (R, J) the distance from each of the points ``q[r]`` (J, 2) to
    the polyline through the samples ``p[r]`` (S, 2): the least of its segments'."""
    for r in range(p.shape[0]):
        for j in range(q.shape[1]):
            cx, cy = q[r, j, 0], q[r, j, 1]
            best = math.inf
            for k in range(p.shape[1] - 1):
                ax, ay = p[r, k, 0], p[r, k, 1]
                abx, aby = p[r, k + 1, 0] - ax, p[r, k + 1, 1] - ay
                acx, acy = cx - ax, cy - ay
                den = abx * abx + aby * aby
                t = (acx * abx + acy * aby) / (den if den > 0.0 else 1.0)
                t = min(max(t, 0.0), 1.0)
                d = np.hypot(acx - t * abx, acy - t * aby)  # (NumPy's, also as plain Python)
                if d < best:
                    best = d
            out[r, j] = best
