"""A stable-baselines3 ``VecEnv`` over copies of the PettingZoo parallel environment.

Parameter sharing: one policy drives every sensor, so each (copy, agent) pair is one slot of
the ``VecEnv`` and ``num_envs = n_copies * n_agents``. Slot ``s`` is agent ``s % M`` of copy
``s // M``. The adapter is owned by the project because SuperSuit's ``concat_vec_envs``
crashes on ``seed`` and drops time-limit truncation; here:

- ``seed(s)`` (called by ``PPO(seed=s)``) gives copy ``i`` the seed ``s + i`` at the next
  ``reset``; later episodes of a copy continue that copy's own generator, so a whole run is
  reproducible from ``s``;
- an episode that ends by the time limit is reported as ``done`` with
  ``infos[slot]["TimeLimit.truncated"] = True`` and the last observation in
  ``infos[slot]["terminal_observation"]``, so PPO bootstraps from its value instead of
  treating the cut as a real end;
- copies end and reset independently (auto-reset), as in SB3's ``DummyVecEnv``.

The copies live behind a small backend with two methods on arrays shaped
(copies, agents, ...): ``reset(indices, seeds)`` and ``step(actions)`` (no auto-reset of its
own). :class:`ParallelCopies` loops over PettingZoo envs (any ``ParallelEnv``);
:class:`BatchedCopies` advances all copies in one call of
:class:`activetrack.envs.BatchedActiveTracking` (same physics and the same random draws
per copy, so both give the same numbers; the batched one is faster). The SB3 semantics
above live only in :class:`SharedPolicyVecEnv`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import (
    VecEnv,
    VecEnvIndices,
    VecEnvObs,
    VecEnvStepReturn,
)

from activetrack.validation import check_int, check_seed


class ParallelCopies:
    """``n`` independent PettingZoo ``ParallelEnv`` copies with the same agents, as arrays.

    Environments that offer the array-level core of the project's tracking env
    (``reset_arrays(seed)``, ``step_arrays(actions) -> (obs, reward, terminated,
    truncated)``) are stepped through it, which skips the per-agent dicts (2x faster, same
    numbers); their per-agent info is then only ``{"trace": env.trace}``. Any other
    ``ParallelEnv`` goes through ``reset``/``step``.
    """

    def __init__(self, envs: Sequence[Any], fast: bool = True) -> None:
        if not envs:
            raise ValueError("need at least one environment copy")
        self.envs = list(envs)
        self.fast = fast and all(
            hasattr(e, "reset_arrays") and hasattr(e, "step_arrays") for e in self.envs
        )
        self.agents: list[str] = list(self.envs[0].possible_agents)
        first = self.agents[0]
        self.observation_space: gym.spaces.Box = self.envs[0].observation_space(first)
        self.action_space: gym.spaces.Box = self.envs[0].action_space(first)
        for env in self.envs:
            if list(env.possible_agents) != self.agents:
                raise ValueError("every copy must have the same agents")
            for agent in self.agents:
                # Parameter sharing needs one observation and one action space for all.
                if env.observation_space(agent) != self.observation_space:
                    raise ValueError(f"agent {agent} has a different observation space")
                if env.action_space(agent) != self.action_space:
                    raise ValueError(f"agent {agent} has a different action space")

    @property
    def n_copies(self) -> int:
        """Return the number of copies."""
        return len(self.envs)

    def reset(
        self, indices: Sequence[int], seeds: Sequence[int | None]
    ) -> tuple[np.ndarray, list[dict]]:
        """Reset copies ``indices`` (``seeds[j]`` for the j-th, None: continue its generator).

        Returns their observations (len(indices), M, D) and one ``{agent: info}`` per copy.
        """
        out_obs, out_info = [], []
        for i, seed in zip(indices, seeds, strict=True):
            env = self.envs[i]
            if self.fast:
                out_obs.append(np.asarray(env.reset_arrays(seed), self.observation_space.dtype))
                out_info.append({a: {"trace": env.trace} for a in self.agents})
            else:
                obs, infos = env.reset(seed=seed)
                out_obs.append(self._stack(obs))
                out_info.append(infos)
        return np.stack(out_obs), out_info

    def attribute_owner(self, i: int) -> Any:
        """Return the object whose attributes copy ``i`` exposes (its env)."""
        return self.envs[i]

    def render(self) -> list[Any]:
        """Return one frame per copy."""
        return [env.render() for env in self.envs]

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        """Step every copy with ``actions`` (C, M, A).

        Returns observations (C, M, D), rewards, terminated and truncated flags (C, M) and
        one ``{agent: info}`` dict per copy.
        """
        if self.fast:
            return self._step_fast(actions)
        out_obs, out_rew, out_term, out_trunc, out_info = [], [], [], [], []
        for env, act in zip(self.envs, actions, strict=True):
            obs, rew, term, trunc, info = env.step(
                {agent: act[j] for j, agent in enumerate(self.agents)}
            )
            out_obs.append(self._stack(obs))
            out_rew.append([rew[a] for a in self.agents])
            out_term.append([term[a] for a in self.agents])
            out_trunc.append([trunc[a] for a in self.agents])
            out_info.append(info)
        return (
            np.stack(out_obs),
            np.asarray(out_rew, dtype=np.float32),
            np.asarray(out_term, dtype=bool),
            np.asarray(out_trunc, dtype=bool),
            out_info,
        )

    def _step_fast(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        m = len(self.agents)
        c = len(self.envs)
        obs = np.empty((c, m, *self.observation_space.shape), self.observation_space.dtype)
        rew = np.empty((c, m), np.float32)
        term = np.empty((c, m), bool)
        trunc = np.empty((c, m), bool)
        infos = []
        # SB3 passes finite actions clipped to the box; step_arrays skips dict validation.
        actions = np.asarray(actions, dtype=np.float64)
        for i, env in enumerate(self.envs):
            o, r, te, tr = env.step_arrays(actions[i])
            obs[i], rew[i], term[i], trunc[i] = o, r, te, tr
            infos.append({a: {"trace": env.trace} for a in self.agents})
        return obs, rew, term, trunc, infos

    def _stack(self, obs: dict[str, np.ndarray]) -> np.ndarray:
        return np.stack(
            [np.asarray(obs[a], dtype=self.observation_space.dtype) for a in self.agents]
        )

    def close(self) -> None:
        """Close every copy."""
        for env in self.envs:
            env.close()


class BatchedCopies:
    """All copies in one :class:`activetrack.envs.BatchedActiveTracking` (auto-reset off).

    Copy ``i`` draws from its own generator in the single environment's order, so with the
    same seeds it reproduces :class:`ParallelCopies` over ``parallel_env`` exactly.
    """

    def __init__(self, n_copies: int, scenario: Any = "paper", **overrides: Any) -> None:
        from activetrack.envs import BatchedActiveTracking

        self.env = BatchedActiveTracking(n_copies, scenario, autoreset_mode="Disabled", **overrides)
        m = self.env.n_sensors
        self.agents = [f"sensor_{i}" for i in range(m)]
        low, high = self.env.world.layout.bounds(self.env.length_scale)
        self.observation_space = gym.spaces.Box(low, high, dtype=np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        self.n_copies = int(n_copies)

    def reset(
        self, indices: Sequence[int], seeds: Sequence[int | None]
    ) -> tuple[np.ndarray, list[dict]]:
        """Reset copies ``indices`` in one call; as :meth:`ParallelCopies.reset`."""
        mask = np.zeros(self.n_copies, dtype=bool)
        mask[list(indices)] = True
        all_seeds: list[int | None] = [None] * self.n_copies
        for i, seed in zip(indices, seeds, strict=True):
            all_seeds[i] = seed
        obs, infos = self.env.reset(seed=all_seeds, options={"reset_mask": mask})
        obs = obs.reshape(self.n_copies, len(self.agents), -1)[list(indices)]
        trace = infos["trace"]
        return obs, [{a: {"trace": float(trace[i])} for a in self.agents} for i in indices]

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[dict]]:
        """Step every copy; as :meth:`ParallelCopies.step`."""
        obs, rew, term, trunc, infos = self.env.step_agents(actions)
        m = len(self.agents)
        trace = infos["trace"]
        return (
            obs,
            np.repeat(rew.astype(np.float32)[:, None], m, 1),
            np.repeat(term[:, None], m, 1),
            np.repeat(trunc[:, None], m, 1),
            [{a: {"trace": float(trace[i])} for a in self.agents} for i in range(self.n_copies)],
        )

    def attribute_owner(self, i: int) -> Any:
        """Return the batched env (all copies share it)."""
        return self.env

    def render(self) -> list[Any]:
        """Return each copy's frame (the batched env made with ``render_mode="rgb_array"``),
        else None per copy."""
        if self.env.render_mode != "rgb_array":
            return [None] * self.n_copies
        return list(self.env.render())

    def close(self) -> None:
        """Close the batched env."""
        self.env.close()


class SharedPolicyVecEnv(VecEnv):
    """SB3 ``VecEnv`` with one slot per (copy, agent): parameter sharing over a parallel env.

    Args:
        copies: a backend (:class:`ParallelCopies`, :class:`BatchedCopies`) or a list of
            PettingZoo parallel envs (wrapped in :class:`ParallelCopies`).
    """

    def __init__(self, copies: ParallelCopies | BatchedCopies | Sequence[Any]) -> None:
        if not isinstance(copies, (ParallelCopies, BatchedCopies)):
            copies = ParallelCopies(copies)
        self.copies = copies
        self.n_agents = len(self.copies.agents)
        n_slots = self.copies.n_copies * self.n_agents
        super().__init__(n_slots, self.copies.observation_space, self.copies.action_space)
        self._copy_seeds: list[int | None] = [None] * self.copies.n_copies
        self._obs = np.zeros((n_slots, *self.observation_space.shape), self.observation_space.dtype)
        self._actions: np.ndarray | None = None

    # Seeding ------------------------------------------------------------------------
    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Give copy ``i`` the seed ``seed + i`` at the next reset; return the per-slot seeds."""
        if seed is None:
            # Like SB3: draw from numpy's global state (which SB3's set_random_seed seeds).
            seed = int(np.random.randint(0, 2**32 - 1, dtype=np.uint32))  # noqa: NPY002
        seed = check_seed("seed", seed)
        self._copy_seeds = [seed + i for i in range(self.copies.n_copies)]
        return [s for s in self._copy_seeds for _ in range(self.n_agents)]

    # Core API -----------------------------------------------------------------------
    def reset(self) -> VecEnvObs:
        """Reset every copy (with its pending seed, then forget it) and return all slots' obs."""
        indices = list(range(self.copies.n_copies))
        obs, infos = self.copies.reset(indices, self._copy_seeds)
        for i in indices:
            self._write_copy(i, obs[i])
            self._store_reset_infos(i, infos[i])
        self._copy_seeds = [None] * self.copies.n_copies
        self._reset_options()
        return self._obs.copy()

    def step_async(self, actions: np.ndarray) -> None:
        """Store the slots' actions (num_envs, A) for :meth:`step_wait`."""
        a = np.asarray(actions)
        if a.size != self.num_envs * math.prod(self.action_space.shape):
            raise ValueError(
                f"actions must have shape ({self.num_envs}, "
                f"{', '.join(map(str, self.action_space.shape))}), got {a.shape}"
            )
        self._actions = a.reshape(self.copies.n_copies, self.n_agents, *self.action_space.shape)

    def step_wait(self) -> VecEnvStepReturn:
        """Step all copies, auto-resetting finished ones; return SB3's (obs, rew, done, infos)."""
        if self._actions is None:
            raise RuntimeError("step_wait called before step_async")
        obs, rew, term, trunc, copy_infos = self.copies.step(self._actions)
        self._actions = None
        dones = term | trunc
        infos: list[dict[str, Any]] = []
        ended = []
        for i in range(self.copies.n_copies):
            # The reward is shared and so is the end of an episode: a copy whose agents end
            # at different steps has no slot semantics here.
            if dones[i].any() and not dones[i].all():
                raise RuntimeError(f"copy {i}: agents ended at different steps {dones[i]}")
            for j, agent in enumerate(self.copies.agents):
                info = dict(copy_infos[i].get(agent, {}))
                if dones[i, j]:
                    info["terminal_observation"] = obs[i, j].copy()
                    info["TimeLimit.truncated"] = bool(trunc[i, j] and not term[i, j])
                infos.append(info)
            if dones[i].all():
                ended.append(i)
        if ended:  # auto-reset, after the terminal observations were saved
            new_obs, reset_infos = self.copies.reset(ended, [self._copy_seeds[i] for i in ended])
            for j, i in enumerate(ended):
                obs[i] = new_obs[j]
                self._copy_seeds[i] = None
                self._store_reset_infos(i, reset_infos[j])
        self._obs[:] = obs.reshape(self._obs.shape)
        return self._obs.copy(), rew.reshape(-1), dones.reshape(-1), infos

    def close(self) -> None:
        """Close every copy."""
        self.copies.close()

    def _write_copy(self, i: int, obs: np.ndarray) -> None:
        self._obs[i * self.n_agents : (i + 1) * self.n_agents] = obs

    def _store_reset_infos(self, i: int, infos: dict[str, dict]) -> None:
        for j, agent in enumerate(self.copies.agents):
            self.reset_infos[i * self.n_agents + j] = dict(infos.get(agent, {}))

    # Attribute access (slot -> its copy) --------------------------------------------------
    def _copy_envs(self, indices: VecEnvIndices) -> list[Any]:
        return [self.copies.attribute_owner(s // self.n_agents) for s in self._get_indices(indices)]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """Return the attribute of each slot's copy."""
        return [getattr(env, attr_name) for env in self._copy_envs(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set the attribute on each slot's copy."""
        for env in self._copy_envs(indices):
            setattr(env, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: VecEnvIndices = None, **method_kwargs
    ) -> list[Any]:
        """Call the method of each slot's copy (a copy shared by M slots is called M times)."""
        return [
            getattr(env, method_name)(*method_args, **method_kwargs)
            for env in self._copy_envs(indices)
        ]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        """Return False for every slot: PettingZoo envs are not Gymnasium wrappers."""
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """Return one rendered frame per copy (not per slot)."""
        return self.copies.render()


BACKENDS = ("batched", "parallel")


def make_shared_vec_env(
    scenario: Any = "paper",
    n_copies: int = 8,
    backend: str = "batched",
    env_factory: Callable[..., Any] | None = None,
    **overrides: Any,
) -> SharedPolicyVecEnv:
    """Return a :class:`SharedPolicyVecEnv` over ``n_copies`` copies of the tracking game.

    ``backend="batched"`` steps them in one :class:`~activetrack.envs.BatchedActiveTracking`;
    ``"parallel"`` loops over ``env_factory(scenario, **overrides)`` (default
    ``activetrack.envs.parallel_env``). Both give the same numbers from the same seed. Seed
    it with ``vec.seed(s)`` (or ``PPO(seed=s)``) before the first reset.
    """
    n_copies = check_int("n_copies", n_copies, 1)
    if backend == "batched" and env_factory is None:
        return SharedPolicyVecEnv(BatchedCopies(n_copies, scenario, **overrides))
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if env_factory is None:
        from activetrack.envs import parallel_env as env_factory
    return SharedPolicyVecEnv([env_factory(scenario, **overrides) for _ in range(n_copies)])
