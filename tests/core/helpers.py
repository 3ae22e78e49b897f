"""Independent reference computations for the core tests (textbook forms, no shortcuts)."""

import numpy as np

from activetrack.models.measurement import ZERO_DISTANCE2, wrap_angle


def random_spd(rng, n, scale=1.0):
    """Return a random non-diagonal SPD matrix."""
    A = rng.standard_normal((n, n))
    return scale * (A @ A.T + 0.5 * np.eye(n))


def range_bearing(target_pos, sensor_pos, orientation=0.0, *, wrap=True):
    """Return the noise-free range-bearing measurements ``[d_i, theta_i]`` of eq. (4),
    (..., M, 2): ``d = hypot(dx, dy)``, ``theta = atan2(dy, dx) - phi`` with
    ``(dx, dy) = p_T - p_S``, the bearing wrapped to [-pi, pi) unless ``wrap=False``
    (:func:`wrap_angle`, itself checked against sin/cos in test_measurement.py).
    ``target_pos`` (..., 2), ``sensor_pos`` (..., M, 2), ``orientation`` (..., M)."""
    target_pos, sensor_pos = np.asarray(target_pos, float), np.asarray(sensor_pos, float)
    dx = target_pos[..., None, 0] - sensor_pos[..., 0]
    dy = target_pos[..., None, 1] - sensor_pos[..., 1]
    theta = np.arctan2(dy, dx) - orientation
    return np.stack([np.hypot(dx, dy), wrap_angle(theta) if wrap else theta], axis=-1)


def jacobian(target_pos, sensor_pos):
    """Return the Jacobians ``[h_d^T; h_theta^T]`` of eq. (9) with respect to the target
    position, (..., M, 2, 2): ``h_d = (dx, dy) / d``, ``h_theta = (-dy, dx) / d^2``; zero
    rows for a sensor at zero distance (``d^2 < ZERO_DISTANCE2``: no information)."""
    target_pos, sensor_pos = np.asarray(target_pos, float), np.asarray(sensor_pos, float)
    dx = target_pos[..., None, 0] - sensor_pos[..., 0]
    dy = target_pos[..., None, 1] - sensor_pos[..., 1]
    d2 = dx * dx + dy * dy
    far = d2 >= ZERO_DISTANCE2
    safe = np.where(far, d2, 1.0)
    d = np.sqrt(safe)
    h_d = np.stack([np.where(far, dx / d, 0.0), np.where(far, dy / d, 0.0)], axis=-1)
    h_theta = np.stack([np.where(far, -dy / safe, 0.0), np.where(far, dx / safe, 0.0)], axis=-1)
    return np.stack([h_d, h_theta], axis=-2)


def sample(target_pos, sensor_pos, sigma_d2, sigma_theta2, rng, orientation=0.0):
    """Return noisy range-bearing measurements of eq. (4), (..., M, 2): :func:`range_bearing`
    plus Gaussian noise of variances ``sigma_d2``, ``sigma_theta2`` (per sensor), the bearing
    wrapped to [-pi, pi)."""
    z = range_bearing(target_pos, sensor_pos, orientation)
    std = np.stack(np.broadcast_arrays(np.sqrt(sigma_d2), np.sqrt(sigma_theta2)), axis=-1)
    z = z + rng.standard_normal(z.shape) * std
    z[..., 1] = wrap_angle(z[..., 1])
    return z


def textbook_h(target_pos, sensors):
    """Return the stacked 2M x 2 Jacobian built row by row from eq. (9), written out longhand."""
    rows = []
    for s in sensors:
        dx, dy = target_pos[0] - s[0], target_pos[1] - s[1]
        d2 = dx * dx + dy * dy
        rows.append([dx / np.sqrt(d2), dy / np.sqrt(d2)])  # d/dpT of ||pT - pS||
        rows.append([-dy / d2, dx / d2])  # d/dpT of atan2(dy, dx)
    return np.array(rows)


def textbook_update(x, P, z, sensors, sd2, st2):
    """Return the EKF update of eq. (11) with the full 2M x 2M innovation covariance."""
    n = x.shape[0]
    He = textbook_h(x[:2], sensors)
    H = np.zeros((He.shape[0], n))
    H[:, :2] = He
    R = np.diag(np.ravel(np.column_stack([sd2, st2])))
    zhat = []
    for s in sensors:
        dx, dy = x[0] - s[0], x[1] - s[1]
        zhat += [np.hypot(dx, dy), np.arctan2(dy, dx)]
    nu = np.ravel(z) - np.array(zhat)
    nu[1::2] = (nu[1::2] + np.pi) % (2 * np.pi) - np.pi
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    return x + K @ nu, P - K @ S @ K.T


def in_any(paths, pts, margin=1e-7):
    """Whether points (n, 2) lie inside any of the matplotlib ``paths`` by more than
    ``margin`` (a dent into the boundary within it is on the boundary)."""
    out = np.zeros(len(pts), dtype=bool)
    for path in paths:
        # A negative radius shrinks the polygon (for counter-clockwise vertices; both tried).
        out |= path.contains_points(pts, radius=-margin) & path.contains_points(pts, radius=margin)
    return out


def segments_enter(paths, a, b, n=201):
    """Whether segments a -> b (S, 2) pass inside any of ``paths`` at one of n samples."""
    t = np.linspace(0.0, 1.0, n)[:, None, None]
    pts = (a + t * (b - a)).reshape(-1, 2)
    return in_any(paths, pts).reshape(n, -1).any(axis=0)
