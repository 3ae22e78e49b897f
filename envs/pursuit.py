"""The two-team game: sensors that track, targets that evade, as one PettingZoo
``ParallelEnv`` (``activetrack/Pursuit-v0``).

Agents ``sensor_0 .. sensor_{M-1}`` are the tracking game's
(:class:`~activetrack.envs.tracking_env.TrackingParallelEnv`: the same observation, action
and reward); agents ``target_0 .. target_{C-1}`` move the scenario's controlled targets
(:class:`activetrack.Controlled`, in target order). A target's action is its velocity
over its speed (``Box(-1, 1, (2,))``; longer vectors are scaled onto the unit disk), set
on the world before the step (:meth:`activetrack.world.World.set_target_actions`), so the
target and the sensors move at once. The game is zero-sum: a target's reward is the
opposite of the sensors' (``+reward_scale`` times the objective, the team's posterior trace
by default): the worse the team's estimate, the better for the evader.

A target observes (float32, ``7 + 2M`` entries, ``+ M`` with limited sensing), with ``L``
the world's length scale and ``v`` the target's speed limit:

====================  ==========================================================
entries               meaning
====================  ==========================================================
0-1                   its true position / ``L``
2-3                   its true velocity / ``v``
4 .. 3 + 2M           each sensor's true position relative to it, / ``L``
4 + 2M                ``ln(trace / L^2)``: the team's current posterior trace (what
                      it is rewarded with)
5 + 2M                the elapsed fraction of the episode, ``k / n_steps``
6 + 2M                1 (a constant: the layout's version for a network's bias)
7 + 2M ..             with limited sensing: which sensor measured it at the last step
====================  ==========================================================

Entries are clipped to the tracking observation's bounds (:mod:`activetrack.world.
observation`, "Bounds"), so the space is finite. An expert steps the sensors with
:meth:`PursuitParallelEnv.step_positions` (GSR's plan) and the targets with actions, or
with none (their ``fallback``, e.g. the scripted :class:`activetrack.Evasive`).

Example::

    from activetrack.envs.pursuit import parallel_env

    env = parallel_env()  # the ``pursuit`` preset
    obs, infos = env.reset(seed=0)
    while env.agents:
        actions = {a: env.action_space(a).sample() for a in env.agents}
        obs, rewards, terminations, truncations, infos = env.step(actions)
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from activetrack.world._observation_kernels import LOG_STD_MAX, POSITION_MAX
from activetrack.world.problem import PlanningProblem
from activetrack.world.scenarios import Scenario

from .tracking_env import (
    StepReturn,
    TrackingParallelEnv,
    actions_array,
    check_no_options,
    positions_array,
)

#: Bound of ``ln(trace / L^2)`` in a target's observation (a trace between e^-100 and
#: e^100 L^2: beyond any tracking).
LOG_TRACE_MAX = 2.0 * LOG_STD_MAX


class PursuitParallelEnv(ParallelEnv):
    """Sensors against controlled targets (see the module docstring).

    Args:
        scenario: a preset name (default ``"pursuit"``) or a :class:`Scenario` with at least
            one :class:`activetrack.Controlled` target (else a ValueError naming
            ``target_behaviour``).
        render_mode: ``None``, ``"rgb_array"`` or ``"human"`` (the tracking game's drawing).
        **overrides: any :class:`Scenario` field.

    Episode end, starting state, the sensors' spaces, rewards and infos are the tracking
    game's; every target ends with the sensors. A target's infos: ``step``, ``trace``.
    :meth:`state` is the tracking game's global state.
    """

    metadata: dict[str, Any] = {
        "name": "activetrack/Pursuit-v0",
        "render_modes": ["human", "rgb_array"],
        "render_fps": 10,
        "is_parallelizable": True,
    }

    def __init__(
        self, scenario: str | Scenario = "pursuit", render_mode: str | None = None, **overrides: Any
    ) -> None:
        self.tracking = TrackingParallelEnv(scenario, render_mode, **overrides)
        self.world = self.tracking.world
        self.scenario = self.tracking.scenario
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": self.tracking.metadata["render_fps"]}
        controlled = self.world.controlled_targets
        if not controlled:
            raise ValueError(
                "target_behaviour must make at least one target activetrack.Controlled for "
                f"the pursuit game, got {self.scenario.target_behaviour!r}"
            )
        behaviours = self.scenario.target_behaviour
        each = behaviours if isinstance(behaviours, tuple) else (behaviours,) * len(controlled)
        self.speeds = [float(each[k].speed) for k in controlled]
        self.sensor_agents = list(self.tracking.possible_agents)
        self.target_agents = [f"target_{j}" for j in range(len(controlled))]
        self.possible_agents = self.sensor_agents + self.target_agents
        self.agents: list[str] = []
        m = self.scenario.n_sensors
        self._flags = bool(self.scenario.limited_sensing)
        dim = 7 + 2 * m + (m if self._flags else 0)
        low = np.full(dim, -POSITION_MAX, dtype=np.float32)
        high = np.full(dim, POSITION_MAX, dtype=np.float32)
        low[4 + 2 * m], high[4 + 2 * m] = -LOG_TRACE_MAX, LOG_TRACE_MAX
        low[5 + 2 * m :], high[5 + 2 * m :] = 0.0, 1.0
        target_obs = spaces.Box(low, high, dtype=np.float32)
        self.observation_spaces = {
            **self.tracking.observation_spaces,
            **{a: spaces.Box(low, high, dtype=np.float32) for a in self.target_agents},
        }
        self.action_spaces = {
            **self.tracking.action_spaces,
            **{a: spaces.Box(-1.0, 1.0, (2,), dtype=np.float32) for a in self.target_agents},
        }
        self.target_observation_space = target_obs
        self.state_space = self.tracking.state_space

    def observation_space(self, agent: str) -> spaces.Box:
        """Return the agent's observation space (the same object every call)."""
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """Return the agent's action space (the same object every call)."""
        return self.action_spaces[agent]

    @property
    def np_random(self) -> np.random.Generator:
        """Return the episode generator (the tracking game's)."""
        return self.tracking.np_random

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start an episode (``seed``: the tracking game's, bit for bit); return every
        agent's observation and infos."""
        check_no_options(options)
        obs, infos = self.tracking.reset(seed)
        self.agents = self.possible_agents[:]
        return {**obs, **self._target_obs()}, {**infos, **self._target_infos()}

    def step(self, actions: dict[str, Any]) -> StepReturn:
        """Move the targets and the sensors by their actions (all at once) and advance."""
        if not self.agents:
            raise RuntimeError("the episode is over (no live agents): call reset() first")
        sensors = actions_array(actions, self.sensor_agents)
        self._set_targets(actions)
        return self._finish(self.tracking.step(dict(zip(self.sensor_agents, sensors, strict=True))))

    def step_team(
        self, sensor_actions: dict[str, Any], target_actions: dict[str, Any] | None = None
    ) -> StepReturn:
        """Move the sensors by their actions (``{sensor_i: (2,)}``) and the targets by
        ``target_actions`` (None: by their fallback behaviour) and advance."""
        if not self.agents:
            raise RuntimeError("the episode is over (no live agents): call reset() first")
        sensors = actions_array(sensor_actions, self.sensor_agents)
        if target_actions is not None:
            self._set_targets(target_actions)
        return self._finish(self.tracking.step(dict(zip(self.sensor_agents, sensors, strict=True))))

    def step_positions(
        self, positions: dict[str, Any] | np.ndarray, target_actions: dict[str, Any] | None = None
    ) -> StepReturn:
        """Move the sensors to absolute positions (an expert's plan, as the tracking game's
        :meth:`~TrackingParallelEnv.step_positions`) and the targets by ``target_actions``
        (``{target_j: (2,)}``; None: by their fallback behaviour) and advance."""
        if not self.agents:
            raise RuntimeError("the episode is over (no live agents): call reset() first")
        p = positions_array(positions, self.sensor_agents)
        if target_actions is not None:
            self._set_targets(target_actions)
        return self._finish(self.tracking.step_positions(p))

    def planning_problem(self) -> PlanningProblem:
        """Return the sensors' planning problem (the tracking game's)."""
        return self.tracking.planning_problem()

    def _set_targets(self, actions: dict[str, Any]) -> None:
        a = actions_array(actions, self.target_agents)  # ValueError naming a bad agent
        self.world.set_target_actions(a)

    def _finish(self, out: StepReturn) -> StepReturn:
        obs, rewards, terms, truncs, infos = out
        reward = next(iter(rewards.values()))
        term, trunc = next(iter(terms.values())), next(iter(truncs.values()))
        t = self.target_agents
        out = (
            {**obs, **self._target_obs()},
            {**rewards, **dict.fromkeys(t, -reward)},  # zero-sum
            {**terms, **dict.fromkeys(t, term)},
            {**truncs, **dict.fromkeys(t, trunc)},
            {**infos, **self._target_infos()},
        )
        if not self.tracking.agents:  # the episode is over: every agent leaves
            self.agents = []
        return out

    def target_observations(self) -> np.ndarray:
        """Return every target agent's observation, (C, 7 + 2M [+ M]) float32 (the module
        docstring's layout)."""
        w, m = self.world, self.scenario.n_sensors
        L = w.length_scale
        sensors = w.get("sensors", 0)
        trace = max(float(w.get("trace", 0)), 1e-300)
        frac = min(1.0, int(w.get("k", 0)) / max(1, w.episode_steps))
        out = np.empty((len(self.target_agents), self.observation_spaces[self.target_agents[0]]
                        .shape[0]))  # fmt: skip
        detected = w.get("detected", 0) if self._flags else None
        for j, (k, speed) in enumerate(zip(w.controlled_targets, self.speeds, strict=True)):
            x = w.get("x_true", 0, target=k)
            out[j, 0:2] = x[:2] / L
            out[j, 2:4] = x[2:4] / speed
            out[j, 4 : 4 + 2 * m] = ((sensors - x[:2]) / L).ravel()
            out[j, 4 + 2 * m] = math.log(trace / L**2)
            out[j, 5 + 2 * m] = frac
            out[j, 6 + 2 * m] = 1.0
            if detected is not None:
                out[j, 7 + 2 * m :] = np.asarray(detected)[k]
        out[:, : 4 + 2 * m] = np.clip(out[:, : 4 + 2 * m], -POSITION_MAX, POSITION_MAX)
        out[:, 4 + 2 * m] = np.clip(out[:, 4 + 2 * m], -LOG_TRACE_MAX, LOG_TRACE_MAX)
        return out.astype(np.float32)

    def _target_obs(self) -> dict[str, np.ndarray]:
        if not self.agents:
            return {}
        return dict(zip(self.target_agents, self.target_observations(), strict=True))

    def _target_infos(self) -> dict[str, dict[str, Any]]:
        if not self.agents:
            return {}
        k, trace = int(self.world.get("k", 0)), float(self.world.get("trace", 0))
        return {a: {"step": k, "trace": trace} for a in self.target_agents}

    def observe(self, agent: str) -> np.ndarray:
        """Return one agent's current observation."""
        if agent in self.target_agents:
            return self.target_observations()[self.target_agents.index(agent)]
        return self.tracking.observe(agent)

    def state(self) -> np.ndarray:
        """Return the global state (the tracking game's)."""
        return self.tracking.state()

    def render(self) -> np.ndarray | None:
        """Draw the episode so far (the tracking game's drawing)."""
        return self.tracking.render()

    def close(self) -> None:
        """Close the rendering window, if any."""
        self.tracking.close()

    def __str__(self) -> str:
        return f"pursuit_v0({self.scenario.name}, M={self.scenario.n_sensors})"


def parallel_env(
    scenario: str | Scenario = "pursuit", render_mode: str | None = None, **overrides: Any
) -> PursuitParallelEnv:
    """Return the two-team ``ParallelEnv`` (a preset or Scenario, a render mode, overrides)."""
    return PursuitParallelEnv(scenario, render_mode, **overrides)


class PursuitAECEnv(parallel_to_aec_wrapper):
    """The two-team game as a PettingZoo ``AECEnv`` (PettingZoo's conversion)."""

    def __init__(
        self, scenario: str | Scenario = "pursuit", render_mode: str | None = None, **overrides: Any
    ) -> None:
        super().__init__(PursuitParallelEnv(scenario, render_mode, **overrides))

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.env, name)


def env(scenario: str | Scenario = "pursuit", render_mode: str | None = None, **overrides: Any):
    """Return the AEC game, order-enforced (PettingZoo's ``OrderEnforcingWrapper``)."""
    return OrderEnforcingWrapper(PursuitAECEnv(scenario, render_mode, **overrides))
