"""N copies of the tracking game advanced in one call: a Gymnasium ``VectorEnv``.

Every copy is the centralized view of :mod:`activetrack.envs.centralized` (joint action
``(2M,)``, concatenated observations), and the loop is the core's
:class:`activetrack.world.World` with N copies, the same the single environment runs with
one. This class adds the Gymnasium ``VectorEnv`` interface: spaces, autoreset, infos.

Seeding and reproducibility: ``reset(seed=s)`` seeds copy ``i`` with
``np.random.default_rng(s + i)``, and every copy draws its random numbers in exactly the
order of a single environment: initial conditions, then ``n + 2M`` standard normals per
step. To avoid a Python call per copy and step, the normals are drawn in blocks of up to
``noise_block`` steps, never beyond the episode's last step, so a copy's generator is in
the same state as the single environment's at every reset (a copy whose episode ends before
its block is used up, terminated on ``max_trace`` or reset, has its generator put back:
:class:`activetrack.world.World`).

Gymnasium's keywords: ``render_mode``: ``"rgb_array"`` records every copy's episode and
:meth:`render` returns a tuple of N frames, as ``VectorEnv.render`` does (so Gymnasium's
``wrappers.vector.RecordVideo`` and ``HumanRendering`` work; recording costs Python work per
copy and step, so render with a few copies), ``"human"`` draws copy 0's episode in a
window, as VMAS renders its first environment; ``max_episode_steps`` truncates every
copy's episodes after ``min(scenario.n_steps, max_episode_steps)`` steps, as the
``TimeLimit`` that ``gymnasium.make`` adds to the single environment. Infos hold what the
single environment's hold, batched, with Gymnasium's ``_key`` masks: ``step``, ``trace``,
``position_error``, ``projected`` and ``n_projected`` (N, M), ``max_trace_exceeded``.

Autoreset follows Gymnasium's modes (https://farama.org/Vector-Autoreset-Mode):
``NEXT_STEP`` (the default: the step after a copy ends resets it, returning its first
observation with reward 0), ``SAME_STEP`` (the copy is reset within the step; the last
observation is in ``infos["final_obs"]``) and ``DISABLED`` (``reset(options={"reset_mask":
mask})`` resets chosen copies; stepping a copy whose episode has ended raises). Libraries
that reset ended copies themselves, such as TorchRL's ``GymWrapper``, need
``autoreset_mode="Disabled"`` (tested). :meth:`step_agents` gives the per-agent
observations for parameter-sharing learners (slots = copies x agents);
:meth:`step_positions` steps with absolute next positions (N, M, 2), an expert's plan
for every copy (:meth:`planning_problem`).
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from activetrack.validation import FloatArray, check_int, check_seed, real_array
from activetrack.world import World
from activetrack.world.problem import PlanningProblem
from activetrack.world.scenarios import Scenario, make_scenario

from . import _action_spaces
from .rendering import EpisodeRecorder
from .tracking_env import RENDER_MODES, check_no_options, check_render_mode

StepReturn = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]


class BatchedActiveTracking(VectorEnv):
    """``num_envs`` independent tracking games stepped together over a leading copy axis.

    Args:
        num_envs: the number of copies N.
        scenario: a preset name or a :class:`~activetrack.Scenario`; ``**overrides`` as in
            :func:`activetrack.envs.parallel_env`.
        autoreset_mode: a :class:`gymnasium.vector.AutoresetMode` or its value string.
        noise_block: how many steps of noise a copy draws per generator call.
        render_mode: None, ``"rgb_array"`` (:meth:`render` returns every copy's frame) or
            ``"human"`` (copy 0's window).
        max_episode_steps: None, or truncate episodes after this many steps (at most
            ``scenario.n_steps``).

    Arrays of the current state (leading axis N, read-only views of :attr:`world`, updated
    in place by every step): ``x_true``,
    ``x_hat``/``P`` (posterior), ``x_pred``/``P_pred`` (prediction), ``sensors`` (N, M, 2),
    ``k`` (steps taken), ``trace``.
    """

    metadata: dict[str, Any] = {
        "autoreset_mode": AutoresetMode.NEXT_STEP,
        "render_modes": list(RENDER_MODES),
    }

    def __init__(
        self,
        num_envs: int,
        scenario: str | Scenario = "paper",
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        noise_block: int = 64,
        render_mode: str | None = None,
        max_episode_steps: int | None = None,
        **overrides: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)):
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            modes = [m.value for m in AutoresetMode]
            raise ValueError(
                f"autoreset_mode must be one of {modes}, got {autoreset_mode!r}"
            ) from None
        check_render_mode(render_mode)
        if max_episode_steps is not None:
            max_episode_steps = check_int("max_episode_steps", max_episode_steps, 1)
        sc = make_scenario(scenario, **overrides)
        self.world = World(sc, int(num_envs), noise_block=noise_block, max_steps=max_episode_steps)
        self.scenario = sc
        self.num_envs = int(num_envs)
        self.noise_block = self.world.noise_block
        fps = max(1, round(1.0 / sc.dt))
        self.metadata = {
            **type(self).metadata, "autoreset_mode": self.autoreset_mode, "render_fps": fps
        }  # fmt: skip
        self.render_mode = render_mode
        copies = {None: 0, "human": 1}.get(render_mode, self.num_envs)
        self._recorders = [EpisodeRecorder(self.world, render_mode, fps, i) for i in range(copies)]
        self._seeds: list[int] = [-1] * self.num_envs  # -1: not seeded (Gymnasium's "unknown")
        self.params = self.world.params
        m = self.n_sensors = sc.n_sensors
        self.length_scale = self.world.length_scale

        low, high = self.world.observation_bounds()
        self.single_observation_space = spaces.Box(
            np.tile(low, m), np.tile(high, m), dtype=np.float32
        )
        self.single_action_space = _action_spaces.joint_space(self.scenario)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._autoreset = np.zeros(self.num_envs, dtype=bool)
        self._started = False

    # State (views of the world) --------------------------------------------------------------
    x_true = property(lambda self: self.world.x_true, doc="True target states (N, n).")
    x_hat = property(lambda self: self.world.x_hat, doc="Posterior means (N, n).")
    P = property(lambda self: self.world.P, doc="Posterior covariances (N, n, n).")
    x_pred = property(lambda self: self.world.x_pred, doc="Predictions x_hat(k+1|k) (N, n).")
    P_pred = property(lambda self: self.world.P_pred, doc="Predicted covariances (N, n, n).")
    sensors = property(lambda self: self.world.sensors, doc="Sensor positions (N, M, 2).")
    k = property(lambda self: self.world.k, doc="Steps taken in each copy's episode (N,).")
    trace = property(lambda self: self.world.trace, doc="Posterior traces (N,).")
    last_projected = property(lambda self: self.world.projected, doc="Projected moves (N, M).")

    # Reset ----------------------------------------------------------------------------------
    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset all copies (or ``options["reset_mask"]``); copy i is seeded ``seed + i``."""
        N = self.num_envs
        mask = np.ones(N, dtype=bool)
        if options is not None and not isinstance(options, dict):
            raise ValueError(f"options must be a dict or None, got {type(options).__name__}")
        options = dict(options or {})
        if "reset_mask" in options:
            mask = np.asarray(options.pop("reset_mask"))
            if mask.shape != (N,) or mask.dtype != np.bool_:
                raise ValueError(f"options['reset_mask'] must be a bool array ({N},)")
        check_no_options(options, ("reset_mask",))
        seeds = None
        if seed is not None:
            if isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)):
                seeds = [check_seed("seed", seed) + i for i in range(N)]
            elif isinstance(seed, (list, tuple, np.ndarray)) and len(seed) == N:
                seeds = [check_seed(f"seed[{i}]", s) for i, s in enumerate(seed)]
            else:
                raise ValueError(
                    f"seed must be None, an integer >= 0 or a list of {N} seeds, got {seed!r}"
                )
            seeds = [seeds[i] for i in np.flatnonzero(mask)]
            for i, s in zip(np.flatnonzero(mask).tolist(), seeds, strict=True):
                if s is not None:
                    self._seeds[i] = s
        self.world.reset(mask, seeds)
        self._autoreset[mask] = False
        self._started = True
        for rec in self._recorders:
            if mask[rec.copy]:
                rec.restart()
        if self.render_mode == "human" and mask[0]:
            self.render()
        # As SyncVectorEnv: a partial reset reports (masks) the copies it reset only.
        return self._joint_obs(), self._infos(mask=mask)

    @property
    def np_random_seed(self) -> tuple[int, ...]:
        """Return each copy's seed of its last seeded reset (-1: never seeded), as
        ``SyncVectorEnv.np_random_seed``."""
        return tuple(self._seeds)

    # Step -------------------------------------------------------------------------------------
    def step_agents(self, actions: FloatArray) -> StepReturn:
        """Step with actions (N, M, 2) or (N, 2M); return per-agent observations (N, M, D).

        Returns ``(obs, rewards, terminated, truncated, infos)``; rewards, terminated and
        truncated have shape (N,) (the team's shared reward).
        """
        return self._step(self.world.step_actions, self._moves("actions", actions))

    def step(self, actions: FloatArray) -> StepReturn:
        """Step every copy with joint actions (N, 2M); observations are (N, M (5 + 6M))."""
        obs, rewards, terminated, truncated, infos = self.step_agents(actions)
        return obs.reshape(self.num_envs, -1), rewards, terminated, truncated, infos

    def step_positions(self, positions: FloatArray) -> StepReturn:
        """Step every copy to absolute next positions (N, M, 2) (an expert's plan).

        Returns per-agent observations (N, M, D) as :meth:`step_agents`. Copies that
        NEXT_STEP autoreset this step ignore their positions.
        """
        return self._step(self.world.step, self._moves("positions", positions))

    def _moves(self, name: str, value: FloatArray) -> FloatArray:
        """Return actions or positions as a finite float64 (N, M, 2) array, or raise."""
        if not self._started:
            raise RuntimeError("call reset() before step()")
        N, m = self.num_envs, self.n_sensors
        a = real_array(name, value, finite=False)
        if a.shape == (N, 2 * m):
            a = a.reshape(N, m, 2)
        if a.shape != (N, m, 2):
            raise ValueError(
                f"{name} must have shape ({N}, {m}, 2) or ({N}, {2 * m}), got {a.shape}"
            )
        if not np.isfinite(a).all():
            bad = np.argwhere(~np.isfinite(a).all(-1))
            raise ValueError(
                f"{name} must be finite (no NaN or inf); bad (copy, agent): {bad[:5].tolist()}"
            )
        return a

    def _step(self, world_step: Any, moves: FloatArray) -> StepReturn:
        N, w = self.num_envs, self.world
        resetting = None
        if self.autoreset_mode == AutoresetMode.NEXT_STEP and self._autoreset.any():
            resetting = self._autoreset.copy()
        centers = [rec.centers() for rec in self._recorders]
        world_step(moves, None if resetting is None else ~resetting)
        terminated, truncated = w.terminated.copy(), w.truncated.copy()
        rewards = -self.scenario.reward_scale * w.score  # the objective (the trace by default)
        infos: dict[str, Any] = {}
        if resetting is not None:
            w.reset(resetting)
            rewards[resetting] = 0.0
            terminated[resetting] = truncated[resetting] = False
        for rec, c in zip(self._recorders, centers, strict=True):
            if resetting is not None and resetting[rec.copy]:
                rec.restart()  # its new episode
            else:
                rec.record(c)
        done = terminated | truncated
        if self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            idx = np.flatnonzero(done)
            final_obs = w.observe()[idx].reshape(len(idx), -1)
            infos["final_obs"] = np.full(N, None, dtype=object)
            infos["final_obs"][idx] = list(final_obs)
            infos["_final_obs"] = done.copy()
            infos["final_info"] = self._infos(terminated, done)
            infos["_final_info"] = done.copy()
            w.reset(done)
            for rec in self._recorders:
                if done[rec.copy]:
                    rec.restart()
        self._autoreset = done.copy()
        exceeded = terminated.copy()
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            exceeded[done] = False  # reset within the step: its infos are the new episode's
        infos.update(self._infos(exceeded))
        if self.render_mode == "human":
            self.render()
        return w.observe(), rewards, terminated, truncated, infos

    def render(self) -> tuple[np.ndarray, ...] | None:
        """Draw the episodes so far (as the single environment draws its own): in
        ``rgb_array`` mode a tuple of N RGB arrays, one per copy; in ``human`` mode copy 0's
        in a window, returning None."""
        if not self._recorders:
            gymnasium.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human'."
            )
            return None
        if self.render_mode == "human":
            return self._recorders[0].render()
        return tuple(rec.render() for rec in self._recorders)

    # Observations -------------------------------------------------------------------------------
    def observe(self) -> np.ndarray:
        """Return every copy's per-agent observations (N, M, 5 + 6M), float32."""
        return self.world.observe()

    def planning_problem(self) -> PlanningProblem:
        """Return every copy's planning problem (eq. 15-17) with a leading batch axis N."""
        return self.world.planning_problem()

    def _joint_obs(self) -> np.ndarray:
        return self.world.observe().reshape(self.num_envs, -1)

    def _infos(self, exceeded: np.ndarray | None = None, mask: np.ndarray | None = None) -> dict:
        """Return the batched infos of the single environment (``max_trace_exceeded``:
        ``exceeded``, False if None), each with its ``_key`` mask (``mask``; all True)."""
        w, N = self.world, self.num_envs
        out = {
            "step": w.k.copy(),
            "trace": w.trace.copy(),
            "position_error": w.position_error(),
            "projected": w.projected.copy(),
            "n_projected": w.n_projected.copy(),
            "max_trace_exceeded": np.zeros(N, bool) if exceeded is None else exceeded.copy(),
        }
        mask = np.ones(N, bool) if mask is None else mask
        out.update({f"_{key}": mask.copy() for key in list(out)})
        return out

    def close_extras(self, **kwargs: Any) -> None:
        """Close the rendering windows and figures, if any."""
        for rec in getattr(self, "_recorders", []):  # none too if __init__ raised
            rec.close()
