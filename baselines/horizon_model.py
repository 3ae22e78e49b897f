"""The deterministic planning model of a receding-horizon planner: covariances over H steps.

Under the EKF of eq. (11), linearized at the predicted mean, the covariance after an
update depends only on where the sensors are relative to the predicted target, never on
the measurements (Lemma 1, eq. 12, 17). Along a plan whose target moves exactly as
predicted (``x(h+1) = Phi x(h)``, eq. 3) with noise-free measurements the innovations
vanish, the mean stays on the predicted path and the covariance sequence is a
deterministic function of the plan:

- update (eq. 11 in information form): ``P+ = P - Pc G Pc^T`` with ``Pc = P[:, :2]``,
  ``G = (I + Y P11)^{-1} Y = (P11 + Y^{-1})^{-1}`` and ``Y = sum_i info_i`` the sensors'
  position information at their planned positions (eq. 17);
- predict (eq. 3): ``P(h+1) = Phi P+ Phi^T + Q``.

The score of a plan is the objective of eq. (17), ``tr P+_11``, summed over the horizon
with weights ``gamma^h`` (h = 0 is the one-step objective GSR minimizes). Everything is
batched over leading axes (copies, candidates) and uses 2x2 closed forms.
"""

from __future__ import annotations

import numpy as np

from activetrack.models.motion import predict
from activetrack.models.objective import TRACE, TraceObjective, sensor_information
from activetrack.validation import FloatArray


def predicted_means(x_pred: FloatArray, Phi: FloatArray, horizon: int) -> FloatArray:
    """Return the predicted target states ``x(h) = Phi^h x_pred``, (..., H, n), h = 0..H-1."""
    out = np.empty(x_pred.shape[:-1] + (horizon, x_pred.shape[-1]))
    x = np.asarray(x_pred, dtype=np.float64)
    for h in range(horizon):
        out[..., h, :] = x
        # Row by row (a matrix product of all copies at once rounds a row differently
        # with another number of rows): a copy's means do not depend on its batch.
        x = np.add.reduce(x[..., None, :] * Phi, axis=-1)
    return out


def path_information(
    paths: FloatArray, means: FloatArray, sigma_d2: FloatArray, sigma_theta2: FloatArray
) -> FloatArray:
    """Return each sensor's information (eq. 17) along its path, (..., H, 2, 2).

    ``paths`` (..., H, 2) absolute positions, ``means`` the predicted target positions
    broadcastable to (..., H, 2); the variances broadcast to ``paths.shape[:-2]``.
    """
    rel = paths - means
    sd2 = np.asarray(sigma_d2, dtype=np.float64)[..., None]
    st2 = np.asarray(sigma_theta2, dtype=np.float64)[..., None]
    return sensor_information(rel, sd2, st2)


def predict_covariance(
    P: FloatArray, Phi: FloatArray, Q: FloatArray, zeros: FloatArray | None = None
) -> FloatArray:
    """Return ``Phi P Phi^T + Q`` (eq. 3) for covariances (..., n, n)."""
    if zeros is None:
        zeros = np.zeros(P.shape[:-1])
    return predict(zeros, P, Phi, Q)[1]


