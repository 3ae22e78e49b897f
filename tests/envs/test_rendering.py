"""Rendering (Fig. 4 style), headless human mode, and record_video."""

import warnings

import imageio.v3 as iio
import numpy as np
import pytest

from activetrack.envs import parallel_env, record_video
from activetrack.envs.rendering import TrackingRenderer, ellipse


def test_rgb_array_frames_show_the_episode():
    env = parallel_env(scenario="paper", render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    assert first.dtype == np.uint8 and first.ndim == 3 and first.shape[2] == 3
    for _ in range(10):
        env.step({a: np.array([-1.0, 0.0]) for a in env.agents})
    frame = env.render()
    assert frame.shape == first.shape
    assert not np.array_equal(frame, first)
    # sensor 0 is drawn in matplotlib's C0 blue (31, 119, 180), the true track in black
    blue = np.all(np.abs(frame.astype(int) - [31, 119, 180]) < 40, axis=-1)
    assert blue.sum() > 20
    assert np.all(frame == 0, axis=-1).sum() > 20
    env.close()
    env.close()  # closing twice is fine


def test_blitted_frame_equals_a_full_redraw():
    env = parallel_env(scenario="paper", render_mode="rgb_array")
    env.reset(seed=1)
    for _ in range(6):
        env.step({a: np.array([0.0, 0.5]) for a in env.agents})
        env.render()  # the view is reused between frames: only the data is redrawn
    blitted = env.render()
    fresh = TrackingRenderer(env.params.rho)
    fresh._build(human=False)
    fresh._view = env._renderer._view  # the same view, drawn from scratch
    fresh._ax.set_xlim(env._renderer._ax.get_xlim())
    fresh._ax.set_ylim(env._renderer._ax.get_ylim())
    full = fresh.rgb_array(env._history)
    assert np.mean(np.any(blitted != full, axis=-1)) < 0.002


def test_ellipse_is_the_three_sigma_contour():
    cov = np.array([[4.0, 1.2], [1.2, 1.0]])
    pts = ellipse(np.array([1.0, -2.0]), cov) - [1.0, -2.0]
    mahal = np.einsum("ki,ij,kj->k", pts, np.linalg.inv(cov), pts)
    np.testing.assert_allclose(mahal, 9.0, rtol=1e-12)


def test_human_mode_headless_does_not_crash():
    env = parallel_env(scenario="paper", render_mode="human", n_steps=3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env.reset(seed=0)
        while env.agents:
            env.step({a: np.zeros(2) for a in env.agents})
        assert env.render() is None
    env.close()
    messages = [str(w.message) for w in caught]
    assert sum("interactive matplotlib backend" in m for m in messages) == 1


def test_human_mode_draws_on_a_pyplot_figure(monkeypatch):
    # Exercise the window code path on the non-interactive Agg backend.
    import matplotlib.pyplot as plt

    from activetrack.envs import rendering

    monkeypatch.setattr(rendering, "_interactive_backend", lambda: True)
    env = parallel_env(scenario="paper", render_mode="human", n_steps=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Agg: "cannot show the figure"
        env.reset(seed=0)
        env.step({a: np.zeros(2) for a in env.agents})
        fig = env._renderer._fig
        assert plt.fignum_exists(fig.number)
        assert len(fig.axes[0].lines[0].get_xdata()) == 2  # the true track so far
        env.close()
    assert not plt.fignum_exists(fig.number)


def test_render_without_mode_warns_and_returns_none():
    env = parallel_env(scenario="paper")
    env.reset(seed=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert env.render() is None
    assert any("render_mode" in str(w.message) for w in caught)


def test_record_video_gif_has_every_step(tmp_path):
    path = record_video(tmp_path / "ep.gif", seed=0, scenario="paper", n_steps=6)
    assert path.exists()
    frames = iio.imread(path, index=None)
    assert frames.shape[0] == 7  # the reset frame and one per step
    assert frames.shape[1:3] == (480, 480)


def test_record_video_with_a_policy_and_env(tmp_path):
    env = parallel_env(scenario="paper", n_steps=50, render_mode="rgb_array")
    calls = []

    def policy(observations):
        calls.append(env.k)
        return {a: np.array([-0.5, 0.5]) for a in observations}

    record_video(tmp_path / "p.gif", policy, env=env, seed=1, max_steps=4)
    assert calls == [0, 1, 2, 3]
    assert iio.imread(tmp_path / "p.gif", index=None).shape[0] == 5
    with pytest.raises(ValueError, match="render_mode"):
        record_video(tmp_path / "x.gif", env=parallel_env(scenario="paper"))
    with pytest.raises(ValueError, match="not both"):
        record_video(tmp_path / "x.gif", env=env, n_sensors=4)


def test_record_video_mp4_without_backend_says_so(tmp_path):
    import importlib.util

    if importlib.util.find_spec("imageio_ffmpeg") or importlib.util.find_spec("av"):
        path = record_video(tmp_path / "ep.mp4", seed=0, scenario="paper", n_steps=3)
        assert path.stat().st_size > 0
    else:
        with pytest.raises(RuntimeError, match="gif"):
            record_video(tmp_path / "ep.mp4", seed=0, scenario="paper", n_steps=3)
