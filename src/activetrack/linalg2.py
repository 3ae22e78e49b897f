"""Closed-form 2x2 linear algebra, batched over leading axes.

The planners evaluate the 2x2 posterior information of eq. (17) millions of times;
closed forms are exact and avoid LAPACK call overhead on tiny matrices.
"""

from __future__ import annotations

import numpy as np

from activetrack.validation import FloatArray


def det2(A: FloatArray) -> FloatArray:
    """Return the determinants of ``A`` with shape (..., 2, 2)."""
    return A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]


def inv2(A: FloatArray) -> FloatArray:
    """Return the inverses of ``A`` with shape (..., 2, 2) (adjugate over determinant)."""
    out = np.empty_like(A)
    d = det2(A)
    out[..., 0, 0] = A[..., 1, 1] / d
    out[..., 1, 1] = A[..., 0, 0] / d
    out[..., 0, 1] = -A[..., 0, 1] / d
    out[..., 1, 0] = -A[..., 1, 0] / d
    return out


def trace_inv2(A: FloatArray) -> FloatArray:
    """Return ``tr(A^{-1})`` for 2x2 ``A``: ``tr(A) / det(A)``."""
    return (A[..., 0, 0] + A[..., 1, 1]) / det2(A)


def rotation(phi: float | FloatArray) -> FloatArray:
    """Return the rotation matrix ``C(phi)`` (shape (..., 2, 2)) used throughout the paper."""
    c, s = np.cos(phi), np.sin(phi)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


_FLOAT64 = np.dtype(np.float64)


def as_complex(v: FloatArray) -> np.ndarray:
    """Return 2-vectors ``v`` (..., 2) as complex numbers ``x + i y``, shape (...).

    A view when the last axis is contiguous float64 (no copy), else a new array. One
    complex operation replaces two or three real ones on the coordinates, which matters
    when the arrays are small and every NumPy call costs about a microsecond.
    """
    # ``is``: builtin dtypes are singletons, and ``==`` with a type object costs a
    # conversion per call (a few such calls per environment step).
    if v.dtype is _FLOAT64 and v.strides[-1] == 8:
        return v.view(np.complex128)[..., 0]
    return v[..., 0] + 1j * v[..., 1]


def symmetrize(A: FloatArray) -> FloatArray:
    """Return ``(A + A^T) / 2`` over the last two axes."""
    return 0.5 * (A + A.mT)
