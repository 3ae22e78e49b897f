"""N copies of the tracking game advanced in one call: a Gymnasium ``VectorEnv``.

Every copy is the centralized view of :mod:`activetrack.envs.centralized` (joint action
``(2M,)``, concatenated observations), and the physics is the same pure, batched code the
single environment runs (:func:`~activetrack.envs.dynamics.apply_actions`,
:func:`activetrack.tracking.advance` with the EKF of eq. (11), and the prediction of
eq. (3)); here the leading axis is the copy. There is no second copy of the math.

Seeding and reproducibility: ``reset(seed=s)`` seeds copy ``i`` with
``np.random.default_rng(s + i)``, and every copy draws its random numbers in exactly the
order of a single environment: initial conditions, then ``n + 2M`` standard normals per
step. To avoid a Python call per copy and step, the normals are drawn in blocks of up to
``noise_block`` steps, never beyond the episode's last step, so a copy's generator is in
the same state as the single environment's at every reset. (A copy that terminates early
on ``max_trace`` has drawn the rest of its block: its next episodes then differ from a
single environment's, though they stay reproducible.)

Autoreset follows Gymnasium's modes (https://farama.org/Vector-Autoreset-Mode):
``NEXT_STEP`` (the default: the step after a copy ends resets it, returning its first
observation with reward 0), ``SAME_STEP`` (the copy is reset within the step; the last
observation is in ``infos["final_obs"]``) and ``DISABLED`` (``reset(options={"reset_mask":
mask})`` resets chosen copies). :meth:`step_agents` gives the per-agent observations for
parameter-sharing learners (slots = copies x agents).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from activetrack.motion import predict
from activetrack.scenarios import Scenario, make_scenario
from activetrack.tracking import LoopParams, advance
from activetrack.validation import FloatArray

from . import features
from .dynamics import apply_actions


class BatchedActiveTracking(VectorEnv):
    """``num_envs`` independent tracking games stepped together over a leading copy axis.

    Args:
        num_envs: the number of copies N.
        scenario: a preset name or a :class:`~activetrack.Scenario`; ``**overrides`` as in
            :func:`activetrack.envs.parallel_env`.
        autoreset_mode: a :class:`gymnasium.vector.AutoresetMode` or its value string.
        noise_block: how many steps of noise a copy draws per generator call.

    Arrays of the current state (leading axis N): ``x_true``, ``x_hat``/``P`` (posterior),
    ``x_pred``/``P_pred`` (prediction), ``sensors`` (N, M, 2), ``k`` (steps taken).
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int,
        scenario: str | Scenario = "paper",
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        noise_block: int = 64,
        **overrides: Any,
    ) -> None:
        if not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if not isinstance(noise_block, (int, np.integer)) or noise_block < 1:
            raise ValueError(f"noise_block must be an integer >= 1, got {noise_block!r}")
        try:
            self.autoreset_mode = AutoresetMode(autoreset_mode)
        except ValueError:
            modes = [m.value for m in AutoresetMode]
            raise ValueError(
                f"autoreset_mode must be one of {modes}, got {autoreset_mode!r}"
            ) from None
        sc = make_scenario(scenario, **overrides)
        self.scenario = sc
        self.num_envs = int(num_envs)
        self.noise_block = int(noise_block)
        self.metadata = {**type(self).metadata, "autoreset_mode": self.autoreset_mode}
        self.render_mode = None
        self.params = LoopParams.from_scenario(sc)
        m = self.n_sensors = sc.n_sensors
        self.length_scale = features.length_scale(sc)
        p = self.params
        self._constants = features.sensor_constants(
            p.sigma_d2, p.sigma_theta2, p.r, p.rho, self.length_scale
        )
        self._order = features.cyclic_order(m)
        self._max_trace = np.inf if sc.max_trace is None else float(sc.max_trace)
        self._chol0 = np.linalg.cholesky(sc.initial_cov)
        self._x0 = np.asarray(sc.x0, dtype=np.float64)
        self._x0_hat = np.asarray(sc.x0_hat, dtype=np.float64)

        low, high = features.observation_bounds(m)
        self.single_observation_space = spaces.Box(
            np.tile(low, m), np.tile(high, m), dtype=np.float32
        )
        self.single_action_space = spaces.Box(-1.0, 1.0, (2 * m,), dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)

        n, N = p.Phi.shape[0], self.num_envs
        self._rngs: list[np.random.Generator] = [np.random.default_rng() for _ in range(N)]
        self._noise = np.zeros((N, self.noise_block, p.n_noise))
        self._noise_left = np.zeros(N, dtype=np.int64)  # unused steps in each copy's block
        self.x_true = np.zeros((N, n))
        self.x_hat = np.zeros((N, n))
        self.P = np.broadcast_to(np.eye(n), (N, n, n)).copy()
        self.x_pred, self.P_pred = self.x_hat.copy(), self.P.copy()
        self.sensors = np.zeros((N, m, 2))
        self.k = np.zeros(N, dtype=np.int64)
        self.trace = np.zeros(N)
        self.last_projected = np.zeros((N, m), dtype=bool)
        self._autoreset = np.zeros(N, dtype=bool)
        self._started = False

    # Random numbers ------------------------------------------------------------------------
    def _seed(self, seed: int | list[int | None] | None, mask: np.ndarray) -> None:
        """Re-create the generators of the copies in ``mask`` from ``seed``."""
        if seed is None:
            return
        if isinstance(seed, (int, np.integer)):
            seeds: list[int | None] = [int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"seed must be an int or a list of {self.num_envs} seeds")
        for i in np.flatnonzero(mask):
            if seeds[i] is not None:
                self._rngs[i] = np.random.default_rng(seeds[i])

    def _draw_noise(self, idx: np.ndarray) -> None:
        """Refill the noise blocks of copies ``idx``, never past their episode's last step."""
        n_steps = self.scenario.n_steps
        for i in idx:
            steps = int(min(self.noise_block, max(n_steps - self.k[i], 1)))
            self._noise[i, self.noise_block - steps :] = self._rngs[i].standard_normal(
                (steps, self.params.n_noise)
            )
            self._noise_left[i] = steps

    # Reset ----------------------------------------------------------------------------------
    def _reset_copies(self, idx: np.ndarray) -> None:
        """Draw new episodes for copies ``idx`` (as ``tracking.initial_conditions`` does)."""
        sc, m = self.scenario, self.n_sensors
        gaussian = sc.target_init == "gaussian"
        u = np.empty((len(idx), m, 2))
        g = np.empty((len(idx), self._x0.shape[0])) if gaussian else None
        for j, i in enumerate(idx):
            rng = self._rngs[i]
            u[j] = rng.random((m, 2))
            if gaussian:
                g[j] = rng.standard_normal(self._x0.shape[0])
        radius = sc.sensor_radius * np.sqrt(u[..., 0])  # uniform by area
        angle = 2.0 * np.pi * u[..., 1]
        self.sensors[idx] = np.asarray(sc.sensor_center) + radius[..., None] * np.stack(
            [np.cos(angle), np.sin(angle)], -1
        )
        self.x_hat[idx] = self._x0_hat
        self.x_true[idx] = self._x0_hat + g @ self._chol0.T if gaussian else self._x0
        P0 = sc.initial_cov
        self.P[idx] = P0
        self.x_pred[idx], self.P_pred[idx] = predict(
            self.x_hat[idx], self.P[idx], self.params.Phi, self.params.Q
        )
        self.k[idx] = 0
        self.trace[idx] = P0[0, 0] + P0[1, 1]
        self.last_projected[idx] = False
        self._noise_left[idx] = 0
        self._draw_noise(idx)

    def reset(
        self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset all copies (or ``options["reset_mask"]``); copy i is seeded ``seed + i``."""
        mask = np.ones(self.num_envs, dtype=bool)
        if options and "reset_mask" in options:
            mask = np.asarray(options["reset_mask"])
            if mask.shape != (self.num_envs,) or mask.dtype != np.bool_:
                raise ValueError(f"options['reset_mask'] must be a bool array ({self.num_envs},)")
        self._seed(seed, mask)
        idx = np.flatnonzero(mask)
        self._reset_copies(idx)
        self._autoreset[idx] = False
        self._started = True
        return self._joint_obs(), self._infos()

    # Step -------------------------------------------------------------------------------------
    def step_agents(
        self, actions: FloatArray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step with actions (N, M, 2) or (N, 2M); return per-agent observations (N, M, D).

        Returns ``(obs, rewards, terminated, truncated, infos)``; rewards, terminated and
        truncated have shape (N,) (the team's shared reward).
        """
        if not self._started:
            raise RuntimeError("call reset() before step()")
        N, m = self.num_envs, self.n_sensors
        a = np.asarray(actions, dtype=np.float64)
        if a.shape == (N, 2 * m):
            a = a.reshape(N, m, 2)
        if a.shape != (N, m, 2):
            raise ValueError(
                f"actions must have shape ({N}, {m}, 2) or ({N}, {2 * m}), got {a.shape}"
            )
        if not np.isfinite(a).all():
            bad = np.argwhere(~np.isfinite(a).all(-1))
            raise ValueError(
                f"actions must be finite (no NaN or inf); bad (copy, agent): {bad[:5].tolist()}"
            )

        resetting = self._autoreset if self.autoreset_mode == AutoresetMode.NEXT_STEP else None
        p = self.params
        sensors, projected = apply_actions(a, self.sensors, self.x_pred[:, :2], p.r, p.rho)
        empty = self._noise_left == 0
        if resetting is not None:
            empty &= ~resetting  # a copy about to be reset must not draw: its stream moves on
        if empty.any():
            self._draw_noise(np.flatnonzero(empty))
        noise = self._noise[np.arange(N), self.noise_block - np.maximum(self._noise_left, 1)]
        x_true, _, x_post, P_post = advance(
            p, self.x_true, self.x_pred, self.P_pred, sensors, noise
        )
        live = slice(None) if resetting is None or not resetting.any() else ~resetting
        self._noise_left[live] -= 1
        self.x_true[live], self.x_hat[live], self.P[live] = x_true[live], x_post[live], P_post[live]
        self.sensors[live] = sensors[live]
        self.last_projected[live] = projected[live]
        self.k[live] += 1
        trace = P_post[:, 0, 0] + P_post[:, 1, 1]
        self.trace[live] = trace[live]
        self.x_pred[live], self.P_pred[live] = predict(x_post[live], P_post[live], p.Phi, p.Q)

        terminated = self.trace > self._max_trace
        truncated = self.k >= self.scenario.n_steps
        rewards = -self.scenario.reward_scale * self.trace
        infos: dict[str, Any] = {}
        if resetting is not None and resetting.any():
            idx = np.flatnonzero(resetting)
            self._reset_copies(idx)
            rewards[idx] = 0.0
            terminated[idx] = truncated[idx] = False
        done = terminated | truncated
        if self.autoreset_mode == AutoresetMode.SAME_STEP and done.any():
            idx = np.flatnonzero(done)
            final_obs = self._agent_obs()[idx].reshape(len(idx), -1)
            infos["final_obs"] = np.full(N, None, dtype=object)
            infos["final_obs"][idx] = list(final_obs)
            infos["_final_obs"] = done.copy()
            infos["final_info"] = {"trace": self.trace.copy(), "_trace": done.copy()}
            self._reset_copies(idx)
        self._autoreset = done.copy()
        infos.update(self._infos())
        return self._agent_obs(), rewards, terminated, truncated, infos

    def step(
        self, actions: FloatArray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Step every copy with joint actions (N, 2M); observations are (N, M (5 + 6M))."""
        obs, rewards, terminated, truncated, infos = self.step_agents(actions)
        return obs.reshape(self.num_envs, -1), rewards, terminated, truncated, infos

    # Observations -------------------------------------------------------------------------------
    def _agent_obs(self) -> np.ndarray:
        L = self.length_scale
        target = features.target_features(self.x_pred, self.P_pred, self.scenario.dt, L)
        sensor = features.sensor_features(self.sensors, self.x_pred[:, :2], self._constants, L)
        return features.observations(target, sensor, self._order)

    def _joint_obs(self) -> np.ndarray:
        return self._agent_obs().reshape(self.num_envs, -1)

    def _infos(self) -> dict[str, Any]:
        return {"step": self.k.copy(), "trace": self.trace.copy()}

    def close_extras(self, **kwargs: Any) -> None:
        """Nothing to release (no subprocesses, no windows)."""
