"""Registration of the tracking environments with Gymnasium and PettingZoo.

Registration stores only entry-point strings, so it imports no environment code; the
environment modules are imported by ``make``. :func:`register_envs` is idempotent and
runs when :mod:`activetrack.envs` is imported (the core package ``activetrack`` registers
nothing, so it imports neither Gymnasium nor PettingZoo).

Gymnasium (>= 1.0) has no plugin entry points: an id is known once the module that
registers it is imported. From a fresh interpreter, name the module in the id, and
``gymnasium.make`` / ``gymnasium.make_vec`` import it first::

    gymnasium.make("activetrack.envs:activetrack/ActiveTracking-v0")
"""

from __future__ import annotations

ENV_ID = "activetrack/ActiveTracking-v0"
#: The tasks beyond the paper: registered id -> preset (:data:`activetrack.world.scenarios.TASKS`).
TASK_IDS = {
    "activetrack/TwoTargets-v0": "two_targets",
    "activetrack/RangeOnly-v0": "range_only",
    "activetrack/BearingOnly-v0": "bearing_only",
    "activetrack/MixedTeam-v0": "mixed",
    "activetrack/UncertainPoses-v0": "uncertain_poses",
    "activetrack/Urban-v0": "urban",
    "activetrack/UrbanRandom-v0": "urban_random",
}
#: Every registered id and its preset (``ActiveTracking-v0`` is the paper).
ALL_IDS = {ENV_ID: "paper", **TASK_IDS}
GYM_ENTRY_POINT = "activetrack.envs.centralized:CentralizedTrackingEnv"
VECTOR_ENTRY_POINT = "activetrack.envs.batched:BatchedActiveTracking"
PARALLEL_ENTRY_POINT = "activetrack.envs.tracking_env:parallel_env"
AEC_ENTRY_POINT = "activetrack.envs.tracking_env:env"


def register_envs() -> None:
    """Register ``activetrack/ActiveTracking-v0`` and the tasks of :data:`TASK_IDS` with
    Gymnasium and PettingZoo.

    Gymnasium: the centralized single-agent view for ``gymnasium.make`` and
    :class:`~activetrack.envs.batched.BatchedActiveTracking` as the ``vector_entry_point``,
    so ``gymnasium.make_vec(ENV_ID, num_envs=N)`` steps N copies in one batched call.
    PettingZoo (>= 1.27, the first with a registry): the parallel and AEC games, for
    ``pettingzoo.make("parallel" | "aec", ENV_ID)``.

    No ``max_episode_steps``: the environment truncates after ``scenario.n_steps``
    itself, so ``gymnasium.make`` adds no second ``TimeLimit``.
    """
    import gymnasium
    import pettingzoo

    for env_id, preset in ALL_IDS.items():
        # The paper's id passes no keyword (its defaults are the paper); a task names its preset.
        kwargs = {} if env_id == ENV_ID else {"scenario": preset}
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point=GYM_ENTRY_POINT,
                vector_entry_point=VECTOR_ENTRY_POINT,
                kwargs=kwargs,
            )
        if env_id not in pettingzoo.parallel_registry:
            pettingzoo.register("parallel", env_id, entry_point=PARALLEL_ENTRY_POINT, kwargs=kwargs)
        if env_id not in pettingzoo.aec_registry:
            pettingzoo.register("aec", env_id, entry_point=AEC_ENTRY_POINT, kwargs=kwargs)
