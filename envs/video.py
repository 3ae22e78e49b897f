"""Record one tracking episode as an animated GIF or an MP4 (imageio).

Example::

    from activetrack.envs import record_video

    record_video("episode.gif", seed=0)  # random actions, paper scenario
    record_video("gsr.gif", policy=GSRPolicy(seed=0), seed=0, n_sensors=3)  # an expert

GIF needs only Pillow; MP4 needs an imageio video backend (``pip install imageio[ffmpeg]``).
"""

from __future__ import annotations

import importlib.util
import os
import pathlib
from collections.abc import Callable
from typing import Any

import numpy as np

from activetrack.validation import check_float, check_int, check_seed

from .tracking_env import TrackingParallelEnv, policy_step

Policy = Callable[[dict[str, np.ndarray]], dict[str, Any]]


#: Most bytes of frames ``record_video`` holds: a GIF is written from every frame at once
#: (Pillow's writer keeps them all until it saves), so the episode's frames are bounded:
#: 2,330 frames of 480x480 RGB (a 233 s GIF at 10 fps).
FRAME_BYTES_MAX = 1_610_612_736  # 1.5 GiB


def record_video(
    path: str | pathlib.Path,
    policy: Policy | Any | None = None,
    *,
    env: TrackingParallelEnv | None = None,
    seed: int | None = None,
    fps: float | None = None,
    max_steps: int | None = None,
    **config: Any,
) -> pathlib.Path:
    """Run one episode, render every step, and write the frames to ``path``.

    Args:
        path: output file; ``.gif`` (always available) or ``.mp4``/``.webm``/... (needs
            ``imageio[ffmpeg]`` or ``imageio[pyav]``).
        policy: ``None`` for uniform random actions (drawn from the agents' action spaces,
            seeded with ``seed``), an expert with ``plan(problem) -> positions`` (e.g.
            ``GSRPolicy``), or a map from observations to actions: a callable
            ``policy(observations) -> {agent: action}`` or an object with such an ``act``.
        env: a parallel env made with ``render_mode="rgb_array"``; by default one is built
            from ``config`` (``scenario=`` and any Scenario field).
        seed: the episode seed passed to ``reset``.
        fps: frames per second (default: the env's ``render_fps``, real time).
        max_steps: stop after this many steps (default: the whole episode).

    Returns:
        The path written.

    Raises ``ValueError`` before the episode runs when its frames (``min(n_steps,
    max_steps) + 1`` of them) would take more than :data:`FRAME_BYTES_MAX` bytes: pass a
    smaller ``max_steps`` (or ``n_steps``).
    """
    path = pathlib.Path(path)
    seed = check_seed("seed", seed)
    if fps is not None:
        fps = check_float("fps", fps, 0.1, 1000.0)  # a GIF frame lasts at most 65.535 s
    if max_steps is not None:
        max_steps = check_int("max_steps", max_steps, 1)
    _check_output(path)
    if env is None:
        env = TrackingParallelEnv(render_mode="rgb_array", **config)
    elif config:
        raise ValueError(f"pass either env or configuration keywords, not both: {sorted(config)}")
    base = env.unwrapped
    if base.render_mode != "rgb_array":
        raise ValueError(f"env must have render_mode='rgb_array', got {base.render_mode!r}")
    if policy is None:
        policy = _random_policy(base, seed)
    elif not (callable(getattr(policy, "plan", None)) or callable(getattr(policy, "act", policy))):
        raise ValueError("policy must be None, an expert with plan(problem), or map observations")
    obs, _ = env.reset(seed=seed)
    frames = [env.render()]
    steps_max = (
        base.scenario.n_steps if max_steps is None else min(max_steps, base.scenario.n_steps)
    )
    most = max(1, FRAME_BYTES_MAX // frames[0].nbytes)  # frames the budget holds
    if steps_max + 1 > most:
        raise ValueError(
            f"max_steps: the episode's {steps_max + 1} frames of {frames[0].shape} would take "
            f"{(steps_max + 1) * frames[0].nbytes / 2**30:.1f} GiB, more than the "
            f"{FRAME_BYTES_MAX / 2**30:g} GiB record_video holds; pass max_steps <= {most - 1}"
        )
    steps = 0
    while base.agents and (max_steps is None or steps < max_steps):
        obs, *_ = policy_step(env, policy, obs)
        frames.append(env.render())
        steps += 1
    _write(path, frames, fps or base.metadata["render_fps"])
    return path


def _random_policy(env: TrackingParallelEnv, seed: int | None) -> Policy:
    for i, agent in enumerate(env.possible_agents):
        env.action_space(agent).seed(None if seed is None else seed + i)

    def act(observations: dict[str, np.ndarray]) -> dict[str, Any]:
        return {a: env.action_space(a).sample() for a in observations}

    return act


def _check_output(path: pathlib.Path) -> None:
    """Raise before any episode runs if ``path`` cannot be written in its format."""
    if path.suffix.lower() != ".gif" and not any(
        importlib.util.find_spec(m) for m in ("imageio_ffmpeg", "av")
    ):
        raise RuntimeError(
            f"cannot write a {path.suffix!r} video without a video backend: "
            "pip install 'imageio[ffmpeg]' (or 'imageio[pyav]'), or write a '.gif' instead"
        )
    if path.is_dir():
        raise ValueError(f"{path} is a folder; give a file name such as episode.gif")
    path.parent.mkdir(parents=True, exist_ok=True)
    if not os.access(path.parent, os.W_OK):
        raise ValueError(f"cannot write to {path.parent}")


def _write(path: pathlib.Path, frames: list[np.ndarray], fps: float) -> None:
    """Write the frames to ``path`` atomically (a temporary file renamed into place)."""
    import imageio.v3 as iio

    from activetrack.files import atomic_path

    stack = np.stack(frames)
    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".gif":
            # Pillow's GIF writer takes the frame duration in milliseconds; loop forever.
            iio.imwrite(tmp, stack, duration=1000.0 / fps, loop=0)
        else:
            iio.imwrite(tmp, stack, fps=fps)
