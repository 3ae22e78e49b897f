"""The environments run with the IMM estimator unchanged (the scenario field ``estimator``
passes through ``gymnasium.make``): the observation and the reward are the IMM world's
(its predicted and posterior mixtures), not the default EKF world's."""

from __future__ import annotations

import gymnasium
import numpy as np

import activetrack  # noqa: F401 (registers the ids)
from activetrack import IMMSpec
from activetrack.world import World
from activetrack.world.presets import MANEUVERING


def test_gymnasium_env_observes_and_rewards_the_imm_world():
    spec = IMMSpec.from_behaviour(MANEUVERING)
    env = gymnasium.make("activetrack/Maneuvering-v0", estimator=spec)
    imm, ekf = World("maneuvering", estimator=spec), World("maneuvering")
    try:
        obs, _ = env.reset(seed=3)
        for w in (imm, ekf):
            w.reset(seeds=[3])
        rng = np.random.default_rng(0)
        for _ in range(10):
            action = rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)
            obs, reward, *_ = env.step(action)
            for w in (imm, ekf):
                w.step_actions(action.astype(np.float64).reshape(w.n_sensors, 2))
            np.testing.assert_array_equal(obs, np.ravel(imm.observe(0)))
            assert reward == -imm.get("trace", 0) != -ekf.get("trace", 0)
        assert not np.array_equal(obs, np.ravel(ekf.observe(0)))
    finally:
        env.close()
