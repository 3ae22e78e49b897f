"""Compiled target motion (eq. 2) and prediction (eq. 3), one row at a time.

The kernels behind :func:`activetrack.models.motion.predict` and the world's target motion
(:mod:`activetrack.world._loop_kernels` inlines them in one copy's step). Each product is
rounded and the sums run in index order (see :mod:`activetrack.world._loop_kernels`).
"""

from __future__ import annotations

import numpy as np

from activetrack._jit import inline_kernel, kernel


@inline_kernel
def move_target_into(Phi, F, x, w, out):
    """Write the true target's next state ``Phi x + F w`` (eq. 2) into ``out`` (n,)."""
    n = x.shape[0]
    for i in range(n):
        a = 0.0
        for j in range(n):
            a += Phi[i, j] * x[j]
        c = 0.0
        for j in range(w.shape[0]):
            c += F[i, j] * w[j]
        out[i] = a + c


@kernel
def move_target_rows(Phi, F, x, w, out):
    """Write :func:`move_target_into` of rows ``x`` (B, n), ``w`` (B, n) into ``out``."""
    for b in range(x.shape[0]):
        move_target_into(Phi, F, x[b], w[b], out[b])


@inline_kernel
def times_transpose_into(A, B, out):
    """Write ``A B^T`` into ``out``, each entry's products added in index order."""
    for i in range(A.shape[0]):
        for j in range(B.shape[0]):
            c = 0.0
            for k in range(A.shape[1]):
                c += A[i, k] * B[j, k]
            out[i, j] = c


@inline_kernel
def predict_into(x, P, Phi, Q, x_out, P_out, scratch):
    """Write the prediction of eq. (3), ``Phi x`` and ``Phi P Phi^T + Q``, into ``x_out``,
    ``P_out`` (``scratch`` (n, n) for ``P Phi^T``); the covariance symmetrized as the mean
    of its two triangles, exactly symmetric (``P`` must be symmetric)."""
    n = x.shape[0]
    for i in range(n):
        a = 0.0
        for j in range(n):
            a += Phi[i, j] * x[j]
        x_out[i] = a
    times_transpose_into(P, Phi, scratch)  # P Phi^T
    times_transpose_into(Phi, scratch.T, P_out)  # Phi (P Phi^T)
    for i in range(n):
        for j in range(i + 1):
            v = 0.5 * ((P_out[i, j] + Q[i, j]) + (P_out[j, i] + Q[j, i]))
            P_out[i, j] = v
            P_out[j, i] = v


@kernel
def predict_rows(x, P, Phi, Q, x_out, P_out):
    """Write :func:`predict_into` of rows ``x`` (B, n), ``P`` (B, n, n) into ``x_out``,
    ``P_out``."""
    scratch = np.empty(Phi.shape)
    for b in range(x.shape[0]):
        predict_into(x[b], P[b], Phi, Q, x_out[b], P_out[b], scratch)
