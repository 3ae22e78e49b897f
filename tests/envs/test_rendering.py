"""Rendering (Fig. 4 style), several targets, sensor models, uncertain poses, headless
human mode, and record_video."""

import importlib.util
import pathlib
import subprocess
import sys
import types
import warnings

import imageio.v3 as iio
import numpy as np
import pytest

from activetrack.envs import parallel_env, record_video
from activetrack.envs.rendering import (
    MODEL_MARKERS,
    EpisodeHistory,
    TrackingRenderer,
    ellipse,
)
from activetrack.world.scenarios import TASKS

#: The commit whose renderer drew the paper's frames before several targets existed.
PAPER_RENDERER_COMMIT = "1a245c2942c68c7c6ede434c7756f5ba8ed60a79"
REPO = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture
def feasible_set_guard(monkeypatch):
    """Several-target worlds import ``activetrack.kinematics.feasible_set`` on every step; until
    that
    module exists, stand in a stub that fails if a projection is ever needed (the tests
    keep the sensors out of every rho disk)."""
    if importlib.util.find_spec("activetrack.kinematics.feasible_set") is None:
        stub = types.ModuleType("activetrack.kinematics.feasible_set")

        def project(*args, **kwargs):
            raise AssertionError("a sensor entered a rho disk: the test needs feasible_set")

        stub.project = project
        monkeypatch.setitem(sys.modules, "activetrack.kinematics.feasible_set", stub)


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
    fresh._view = env._recorder._renderer._view  # the same view, drawn from scratch
    fresh._ax.set_xlim(env._recorder._renderer._ax.get_xlim())
    fresh._ax.set_ylim(env._recorder._renderer._ax.get_ylim())
    full = fresh.rgb_array(env._recorder.history)
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
        fig = env._recorder._renderer._fig
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


