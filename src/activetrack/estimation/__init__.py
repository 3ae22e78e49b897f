"""The target's estimator: the extended Kalman filter (eq. 3, 11)."""
