"""Self-play on the two-team game ``pursuit``: an evader and the sensors trained in
alternation (``activetrack train selfplay``).

The game is :class:`activetrack.envs.pursuit.PursuitParallelEnv` (zero-sum: the evader is
rewarded with the team's posterior trace). Each side is trained with SB3's PPO on a
single-agent view of the game in which the other side is fixed (:class:`EvaderView`,
:class:`SensorsView`):

1. round 0 starts with the sensors played by a planner (``sensors``: GSR by default);
2. each round trains the evader for ``evader_steps`` against the current sensors, then,
   if ``sensor_steps > 0``, the sensors (one network for the joint action of the team,
   the centralized view) for ``sensor_steps`` against the evader just trained; from then
   on the learned sensors are the evader's opponent. With ``sensor_steps = 0`` the evader
   learns a best response to the planner (the run of ``docs/results/tasks.md``).

Around each phase the learner's mean return is measured on ``eval_episodes`` fixed
validation seeds (:data:`VALIDATION_SEED` on), deterministic actions, before and after:
``history`` in ``selfplay.json`` says whether each phase improved on its measured start.

Rewards are normalized during training by ``VecNormalize(norm_obs=False)`` as in
:mod:`activetrack.train.ppo` (observations are already normalized by the game). Outputs in
``out_dir``: ``evader.zip`` (SB3), ``sensors.zip`` (SB3, when trained), ``selfplay.json``
(configuration and history). :func:`load_evader` reads ``evader.zip`` back as a function
from the target's observation to its action, what ``activetrack.baselines``'s pursuit
evaluation (:func:`evaluate_against_evaders`) takes.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from activetrack.envs.pursuit import PursuitParallelEnv
from activetrack.files import RunOutputs
from activetrack.train.utils import (
    DEFAULT_THREADS,
    check_choice,
    check_float,
    check_int,
    configure_torch,
    seed_everything,
)

#: Validation episodes (the measured starts and ends) use seeds from here, disjoint from
#: evaluation's held-out seeds (1000 on).
VALIDATION_SEED = 600_000
#: The planners that can play the sensors.
PLANNERS = ("gsr", "lookahead", "rm")
#: What a run writes in its output folder.
OUTPUTS = ("evader.zip", "sensors.zip", "selfplay.json")
MAX_STEPS = 10**9


@dataclass
class SelfPlayConfig:
    """A self-play run's settings (checked on construction: ValueError naming the field).

    Attributes:
        rounds: alternations (evader, then sensors), 1 to 1000.
        evader_steps: the evader's PPO timesteps per round (>= 1).
        sensor_steps: the sensors' PPO timesteps per round (0: the planner plays them).
        sensors: the planner that plays the sensors until they are trained.
        n_steps: PPO's rollout length per update (>= 2); batch_size its minibatch.
        learning_rate, gamma, ent_coef: PPO's.
        hidden: the MLP's hidden sizes (both sides).
        eval_episodes: validation episodes before and after each phase (>= 1).
    """

    rounds: int = 1
    evader_steps: int = 20_000
    sensor_steps: int = 0
    sensors: str = "gsr"
    n_steps: int = 1024
    batch_size: int = 64
    learning_rate: float = 3e-4
    gamma: float = 0.99
    ent_coef: float = 0.0
    hidden: tuple[int, ...] = (64, 64)
    eval_episodes: int = 10

    def __post_init__(self) -> None:
        self.rounds = check_int("rounds", self.rounds, 1, 1000)
        self.evader_steps = check_int("evader_steps", self.evader_steps, 1, MAX_STEPS)
        self.sensor_steps = check_int("sensor_steps", self.sensor_steps, 0, MAX_STEPS)
        self.sensors = check_choice("sensors", self.sensors, PLANNERS)
        self.n_steps = check_int("n_steps", self.n_steps, 2, 1_000_000)
        self.batch_size = check_int("batch_size", self.batch_size, 2, self.n_steps)
        self.learning_rate = check_float("learning_rate", self.learning_rate, 0.0, 1.0)
        if self.learning_rate <= 0.0:
            raise ValueError(f"learning_rate must be > 0, got {self.learning_rate!r}")
        self.gamma = check_float("gamma", self.gamma, 0.0, 1.0)
        self.ent_coef = check_float("ent_coef", self.ent_coef, 0.0, 1.0)
        hidden = tuple(self.hidden)
        if not hidden or any(not isinstance(h, int) or not 1 <= h <= 4096 for h in hidden):
            raise ValueError(f"hidden must be 1 or more layer sizes in [1, 4096], got {hidden!r}")
        self.hidden = hidden
        self.eval_episodes = check_int("eval_episodes", self.eval_episodes, 1, 100_000)


def _planner(name: str) -> Any:
    from activetrack.baselines.policy_specs import resolve_policy

    return resolve_policy(name)


class _View(gym.Env):
    """One side's single-agent view of the pursuit game; the other side is ``opponent``."""

    def __init__(self, opponent: Any, scenario: Any = "pursuit", **overrides: Any) -> None:
        self.game = PursuitParallelEnv(scenario, **overrides)
        if len(self.game.target_agents) != 1:
            raise ValueError(
                "self-play takes a scenario with exactly one controlled target, got "
                f"{len(self.game.target_agents)}"
            )
        self.opponent = opponent
        self._obs: dict[str, np.ndarray] = {}

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self._obs, _ = self.game.reset(seed=seed)
        return self._own(), {}

    def _sensor_obs(self) -> np.ndarray:
        return np.concatenate([self._obs[a] for a in self.game.sensor_agents])

    def _play(self, sensors: Any, target: Any) -> tuple[float, bool, bool, dict]:
        """Step with the sensors' joint action (2M,) (None: the planner ``opponent``'s plan)
        and the target's action (None: its fallback); return the sensors' reward, the
        termination, truncation and a sensor's infos."""
        g = self.game
        ta = None if target is None else {"target_0": target}
        if sensors is None:
            out = g.step_positions(self.opponent.plan(g.planning_problem()), ta)
        else:
            acts = dict(zip(g.sensor_agents, np.reshape(sensors, (-1, 2)), strict=True))
            out = g.step_team(acts, ta)
        self._obs, rewards, terms, truncs, infos = out  # (every agent's, the last step's too)
        a = g.sensor_agents[0]
        return rewards[a], terms[a], truncs[a], infos[a]


