"""Independent reference computations for the core tests (textbook forms, no shortcuts)."""

import numpy as np
from scipy import stats

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


def misspecify_filter(world, r_scale=1.0, q_scale=1.0):
    """Return ``world`` with a mis-modelled filter: it assumes measurement noise
    ``r_scale * R`` and process noise ``q_scale * Q`` while the world still draws the
    measurements with R and the targets' motion with Q (call before the first reset).

    The filter reads the weights ``1/sigma^2`` (``params.weights``; in the one-target
    compiled step, the table's W columns) and each target's ``Q`` (``params.targets``; in
    the compiled step, the last of its matrices ``(Phi, noise_factor, Q)``); the draws read
    ``noise_std`` (the table's STD columns) and ``noise_factor`` (a square root of the
    true Q), left unchanged.
    """
    import dataclasses

    from activetrack.world import _loop_kernels as loop_kernels
    from activetrack.world.tracking import TargetParams

    wd, wt = world.params.weights
    targets = tuple(
        TargetParams(t.Phi, q_scale * t.Q, t.noise_factor) for t in world.params.targets
    )
    world.params = dataclasses.replace(
        world.params,
        weights=(wd / r_scale, wt / r_scale),
        Q=q_scale * world.params.Q,
        targets=targets,
    )
    if world._fused:
        table = world._fused_args[0].copy()
        table[:, loop_kernels.W_D] /= r_scale
        table[:, loop_kernels.W_T] /= r_scale
        matrices = world._fused_args[1].copy()
        matrices[2] *= q_scale
        world._fused_args = (table, matrices)
    return world


def nees_band(run_means, dim=2, level=0.99):
    """Return the ``level`` band ``(lo, hi)`` of the mean over runs of each run's
    time-averaged NEES under a consistent filter (expected value ``dim``).

    The runs are independent, the steps of one run are not (the estimation error is
    autocorrelated: on range_only a run's 50-step average has standard deviation 0.49,
    where 50 independent chi-square(2) values' would have 0.28), so neither the band of
    one chi-square(2 runs) draw per run nor that of chi-square(2 runs steps) describes
    the statistic. Each run's average is one i.i.d. sample: the band is the t-interval
    ``dim +- t(level; runs - 1) s / sqrt(runs)`` with ``s`` the runs' sample standard
    deviation (the central limit theorem on the mean of ``runs`` averages). On range_only
    with 200 runs its 95% half-width is 0.068: the chi-square(2 runs) band's (0.28) is 4
    times as wide, the chi-square(2 runs steps) band's (0.039) too narrow by 1.7. 99%
    by default: the suite checks a dozen such statistics on fixed seeds.
    """
    x = np.asarray(run_means, dtype=np.float64)
    n = x.size
    half = stats.t.ppf(0.5 + level / 2, n - 1) * x.std(ddof=1) / np.sqrt(n)
    return float(dim - half), float(dim + half)


def rk4(f, y, dt, n):
    """Return the classical Runge-Kutta solution of ``y' = f(y)`` over ``dt`` in ``n``
    steps at the ``n + 1`` instants (..., n + 1, D)."""
    h = dt / n
    out = [y]
    for _ in range(n):
        k1 = f(y)
        k2 = f(y + 0.5 * h * k1)
        k3 = f(y + 0.5 * h * k2)
        k4 = f(y + h * k3)
        y = y + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        out.append(y)
    return np.stack(out, -2)