def information_update(P: FloatArray, Y: FloatArray) -> FloatArray:
    """Return the posterior covariance ``P - Pc G Pc^T`` (eq. 11) for information ``Y``.

    ``P`` (..., n, n), ``Y`` (..., 2, 2) the total measurement information of the step.
    """
    p, q, s = P[..., 0, 0], P[..., 0, 1], P[..., 1, 1]
    a, b, c = Y[..., 0, 0], Y[..., 0, 1], Y[..., 1, 1]
    # A = I + Y P11 and G = A^{-1} Y (symmetric in exact arithmetic; symmetrized here).
    a00, a01 = 1.0 + a * p + b * q, a * q + b * s
    a10, a11 = b * p + c * q, 1.0 + b * q + c * s
    inv = 1.0 / (a00 * a11 - a01 * a10)
    g00 = (a11 * a - a01 * b) * inv
    g11 = (a00 * c - a10 * b) * inv
    g01 = 0.5 * ((a11 * b - a01 * c) + (a00 * b - a10 * a)) * inv
    # Z = Pc G with Pc = P[:, :2]; P+ = P - Z Pc^T, written as two outer products and
    # symmetrized (the two halves differ by rounding only).
    c0, c1 = P[..., :, 0], P[..., :, 1]
    z0 = c0 * g00[..., None] + c1 * g01[..., None]
    z1 = c0 * g01[..., None] + c1 * g11[..., None]
    low = z0[..., :, None] * c0[..., None, :]
    low += z1[..., :, None] * c1[..., None, :]
    out = P - 0.5 * (low + low.mT)
    return out


def rollout(
    P_pred: FloatArray,
    Y: FloatArray,
    Phi: FloatArray,
    Q: FloatArray,
    weights: FloatArray,
    *,
    return_covariances: bool = False,
    objective: TraceObjective = TRACE,
) -> tuple[FloatArray, FloatArray] | tuple[FloatArray, FloatArray, FloatArray]:
    """Return ``(score, traces)`` of plans with step information ``Y`` (..., H, 2, 2).

    ``P_pred`` (..., n, n) is the current prediction ``P(k+1|k)`` (broadcast over the
    candidates' axes of ``Y``); ``traces`` (..., H) are the posterior ``tr P+_11`` of each
    step (``objective.of_covariance`` of the posterior: the trace for eq. 17's objective)
    and ``score = sum_h weights[h] traces[..., h]``. With ``return_covariances`` the
    posteriors (..., H, n, n) come third.
    """
    H = Y.shape[-3]
    n = P_pred.shape[-1]
    batch = Y.shape[:-3]
    P = np.broadcast_to(P_pred, batch + (n, n))
    traces = np.empty(batch + (H,))
    posts = np.empty(batch + (H, n, n)) if return_covariances else None
    x0 = np.zeros(batch + (n,))
    for h in range(H):
        post = information_update(P, Y[..., h, :, :])
        traces[..., h] = objective.of_covariance(post)
        if posts is not None:
            posts[..., h, :, :] = post
        if h + 1 < H:
            P = predict_covariance(post, Phi, Q, x0)
    score = weighted_sum(traces, weights)
    if posts is not None:
        return score, traces, posts
    return score, traces


def weighted_sum(values: FloatArray, weights: FloatArray) -> FloatArray:
    """Return ``sum_h weights[h] values[..., h]``, (...), each row summed on its own.

    Not ``values @ weights``: a matrix-vector product over many rows rounds a row
    differently with another number of rows, and a copy's plan must not depend on the
    batch it is planned in.
    """
    w = np.asarray(weights, dtype=np.float64)
    return np.add.reduce(np.asarray(values, dtype=np.float64) * w, axis=-1)


def prior_sequence(P_pred: FloatArray, Y: FloatArray, Phi: FloatArray, Q: FloatArray) -> FloatArray:
    """Return the predicted covariances ``P(h)`` before each step's update, (..., H, n, n)."""
    H = Y.shape[-3]
    n = P_pred.shape[-1]
    out = np.empty(Y.shape[:-3] + (H, n, n))
    P = np.broadcast_to(P_pred, Y.shape[:-3] + (n, n))
    x0 = np.zeros(Y.shape[:-3] + (n,))
    for h in range(H):
        out[..., h, :, :] = P
        P = predict_covariance(information_update(P, Y[..., h, :, :]), Phi, Q, x0)
    return out


def discount_weights(horizon: int, discount: float) -> FloatArray:
    """Return ``gamma^h`` for h = 0..H-1."""
    return float(discount) ** np.arange(horizon, dtype=np.float64)