class EvaderView(_View):
    """The evader's view: observation and action of ``target_0``; the sensors are
    ``opponent``, a planner (``plan(problem)``) or a sensors' SB3 model (the joint action
    from the concatenated sensors' observations, deterministic). Reward: the target's
    (the team's posterior trace)."""

    def __init__(self, opponent: Any, scenario: Any = "pursuit", **overrides: Any) -> None:
        super().__init__(opponent, scenario, **overrides)
        self.observation_space = self.game.observation_space("target_0")
        self.action_space = self.game.action_space("target_0")

    def _own(self) -> np.ndarray:
        return self._obs["target_0"]

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        if callable(getattr(self.opponent, "plan", None)):
            r, term, trunc, info = self._play(None, action)
        else:
            joint, _ = self.opponent.predict(self._sensor_obs(), deterministic=True)
            r, term, trunc, info = self._play(joint, action)
        return self._obs["target_0"], -r, term, trunc, info


class SensorsView(_View):
    """The sensors' centralized view: the M observations concatenated, the joint action
    (2M,); the target is ``opponent``, the evader's SB3 model (deterministic) or None (its
    fallback, the scripted evader). Reward: the team's."""

    def __init__(self, opponent: Any, scenario: Any = "pursuit", **overrides: Any) -> None:
        super().__init__(opponent, scenario, **overrides)
        boxes = [self.game.observation_space(a) for a in self.game.sensor_agents]
        self.observation_space = gym.spaces.Box(
            np.concatenate([b.low for b in boxes]), np.concatenate([b.high for b in boxes]),
            dtype=np.float32,
        )  # fmt: skip
        m = len(boxes)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2 * m,), dtype=np.float32)

    def _own(self) -> np.ndarray:
        return self._sensor_obs()

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self.opponent is None:
            r, term, trunc, info = self._play(action, None)
        else:
            t_act, _ = self.opponent.predict(self._obs["target_0"], deterministic=True)
            r, term, trunc, info = self._play(action, t_act)
        return self._sensor_obs(), r, term, trunc, info


