"""The tracking game as one Gymnasium agent controlling the whole team.

A thin view of :class:`~activetrack.envs.tracking_env.TrackingParallelEnv` (same physics,
same random draws, same configuration keywords) for single-agent libraries:

- action ``Box(-1, 1, (2M,), float32)``: the agents' actions concatenated,
  ``[a_0x, a_0y, a_1x, a_1y, ...]`` (each a displacement in units of the reach, eq. 13);
- observation ``Box(float32, (M (5 + 6M),))``: the agents' observations concatenated in
  agent order (layout in :mod:`activetrack.world.observation`);
- reward ``-reward_scale`` times the scenario's objective (by default the trace
  ``tr P(k+1|k+1)_11``, eq. 12, 17), the team's shared reward.

The episode truncates itself after ``scenario.n_steps`` steps, so it is registered
without a ``TimeLimit`` (``gymnasium.make`` adds none). Registered as
``activetrack/ActiveTracking-v0``::

    import gymnasium as gym
    import activetrack.envs  # registers the id

    env = gym.make("activetrack/ActiveTracking-v0", scenario="homogeneous", n_sensors=5)
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from activetrack.validation import FloatArray, real_array
from activetrack.world.problem import PlanningProblem
from activetrack.world.scenarios import Scenario

from . import _action_spaces
from .tracking_env import (
    RENDER_MODES,
    TrackingParallelEnv,
    check_no_options,
    positions_array,
)


class CentralizedTrackingEnv(gym.Env):
    """One agent choosing every sensor's move; see the module docstring for the spaces.

    Starting state, rewards and episode end are those of
    :class:`~activetrack.envs.tracking_env.TrackingParallelEnv` (the same episode: the
    joint reward is the agents' shared reward, ``terminated``/``truncated`` theirs).

    Info keys: ``step``, ``trace``, ``position_error``, ``max_trace_exceeded`` (as in the
    parallel env), ``projected`` (M,) bool and ``n_projected`` (M,) int arrays.
    """

    metadata: dict[str, Any] = {
        "render_modes": list(RENDER_MODES),
        "render_fps": 10,
    }

    def __init__(
        self, scenario: str | Scenario = "paper", render_mode: str | None = None, **overrides: Any
    ) -> None:
        self.env = TrackingParallelEnv(scenario, render_mode, **overrides)
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": self.env.metadata["render_fps"]}
        m = self.env.n_sensors
        self.n_sensors = m
        box = self.env.observation_space(self.env.possible_agents[0])
        low, high = np.tile(box.low, m), np.tile(box.high, m)
        self.observation_space = spaces.Box(low, high, dtype=np.float32)
        self.action_space = _action_spaces.joint_space(self.scenario)

    @property
    def scenario(self) -> Scenario:
        """Return the scenario."""
        return self.env.scenario

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode (``seed`` as in the parallel env: ``default_rng(seed)``)."""
        check_no_options(options)
        obs = self.env.reset_arrays(seed)
        # Gymnasium's np_random is the episode generator itself.
        self._np_random = self.env.np_random
        if seed is not None:
            self._np_random_seed = seed
        if self.render_mode == "human":
            self.render()
        return obs.reshape(-1), self._info(False)

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Move the team by the joint action ``(2M,)``, advance one step, and observe."""
        self.env._running_agents()
        a = real_array("action", action, finite=False)
        if a.shape != (2 * self.n_sensors,) or np.count_nonzero(np.isfinite(a)) != a.size:
            raise ValueError(self._bad_action(a))
        a = a.reshape(self.n_sensors, 2)
        return self._out(*self.env.step_arrays(a))

    def step_positions(self, positions: FloatArray) -> tuple[np.ndarray, float, bool, bool, dict]:
        """Move the sensors to absolute next positions (M, 2) or (2M,) (an expert's plan)."""
        agents = self.env._running_agents()
        p = real_array("positions", positions, finite=False)
        p = positions_array(p.reshape(-1, 2) if p.shape == (2 * self.n_sensors,) else p, agents)
        return self._out(*self.env._advance(self.env.world.step, p))

    def _out(self, obs: np.ndarray, reward: float, terminated: bool, truncated: bool):
        if self.render_mode == "human":
            self.render()
        return obs.reshape(-1), reward, terminated, truncated, self._info(terminated)

    def observe(self) -> np.ndarray:
        """Return the current joint observation ``(M (5 + 6M),)`` (what reset/step returned)."""
        return self.env.world.observe(0).reshape(-1)

    def _info(self, exceeded: bool) -> dict[str, Any]:
        e = self.env
        return {
            "step": e.k,
            "trace": e.trace,
            "position_error": e.position_error,
            "projected": e.last_projected.copy(),
            "n_projected": e.n_projected.copy(),
            "max_trace_exceeded": exceeded,
        }

    def _bad_action(self, a: np.ndarray) -> str:
        if a.shape != (2 * self.n_sensors,):
            return f"action must have shape ({2 * self.n_sensors},), got {a.shape}"
        bad = np.flatnonzero(~np.isfinite(a.reshape(self.n_sensors, 2)).all(-1))
        names = [self.env.possible_agents[i] for i in bad]
        return f"action of agent(s) {names} must be finite (no NaN or inf), got {a.tolist()}"

    def planning_problem(self) -> PlanningProblem:
        """Return the current step's raw planning problem (see the parallel env)."""
        return self.env.planning_problem()

    def state(self) -> np.ndarray:
        """Return the compact global state (6 + 6M float32)."""
        return self.env.state()

    @property
    def possible_agents(self) -> list[str]:
        """Return the sensors' agent names (the order of the joint action)."""
        return self.env.possible_agents

    def render(self) -> np.ndarray | None:
        """Draw the episode so far; an RGB array in ``rgb_array`` mode."""
        return self.env.render()

    def close(self) -> None:
        """Close the rendering window, if any."""
        self.env.close()
