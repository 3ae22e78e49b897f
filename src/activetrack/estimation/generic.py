"""The generic (NumPy, not compiled) sensing path: a team whose sensors' models are any
:class:`activetrack.SensorModel`, the world's measurement, the EKF and the planners'
information asked of each model.

A scenario whose every sensor is built-in never comes here (its compiled kernels are the
fast path, :attr:`activetrack.world.capabilities.Capabilities.builtin_sensors`). Here a
team is a tuple of M models; the functions group the sensors by model (one vectorized
call per distinct model) and keep the world's layout: measurements (..., M, 2) with the
slots of :mod:`activetrack.models.sensor`, two standard normals per sensor and target.

The EKF is eq. (11) in information form, ``Y = sum_i H_i^T R_eff_i^+ H_i`` and ``b = sum_i
H_i^T R_eff_i^+ nu_i`` from each model (:meth:`activetrack.SensorModel.update_terms`), the
posterior by the same compiled kernel as every other model
(:func:`activetrack.estimation._kernels.posterior_rows`), the iterated EKF relinearizing
each filter until its position settles.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from activetrack._jit import as_rows
from activetrack.estimation import _kernels as ek
from activetrack.models.sensor import SensorModel
from activetrack.validation import FloatArray


def groups(models: Sequence[SensorModel]) -> list[tuple[SensorModel, np.ndarray]]:
    """Return the distinct models of a team with the indices of their sensors."""
    out: list[tuple[SensorModel, list[int]]] = []
    for i, m in enumerate(models):
        for model, idx in out:
            if model == m:
                idx.append(i)
                break
        else:
            out.append((m, [i]))
    return [(model, np.array(idx)) for model, idx in out]


def _finite(model: SensorModel, what: str, *arrays: FloatArray) -> None:
    """Raise ValueError naming the model unless ``arrays`` are finite: a model of one's own
    that passed the scenario's probe may still return NaN or inf on a geometry of an
    episode, which would otherwise turn the filter's covariance or a plan NaN silently."""
    if not all(np.all(np.isfinite(a)) for a in arrays):
        raise ValueError(
            f"sensor_model {model.name!r} ({type(model).__name__}) returned NaN or inf from "
            f"its {what} on this step's geometry; a model must be finite for every sensor "
            "and target position (detection is the scenario's max_range and p_detect)"
        )


def _per_sensor(value: FloatArray | float, idx: np.ndarray, m: int) -> FloatArray:
    """Return a per-sensor value (scalar, (M,) or (..., M)) at the sensors ``idx``."""
    v = np.asarray(value, np.float64)
    return v if v.ndim == 0 else np.broadcast_to(v, v.shape[:-1] + (m,))[..., idx]


def measure(
    models: Sequence[SensorModel],
    targets: FloatArray,
    sensors: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    orientation: FloatArray,
    noise: FloatArray,
) -> FloatArray:
    """Return every sensor's noisy measurement of K targets, (..., K, M, 2).

    ``targets`` (..., K, 2) true positions, ``sensors`` (..., M, 2) true positions,
    ``noise`` (..., 2MK) standard normals (target-major, then sensor-major: the world's
    order), per-sensor values (M,). Each model's :meth:`~activetrack.SensorModel.measure`.
    """
    k, m = targets.shape[-2], sensors.shape[-2]
    batch = np.broadcast_shapes(targets.shape[:-2], sensors.shape[:-2])
    normals = np.reshape(noise, batch + (k, m, 2))
    out = np.zeros(batch + (k, m, 2))
    for model, idx in groups(models):
        out[..., idx, :] = model.measure(
            targets[..., :, None, :], sensors[..., None, idx, :],
            _per_sensor(sigma_d2, idx, m), _per_sensor(sigma_theta2, idx, m),
            normals[..., idx, :], _per_sensor(orientation, idx, m),
        )  # fmt: skip
        _finite(model, "measure", out[..., idx, :])
    return out