def _ppo(env: gym.Env, cfg: SelfPlayConfig, seed: int) -> PPO:
    vec = VecNormalize(DummyVecEnv([lambda: env]), norm_obs=False, norm_reward=True,
                       gamma=cfg.gamma)  # fmt: skip
    return PPO(
        "MlpPolicy", vec, n_steps=cfg.n_steps, batch_size=cfg.batch_size,
        learning_rate=cfg.learning_rate, gamma=cfg.gamma, ent_coef=cfg.ent_coef,
        policy_kwargs={"net_arch": list(cfg.hidden)}, seed=seed, verbose=0, device="cpu",
    )  # fmt: skip


def mean_return(view: _View, act: Any, seeds: list[int]) -> np.ndarray:
    """Return the per-episode mean reward (per step) of ``view``'s learner acting by
    ``act(obs) -> action`` on episodes ``seeds`` (one value per seed)."""
    out = []
    for s in seeds:
        obs, _ = view.reset(seed=s)
        total, n, done = 0.0, 0, False
        while not done:
            obs, r, term, trunc, _ = view.step(act(obs))
            total, n, done = total + r, n + 1, term or trunc
        out.append(total / n)
    return np.array(out)


def _deterministic(model: PPO) -> Any:
    return lambda obs: model.predict(obs, deterministic=True)[0]


@dataclass
class SelfPlayResult:
    """What :func:`train_selfplay` returns: the trained models (``sensors`` None when the
    planner played them), the history of phases and the seconds taken."""

    evader: PPO
    sensors: PPO | None
    history: list[dict[str, Any]]
    seconds: float


def train_selfplay(
    scenario: Any = "pursuit",
    *,
    seed: int = 0,
    config: SelfPlayConfig | None = None,
    threads: int = DEFAULT_THREADS,
    **overrides: Any,
) -> SelfPlayResult:
    """Train an evader (and the sensors, with ``sensor_steps > 0``) in alternation; return
    the models and, per phase, the learner's mean return per step on the validation seeds
    before and after it (``history``: ``{"round", "side", "opponent", "before",
    "after"}``, each a list per episode)."""
    cfg = config or SelfPlayConfig()
    configure_torch(threads)
    seed_everything(seed)
    t0 = time.perf_counter()
    seeds = list(range(VALIDATION_SEED, VALIDATION_SEED + cfg.eval_episodes))
    # Each side trains on its view and is measured on a twin (a measurement must not
    # leave the training view's episode ended under the learner's feet).
    planner: Any = _planner(cfg.sensors)
    evader_views = [EvaderView(planner, scenario, **overrides) for _ in range(2)]
    sensors_views = [SensorsView(None, scenario, **overrides) for _ in range(2)]
    evader = _ppo(evader_views[0], cfg, seed)
    sensors: PPO | None = None
    history: list[dict[str, Any]] = []

    def phase(r: int, side: str, who: str, model: PPO, view: _View, steps: int) -> None:
        before = mean_return(view, _deterministic(model), seeds)
        model.learn(steps, reset_num_timesteps=False)
        after = mean_return(view, _deterministic(model), seeds)
        history.append({"round": r, "side": side, "opponent": who,
                        "before": before.tolist(), "after": after.tolist()})  # fmt: skip

    for r in range(cfg.rounds):
        who = cfg.sensors if sensors is None else "learned sensors"
        phase(r, "evader", who, evader, evader_views[1], cfg.evader_steps)
        if cfg.sensor_steps == 0:
            continue
        for v in sensors_views:
            v.opponent = evader
        if sensors is None:
            sensors = _ppo(sensors_views[0], cfg, seed + 1)
        phase(r, "sensors", "learned evader", sensors, sensors_views[1], cfg.sensor_steps)
        for v in evader_views:  # the evader's next opponent: the learned sensors
            v.opponent = sensors
    return SelfPlayResult(evader, sensors, history, time.perf_counter() - t0)


def save_selfplay(result: SelfPlayResult, outputs: RunOutputs, record: dict[str, Any]) -> Path:
    """Stage ``evader.zip`` (and ``sensors.zip``) and ``selfplay.json`` in ``outputs``,
    commit them; return the evader's final path."""
    with outputs:
        result.evader.save(outputs.staged("evader.zip"))
        if result.sensors is not None:
            result.sensors.save(outputs.staged("sensors.zip"))
        outputs.write_json(
            "selfplay.json", {**record, "history": result.history, "seconds": result.seconds}
        )
        return outputs.commit()["evader.zip"]


