"""Bounds and dimensions of the observation encoding (activetrack.observation)."""

import numpy as np

from activetrack import observation as features


def test_bounds_and_dimensions():
    low, high = features.observation_bounds(3)
    assert low.shape == high.shape == (features.obs_dim(3),) == (23,)
    assert (low[2], high[2]) == (-1.0, 1.0)
    assert np.all(low[[9, 10, 15, 16, 21, 22]] == 0.0)
    slow, shigh = features.state_bounds(3)
    assert slow.shape == (features.state_dim(3),) == (24,) and (slow[-1], shigh[-1]) == (0, 1)
