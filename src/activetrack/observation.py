"""Observation and global-state encoding of the tracking loop (pure, batched).

At step k every agent sees what the planners of Section IV see (eq. 15-17): the
prediction ``x_hat(k+1|k)``, ``P(k+1|k)`` (only its position block matters, Lemma 1), all
sensors' current positions and all their parameters. Everything is made dimensionless
with one length scale ``L`` (:func:`length_scale`, 23.1 m in the paper's scenario) and
variances go through logarithms, so the entries are O(1) and the map is invertible
(:func:`decode_target`, :func:`decode_sensors`).

Target block (5 entries), shared by all agents::

    0  ln(sigma_x / L)         sigma_x^2 = P(k+1|k)[0, 0]
    1  ln(sigma_y / L)         sigma_y^2 = P(k+1|k)[1, 1]
    2  corr = P[0, 1] / (sigma_x sigma_y)       in (-1, 1)
    3  v_x dt / L              predicted target velocity x_hat(k+1|k)[2:4] as the
    4  v_y dt / L              displacement per step (0 for a position-only model)

Sensor block of sensor j (6 entries)::

    0  (x_S_j(k) - x_hat_T(k+1|k)) / L      the c_j of eq. (15) over L
    1  (y_S_j(k) - y_hat_T(k+1|k)) / L
    2  ln(sigma_d_j / L)                    sigma_d_j^2 = range noise variance (m^2)
    3  ln(sigma_theta_j)                    sigma_theta_j^2 = bearing noise variance (rad^2)
    4  r_j / L                              reach per step, vmax_j dt (eq. 13)
    5  rho_j / L                            minimum distance to the predicted target (eq. 14)

Agent i's observation is the target block, then the sensor blocks of sensors
``i, i+1, ..., i+M-1 (mod M)``: its own block first, the others in cyclic order, so
every agent sees the team from its own seat. Size ``5 + 6M``. The global state is the
target block, the sensor blocks of sensors ``0..M-1`` and the elapsed fraction
``k / n_steps`` of the episode. Size ``6 + 6M``.
"""

from __future__ import annotations

import numpy as np

from activetrack.scenarios import Scenario
from activetrack.validation import FloatArray

TARGET_DIM = 5
SENSOR_DIM = 6


def obs_dim(n_sensors: int) -> int:
    """Return the size of one agent's observation, ``5 + 6M``."""
    return TARGET_DIM + SENSOR_DIM * n_sensors


def state_dim(n_sensors: int) -> int:
    """Return the size of the global state, ``6 + 6M``."""
    return TARGET_DIM + SENSOR_DIM * n_sensors + 1


def length_scale(sc: Scenario) -> float:
    """Return ``L``: the farthest a sensor can start from the estimated target.

    ``L = ||sensor_center - x0_hat[:2]|| + sensor_radius`` (23.1 m for ``paper``), at least
    ``max(rho_i + r_i)`` and at least 1e-6 m so that it is never zero.
    """
    d = float(np.hypot(*(np.asarray(sc.sensor_center) - np.asarray(sc.x0_hat[:2]))))
    floor = float(np.max(sc.per_sensor("rho") + sc.r))
    return max(d + sc.sensor_radius, floor, 1e-6)


def sensor_constants(
    sigma_d2: FloatArray, sigma_theta2: FloatArray, r: FloatArray, rho: FloatArray, L: float
) -> FloatArray:
    """Return the constant entries 2..5 of every sensor block, shape (M, 4)."""
    return np.stack([0.5 * np.log(sigma_d2 / L**2), 0.5 * np.log(sigma_theta2), r / L, rho / L], -1)


def target_features(x_pred: FloatArray, P_pred: FloatArray, dt: float, L: float) -> FloatArray:
    """Return the target block from the prediction ``(x_hat(k+1|k), P(k+1|k))``, (..., 5)."""
    # ``[()]``: NumPy scalars for a single prediction (cheaper arithmetic), views for a batch.
    pxx, pyy, pxy = P_pred[..., 0, 0][()], P_pred[..., 1, 1][()], P_pred[..., 0, 1][()]
    out = np.empty(x_pred.shape[:-1] + (TARGET_DIM,))
    out[..., 0] = 0.5 * np.log(pxx / L**2)
    out[..., 1] = 0.5 * np.log(pyy / L**2)
    out[..., 2] = pxy / np.sqrt(pxx * pyy)
    if x_pred.shape[-1] >= 4:
        out[..., 3:5] = x_pred[..., 2:4] * (dt / L)
    else:
        out[..., 3:5] = 0.0
    return out


