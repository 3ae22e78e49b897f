"""The observation kernels are batch-aware: a batch equals its elements one by one."""

import numpy as np

from activetrack.envs import features, parallel_env


def test_batched_features_equal_single_ones():
    envs = [parallel_env(scenario="homogeneous", n_sensors=4) for _ in range(3)]
    for i, e in enumerate(envs):
        e.reset(seed=i)
        e.step({a: np.array([0.2 * i, -0.3]) for a in e.agents})
    e0 = envs[0]
    L, dt = e0.length_scale, e0.scenario.dt
    x = np.stack([e.x_pred for e in envs])
    P = np.stack([e.P_pred for e in envs])
    s = np.stack([e.sensors for e in envs])
    target = features.target_features(x, P, dt, L)
    sensor = features.sensor_features(s, x[:, :2], e0._constants, L)
    obs = features.observations(target, sensor, features.cyclic_order(4))
    state = features.global_state(target, sensor, np.array([0.1, 0.2, 0.3]))
    assert obs.shape == (3, 4, 29) and state.shape == (3, 30)
    for i, e in enumerate(envs):
        single = features.observations(
            features.target_features(e.x_pred, e.P_pred, dt, L),
            features.sensor_features(e.sensors, e.x_pred[:2], e0._constants, L),
            features.cyclic_order(4),
        )
        np.testing.assert_array_equal(obs[i], single)
        assert state[i, -1] == np.float32(0.1 * (i + 1))


def test_bounds_and_dimensions():
    low, high = features.observation_bounds(3)
    assert low.shape == high.shape == (features.obs_dim(3),) == (23,)
    assert (low[2], high[2]) == (-1.0, 1.0)
    assert np.all(low[[9, 10, 15, 16, 21, 22]] == 0.0)
    slow, shigh = features.state_bounds(3)
    assert slow.shape == (features.state_dim(3),) == (24,) and (slow[-1], shigh[-1]) == (0, 1)