def load_evader(path: str | Path) -> Any:
    """Return the evader of ``evader.zip`` as ``obs -> action`` (deterministic), or a
    ValueError naming the file."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(
            f"{p}: no such evader file (an evader.zip of 'activetrack train selfplay')"
        )
    try:
        model = PPO.load(p, device="cpu")
    except Exception as exc:  # a zip of something else
        raise ValueError(f"{p}: not an evader.zip of 'activetrack train selfplay' ({exc})") from exc
    return _deterministic(model)


def config_dict(cfg: SelfPlayConfig) -> dict[str, Any]:
    """Return ``cfg`` as JSON-friendly values."""
    d = asdict(cfg)
    d["hidden"] = list(cfg.hidden)
    return d


def pursuit_episodes(
    planner: str, evader: Any, seeds: list[int], scenario: Any = "pursuit", **overrides: Any
) -> np.ndarray:
    """Return the sensors' mean posterior trace per step (m^2; the protocol's score) on
    each episode of ``seeds``: the sensors planned by ``planner`` (a name of
    :data:`PLANNERS`), the target moved by ``evader`` (``obs -> action``) or, with
    ``evader`` None, by its fallback (the scripted evader). A planner that draws (RM) is
    reseeded for each episode as ``activetrack evaluate`` does, so with the scripted
    evader every row is the ``evader`` task's, episode for episode."""
    from activetrack.baselines.rollout import reset_policy

    game = PursuitParallelEnv(scenario, **overrides)
    plan = _planner(planner)
    out = []
    for s in seeds:
        obs, _ = game.reset(seed=s)
        reset_policy(plan, s)  # a planner that draws: the runner's generator for the seed
        traces = []
        while game.agents:
            ta = None if evader is None else {"target_0": evader(obs["target_0"])}
            obs, rewards, *_ = game.step_positions(plan.plan(game.planning_problem()), ta)
            traces.append(-rewards["sensor_0"])
        out.append(float(np.mean(traces)))
    return np.array(out)


def evaluate_against_evaders(
    planners: list[str],
    evader: Any,
    seeds: list[int],
    scenario: Any = "pursuit",
    **overrides: Any,
) -> list[dict[str, Any]]:
    """Return one row per (planner, evader) pair, the scripted evader (the fallback) and
    ``evader`` (``obs -> action``): the protocol's statistics of the episodes' mean traces
    (:func:`activetrack.baselines.protocol.summary`: IQM, median and mean with their 95%
    bootstrap intervals), the paired ratio of the IQM to GSR's against the same evader
    (``ratio_to_gsr``, when GSR is among ``planners``) and, for the learned evader, the
    paired ratio of the IQM to the scripted evader's with the same planner
    (``ratio_to_scripted``), each ``[point, low, high]``; ``scores`` the episodes'."""
    from activetrack.baselines import protocol

    scores = {
        (p, name): pursuit_episodes(p, ev, seeds, scenario, **overrides)
        for p in planners
        for name, ev in (("scripted", None), ("learned", evader))
    }
    rows = []
    for (p, name), x in scores.items():
        row = {"policy": p, "evader": name, **protocol.summary(x), "scores": x.tolist()}
        if "gsr" in planners:
            row["ratio_to_gsr"] = list(protocol.paired_ratio_interval(x, scores["gsr", name]))
        if name == "learned":
            row["ratio_to_scripted"] = list(
                protocol.paired_ratio_interval(x, scores[p, "scripted"])
            )
        rows.append(row)
    return rows


def format_rows(rows: list[dict[str, Any]]) -> str:
    """Return ``rows`` of :func:`evaluate_against_evaders` as a Markdown table."""

    def ci(v: Any) -> str:
        return f"{v[0]:.3f} [{v[1]:.3f}, {v[2]:.3f}]"

    lines = [
        "| sensors | evader | IQM trace (m²) [95% CI] | median | mean | IQM / GSR's | "
        "IQM / scripted's |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['policy']} | {r['evader']} | {ci([r['iqm'], *r['iqm_ci95']])} | "
            f"{ci([r['median'], *r['median_ci95']])} | {ci([r['mean'], *r['mean_ci95']])} | "
            f"{ci(r['ratio_to_gsr']) if 'ratio_to_gsr' in r else '-'} | "
            f"{ci(r['ratio_to_scripted']) if 'ratio_to_scripted' in r else '-'} |"
        )
    return "\n".join(lines)
