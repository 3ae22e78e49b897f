"""The Gymnasium single-agent view: registration, equivalence, vector envs, video."""

import pickle

import gymnasium as gym
import numpy as np
import pytest

from activetrack.envs import ENV_ID, CentralizedTrackingEnv, parallel_env


def test_make_with_config_keywords_and_no_time_limit():
    env = gym.make(ENV_ID, scenario="homogeneous", n_sensors=5, rho=1.5, n_steps=7)
    base = env.unwrapped
    assert isinstance(base, CentralizedTrackingEnv)
    assert base.scenario.n_sensors == 5 and base.scenario.rho == 1.5
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (10,), np.float32)
    assert env.observation_space.shape == (5 * (5 + 6 * 5),)
    # The env truncates itself: no TimeLimit wrapper (and so no double truncation).
    wrapper, names = env, []
    while wrapper is not base:
        names.append(type(wrapper).__name__)
        wrapper = wrapper.env
    assert "TimeLimit" not in names
    env.reset(seed=0)
    flags = [env.step(env.action_space.sample())[2:4] for _ in range(7)]
    assert flags == [(False, False)] * 6 + [(False, True)]


def test_same_trajectory_as_the_parallel_env():
    cen = gym.make(ENV_ID, scenario="paper")
    par = parallel_env(scenario="paper")
    o_c, info_c = cen.reset(seed=11)
    o_p, _ = par.reset(seed=11)
    np.testing.assert_array_equal(o_c, np.concatenate([o_p[a] for a in par.possible_agents]))
    rng = np.random.default_rng(0)
    done = False
    while not done:
        a = rng.uniform(-1, 1, 6)
        o_c, r_c, term, trunc, info_c = cen.step(a)
        o_p, r_p, _, trunc_p, info_p = par.step(
            {ag: a[2 * i : 2 * i + 2] for i, ag in enumerate(par.possible_agents)}
        )
        np.testing.assert_array_equal(o_c, np.concatenate([o_p[ag] for ag in par.possible_agents]))
        assert r_c == r_p["sensor_0"] and trunc == trunc_p["sensor_0"]
        assert info_c["projected"].tolist() == [info_p[ag]["projected"] for ag in o_p]
        done = term or trunc
    np.testing.assert_array_equal(cen.unwrapped.state(), par.state())
    assert cen.unwrapped.np_random is cen.unwrapped.env.np_random


def test_nan_joint_action_names_the_agent():
    env = CentralizedTrackingEnv(scenario="paper")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="sensor_1"):
        env.step(np.array([0, 0, np.nan, 0, 0, 0]))
    with pytest.raises(ValueError, match=r"shape \(6,\)"):
        env.step(np.zeros(4))


def test_pickle_mid_episode():
    env = gym.make(ENV_ID, scenario="paper")
    env.reset(seed=1)
    env.step(np.full(6, 0.3))
    clone = pickle.loads(pickle.dumps(env))
    a = np.full(6, -0.2)
    np.testing.assert_array_equal(clone.step(a)[0], env.step(a)[0])


def _make():
    return gym.make(ENV_ID, scenario="homogeneous", n_sensors=3)


def test_async_vector_env_with_two_workers():
    vec = gym.vector.AsyncVectorEnv([_make, _make])
    try:
        obs, _ = vec.reset(seed=[3, 4])
        assert obs.shape == (2, 3 * 23)
        singles = [_make() for _ in range(2)]
        expected = [s.reset(seed=sd)[0] for s, sd in zip(singles, [3, 4], strict=True)]
        np.testing.assert_array_equal(obs, np.stack(expected))
        rng = np.random.default_rng(0)
        for t in range(1, 61):  # across the 50-step truncation and the autoreset
            a = rng.uniform(-1, 1, (2, 6)).astype(np.float32)
            obs, rew, term, trunc, _ = vec.step(a)
            assert np.isfinite(obs).all()
            assert trunc.tolist() == [t == 50] * 2 and not term.any()
            # Gymnasium's next-step autoreset: step 51 only resets (reward 0).
            assert np.all(rew == 0) if t == 51 else np.all(rew < 0)
        assert obs.shape == (2, 69)
    finally:
        vec.close()


def test_record_video_wrapper(tmp_path):
    """Gymnasium's RecordVideo (moviepy, in the dev extra) writes one frame per reset and
    step, each the frame the unwrapped environment renders for the same seed and actions."""
    import imageio.v3 as iio  # reads the MP4 back (imageio-ffmpeg, which moviepy brings)

    actions = np.random.default_rng(0).uniform(-1, 1, (5, 6)).astype(np.float32)
    env = gym.make(ENV_ID, scenario="paper", n_steps=5, render_mode="rgb_array")
    env = gym.wrappers.RecordVideo(env, str(tmp_path), episode_trigger=lambda i: True)
    env.reset(seed=0)
    for a in actions:
        *_, term, trunc, _ = env.step(a)
    assert trunc and not term
    env.close()
    (path,) = tmp_path.glob("*.mp4")
    video = iio.imread(path).astype(np.float64)

    plain = gym.make(ENV_ID, scenario="paper", n_steps=5, render_mode="rgb_array")
    plain.reset(seed=0)
    expected = [plain.render().copy()]  # copied at once: a reused buffer would show
    for a in actions:
        plain.step(a)
        expected.append(plain.render().copy())
    expected = np.asarray(expected, dtype=np.float64)
    assert video.shape == expected.shape  # (6, H, W, 3): reset + 5 steps
    # Mean absolute difference in 0..255 levels between decoded frame i and rendered frame
    # j. H.264 is lossy (about 0.5-0.7 on the diagonal here, the frames of the episode
    # about 1.6-2.7 apart), so no frame is bit-exact: each must be nearest its own.
    diff = np.abs(video[:, None] - expected[None]).mean(axis=(2, 3, 4))
    assert diff.argmin(axis=1).tolist() == list(range(len(expected))), diff
