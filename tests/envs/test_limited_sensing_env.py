"""The environments on a limited-sensing scenario: spaces, the detection flags and the
range-finder rays of the observation (layout in activetrack.world.observation)."""

import numpy as np
from pettingzoo.test import parallel_api_test

from activetrack.envs import parallel_env
from activetrack.world.observation import EXT_SENSOR_DIM, EXT_TARGET_DIM, RAY_MAX, RAYS

WALL = [[(0.0, -3.0), (4.0, -3.0), (4.0, 3.0), (0.0, 3.0)]]


def _env():
    return parallel_env(scenario="two_targets", occluders=WALL, max_range=15.0, p_detect=0.8)


def test_api_and_sizes():
    env = _env()
    parallel_api_test(env, num_cycles=60)
    obs, _ = env.reset(seed=0)
    k, m = 2, 4
    size = EXT_TARGET_DIM * k + (EXT_SENSOR_DIM + k) * m + RAYS
    assert all(o.shape == (size,) for o in obs.values())
    assert env.state().shape == (size - RAYS + m * RAYS + 1,)


def test_flags_are_the_detections_in_each_agents_order():
    env = _env()
    obs, _ = env.reset(seed=1)
    rng = np.random.default_rng(0)
    for _ in range(15):
        obs, *_ = env.step({a: rng.uniform(-1, 1, 2) for a in env.agents})
        if not env.agents:
            break
        detected = env.world.get("detected", 0)  # (K, M)
        for i, a in enumerate(env.possible_agents):
            for seat in range(4):
                j = (i + seat) % 4  # agent i's seat `seat` holds sensor j
                b = EXT_TARGET_DIM * 2 + (EXT_SENSOR_DIM + 2) * seat + EXT_SENSOR_DIM
                np.testing.assert_array_equal(obs[a][b : b + 2], detected[:, j].astype(np.float32))


def test_rays_measure_the_wall_by_hand():
    # Put sensor 0 at (6, 0), facing the wall's right side x = 4: the ray at angle pi
    # meets it at 2 m; rays that miss the wall read 1 (nothing within RAY_MAX).
    env = _env()
    env.reset(seed=2)
    w = env.world
    w._s["sensors"][0] = (6.0, 0.0)
    obs = w.observe(0)
    rays = obs[0, -RAYS:]
    angles = 2 * np.pi * np.arange(RAYS) / RAYS
    assert rays[RAYS // 2] == np.float32(2.0 / RAY_MAX)  # angle pi
    # Ray at angle a (pointing left, |a - pi| < atan(3 / 2)) hits x = 4 at 2 / |cos a|.
    for r, a in zip(rays, angles, strict=True):
        if np.cos(a) < 0 and abs(2 * np.tan(a)) < 3:
            assert abs(r - 2 / abs(np.cos(a)) / RAY_MAX) < 1e-6
        elif np.cos(a) >= 0:
            assert r == 1.0


def test_batched_env_over_an_episode_boundary():
    from activetrack.envs.batched import BatchedActiveTracking

    env = BatchedActiveTracking(
        8, scenario="two_targets", occluders=WALL, max_range=15.0, p_detect=0.8
    )
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(60):  # past the 50-step episodes: autoreset
        obs, rewards, *_ = env.step(rng.uniform(-1, 1, (8, 8)).astype(np.float32))
        assert env.observation_space.contains(obs)
        assert np.all(np.isfinite(rewards))
    flags = env.world.observe()[:, 0, EXT_TARGET_DIM * 2 + EXT_SENSOR_DIM :][:, :2]
    np.testing.assert_array_equal(flags, env.world.get("detected")[:, :, 0].astype(np.float32))
