"""Registration of the tracking environments with Gymnasium and PettingZoo.

Registration stores only entry-point strings, so it imports no environment code; the
environment modules are imported by ``make``. :func:`register_envs` is idempotent.
"""

from __future__ import annotations

ENV_ID = "activetrack/ActiveTracking-v0"
GYM_ENTRY_POINT = "activetrack.envs.centralized:CentralizedTrackingEnv"
PARALLEL_ENTRY_POINT = "activetrack.envs.tracking_env:parallel_env"
AEC_ENTRY_POINT = "activetrack.envs.tracking_env:env"


def register_envs() -> None:
    """Register ``activetrack/ActiveTracking-v0`` with Gymnasium (centralized view) and,
    where PettingZoo has a registry (>= 1.27), as its parallel and AEC environments.

    No ``max_episode_steps``: the environment truncates after ``scenario.n_steps``
    itself, so ``gymnasium.make`` adds no second ``TimeLimit``.
    """
    import gymnasium

    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point=GYM_ENTRY_POINT)
    try:
        import pettingzoo

        register = pettingzoo.register
    except (ImportError, AttributeError):  # PettingZoo without a registry
        return
    if ENV_ID not in pettingzoo.parallel_registry:
        register("parallel", ENV_ID, entry_point=PARALLEL_ENTRY_POINT)
    if ENV_ID not in pettingzoo.aec_registry:
        register("aec", ENV_ID, entry_point=AEC_ENTRY_POINT)