def sensor_features(
    sensors: FloatArray, target_pos: FloatArray, constants: FloatArray, L: float
) -> FloatArray:
    """Return every sensor's block, shape (..., M, 6)."""
    out = np.empty(sensors.shape[:-1] + (SENSOR_DIM,))
    out[..., :2] = (sensors - target_pos[..., None, :]) / L
    out[..., 2:] = constants
    return out


def cyclic_order(n_sensors: int) -> np.ndarray:
    """Return the (M, M) index table whose row i is ``i, i+1, ..., i+M-1 (mod M)``."""
    idx = np.arange(n_sensors)
    return (idx[:, None] + idx[None, :]) % n_sensors


def observations(target: FloatArray, sensor: FloatArray, order: np.ndarray) -> np.ndarray:
    """Return all agents' observations, float32 of shape (..., M, 5 + 6M)."""
    m = sensor.shape[-2]
    out = np.empty(sensor.shape[:-2] + (m, obs_dim(m)), dtype=np.float32)
    out[..., :TARGET_DIM] = target[..., None, :]
    # Agent i sees sensors i, i+1, ... (mod M): a contiguous window of the doubled list.
    # Slicing windows is ~5x faster than fancy indexing with ``order`` on large batches.
    doubled = np.concatenate([sensor, sensor], axis=-2)
    shape = sensor.shape[:-2] + (m * SENSOR_DIM,)
    for i, start in enumerate(order[:, 0].tolist()):
        out[..., i, TARGET_DIM:] = doubled[..., start : start + m, :].reshape(shape)
    return out


def global_state(target: FloatArray, sensor: FloatArray, elapsed: FloatArray | float) -> np.ndarray:
    """Return the global state, float32 of shape (..., 6 + 6M)."""
    m = sensor.shape[-2]
    out = np.empty(sensor.shape[:-2] + (state_dim(m),), dtype=np.float32)
    out[..., :TARGET_DIM] = target
    out[..., TARGET_DIM:-1] = sensor.reshape(sensor.shape[:-2] + (m * SENSOR_DIM,))
    out[..., -1] = elapsed
    return out


def observation_bounds(n_sensors: int) -> tuple[np.ndarray, np.ndarray]:
    """Return float32 ``(low, high)`` of one agent's observation (inf where unbounded).

    Only the correlation (in [-1, 1]) and the reach and minimum distance (>= 0) have finite
    bounds. The others have none by nature: a target that outruns the team takes the
    relative positions anywhere, and a lost target's log standard deviations grow without
    limit; a finite box would be a promise the dynamics do not keep (Gymnasium's checker
    notes the infinite bounds as advisory warnings).
    """
    low = np.full(obs_dim(n_sensors), -np.inf, dtype=np.float32)
    high = np.full(obs_dim(n_sensors), np.inf, dtype=np.float32)
    low[2], high[2] = -1.0, 1.0  # correlation coefficient
    for j in range(n_sensors):  # r / L and rho / L are >= 0
        b = TARGET_DIM + SENSOR_DIM * j
        low[b + 4 : b + 6] = 0.0
    return low, high


def state_bounds(n_sensors: int) -> tuple[np.ndarray, np.ndarray]:
    """Return float32 ``(low, high)`` of the global state."""
    low, high = observation_bounds(n_sensors)
    return np.append(low, np.float32(0.0)), np.append(high, np.float32(1.0))


def decode_target(target: FloatArray, dt: float, L: float) -> tuple[FloatArray, FloatArray]:
    """Return ``(P11, v)``: the 2x2 position covariance and velocity of a target block."""
    target = np.asarray(target, dtype=np.float64)
    sx, sy = L * np.exp(target[..., 0]), L * np.exp(target[..., 1])
    pxy = target[..., 2] * sx * sy
    P = np.stack([np.stack([sx * sx, pxy], -1), np.stack([pxy, sy * sy], -1)], -2)
    return P, target[..., 3:5] * (L / dt)


def decode_sensors(sensor: FloatArray, L: float) -> dict[str, FloatArray]:
    """Return the physical quantities of sensor blocks (..., M, 6) as a dict of arrays.

    Keys: ``rel`` (positions relative to the predicted target, m), ``sigma_d2``,
    ``sigma_theta2``, ``r``, ``rho``.
    """
    s = np.asarray(sensor, dtype=np.float64)
    return {
        "rel": s[..., :2] * L,
        "sigma_d2": (L * np.exp(s[..., 2])) ** 2,
        "sigma_theta2": np.exp(s[..., 3]) ** 2,
        "r": s[..., 4] * L,
        "rho": s[..., 5] * L,
    }