@pytest.mark.parametrize(
    "kwargs, match",
    [({"fps": 0.0}, "fps"), ({"fps": float("nan")}, "fps"), ({"fps": "10"}, "fps"),
     ({"max_steps": 0}, "max_steps"), ({"seed": -1}, "seed")],
)  # fmt: skip
def test_record_video_checks_its_arguments_before_the_episode(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        record_video(tmp_path / "x.gif", scenario="paper", **kwargs)
    assert not list(tmp_path.iterdir())


def test_record_video_mp4_without_backend_says_so(tmp_path):
    import importlib.util

    if importlib.util.find_spec("imageio_ffmpeg") or importlib.util.find_spec("av"):
        path = record_video(tmp_path / "ep.mp4", seed=0, scenario="paper", n_steps=3)
        assert path.stat().st_size > 0
    else:
        with pytest.raises(RuntimeError, match="gif"):
            record_video(tmp_path / "ep.mp4", seed=0, scenario="paper", n_steps=3)


# Several targets, sensor models, uncertain poses ---------------------------------------


@pytest.mark.parametrize("scenario", ["paper", "homogeneous", *TASKS])
def test_every_preset_renders_a_few_steps(scenario, feasible_set_guard):
    env = parallel_env(scenario=scenario, render_mode="rgb_array")
    env.reset(seed=0)
    frames = [env.render()]
    for _ in range(3):  # small moves: far from every rho disk in every preset
        env.step({a: np.array([0.3, -0.2]) for a in env.agents})
        frames.append(env.render())
    for f in frames:
        assert f.dtype == np.uint8 and f.shape == (480, 480, 3)
    assert not np.array_equal(frames[0], frames[-1])
    assert len(env._recorder.history.frames) == 4
    assert env._recorder.history.frames[-1].n_targets == env.world.n_targets
    env.close()


def test_frames_have_the_configured_size():
    env = parallel_env(scenario="mixed", render_mode="rgb_array", n_steps=3)
    env.reset(seed=0)
    env.step({a: np.zeros(2) for a in env.agents})
    sc = env.scenario
    r = TrackingRenderer(env.params.rho, (400, 300), 100, models=sc.sensor_models)
    frame = r.rgb_array(env._recorder.history)
    assert frame.dtype == np.uint8 and frame.shape == (300, 400, 3)


def test_history_records_every_target_and_the_fixes(feasible_set_guard):
    for scenario in ("two_targets", "uncertain_poses"):
        env = parallel_env(scenario=scenario, render_mode="rgb_array")
        env.reset(seed=2)
        w = env.world
        K = w.n_targets
        before = [w.get("x_pred", 0, j)[:2].copy() for j in range(K)]
        env.step({a: np.array([0.0, 0.5]) for a in env.agents})
        snap = env._recorder.history.frames[-1]
        assert snap.k == 1 and snap.n_targets == K
        for j in range(K):
            np.testing.assert_array_equal(snap.targets[j], w.get("x_true", 0, j)[:2])
            np.testing.assert_array_equal(snap.estimates[j], w.get("x_hat", 0, j)[:2])
            np.testing.assert_array_equal(snap.covs[j], w.get("P", 0, j)[:2, :2])
            np.testing.assert_array_equal(snap.centers[j], before[j])  # what the move kept rho from
        np.testing.assert_array_equal(snap.sensors, w.get("sensors", 0))
        if scenario == "uncertain_poses":
            np.testing.assert_array_equal(snap.fixes, w.get("fixes", 0))
            assert not np.allclose(snap.fixes, snap.sensors)  # the fix is not the truth
        else:
            assert snap.fixes is None


def _two_target_history(n_steps=6):
    """A history of two targets far apart (target 1 up and to the right), three sensors."""
    h = EpisodeHistory()
    P = np.diag([0.5, 0.3, 1.0, 1.0])
    for k in range(n_steps):
        x0 = np.array([-10.0 + k, -10.0 + 0.5 * k, 1.0, 0.5])
        x1 = np.array([12.0 - 0.5 * k, 14.0 - 0.2 * k, -0.5, -0.2])
        sensors = np.array([[0.0, -5.0 + 0.2 * k], [3.0, 0.0], [-2.0, 4.0]])
        h.append(k, [x0, x1], [x0 + 0.3, x1 - 0.3], [P, 2.0 * P], sensors, [x0, x1])
    return h


def _without_target_1(history):
    h = EpisodeHistory()
    for f in history.frames:
        h.append(f.k, f.targets[0], f.estimates[0], f.covs[0], f.sensors, f.centers[0])
    return h


def _fixed_view_frame(history, lim):
    """Render ``history`` with the axes limits ``lim`` held fixed."""
    r = TrackingRenderer(np.full(3, 1.5))
    r._build(False, *r._layout_of(history))
    r._fit_view = lambda lo, hi: None
    r._ax.set_xlim(*lim)
    r._ax.set_ylim(*lim)
    return r, r.rgb_array(history)


def _pixel(renderer, xy):
    """Return the (row, column) of data point ``xy`` in the frame."""
    x, y = renderer._ax.transData.transform(xy)
    return int(round(renderer.size[1] - y)), int(round(x))


def _near(frame, rc, rgb, half=12, tol=40):
    """Return how many pixels within ``half`` of ``rc`` have the colour ``rgb``."""
    r, c = rc
    patch = frame[max(r - half, 0) : r + half + 1, max(c - half, 0) : c + half + 1].astype(int)
    return int(np.sum(np.all(np.abs(patch - rgb) < tol, axis=-1)))


def test_second_target_is_drawn_in_its_own_colour_where_it_is():
    two = _two_target_history()
    one = _without_target_1(two)
    lim = (-25.0, 25.0)
    r2, f2 = _fixed_view_frame(two, lim)
    r1, f1 = _fixed_view_frame(one, lim)
    last = two.frames[-1]
    magenta = (191, 0, 191)  # matplotlib's "m": target 1's estimate, ellipses
    est1 = _pixel(r2, last.estimates[1])
    assert _pixel(r1, last.estimates[1]) == est1  # the same view
    assert _near(f2, est1, magenta) > 15
    assert _near(f1, est1, magenta) == 0
    dark = (92, 0, 92)  # target 1's true track and star
    assert _near(f2, _pixel(r2, last.targets[1]), dark, half=6, tol=30) > 10
    assert _near(f1, _pixel(r1, last.targets[1]), dark, half=6, tol=30) == 0
    # Target 0 is drawn alike in both frames: the frames agree around it.
    r, c = _pixel(r2, last.targets[0])
    box = (slice(r - 8, r + 9), slice(c - 8, c + 9))
    np.testing.assert_array_equal(f2[box], f1[box])
    # The frames differ where target 1 is (its track, ellipses and rho circles).
    diff = np.any(f2 != f1, axis=-1)
    r, c = est1
    assert diff[r - 12 : r + 13, c - 12 : c + 13].sum() > 30


def test_rho_circles_surround_every_predicted_target():
    two = _two_target_history()
    r = TrackingRenderer(np.array([1.0, 1.5, 2.5]))
    r.rgb_array(two)
    centers = two.frames[-1].centers
    for rho, line in zip(r.rho, r._art["rho"], strict=True):
        pts = np.column_stack([line.get_xdata(), line.get_ydata()])
        pts = pts[np.isfinite(pts[:, 0])]
        dist = np.linalg.norm(pts[:, None, :] - centers[None], axis=-1)  # (points, K)
        np.testing.assert_allclose(dist.min(1), rho, rtol=1e-12)
        # every target has its full ring
        assert np.all(np.sum(np.isclose(dist, rho, rtol=1e-12), axis=0) >= 64)


def _legend_markers(renderer):
    legend = renderer._ax.get_legend()
    return {
        t.get_text(): getattr(h, "get_marker", lambda: None)()
        for t, h in zip(legend.get_texts(), legend.legend_handles, strict=True)
    }


def test_model_markers_and_their_legend_entries():
    env = parallel_env(scenario="mixed", render_mode="rgb_array", n_steps=3)
    env.reset(seed=0)
    env.render()
    r = env._recorder._renderer
    entries = _legend_markers(r)
    codes = env.scenario.sensor_models.tolist()
    assert sorted(set(codes)) == [0, 1, 2]
    for marker, label in MODEL_MARKERS:
        assert entries[label] == marker
    assert [marker for marker, _ in MODEL_MARKERS] == ["o", "s", "^"]  # circle, square, triangle
    for code, head in zip(codes, r._art["heads"], strict=True):
        assert head.get_marker() == MODEL_MARKERS[code][0]
    # Only the models present: a bearing-only team has that entry alone.
    r = TrackingRenderer(np.ones(3), models=np.full(3, 2, dtype=np.int8))
    r.rgb_array(_two_target_history())
    labels = set(_legend_markers(r))
    assert "bearing only" in labels
    assert not labels & {"range & bearing", "range only"}
    assert {"target 0 (true)", "target 1 (estimate)"} <= labels


def test_paper_legend_is_unchanged():
    env = parallel_env(scenario="paper", render_mode="rgb_array")
    env.reset(seed=0)
    env.render()
    assert list(_legend_markers(env._recorder._renderer)) == [
        "target (true)",
        "target (estimate)",
        "3-sigma bounds",
        "sensor trails",
        "rho circles",
    ]


def test_uncertain_poses_show_fixes_and_two_sigma_pose_ellipses():
    env = parallel_env(scenario="uncertain_poses", render_mode="rgb_array", n_steps=5)
    env.reset(seed=4)
    env.step({a: np.array([0.5, 0.0]) for a in env.agents})
    env.render()
    art = env._recorder._renderer._art
    fixes = env._recorder.history.frames[-1].fixes
    cov = env.scenario.pose_covariances
    for i, mark in enumerate(art["fixes"]):
        assert mark.get_marker() == "+"
        np.testing.assert_array_equal(np.column_stack(mark.get_data()), fixes[i : i + 1])
    segments = art["pose"].get_segments()
    assert len(segments) == env.n_sensors
    for i, seg in enumerate(segments):
        d = seg - fixes[i]
        mahal = np.einsum("ki,ij,kj->k", d, np.linalg.inv(cov[i]), d)
        np.testing.assert_allclose(mahal, 4.0, rtol=1e-10)  # the 2-sigma contour
    assert "position fixes (2-sigma)" in _legend_markers(env._recorder._renderer)


def test_singular_pose_covariance_draws_a_segment():
    cov = np.array([np.diag([4.0, 0.0]), np.eye(2), np.zeros((2, 2))])
    r = TrackingRenderer(np.ones(3), pose_cov=cov)
    h = EpisodeHistory()
    x = np.array([0.0, 0.0, 1.0, 0.0])
    sensors = np.array([[5.0, 0.0], [0.0, 5.0], [-5.0, 0.0]])
    h.append(0, x, x, np.eye(4), sensors, x, fixes=sensors + 0.5)
    frame = r.rgb_array(h)
    assert frame.shape == (480, 480, 3)
    seg = r._art["pose"].get_segments()
    assert np.all(np.isfinite(np.concatenate(seg)))
    np.testing.assert_allclose(seg[0][:, 1], 0.5, atol=1e-12)  # along x only, +-2 sigma = 4
    np.testing.assert_allclose(np.ptp(seg[0][:, 0]), 8.0, rtol=1e-3)
    np.testing.assert_allclose(seg[2], np.broadcast_to(sensors[2] + 0.5, seg[2].shape))


def test_renderer_and_history_validate_their_inputs():
    with pytest.raises(ValueError, match="models"):
        TrackingRenderer(np.ones(3), models=[0, 1, 3])
    with pytest.raises(ValueError, match="models"):
        TrackingRenderer(np.ones(3), models=[0, 1])
    with pytest.raises(ValueError, match="pose_cov"):
        TrackingRenderer(np.ones(3), pose_cov=np.zeros((2, 2, 2)))
    with pytest.raises(ValueError, match="size"):
        TrackingRenderer(np.ones(3), size=(0, 480))
    h = EpisodeHistory()
    x = np.zeros(4)
    with pytest.raises(ValueError, match="same number of targets"):
        h.append(0, [x, x], [x, x], np.eye(4), np.zeros((3, 2)), [x, x])
    with pytest.raises(ValueError, match="fixes"):
        h.append(0, x, x, np.eye(4), np.zeros((3, 2)), x, fixes=np.zeros((2, 2)))
    h.append(0, x, x, np.eye(4), np.zeros((3, 2)), x)
    with pytest.raises(ValueError, match="sensors"):
        TrackingRenderer(np.ones(4)).rgb_array(h)


@pytest.mark.parametrize("scenario", ["two_targets", "uncertain_poses"])
def test_human_mode_draws_every_target(scenario, monkeypatch, feasible_set_guard):
    import matplotlib.pyplot as plt

    from activetrack.envs import rendering

    monkeypatch.setattr(rendering, "_interactive_backend", lambda: True)
    env = parallel_env(scenario=scenario, render_mode="human", n_steps=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Agg: "cannot show the figure"
        env.reset(seed=0)
        env.step({a: np.zeros(2) for a in env.agents})
        fig = env._recorder._renderer._fig
        targets = env._recorder._renderer._art["targets"]
        assert len(targets) == env.world.n_targets
        for t in targets:
            assert len(t["true"].get_xdata()) == 2
        env.close()
    assert not plt.fignum_exists(fig.number)


@pytest.mark.parametrize("scenario", ["two_targets", "mixed"])
def test_record_video_of_a_task(scenario, tmp_path, feasible_set_guard):
    env = parallel_env(scenario=scenario, n_steps=50, render_mode="rgb_array")
    path = record_video(tmp_path / "t.gif", lambda obs: {a: np.zeros(2) for a in obs}, env=env,
                        seed=0, max_steps=3)  # fmt: skip
    frames = iio.imread(path, index=None)
    assert frames.shape[:3] == (4, 480, 480)


def _paper_renderer_module(monkeypatch):
    """Return envs/rendering.py as it was before several targets (from git), or skip."""
    try:
        source = subprocess.run(
            ["git", "show", f"{PAPER_RENDERER_COMMIT}:envs/rendering.py"],
            cwd=REPO, capture_output=True, text=True, check=True, timeout=60,
        ).stdout  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        pytest.skip("the paper's renderer needs git and the repository's history")
    module = types.ModuleType("_paper_rendering")
    monkeypatch.setitem(sys.modules, module.__name__, module)  # for its dataclasses
    exec(compile(source, "paper_rendering.py", "exec"), module.__dict__)
    return module


def test_paper_frames_are_pixel_identical_to_the_single_target_renderer(monkeypatch):
    old = _paper_renderer_module(monkeypatch)
    env = parallel_env(scenario="paper", render_mode="rgb_array")
    env.reset(seed=3)
    w = env.world
    # The old recording: the world's state of the one target, as the env recorded it.
    history = old.EpisodeHistory()
    x_hat = w.get("x_hat", 0)
    history.append(0, w.get("x_true", 0), x_hat, w.get("P", 0), w.get("sensors", 0), x_hat)
    renderer = old.TrackingRenderer(env.params.rho)
    rng = np.random.default_rng(0)
    n = 0
    while True:
        new_frame, old_frame = env.render(), renderer.rgb_array(history)
        np.testing.assert_array_equal(new_frame, old_frame, err_msg=f"step {n}")
        if not env.agents:
            break
        planned_from = w.get("x_pred", 0).copy()
        env.step({a: rng.uniform(-1.0, 1.0, 2) for a in env.agents})
        g = w.get
        history.append(g("k", 0), g("x_true", 0), g("x_hat", 0), g("P", 0), g("sensors", 0),
                       planned_from)  # fmt: skip
        n += 1
    assert n == env.scenario.n_steps


# Limited sensing: occluders, sensing ranges, lines of sight, missed detections ----------

#: One rectangular occluder, clear of every other drawn element of _limited_history.
BOX = ((2.0, -18.0), (8.0, -18.0), (8.0, -12.0), (2.0, -12.0))
#: Which sensor measured which target (K = 2, M = 3) at every step after the first.
SEEN = np.array([[True, False, True], [False, True, False]])
LIM = (-25.0, 25.0)


def _limited_history(n_steps=6, detected=SEEN, occluders=(BOX,), max_range=(5.0, np.inf, 8.0)):
    """Two targets (top left and top right), three sensors; step 0 has no detections."""
    h = EpisodeHistory()
    P = np.diag([0.5, 0.3, 1.0, 1.0])
    for k in range(n_steps):
        x0 = np.array([-15.0 + k, 10.0, 1.0, 0.0])
        x1 = np.array([15.0 - 0.5 * k, 15.0, -0.5, 0.0])
        sensors = np.array([[-12.5 + 0.1 * k, -12.0], [12.0, -5.0], [-2.0, 0.2 * k]])
        seen = None if detected is None else (detected if k else np.zeros_like(detected))
        h.append(k, [x0, x1], [x0 + 0.2, x1 - 0.2], [P, P], sensors, [x0, x1], detected=seen,
                 occluders=occluders, max_range=max_range)  # fmt: skip
    return h


def _with(history, **changes):
    """Return ``history`` with the limited-sensing fields of every frame replaced."""
    h = EpisodeHistory()
    for f in history.frames:
        kw = {"detected": f.detected, "occluders": f.occluders, "max_range": f.max_range}
        kw.update(changes)
        h.append(f.k, f.targets, f.estimates, f.covs, f.sensors, f.centers, f.fixes, **kw)
    return h


def _to_pixels(renderer, xy):
    """Return the (row, column) floats of data points ``xy`` (..., 2) in the frame."""
    pts = renderer._ax.transData.transform(np.reshape(xy, (-1, 2)))
    return np.column_stack([renderer.size[1] - pts[:, 1], pts[:, 0]])


def _hex_rgb(color):
    return np.array([int(color[i : i + 2], 16) for i in (1, 3, 5)])


def test_occluders_are_filled_grey_polygons_under_the_data():
    from activetrack.envs.rendering import OCCLUDER_FACE

    grey = _hex_rgb(OCCLUDER_FACE)
    r, frame = _fixed_view_frame(_limited_history(), LIM)
    _, bare = _fixed_view_frame(_limited_history(occluders=()), LIM)
    # The box's pixel extent (pixel (r, c) covers [r, r+1) x [c, c+1)).
    (top, left), (bottom, right) = _to_pixels(r, [(2.0, -12.0), (8.0, -18.0)])
    # 3 pixels in from the edge line (antialiased over about 2 pixels)
    inner = (slice(int(top) + 3, int(bottom) - 2), slice(int(left) + 3, int(right) - 2))
    assert frame[inner].shape[0] > 20 and frame[inner].shape[1] > 20
    assert np.all(frame[inner] == grey)
    assert np.all(bare[inner] == 255)  # nothing else is drawn there
    # Just outside the box the frame is white, as without the occluder.
    ring = np.zeros(frame.shape[:2], bool)
    ring[int(top) - 5 : int(bottom) + 6, int(left) - 5 : int(right) + 6] = True
    ring[int(top) - 2 : int(bottom) + 3, int(left) - 2 : int(right) + 3] = False
    assert np.all(frame[ring] == 255) and np.all(bare[ring] == 255)
    # Under the data: a target crossing the box is drawn over it.
    h = _limited_history()
    f = h.frames[-1]
    x = np.array([5.0, -15.0, 0.0, 0.0])
    h.append(f.k + 1, [x, f.targets[1]], [x, f.estimates[1]], f.covs, f.sensors, [x, f.targets[1]],
             detected=f.detected, occluders=(BOX,), max_range=f.max_range)  # fmt: skip
    r, frame = _fixed_view_frame(h, LIM)
    _, bare = _fixed_view_frame(_with(h, occluders=()), LIM)
    row, col = _to_pixels(r, x[:2])[0].astype(int)
    box = (slice(row - 3, row + 4), slice(col - 3, col + 4))
    black = np.all(bare[box] == 0, axis=-1)  # the black star's opaque pixels
    assert black.sum() >= 3 and np.all(frame[box][black] == 0)  # drawn over the grey
    assert np.any(np.all(frame[box] == grey, axis=-1))  # inside the box


def test_occluders_are_in_the_cached_background_and_follow_the_layout():
    h = _limited_history()
    r = TrackingRenderer(np.full(3, 1.5))
    for n in range(1, len(h.frames) + 1):  # frame by frame, blitting over one background
        blitted = r.rgb_array(EpisodeHistory(h.frames[:n]))
    fresh = TrackingRenderer(np.full(3, 1.5))
    fresh._build(False, *r._layout)
    fresh._view = r._view
    fresh._ax.set_xlim(r._ax.get_xlim())
    fresh._ax.set_ylim(r._ax.get_ylim())
    assert np.mean(np.any(blitted != fresh.rgb_array(h), axis=-1)) < 0.002
    # A new layout (e.g. a new episode's) replaces the drawn one.
    moved = tuple((x - 10.0, y) for x, y in BOX)
    frame = r.rgb_array(_limited_history(occluders=(moved,)))
    r_mid, c_mid = _to_pixels(r, [(5.0, -15.0), (-5.0, -15.0)]).astype(int)
    from activetrack.envs.rendering import OCCLUDER_FACE

    grey = _hex_rgb(OCCLUDER_FACE)
    assert np.all(blitted[r_mid[0], r_mid[1]] == grey)
    assert not np.all(frame[r_mid[0], r_mid[1]] == grey)
    assert np.all(frame[c_mid[0], c_mid[1]] == grey)


def test_sensing_range_is_a_dotted_circle_around_each_sensor():
    h = _limited_history()
    r, frame = _fixed_view_frame(h, LIM)
    last = h.frames[-1]
    ranges = r._art["range"]
    assert len(ranges) == 3 and ranges[0].get_label() == "sensing range"
    for line, center, radius in zip(ranges, last.sensors, last.max_range, strict=True):
        pts = np.column_stack(line.get_data())
        if np.isinf(radius):
            assert len(pts) == 0  # an unlimited sensor has no circle
            continue
        np.testing.assert_allclose(np.linalg.norm(pts - center, axis=1), radius, rtol=1e-12)
        assert line.get_linestyle() != "-"
    # Pixels: sensor 0's lower half circle (nothing else is drawn there) is dotted in C0.
    angles = np.linspace(np.pi + 0.3, 2 * np.pi - 0.3, 400)
    on = last.sensors[0] + 5.0 * np.column_stack([np.cos(angles), np.sin(angles)])
    rc = np.floor(_to_pixels(r, on)).astype(int)  # the pixel holding each point
    _, bare = _fixed_view_frame(_limited_history(max_range=None), LIM)

    def coloured(f):  # C0 blue (31, 119, 180), faint on thin dots: blue well above red
        px = f[rc[:, 0], rc[:, 1]].astype(int)
        return px[:, 2] - px[:, 0] > 25

    dots = coloured(frame)
    white = np.all(frame[rc[:, 0], rc[:, 1]] == 255, axis=-1)
    assert 0.1 < dots.mean() < 0.8 and white.mean() > 0.15  # dots and gaps alternate
    assert not coloured(bare).any()  # no range, no circle


def _pairs(line):
    """Return the segments of a NaN-broken polyline as a set of rounded point pairs."""
    pts = np.column_stack(line.get_data())
    assert len(pts) % 3 == 0 and np.all(np.isnan(pts[2::3]))
    ends = zip(pts[::3], pts[1::3], strict=True)
    return {(tuple(np.round(a, 9)), tuple(np.round(b, 9))) for a, b in ends}


def test_lines_of_sight_join_each_sensor_to_the_targets_it_measured():
    h = _limited_history()
    r, frame = _fixed_view_frame(h, LIM)
    last = h.frames[-1]
    S, T = last.sensors, last.targets
    seg = lambda i, j: (tuple(np.round(S[i], 9)), tuple(np.round(T[j], 9)))  # noqa: E731
    # By hand from SEEN: sensor 0 saw target 0, sensor 1 target 1, sensor 2 target 0.
    assert _pairs(r._art["sight"][0]) == {seg(0, 0)}
    assert _pairs(r._art["sight"][1]) == {seg(1, 1)}
    assert _pairs(r._art["sight"][2]) == {seg(2, 0)}
    assert _pairs(r._art["missed"]) == {seg(0, 1), seg(1, 0), seg(2, 1)}
    for i in range(3):
        assert r._art["sight"][i].get_color() == f"C{i}"
        assert r._art["sight"][i].get_linestyle() == "-"
    assert r._art["missed"].get_linestyle() != "-"
    assert r._art["title"].get_text().endswith("missed 3/6")
    # Pixels: the middle of sensor 1's line of sight is orange (C1), drawn only when seen.
    mid = _to_pixels(r, 0.5 * (S[1] + T[1]))[0].astype(int)
    orange = (255, 127, 14)
    assert _near(frame, mid, orange, half=2, tol=70) > 0
    none_seen = _limited_history(detected=np.zeros((2, 3), bool))
    r0, f0 = _fixed_view_frame(none_seen, LIM)
    assert _near(f0, mid, orange, half=2, tol=70) == 0
    assert all(len(line.get_xdata()) == 0 for line in r0._art["sight"])
    assert len(_pairs(r0._art["missed"])) == 6
    assert r0._art["title"].get_text().endswith("missed 6/6")


def test_first_frame_has_no_lines_of_sight_and_no_count():
    h = _limited_history(n_steps=1)
    r, _ = _fixed_view_frame(h, LIM)
    assert all(len(line.get_xdata()) == 0 for line in [*r._art["sight"], r._art["missed"]])
    assert "missed" not in r._art["title"].get_text()


def _limited_env(render_mode="rgb_array", **kw):
    from activetrack.world.scenarios import make_scenario

    sc = make_scenario("two_targets", occluders=[[(0, -3), (4, -3), (4, 3), (0, 3)]],
                       max_range=12.0, p_detect=0.8, sensor_center=(-6.0, 0.0), **kw)  # fmt: skip
    return parallel_env(scenario=sc, render_mode=render_mode)


def test_missed_count_and_snapshots_come_from_the_world(feasible_set_guard):
    env = _limited_env(n_steps=12)
    env.reset(seed=0)
    w = env.world
    env.render()
    assert "missed" not in env._recorder._renderer._art["title"].get_text()
    counts = []
    while env.agents:
        env.step({a: np.array([0.3, 0.2]) for a in env.agents})
        env.render()
        det = w.get("detected", 0)
        snap = env._recorder.history.frames[-1]
        np.testing.assert_array_equal(snap.detected, det)
        assert not np.shares_memory(snap.detected, det)  # a copy, not a view of the world
        missed = int(np.sum(~det))
        title = env._recorder._renderer._art["title"].get_text()
        assert title.endswith(f"missed {missed}/{det.size}")
        counts.append(missed)
    assert 0 < min(counts) and max(counts) < 8  # some seen, some missed: a real check
    snap = env._recorder.history.frames[-1]
    np.testing.assert_array_equal(snap.max_range, np.full(4, 12.0))
    assert len(snap.occluders) == 1
    np.testing.assert_array_equal(snap.occluders[0], [(0, -3), (4, -3), (4, 3), (0, 3)])
    # The world's immutable layout is converted once per history, not per step.
    assert all(f.occluders is snap.occluders for f in env._recorder.history.frames)
    env.close()


def test_unlimited_sensing_records_and_draws_none_of_it():
    env = parallel_env(scenario="paper", render_mode="rgb_array", n_steps=2)
    env.reset(seed=0)
    env.step({a: np.zeros(2) for a in env.agents})
    env.render()
    snap = env._recorder.history.frames[-1]
    assert snap.detected is None and snap.occluders == () and snap.max_range is None
    assert not snap.limited
    art = env._recorder._renderer._art
    assert art["occluders"] is None and art["missed"] is None
    assert art["range"] == [] and art["sight"] == []
    assert "missed" not in art["title"].get_text()


def test_detection_probability_alone_draws_lines_but_no_occluders_or_ranges(feasible_set_guard):
    env = parallel_env(scenario="two_targets", render_mode="rgb_array", p_detect=0.5, n_steps=3)
    env.reset(seed=1)
    env.step({a: np.zeros(2) for a in env.agents})
    env.render()
    art = env._recorder._renderer._art
    assert art["occluders"] is None and art["range"] == []
    det = env.world.get("detected", 0)
    assert sum(len(_pairs(line)) for line in art["sight"]) == int(det.sum())
    assert len(_pairs(art["missed"])) == int((~det).sum())
    labels = set(_legend_markers(env._recorder._renderer))
    assert {"lines of sight", "missed detections"} <= labels
    assert not labels & {"occluders", "sensing range"}


def test_limited_history_validates_its_inputs():
    h = EpisodeHistory()
    x = np.zeros(4)
    args = (0, x, x, np.eye(4), np.zeros((3, 2)), x)
    with pytest.raises(ValueError, match="detected"):
        h.append(*args, detected=np.ones((1, 2), bool))
    with pytest.raises(ValueError, match="detected"):
        h.append(*args, detected=np.ones((1, 3)))  # not bool
    with pytest.raises(ValueError, match="max_range"):
        h.append(*args, max_range=[1.0, 0.0, 2.0])
    with pytest.raises(ValueError, match="max_range"):
        h.append(*args, max_range=[1.0, 2.0])
    with pytest.raises(ValueError, match=r"occluders\[0\]"):
        h.append(*args, occluders=[[(0, 0), (1, 0)]])
    with pytest.raises(ValueError, match=r"occluders\[1\]"):
        h.append(*args, occluders=[BOX, [(0, 0), (1, np.nan), (0, 1)]])
    assert h.frames == []


def test_record_video_of_a_limited_task(tmp_path, feasible_set_guard):
    env = _limited_env(n_steps=50)
    path = record_video(tmp_path / "l.gif", lambda obs: {a: np.zeros(2) for a in obs}, env=env,
                        seed=0, max_steps=3)  # fmt: skip
    assert iio.imread(path, index=None).shape[:3] == (4, 480, 480)


def test_human_mode_draws_the_limited_world(monkeypatch, feasible_set_guard):
    from activetrack.envs import rendering

    monkeypatch.setattr(rendering, "_interactive_backend", lambda: True)
    env = _limited_env("human", n_steps=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # Agg: "cannot show the figure"
        env.reset(seed=0)
        env.step({a: np.zeros(2) for a in env.agents})
        env.render()
        art = env._recorder._renderer._art
        (path,) = art["occluders"].get_paths()
        np.testing.assert_allclose(path.vertices[:4], [(0, -3), (4, -3), (4, 3), (0, 3)])
        det = env.world.get("detected", 0)
        assert art["title"].get_text().endswith(f"missed {int((~det).sum())}/8")
        env.close()


def test_record_video_refuses_an_episode_whose_frames_exceed_its_memory_bound(tmp_path):
    from activetrack.envs import video

    frame = 480 * 480 * 3  # bytes of one RGB frame at the default size
    most = video.FRAME_BYTES_MAX // frame  # frames the bound holds, reset frame included
    with pytest.raises(ValueError, match=rf"max_steps <= {most - 1}$"):
        record_video(tmp_path / "long.gif", scenario="urban", n_steps=20000, seed=0)
    with pytest.raises(ValueError, match=rf"max_steps <= {most - 1}$"):
        record_video(tmp_path / "long.gif", scenario="paper", n_steps=20000, max_steps=most)
    assert not list(tmp_path.iterdir())  # refused before any file
    # Within the bound, the same long scenario records the steps asked for.
    record_video(tmp_path / "short.gif", scenario="urban", n_steps=20000, seed=0, max_steps=3)
    assert iio.imread(tmp_path / "short.gif", index=None).shape[0] == 4


# The robots' paths and separation disks (issue 36) ----------------------------------------
def _unicycle_ode_path(p0, theta0, p1, theta1, dt, n):
    """The positions at t = j dt / n, j = 0..n, of a unicycle holding one command from
    (p0, theta0) to (p1, theta1), by scipy's integration of x' = v cos(theta), y' = v
    sin(theta), theta' = w, with (v, w) read off the two states by geometry: w =
    dtheta / dt, and v = chord / (dt sinc(w dt / 2)) (an arc of angle dtheta subtends
    the chord 2 R sin(dtheta / 2))."""
    from scipy.integrate import solve_ivp

    dtheta = (theta1 - theta0 + np.pi) % (2.0 * np.pi) - np.pi
    half = 0.5 * dtheta
    chord = float(np.hypot(*(np.asarray(p1) - p0)))
    v = chord / (dt * (np.sin(half) / half if half != 0.0 else 1.0))
    w = dtheta / dt
    sol = solve_ivp(
        lambda t, s: [v * np.cos(s[2]), v * np.sin(s[2]), w],
        (0.0, dt), [p0[0], p0[1], theta0], t_eval=np.linspace(0.0, dt, n + 1),
        rtol=1e-12, atol=1e-13, method="DOP853",
    )  # fmt: skip
    return sol.y[:2].T


@pytest.mark.parametrize("scenario", ["unicycle", "fixed_wing"])
def test_the_last_step_path_is_the_arc_each_unicycle_drove(scenario):
    from activetrack.envs.rendering import PATH_POINTS

    env = parallel_env(scenario=scenario, render_mode="rgb_array")
    env.reset(seed=2)
    w, dt = env.world, env.scenario.dt
    rng = np.random.default_rng(2)
    env.render()
    paths = env._recorder._renderer._art["paths"]
    assert all(len(line.get_xdata()) == 0 for line in paths)  # no step yet: no path
    turned = 0
    for _ in range(12):
        before = w.sensor_states(0).copy()  # (M, 3): x, y, heading
        env.step({a: rng.uniform(-1.0, 1.0, 2) for a in env.agents})
        env.render()
        after = w.sensor_states(0)
        for i, line in enumerate(env._recorder._renderer._art["paths"]):
            drawn = line.get_xydata()
            assert drawn.shape == (PATH_POINTS + 1, 2)
            np.testing.assert_allclose(drawn[0], before[i, :2], rtol=0, atol=1e-12)
            np.testing.assert_allclose(drawn[-1], after[i, :2], rtol=0, atol=1e-9)
            ode = _unicycle_ode_path(before[i, :2], before[i, 2], after[i, :2], after[i, 2], dt,
                                     PATH_POINTS)  # fmt: skip
            np.testing.assert_allclose(drawn, ode, rtol=0, atol=1e-9)
            # An arc, not the chord: the midpoint is off the straight segment when it turned.
            mid = drawn[PATH_POINTS // 2] - 0.5 * (drawn[0] + drawn[-1])
            turned += float(np.hypot(*mid)) > 1e-3
    assert turned >= 10  # (random turn rates: most steps turn)
    # In the legend, the paths; no separation disks (d_sep = 0).
    labels = [t.get_text() for t in env._recorder._renderer._ax.get_legend().get_texts()]
    assert "last step's paths" in labels and "separation disks" not in labels
    env.close()


@pytest.mark.parametrize("d_sep", [2.0, (0.5, 1.0, 0.5, 1.0, 0.5, 1.0, 0.5, 1.0)])
def test_separation_disks_surround_each_sensor_with_half_its_distance(d_sep):
    env = parallel_env(scenario="crowded", d_sep=d_sep, render_mode="rgb_array")
    env.reset(seed=1)
    rng = np.random.default_rng(1)
    for _ in range(3):
        env.step({a: rng.uniform(-1.0, 1.0, 2) for a in env.agents})
    env.render()
    sensors = env.world.get("sensors", 0)
    # Each sensor's own radius: half the one distance, or its radius d_i (pairs keep d_i + d_j).
    radii = np.full(8, d_sep / 2) if np.ndim(d_sep) == 0 else np.asarray(d_sep)
    rings = env._recorder._renderer._art["separation"]
    for i, line in enumerate(rings):
        ring = line.get_xydata()
        assert len(ring) >= 33 and np.allclose(ring[0], ring[-1], rtol=0, atol=1e-12)  # closed
        dist = np.hypot(*(ring - sensors[i]).T)
        np.testing.assert_allclose(dist, radii[i], rtol=1e-12)
        assert line.get_color() == f"C{i}"
    # The world kept the rule, so no two disks overlap.
    e = sensors[:, None] - sensors[None]
    gap = np.hypot(e[..., 0], e[..., 1]) - (radii[:, None] + radii[None])
    assert np.all(gap[np.triu_indices(8, 1)] >= -1e-9)
    # No paths for the disk (the trails are its straight steps).
    assert all(len(line.get_xdata()) == 0 for line in env._recorder._renderer._art["paths"])
    labels = [t.get_text() for t in env._recorder._renderer._ax.get_legend().get_texts()]
    assert "separation disks" in labels and "last step's paths" not in labels
    env.close()


def test_the_paper_draws_no_paths_or_separation_disks():
    env = parallel_env(scenario="paper", render_mode="rgb_array")
    env.reset(seed=0)
    env.step({a: np.array([0.5, 0.5]) for a in env.agents})
    env.render()
    art = env._recorder._renderer._art
    assert all(len(line.get_xdata()) == 0 for line in [*art["paths"], *art["separation"]])
    env.close()
