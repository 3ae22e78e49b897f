"""Multi-robot active target tracking as a PettingZoo ``ParallelEnv`` (Section III, V).

M sensors (agents ``sensor_0 .. sensor_{M-1}``) measure distance and bearing to a moving
target (eq. 4) and share one EKF estimate (eq. 3, 11). Each step follows the paper's
timeline:

1. the observation at step k carries the prediction ``x_hat(k+1|k), P(k+1|k)`` (eq. 3),
   exactly what a planner plans from (so :meth:`reset` ends with a prediction);
2. the actions move the sensors within their reach ``r_i = vmax_i dt`` and outside the
   ``rho_i`` disk around the *predicted* target (eq. 13-16,
   :func:`~activetrack.kinematics.sensor_motion.apply_actions`);
3. the true target moves (eq. 2), every sensor measures (eq. 4), the EKF updates
   (eq. 11), with the step's ``n + 2M`` standard normals drawn from the episode
   generator, in the same order as the simulation runner;
4. every agent gets the reward ``-reward_scale`` times the scenario's objective at the
   posterior (``tr P(k+1|k+1)_11`` by default, the paper's eq. 12, 17);
5. the estimate is predicted again for the next observation.

After ``scenario.n_steps`` steps every agent is truncated; if ``scenario.max_trace`` is
set, the episode terminates as soon as the trace exceeds it. Observations are
described in :mod:`activetrack.world.observation`. The loop itself is the core's
:class:`activetrack.world.World` (one copy); this class only adds the PettingZoo
interface: spaces, dicts, rendering.

An expert steps the environment with its planned positions, no actions needed::

    from activetrack.baselines import GSRPolicy

    expert = GSRPolicy(seed=0)
    obs, infos = env.reset(seed=0)
    while env.agents:
        obs, rewards, terminations, truncations, infos = env.step_positions(
            expert.plan(env.planning_problem())
        )

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
import warnings
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from activetrack.validation import FloatArray, check_seed, real_array
from activetrack.world import World
from activetrack.world.problem import PlanningProblem
from activetrack.world.scenarios import Scenario, make_scenario

from . import _action_spaces
from .rendering import EpisodeRecorder

RENDER_MODES = ("human", "rgb_array")

StepReturn = tuple[
    dict[str, np.ndarray],
    dict[str, float],
    dict[str, bool],
    dict[str, bool],
    dict[str, dict[str, Any]],
]


class TrackingParallelEnv(ParallelEnv):
    """The tracking game for M cooperative sensors with a shared reward.

    Args:
        scenario: a preset name (``"paper"``, ``"homogeneous"``) or a :class:`Scenario`.
        render_mode: ``None``, ``"rgb_array"`` or ``"human"``.
        **overrides: any :class:`Scenario` field, e.g. ``n_sensors=8, rho=1.5``.

    Starting State:
        :meth:`reset` with ``seed`` starts the episode generator ``default_rng(seed)``.
        The true target state is the scenario's ``x0`` (``target_init="fixed"``) or is
        drawn from ``N(x0_hat, P0)`` (``"gaussian"``, every task beyond the paper); the
        filter starts at ``x0_hat, P0`` and is predicted once, so the first observation
        carries ``x_hat(1|0), P(1|0)``. The sensors start uniformly (by area) in the disk
        of radius ``sensor_radius`` about ``sensor_center`` (with ``d_sep > 0``, one that
        starts closer than its distance to an earlier one is drawn again); a robot with a
        heading (:class:`activetrack.Unicycle`: the ``unicycle`` tasks) starts facing the
        centroid of the targets' ``x0_hat``. With ``random_occluders`` the episode's
        rectangles are drawn too.

    Rewards:
        Every agent gets the team's reward each step: ``-reward_scale`` times the
        scenario's ``objective`` at the posterior ``P(k+1|k+1)``: ``"trace"`` is the sum
        over targets of ``tr P_11``, the posterior position covariance's trace (the
        paper's eq. 12, 17), ``"worst_trace"`` the largest of them, ``"logdet"`` the sum of
        their log-determinants (:mod:`activetrack.models.objective`). The return is the sum
        over the episode's steps. With a ``communication`` model (the ``radio`` tasks) each
        robot keeps its own filter and each agent gets ``-reward_scale`` times the
        objective at its own robot's posterior (:mod:`activetrack.world.team_filters`).

    Episode End:
        Truncation: after ``n_steps`` steps every agent is truncated (the episode's
        length; ``max_cycles`` is the same keyword). Termination: only when ``max_trace``
        is set, as soon as the posterior trace (summed over targets) exceeds it (the info
        ``max_trace_exceeded``). Either way the ``agents`` list empties and :meth:`reset`
        starts the next episode.

    Spaces: every agent acts in ``Box(-1, 1, (2,), float32)`` (float64 accepted): its
    displacement as a fraction of its reach ``r_i``; longer vectors are scaled onto the
    unit disk (a scenario's own ``kinematics`` gives its bounds and meaning instead: a
    unicycle's action is its forward speed and turn rate, each scaled from [-1, 1] onto
    ``[v_min, v_max]`` and ``[-w_max, w_max]`` and held over the step). It observes
    ``Box(float32, (5 + 6M,))`` (:mod:`activetrack.world.observation`; a unicycle's
    observation ends with its heading ``(cos, sin)``). :meth:`state` is the ``6 + 6M``
    global state for centralized critics (then every agent's heading). With
    ``team_observation`` each agent observes only its own estimate and its neighbours'
    messages (:mod:`activetrack.world.team_observation`); the global state is unchanged.

    Infos (per agent, plain Python values): ``step`` k, ``trace`` the posterior
    ``tr P(k|k)_11`` (m^2), ``position_error`` ``||p_T - p_hat_T(k|k)||`` (m, privileged),
    ``projected`` whether this agent's move was pushed out of its ``rho`` disk this step,
    ``n_projected`` how often in the episode, ``max_trace_exceeded`` the termination flag;
    with ``d_sep > 0`` the team rule's ``collisions``, ``n_collisions``, ``n_stuck`` and
    ``min_separation`` (:mod:`activetrack.world._motion_state`); with ``communication``
    the agent's ``robot_score`` (the objective on its own estimate) and the team's
    ``robot_score_mean``, ``robot_score_worst`` and ``disagreement`` (m).

    For experts: :meth:`planning_problem` (the raw problem of eq. 15-17) and
    :meth:`step_positions` (step with absolute next positions). :meth:`observe` returns the
    current observations. The state ``x_true``, ``x_hat``/``P`` (posterior),
    ``x_pred``/``P_pred`` (prediction) and ``sensors`` are copies of :attr:`world`'s.
    """

    metadata: dict[str, Any] = {
        "name": "activetrack/ActiveTracking-v0",  # the registered id
        "render_modes": list(RENDER_MODES),
        "render_fps": 10,
        "is_parallelizable": True,
    }

    def __init__(
        self, scenario: str | Scenario = "paper", render_mode: str | None = None, **overrides: Any
    ) -> None:
        check_render_mode(render_mode)
        sc = make_scenario(scenario, **overrides)
        self.world = World(sc, 1)
        self.scenario = sc
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": max(1, round(1.0 / sc.dt))}
        self.params = self.world.params
        m = sc.n_sensors
        self.n_sensors = m
        self.possible_agents = [f"sensor_{i}" for i in range(m)]
        self.agents: list[str] = []
        self.length_scale = self.world.length_scale

        # Some bounds scale with the length scale (activetrack.world.observation, "Bounds").
        low, high = self.world.observation_bounds()
        # One space object per agent, returned as is (PettingZoo seeds them separately);
        # the dicts are also exposed as attributes for libraries that still read them.
        self.observation_spaces = {
            a: spaces.Box(low, high, dtype=np.float32) for a in self.possible_agents
        }
        self.action_spaces = _action_spaces.agent_spaces(sc, self.possible_agents)
        slow, shigh = self.world.layout.state_bounds(self.length_scale)
        self.state_space = spaces.Box(slow, shigh, dtype=np.float32)

        self._recorder = (
            None
            if render_mode is None
            else EpisodeRecorder(self.world, render_mode, self.metadata["render_fps"])
        )
        self._started = False
        self._obs: np.ndarray | None = None

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
        return self.world.rng(0)

    # State of the one copy (views of the world) -----------------------------------------
    # Copies, so that a reference a user keeps does not change with the next step.
    x_true = property(
        lambda self: self.world.get("x_true", 0).copy(), doc="True target state x(k)."
    )
    x_hat = property(
        lambda self: self.world.get("x_hat", 0).copy(), doc="Posterior mean x_hat(k|k)."
    )
    P = property(lambda self: self.world.get("P", 0).copy(), doc="Posterior covariance P(k|k).")
    x_pred = property(
        lambda self: self.world.get("x_pred", 0).copy(), doc="Prediction x_hat(k+1|k)."
    )
    P_pred = property(lambda self: self.world.get("P_pred", 0).copy(), doc="Prediction P(k+1|k).")
    sensors = property(
        lambda self: self.world.get("sensors", 0).copy(), doc="Sensor positions (M, 2)."
    )
    k = property(lambda self: int(self.world.get("k", 0)), doc="Steps taken in the episode.")
    trace = property(lambda self: float(self.world.get("trace", 0)), doc="tr P(k|k)_11 (m^2).")
    n_projected = property(
        lambda self: self.world.get("n_projected", 0).copy(),
        doc="Projections per agent this episode.",
    )
    last_projected = property(
        lambda self: self.world.get("projected", 0).copy(),
        doc="Which agents were projected this step.",
    )

    @property
    def position_error(self) -> float:
        """Return the true estimation error ``||p_T(k) - p_hat_T(k|k)||`` (m)."""
        return float(self.world.position_error(0))

    # Core loop ---------------------------------------------------------------------------
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, np.ndarray], dict[str, dict[str, Any]]]:
        """Start an episode; ``seed`` makes it reproducible bit for bit.

        The generator is ``np.random.default_rng(seed)`` (the simulation runner's world
        generator); with ``seed=None`` the previous generator continues. This environment
        takes no ``options`` (PettingZoo's probe ``{"options": ...}`` is ignored silently,
        any other key with a warning).
        """
        check_no_options(options)
        obs = self.reset_arrays(seed)
        infos = self._infos(self.agents, False)
        if self.render_mode == "human":
            self.render()
        return dict(zip(self.agents, obs, strict=True)), infos

    def reset_arrays(self, seed: int | None = None) -> np.ndarray:
        """Start an episode; return all observations as one (M, 5 + 6M) float32 array."""
        seed = check_seed("seed", seed)
        self.world.reset(seeds=None if seed is None else [seed])
        self._started = True
        self.agents = self.possible_agents[:]
        if self._recorder is not None:
            self._recorder.restart()
        self._obs = self.world.observe(0)
        return self._obs

    def step(self, actions: dict[str, Any]) -> StepReturn:
        """Move every sensor by its action, advance the world one step, and observe."""
        agents = self.agents
        if not agents:
            self._running_agents()  # raises
        return self._dicts(
            agents, *self._advance(self.world.step_actions, actions_array(actions, agents))
        )

    def step_positions(self, positions: dict[str, Any] | FloatArray) -> StepReturn:
        """Move the sensors to absolute next positions (an expert's plan) and advance.

        ``positions``: (M, 2) in agent order, or ``{agent: (2,)}``. A move beyond reach or
        into a ``rho`` disk is mended as :func:`activetrack.kinematics.sensor_motion.move_to` says;
        a
        planner's feasible positions are executed exactly.
        """
        agents = self._running_agents()
        p = positions_array(positions, agents)
        return self._dicts(agents, *self._advance(self.world.step, p))

    def step_arrays(self, actions: FloatArray) -> tuple[np.ndarray, float, bool, bool]:
        """Advance one step from (M, 2) finite actions; return ``(obs, reward, term, trunc)``.

        The array-level core of :meth:`step` (no dicts, no validation), also used by the
        centralized Gymnasium view; like :meth:`step` it empties ``agents`` when the episode
        ends. ``obs`` is (M, 5 + 6M) float32.
        """
        return self._advance(self.world.step_actions, actions)

    def _advance(self, step: Any, moves: FloatArray) -> tuple[np.ndarray, float, bool, bool]:
        """Run the world's ``step`` (positions or actions) and return the array results."""
        w = self.world
        planned_from = None if self._recorder is None else self._recorder.centers()
        res = step(moves)  # (M, 2): a world of one copy takes it unbatched
        terminated, truncated = bool(res.terminated), bool(res.truncated)
        if self._recorder is not None:
            self._recorder.record(planned_from)
        if terminated or truncated:
            self.agents = []  # PettingZoo: finished agents leave the list
        self._obs = w.observe(0)
        return self._obs, float(res.reward), terminated, truncated

    def _dicts(
        self, agents: list[str], obs: np.ndarray, reward: float, terminated: bool, truncated: bool
    ) -> StepReturn:
        if self.world.decentralized:  # each robot's reward from its own estimate
            reward = (-self.scenario.reward_scale * self.world.robot_scores(0)).tolist()
            rewards = dict(zip(self.possible_agents, reward, strict=True))
            rewards = {a: rewards[a] for a in agents}
        else:
            rewards = dict.fromkeys(agents, reward)
        out = (
            dict(zip(agents, obs, strict=True)),
            rewards,
            dict.fromkeys(agents, terminated),
            dict.fromkeys(agents, truncated),
            self._infos(agents, terminated),
        )
        if self.render_mode == "human":
            self.render()
        return out

    def _infos(self, agents: list[str], exceeded: bool) -> dict[str, dict[str, Any]]:
        k, trace, err, proj, nproj = self.world.copy_info(0)
        sep = self.world.separation_info(0)  # (empty without d_sep)
        team = self.world.team_info(0)  # (empty without communication)
        if team:  # each agent its own robot's score
            team["robot_score"] = dict(zip(self.possible_agents, team["robot_score"], strict=True))
        return {
            a: {
                "step": k,
                "trace": trace,
                "position_error": err,
                "projected": proj[i],
                "n_projected": nproj[i],
                "max_trace_exceeded": exceeded,
                **sep,
                **({**team, "robot_score": team["robot_score"][a]} if team else {}),
            }
            for i, a in enumerate(agents)
        }

    def _running_agents(self) -> list[str]:
        if not self.agents:
            raise RuntimeError("the episode is over (no live agents): call reset() first")
        return self.agents

    # Extras ------------------------------------------------------------------------------
    def observe(self, agent: str | None = None) -> dict[str, np.ndarray] | np.ndarray:
        """Return the current observations: ``{agent: obs}`` of the live agents, or one
        agent's observation (what :meth:`reset`/:meth:`step` returned last)."""
        if not self._started:
            raise RuntimeError("call reset() before observe()")
        obs = self.world.observe(0)
        if agent is not None:
            if agent not in self.possible_agents:
                raise ValueError(f"agent must be one of {self.possible_agents}, got {agent!r}")
            return obs[self.possible_agents.index(agent)]
        return dict(zip(self.agents, obs, strict=False))

    def state(self) -> np.ndarray:
        """Return the global state (6 + 6M float32, :mod:`activetrack.world.observation`)."""
        if not self._started:
            raise RuntimeError("call reset() before state()")
        return self.world.state(0)

    def planning_problem(self) -> PlanningProblem:
        """Return the current step's raw, unnormalized planning problem (eq. 15-17)."""
        if not self._started:
            raise RuntimeError("call reset() before planning_problem()")
        return self.world.planning_problem(0)

    def render(self) -> np.ndarray | None:
        """Draw the episode so far (Fig. 4 style, every target, the sensors' models and
        fixes; with limited sensing the occluders, sensing ranges, lines of sight and missed
        detections: :mod:`activetrack.envs.rendering`); an RGB array in ``rgb_array`` mode."""
        if self.render_mode is None:
            gymnasium.logger.warn(
                "render() called without a render_mode; pass render_mode='rgb_array' or 'human'."
            )
            return None
        return self._recorder.render()

    def close(self) -> None:
        """Close the rendering window, if any (safe to call twice)."""
        if self._recorder is not None:
            self._recorder.close()

    def __str__(self) -> str:
        return f"activetrack_v0({self.scenario.name}, M={self.n_sensors})"


def check_render_mode(render_mode: Any) -> None:
    """Raise ``ValueError`` unless ``render_mode`` is None or one of :data:`RENDER_MODES`."""
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(
            f"render_mode must be None or one of {list(RENDER_MODES)}, got {render_mode!r}"
        )


#: Option keys every reset accepts and ignores silently: PettingZoo's ``api_test`` and
#: ``parallel_api_test`` reset with ``options={"options": 1}`` to probe that ``reset``
#: takes an ``options`` argument (PettingZoo 1.24-1.27).
PROBE_OPTIONS = ("options",)


def check_no_options(options: dict[str, Any] | None, valid: tuple[str, ...] = ()) -> None:
    """Warn about keys of ``options`` that are neither in ``valid`` nor
    :data:`PROBE_OPTIONS` (they are ignored); raise ``ValueError`` if ``options`` is not a
    dict or None.

    A warning, not an error, as Gymnasium's environments ignore options they do not take;
    but a misspelt key (``"reset_mak"``) should not pass unnoticed.
    """
    if options is None:
        return
    if not isinstance(options, dict):
        raise ValueError(f"options must be a dict or None, got {type(options).__name__}")
    unknown = sorted(str(k) for k in options if k not in valid and k not in PROBE_OPTIONS)
    if unknown:
        warnings.warn(
            f"reset() ignores unknown options {unknown} (valid: {list(valid)})",
            UserWarning,
            stacklevel=3,
        )


def actions_array(actions: dict[str, Any], agents: list[str], what: str = "action") -> FloatArray:
    """Return the agents' actions as a finite float64 (M, 2) array, or raise ValueError."""
    try:
        a = np.array([actions[ag] for ag in agents])
    except (KeyError, ValueError, TypeError):
        raise ValueError(_bad_action_message(actions, agents, what)) from None
    if (
        a.shape != (len(agents), 2)
        or a.dtype.kind not in "iuf"  # no bool, complex, object or string actions
        or not all(map(math.isfinite, a.ravel().tolist()))  # (cheaper than np.isfinite here)
    ):
        raise ValueError(_bad_action_message(actions, agents, what))
    return a if a.dtype == np.float64 else a.astype(np.float64)


def positions_array(positions: dict[str, Any] | FloatArray, agents: list[str]) -> FloatArray:
    """Return next positions as a finite float64 (M, 2) array, or raise ValueError."""
    if isinstance(positions, dict):
        return actions_array(positions, agents, "position")
    p = real_array("positions", positions, finite=False)
    if p.shape != (len(agents), 2):
        raise ValueError(f"positions must have shape ({len(agents)}, 2), got {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError(f"positions must be finite (no NaN or inf), got {p.tolist()}")
    return p


def agent_action(agent: str, value: Any, what: str = "action") -> FloatArray:
    """Return one agent's action (or position) as a finite float64 (2,), or raise ValueError."""
    a = real_array(f"{what} of agent {agent!r}", value, finite=False)
    if a.shape != (2,):
        raise ValueError(f"{what} of agent {agent!r} must have shape (2,), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(
            f"{what} of agent {agent!r} must be finite (no NaN or inf), got {a.tolist()}"
        )
    return a.astype(np.float64, copy=False)


def _bad_action_message(actions: Any, agents: list[str], what: str = "action") -> str:
    """Return the error message that names the first agent with a bad action (or position)."""
    if not isinstance(actions, dict):
        return f"{what}s must be a dict from agent to {what}, got {type(actions).__name__}"
    for ag in agents:
        if ag not in actions:
            return f"missing {what} for agent {ag!r} (live agents: {agents})"
        try:
            agent_action(ag, actions[ag], what)
        except ValueError as exc:
            return str(exc)
    extra = sorted(set(map(str, actions)) - set(agents))
    return f"{what}s given for agents that are not live: {extra}" if extra else f"invalid {what}s"


def policy_step(env: Any, policy: Any, observations: dict[str, np.ndarray]) -> StepReturn:
    """Step a parallel env (or one wrapping it) by ``policy``; return what ``step`` returns.

    An expert (an object with ``plan(problem) -> positions``, e.g.
    :class:`activetrack.baselines.GSRPolicy`) plans from :meth:`planning_problem` and is
    executed with :meth:`step_positions`; any other policy maps the observations to actions:
    ``policy.act(observations)`` or ``policy(observations)``, ``{agent: action}``.
    """
    base = env.unwrapped
    if callable(getattr(policy, "plan", None)):
        return base.step_positions(policy.plan(base.planning_problem()))
    act = getattr(policy, "act", policy)
    if not callable(act):
        raise TypeError(
            f"a policy needs plan(problem) or act(observations), got {type(policy).__name__}"
        )
    return env.step(act(observations))


def parallel_env(
    scenario: str | Scenario = "paper", render_mode: str | None = None, **overrides: Any
) -> TrackingParallelEnv:
    """Return the tracking ``ParallelEnv`` (a preset or Scenario, a render mode, overrides)."""
    return TrackingParallelEnv(scenario, render_mode, **overrides)


class TrackingAECEnv(parallel_to_aec_wrapper):
    """The tracking game as a PettingZoo ``AECEnv``: agents act one after another.

    PettingZoo's conversion of :class:`TrackingParallelEnv` (the world steps once the last
    agent of a cycle has acted), with each agent's action checked when it is given: a bad
    action raises a ``ValueError`` naming the agent and is not stored, so the agent can
    act again and the environment stays usable.
    """

    def __init__(
        self, scenario: str | Scenario = "paper", render_mode: str | None = None, **overrides: Any
    ) -> None:
        super().__init__(TrackingParallelEnv(scenario, render_mode, **overrides))

    def step(self, action: Any) -> None:
        """Record the selected agent's action; the last agent's action advances the world."""
        agent = self.agent_selection
        if not (self.terminations[agent] or self.truncations[agent]):
            action = agent_action(agent, action)
        super().step(action)

    def __getattr__(self, name: str) -> Any:
        # The parallel env's extras (planning_problem, step_positions, world, ...).
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self.env, name)


def raw_env(
    scenario: str | Scenario = "paper", render_mode: str | None = None, **overrides: Any
) -> TrackingAECEnv:
    """Return the unwrapped AEC env (PettingZoo's convention: ``env()`` wraps ``raw_env()``)."""
    return TrackingAECEnv(scenario, render_mode, **overrides)


def env(scenario: str | Scenario = "paper", render_mode: str | None = None, **overrides: Any):
    """Return the AEC game, order-enforced (PettingZoo's ``OrderEnforcingWrapper``)."""
    return OrderEnforcingWrapper(raw_env(scenario, render_mode, **overrides))
