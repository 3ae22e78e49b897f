"""The planners of Section V as policies acting in the tracking environments (experts).

A :class:`PlannerPolicy` reads the environment's raw planning problem (the prediction
``x_hat(k+1|k), P(k+1|k)`` and the team, eq. 15-17), asks its planner for the sensors'
next positions, and returns the actions that reach them exactly
(:func:`activetrack.envs.actions_to_reach`: ``a_i = (p_next_i - p_i) / r_i``). The
planner draws from the policy's own generator, seeded like the simulation runner's
(``np.random.default_rng([seed, 1])``), so an episode run through the environment with
``reset(seed=s)`` and a policy made with ``seed=s`` reproduces
:func:`activetrack.baselines.simulation.simulate` with seed ``s`` exactly.

Example::

    from activetrack import envs
    from activetrack.baselines.policies import GSRPolicy

    env = envs.parallel_env(scenario="paper")
    policy = GSRPolicy(seed=0)
    obs, infos = env.reset(seed=0)
    while env.agents:
        obs, rewards, terms, truncs, infos = env.step(policy.act(env))
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.envs.dynamics import actions_to_reach
from activetrack.problem import Planner, PlanningProblem
from activetrack.validation import FloatArray


class PlannerPolicy:
    """Act in a tracking environment with any :class:`~activetrack.Planner`.

    Works with the parallel env, the AEC env and the centralized Gymnasium env (wrapped
    or not: it uses ``env.unwrapped``). Call it once per step: every call plans (and
    may draw from the planner generator).

    Args:
        planner: the planner; ``plan(problem, rng) -> (M, 2)`` absolute next positions.
        seed: seeds the planner generator as ``np.random.default_rng([seed, 1])``, the
            simulation runner's; ``None`` for fresh entropy.
    """

    def __init__(self, planner: Planner, seed: int | None = None) -> None:
        self.planner = planner
        self.reset(seed)

    def reset(self, seed: int | None = None) -> None:
        """Re-seed the planner generator (as the runner does for world seed ``seed``)."""
        self.rng = np.random.default_rng() if seed is None else np.random.default_rng([seed, 1])

    def plan(self, env: Any) -> tuple[PlanningProblem, FloatArray]:
        """Return the env's current planning problem and the planner's next positions."""
        problem = env.unwrapped.planning_problem()
        nxt = np.asarray(self.planner.plan(problem, self.rng), dtype=np.float64)
        if nxt.shape != (problem.n_sensors, 2):
            raise ValueError(
                f"planner {self.planner!r} returned shape {nxt.shape}, "
                f"expected ({problem.n_sensors}, 2)"
            )
        return problem, nxt

    def actions(self, env: Any) -> FloatArray:
        """Return every sensor's action, shape (M, 2), float64."""
        problem, nxt = self.plan(env)
        return actions_to_reach(nxt, problem.sensors, problem.r)

    def act(self, env: Any) -> dict[str, FloatArray]:
        """Return ``{agent: action}`` for the parallel (or AEC) environment."""
        a = self.actions(env)
        return dict(zip(env.unwrapped.possible_agents, a, strict=True))

    def joint_action(self, env: Any) -> FloatArray:
        """Return the centralized env's joint action, shape (2M,), float64."""
        return self.actions(env).reshape(-1)

    __call__ = act

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.planner!r})"


class GSRPolicy(PlannerPolicy):
    """Gauss-Seidel relaxation (Section IV-B) as a policy; ``planner_kwargs`` go to ``GSR``."""

    def __init__(self, seed: int | None = None, **planner_kwargs: Any) -> None:
        from activetrack.baselines import GSR  # late: baselines may import this module

        super().__init__(GSR(**planner_kwargs), seed)


class GBESPolicy(PlannerPolicy):
    """Grid-based exhaustive search (Section V) as a policy; kwargs go to ``GBES``."""

    def __init__(self, seed: int | None = None, **planner_kwargs: Any) -> None:
        from activetrack.baselines import GBES

        super().__init__(GBES(**planner_kwargs), seed)


class RMPolicy(PlannerPolicy):
    """Random motion on the curves ADB (Section V) as a policy."""

    def __init__(self, seed: int | None = None, **planner_kwargs: Any) -> None:
        from activetrack.baselines import RandomMotion

        super().__init__(RandomMotion(**planner_kwargs), seed)
