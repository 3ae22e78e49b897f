"""Multi-robot active target tracking as a PettingZoo ``ParallelEnv`` (Section III, V).

M sensors (agents ``sensor_0 .. sensor_{M-1}``) measure distance and bearing to a moving
target (eq. 4) and share one EKF estimate (eq. 3, 11). Each step follows the paper's
timeline:

1. the observation at step k carries the prediction ``x_hat(k+1|k), P(k+1|k)`` (eq. 3),
   exactly what a planner plans from (so :meth:`reset` ends with a prediction);
2. the actions move the sensors within their reach ``r_i = vmax_i dt`` and outside the
   ``rho_i`` disk around the *predicted* target (eq. 13-16,
   :func:`~activetrack.envs.dynamics.apply_actions`);
3. the true target moves (eq. 2), every sensor measures (eq. 4), the EKF updates
   (eq. 11): :func:`activetrack.tracking.advance`, with the step's ``n + 2M`` standard
   normals drawn from the episode generator, in the same order as the simulation runner;
4. every agent gets the reward ``-reward_scale * tr P(k+1|k+1)_11``: minus the paper's
   objective (eq. 12, 17) with the default ``reward_scale = 1``;
5. the estimate is predicted again for the next observation.

After ``scenario.n_steps`` steps every agent is truncated; if ``scenario.max_trace`` is
set, the episode terminates as soon as the trace exceeds it. Observations are
described in :mod:`activetrack.envs.features`. The class only assembles dicts around
pure batched functions, which the batched environment reuses.

Example::

    from activetrack import envs

    env = envs.parallel_env(scenario="homogeneous", n_sensors=8, rho=1.5)
    obs, infos = env.reset(seed=0)
    while env.agents:
        actions = {a: env.action_space(a).sample() for a in env.agents}
        obs, rewards, terminations, truncations, infos = env.step(actions)
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from activetrack.motion import predict
from activetrack.problem import PlanningProblem
from activetrack.scenarios import Scenario, make_scenario
from activetrack.tracking import LoopParams, advance, initial_conditions
from activetrack.validation import FloatArray

from . import features
from .dynamics import apply_actions
from .rendering import EpisodeHistory, TrackingRenderer

RENDER_MODES = ("human", "rgb_array")


class TrackingParallelEnv(ParallelEnv):
    """The tracking game for M cooperative sensors with a shared reward.

    Args:
        scenario: a preset name (``"paper"``, ``"homogeneous"``) or a :class:`Scenario`.
        render_mode: ``None``, ``"rgb_array"`` or ``"human"``.
        **overrides: any :class:`Scenario` field, e.g. ``n_sensors=8, rho=1.5``.

    Spaces: every agent acts in ``Box(-1, 1, (2,), float32)`` (float64 accepted): its
    displacement as a fraction of its reach ``r_i``; longer vectors are scaled onto the
    unit disk. It observes ``Box(float32, (5 + 6M,))`` (:mod:`~activetrack.envs.features`).
    :meth:`state` is the ``6 + 6M`` global state for centralized critics.

    Infos (per agent, plain Python values): ``step`` k, ``trace`` the posterior
    ``tr P(k|k)_11`` (m^2), ``position_error`` ``||p_T - p_hat_T(k|k)||`` (m, privileged),
    ``projected`` whether this agent's move was pushed out of its ``rho`` disk this step,
    ``n_projected`` how often in the episode, ``max_trace_exceeded`` the termination flag.

    Raw quantities for experts: :meth:`planning_problem`, and the attributes ``x_true``,
    ``x_hat``/``P`` (posterior), ``x_pred``/``P_pred`` (prediction) and ``sensors``.
    """

    metadata: dict[str, Any] = {
        "name": "activetrack_v0",
        "render_modes": list(RENDER_MODES),
        "render_fps": 10,
        "is_parallelizable": True,
    }

    def __init__(
        self, scenario: str | Scenario = "paper", render_mode: str | None = None, **overrides: Any
    ) -> None:
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(
                f"render_mode must be None or one of {RENDER_MODES}, got {render_mode!r}"
            )
        sc = make_scenario(scenario, **overrides)
        self.scenario = sc
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": max(1, round(1.0 / sc.dt))}
        self.params = LoopParams.from_scenario(sc)
        m = sc.n_sensors
        self.n_sensors = m
        self.possible_agents = [f"sensor_{i}" for i in range(m)]
        self.agents: list[str] = []
        self.length_scale = features.length_scale(sc)
        self._constants = features.sensor_constants(
            self.params.sigma_d2,
            self.params.sigma_theta2,
            self.params.r,
            self.params.rho,
            self.length_scale,
        )
        self._order = features.cyclic_order(m)
        self._n_noise = self.params.n_noise
        self._dt = float(sc.dt)
        self._scale = float(sc.reward_scale)
        self._max_trace = np.inf if sc.max_trace is None else float(sc.max_trace)

        low, high = features.observation_bounds(m)
        # One space object per agent, returned as is (PettingZoo seeds them separately);
        # the dicts are also exposed as attributes for libraries that still read them.
        self.observation_spaces = {
            a: spaces.Box(low, high, dtype=np.float32) for a in self.possible_agents
        }
        self.action_spaces = {
            a: spaces.Box(-1.0, 1.0, (2,), dtype=np.float32) for a in self.possible_agents
        }
        slow, shigh = features.state_bounds(m)
        self.state_space = spaces.Box(slow, shigh, dtype=np.float32)

        self._rng: np.random.Generator | None = None
        self._history = EpisodeHistory() if render_mode is not None else None
        self._renderer: TrackingRenderer | None = None
        self.k = 0
        self.x_true = self.x_hat = self.P = self.x_pred = self.P_pred = self.sensors = None
        self.n_projected = np.zeros(m, dtype=np.int64)
        self.last_projected = np.zeros(m, dtype=bool)
        self.trace = float("nan")
        self._target_feat: FloatArray | None = None
        self._sensor_feat: FloatArray | None = None

    # Spaces -----------------------------------------------------------------------------
    def observation_space(self, agent: str) -> spaces.Box:
        """Return the agent's observation space (the same object every call)."""
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        """Return the agent's action space (the same object every call)."""
        return self.action_spaces[agent]

    @property
    def np_random(self) -> np.random.Generator:
        """Return the episode generator (created from fresh entropy if never seeded)."""
        if self._rng is None:
            self._rng = np.random.default_rng()
        return self._rng

    # Core loop ---------------------------------------------------------------------------
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start an episode; ``seed`` makes it reproducible bit for bit.

        The generator is ``np.random.default_rng(seed)`` (the simulation runner's world
        generator); with ``seed=None`` the previous generator continues.
        """
        obs = self.reset_arrays(seed)
        trace = self.trace
        err = self.position_error
        infos = {
            a: {
                "step": 0,
                "trace": trace,
                "position_error": err,
                "projected": False,
                "n_projected": 0,
                "max_trace_exceeded": False,
            }
            for a in self.agents
        }
        if self.render_mode == "human":
            self.render()
        return dict(zip(self.agents, obs, strict=True)), infos

    def reset_arrays(self, seed: int | None = None) -> np.ndarray:
        """Start an episode; return all observations as one (M, 5 + 6M) float32 array."""
        if seed is not None or self._rng is None:
            self._rng = np.random.default_rng(seed)
        x_true, x_hat, P, sensors = initial_conditions(self.scenario, self._rng)
        self.x_true, self.x_hat, self.P, self.sensors = x_true, x_hat, P, sensors
        self.x_pred, self.P_pred = predict(x_hat, P, self.params.Phi, self.params.Q)
        self.k = 0
        self.n_projected = np.zeros(self.n_sensors, dtype=np.int64)
        self.last_projected = np.zeros(self.n_sensors, dtype=bool)
        self.trace = float(P[0, 0] + P[1, 1])
        self.agents = self.possible_agents[:]
        if self._history is not None:
            self._history.clear()
            self._history.append(0, x_true, x_hat, P, sensors, x_hat)
            if self._renderer is not None:
                self._renderer.reset()
        return self._observe()

    def step(
        self, actions: dict[str, Any]
    ) -> tuple[
        dict[str, np.ndarray],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        """Move every sensor by its action, advance the world one step, and observe."""
        agents = self.agents
        if not agents:
            raise RuntimeError("the episode is over (no live agents): call reset() first")
        try:
            a = np.array([actions[ag] for ag in agents], dtype=np.float64)
        except (KeyError, ValueError, TypeError):
            raise ValueError(_bad_action_message(actions, agents)) from None
        if a.shape != (len(agents), 2) or np.count_nonzero(np.isfinite(a)) != a.size:
            raise ValueError(_bad_action_message(actions, agents))
        obs, reward, terminated, truncated = self.step_arrays(a)
        proj = self.last_projected.tolist()
        nproj = self.n_projected.tolist()
        trace = self.trace
        err = self.position_error
        infos = {
            ag: {
                "step": self.k,
                "trace": trace,
                "position_error": err,
                "projected": proj[i],
                "n_projected": nproj[i],
                "max_trace_exceeded": terminated,
            }
            for i, ag in enumerate(agents)
        }
        out = (
            dict(zip(agents, obs, strict=True)),
            dict.fromkeys(agents, reward),
            dict.fromkeys(agents, terminated),
            dict.fromkeys(agents, truncated),
            infos,
        )
        if self.render_mode == "human":
            self.render()
        return out

    def step_arrays(self, actions: FloatArray) -> tuple[np.ndarray, float, bool, bool]:
        """Advance one step from (M, 2) finite actions; return ``(obs, reward, term, trunc)``.

        The array-level core of :meth:`step` (no dicts, no validation), also used by the
        centralized Gymnasium view; like :meth:`step` it empties ``agents`` when the episode
        ends. ``obs`` is (M, 5 + 6M) float32.
        """
        p = self.params
        x_pred = self.x_pred
        sensors, projected = apply_actions(actions, self.sensors, x_pred[:2], p.r, p.rho)
        noise = self._rng.standard_normal(self._n_noise)
        x_true, _, x_post, P_post = advance(p, self.x_true, x_pred, self.P_pred, sensors, noise)
        self.k += 1
        self.x_true, self.x_hat, self.P, self.sensors = x_true, x_post, P_post, sensors
        self.last_projected = projected
        self.n_projected += projected
        trace = float(P_post[0, 0] + P_post[1, 1])
        self.trace = trace
        if self._history is not None:
            self._history.append(self.k, x_true, x_post, P_post, sensors, x_pred)
        self.x_pred, self.P_pred = predict(x_post, P_post, p.Phi, p.Q)
        terminated = trace > self._max_trace  # False when max_trace is None (inf)
        truncated = self.k >= self.scenario.n_steps
        if terminated or truncated:
            self.agents = []  # PettingZoo: finished agents leave the list
        return self._observe(), -self._scale * trace, bool(terminated), truncated

    def _observe(self) -> np.ndarray:
        L = self.length_scale
        self._target_feat = features.target_features(self.x_pred, self.P_pred, self._dt, L)
        self._sensor_feat = features.sensor_features(
            self.sensors, self.x_pred[:2], self._constants, L
        )
        return features.observations(self._target_feat, self._sensor_feat, self._order)

    # Extras ------------------------------------------------------------------------------
    @property
    def position_error(self) -> float:
        """Return the true estimation error ``||p_T(k) - p_hat_T(k|k)||`` (m)."""
        xt, xh = self.x_true, self.x_hat
        return math.hypot(xt[0] - xh[0], xt[1] - xh[1])

    def state(self) -> np.ndarray:
        """Return the global state (6 + 6M float32, :mod:`~activetrack.envs.features`)."""
        if self._target_feat is None:
            raise RuntimeError("call reset() before state()")
        elapsed = self.k / self.scenario.n_steps
        return features.global_state(self._target_feat, self._sensor_feat, elapsed)

    def planning_problem(self) -> PlanningProblem:
        """Return the current step's raw, unnormalized planning problem (eq. 15-17)."""
        if self.x_pred is None:
            raise RuntimeError("call reset() before planning_problem()")
        p = self.params
        return PlanningProblem(
            prior_cov=self.P_pred[:2, :2],
            target=self.x_pred[:2],
            sensors=self.sensors,
            r=p.r,
            rho=p.rho,
            sigma_d2=p.sigma_d2,
            sigma_theta2=p.sigma_theta2,
        )

    def render(self) -> np.ndarray | None:
        """Draw the episode so far (Fig. 4 style); an RGB array in ``rgb_array`` mode."""
        if self.render_mode is None:
            gymnasium.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human'."
            )
            return None
        if not self._history.frames:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            self._renderer = TrackingRenderer(self.params.rho)
        if self.render_mode == "rgb_array":
            return self._renderer.rgb_array(self._history)
        self._renderer.show(self._history, self.metadata["render_fps"])
        return None

    def close(self) -> None:
        """Close the rendering window, if any (safe to call twice)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        # The matplotlib figure is not pickled; it is rebuilt on the next render().
        state = self.__dict__.copy()
        state["_renderer"] = None
        return state

    def __str__(self) -> str:
        return f"activetrack_v0({self.scenario.name}, M={self.n_sensors})"


def _bad_action_message(actions: Any, agents: list[str]) -> str:
    """Return the error message that names the first agent with a bad action."""
    if not isinstance(actions, dict):
        return f"actions must be a dict from agent to action, got {type(actions).__name__}"
    for ag in agents:
        if ag not in actions:
            return f"missing action for agent {ag!r} (live agents: {agents})"
        try:
            a = np.asarray(actions[ag], dtype=np.float64)
        except (TypeError, ValueError):
            return f"action of agent {ag!r} must be numeric, got {actions[ag]!r}"
        if a.shape != (2,):
            return f"action of agent {ag!r} must have shape (2,), got {a.shape}"
        if not np.all(np.isfinite(a)):
            return f"action of agent {ag!r} must be finite (no NaN or inf), got {a.tolist()}"
    return "invalid actions"


def parallel_env(
    scenario: str | Scenario = "paper", render_mode: str | None = None, **overrides: Any
) -> TrackingParallelEnv:
    """Return the tracking ``ParallelEnv`` (a preset or Scenario, a render mode, overrides)."""
    return TrackingParallelEnv(scenario, render_mode, **overrides)


def env(scenario: str | Scenario = "paper", render_mode: str | None = None, **overrides: Any):
    """Return the AEC version (PettingZoo's ``parallel_to_aec``, order-enforced)."""
    return parallel_to_aec(TrackingParallelEnv(scenario, render_mode, **overrides))


raw_env = TrackingParallelEnv