def update_terms(
    models: Sequence[SensorModel],
    z: FloatArray,
    target_hat: FloatArray,
    sensors: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    orientation: FloatArray,
    mask: np.ndarray | None = None,
    pose_cov: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Return the team's summed EKF terms ``(Y, b)`` (..., 2, 2), (..., 2) at the estimate
    ``target_hat`` (..., 2): measurements ``z`` (..., M, 2) from sensors believed at
    ``sensors`` (..., M, 2); only the sensors ``mask`` (..., M) measured (None: all)."""
    m = sensors.shape[-2]
    Y = 0.0
    b = 0.0
    for model, idx in groups(models):
        cov = None if pose_cov is None else np.asarray(pose_cov)[..., idx, :, :]
        Yi, bi = model.update_terms(
            z[..., idx, :], target_hat[..., None, :], sensors[..., idx, :],
            _per_sensor(sigma_d2, idx, m), _per_sensor(sigma_theta2, idx, m),
            _per_sensor(orientation, idx, m), cov,
        )  # fmt: skip
        if mask is not None:
            keep = np.asarray(mask)[..., idx]
            Yi = np.where(keep[..., None, None], Yi, 0.0)
            bi = np.where(keep[..., None], bi, 0.0)
        _finite(model, "update_terms (its Jacobian, noise or residual)", Yi, bi)
        Y = Y + Yi.sum(axis=-3)
        b = b + bi.sum(axis=-2)
    return Y, b


def update(
    models: Sequence[SensorModel],
    x: FloatArray,
    P: FloatArray,
    z: FloatArray,
    sensors: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    orientation: FloatArray,
    mask: np.ndarray | None = None,
    pose_cov: FloatArray | None = None,
    iterations: int = 1,
) -> tuple[FloatArray, FloatArray]:
    """Return the EKF posterior ``(x(k+1|k+1), P(k+1|k+1))`` of eq. (11), batched: ``x``
    (..., n), ``P`` (..., n, n), the rest as :func:`update_terms`; ``iterations`` > 1 the
    iterated EKF (at most that many linearizations)."""
    x, P = np.asarray(x, np.float64), np.asarray(P, np.float64)
    n = x.shape[-1]
    batch = np.broadcast_shapes(x.shape[:-1], P.shape[:-2], z.shape[:-2], sensors.shape[:-2])
    xf, Pf = as_rows(x, batch, (n,)), as_rows(P, batch, (n, n))
    zf = np.broadcast_to(z, batch + z.shape[-2:]).reshape(-1, *z.shape[-2:])
    sf = np.broadcast_to(sensors, batch + sensors.shape[-2:]).reshape(-1, *sensors.shape[-2:])
    mf = (
        None
        if mask is None
        else np.broadcast_to(mask, batch + mask.shape[-1:]).reshape(-1, mask.shape[-1])
    )
    x_out, P_out = np.empty(xf.shape), np.empty(Pf.shape)

    def terms(rows: np.ndarray, lin: FloatArray) -> FloatArray:
        Y, b = update_terms(
            models, zf[rows], lin, sf[rows], sigma_d2, sigma_theta2, orientation,
            None if mf is None else mf[rows], pose_cov,
        )  # fmt: skip
        out = np.empty((rows.size, 5))
        out[:, 0], out[:, 1], out[:, 2] = Y[..., 0, 0], Y[..., 0, 1], Y[..., 1, 1]
        out[:, 3:] = b
        return out

    active = np.arange(xf.shape[0])
    ek.posterior_rows(xf, Pf, terms(active, xf[:, :2]), active, False, x_out, P_out)
    for _ in range(int(iterations) - 1):
        moving = ek.posterior_rows(
            xf, Pf, terms(active, x_out[active, :2]), active, True, x_out, P_out
        )
        active = active[moving]
        if active.size == 0:
            break
    return x_out.reshape(batch + (n,)), P_out.reshape(batch + (n, n))


def entries(
    models: Sequence[SensorModel],
    rel: FloatArray,
    sigma_d2: FloatArray,
    sigma_theta2: FloatArray,
    pose_cov: FloatArray | None = None,
    detect: tuple | None = None,
    orientation: FloatArray | float = 0.0,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Return each sensor's information entries ``(a, b, c)`` (..., M) about the target
    position, from offsets ``rel = p_S - p_T`` (..., M, 2): each model's
    :meth:`~activetrack.SensorModel.information` (the planners' generic path; the
    arguments as :func:`activetrack.models.sensor_models.information_entries`, per-sensor
    arrays broadcasting against (..., M))."""
    shape = rel.shape[:-1]
    a, b, c = np.zeros(shape), np.zeros(shape), np.zeros(shape)
    for model, idx in groups(models):
        cov = None
        if pose_cov is not None:
            cov = np.broadcast_to(pose_cov, shape + (2, 2))[..., idx, :, :]
        det = None
        if detect is not None:
            det = tuple(np.broadcast_to(d, shape)[..., idx] for d in detect)
        J = model.information(
            rel[..., idx, :],
            np.broadcast_to(sigma_d2, shape)[..., idx],
            np.broadcast_to(sigma_theta2, shape)[..., idx],
            cov, det, np.broadcast_to(orientation, shape)[..., idx],
        )  # fmt: skip
        _finite(model, "information", J)
        a[..., idx], b[..., idx], c[..., idx] = J[..., 0, 0], J[..., 0, 1], J[..., 1, 1]
    return a, b, c
