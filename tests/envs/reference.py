"""A longhand closed loop (Section III, V) to check the environments against.

Written from the paper, not from activetrack's kernels: the constant-velocity model of
eq. (39) discretized by hand, the measurement of eq. (4), the EKF update of eq. (11) with
the full 2M x 2M innovation covariance, and the draw order documented by
:mod:`activetrack.world.tracking` (2M uniforms for the sensors; then per step n process and 2M
measurement standard normals). Only the square root used to colour the process noise is
taken from the scenario, because it defines which target path a seed gives.
"""

import numpy as np


def cv_matrices(q, dt):
    """Return (Phi, Qd) of eq. (39), discretized exactly (white acceleration)."""
    eye = np.eye(2)
    Phi = np.block([[eye, dt * eye], [0 * eye, eye]])
    Q = q * np.block([[dt**3 / 3 * eye, dt**2 / 2 * eye], [dt**2 / 2 * eye, dt * eye]])
    return Phi, Q


def ekf_update(x, P, z, sensors, sd2, st2):
    """Return the EKF posterior of eq. (11), built with the stacked Jacobian of eq. (6)-(9)."""
    H = np.zeros((2 * len(sensors), x.shape[0]))
    zhat = np.zeros(2 * len(sensors))
    for i, s in enumerate(sensors):
        dx, dy = x[0] - s[0], x[1] - s[1]
        d2 = dx * dx + dy * dy
        H[2 * i, :2] = [dx / np.sqrt(d2), dy / np.sqrt(d2)]
        H[2 * i + 1, :2] = [-dy / d2, dx / d2]
        zhat[2 * i : 2 * i + 2] = [np.sqrt(d2), np.arctan2(dy, dx)]
    R = np.diag(np.ravel(np.column_stack([sd2, st2])))
    nu = np.ravel(z) - zhat
    nu[1::2] = (nu[1::2] + np.pi) % (2 * np.pi) - np.pi
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    return x + K @ nu, P - K @ S @ K.T


class ReferenceLoop:
    """The closed loop of one episode, step by step, for a CV scenario without projection."""

    def __init__(self, sc, seed):
        self.sc = sc
        self.rng = np.random.default_rng(seed)
        self.restart()

    def restart(self):
        """Start the next episode from the same generator (the draws continue)."""
        sc = self.sc
        m = sc.n_sensors
        u = self.rng.random((m, 2))
        rad = sc.sensor_radius * np.sqrt(u[:, 0])
        ang = 2 * np.pi * u[:, 1]
        self.sensors = np.asarray(sc.sensor_center) + np.column_stack(
            [rad * np.cos(ang), rad * np.sin(ang)]
        )
        self.x_true = np.array(sc.x0, float)
        self.x_hat = np.array(sc.x0_hat, float)
        self.P = np.diag(np.array(sc.P0, float))
        self.Phi, self.Q = cv_matrices(sc.q, sc.dt)
        self.F = sc.model.noise_factor  # the convention that maps draws to paths
        self.sd2 = np.broadcast_to(np.array(sc.sigma_d2, float), (m,))
        self.st2 = np.broadcast_to(np.array(sc.sigma_theta2, float), (m,))
        self.r = np.broadcast_to(np.array(sc.vmax, float) * sc.dt, (m,))
        self._predict()

    def _predict(self):
        self.x_pred = self.Phi @ self.x_hat
        self.P_pred = self.Phi @ self.P @ self.Phi.T + self.Q

    def step(self, actions):
        """Apply (M, 2) actions (norm <= 1, no projection needed); return the reward."""
        m = self.sc.n_sensors
        self.sensors = self.sensors + actions * self.r[:, None]
        w = self.rng.standard_normal(4 + 2 * m)
        self.x_true = self.Phi @ self.x_true + self.F @ w[:4]
        z = np.zeros((m, 2))
        for i, s in enumerate(self.sensors):
            dx, dy = self.x_true[0] - s[0], self.x_true[1] - s[1]
            z[i, 0] = np.hypot(dx, dy) + np.sqrt(self.sd2[i]) * w[4 + 2 * i]
            bearing = np.arctan2(dy, dx) + np.sqrt(self.st2[i]) * w[5 + 2 * i]
            z[i, 1] = (bearing + np.pi) % (2 * np.pi) - np.pi
        self.x_hat, self.P = ekf_update(
            self.x_pred, self.P_pred, z, self.sensors, self.sd2, self.st2
        )
        reward = -self.sc.reward_scale * (self.P[0, 0] + self.P[1, 1])
        self._predict()
        return reward
