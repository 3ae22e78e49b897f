"""Registration of the tracking environments with Gymnasium and PettingZoo.

The ids and the registration live in the core (:mod:`activetrack._registry`), so that
``import activetrack`` registers them without importing Gymnasium or PettingZoo: with a
framework already imported at once, else as soon as it is imported. Registration stores
only entry-point strings; the environment modules are imported by ``make``.
:func:`register_envs` registers with both frameworks now (importing them); it is
idempotent and runs when :mod:`activetrack.envs` is imported.

So, after ``import activetrack`` (or ``gymnasium.register_envs(activetrack)``)::

    gymnasium.make("activetrack/ActiveTracking-v0")
    pettingzoo.make("parallel", "activetrack/ActiveTracking-v0")

and from an interpreter that has not imported activetrack, name the module in the id:
``gymnasium.make("activetrack:activetrack/ActiveTracking-v0")``.
"""

from __future__ import annotations

from activetrack._registry import (
    AEC_ENTRY_POINT,
    ALL_IDS,
    ENV_ID,
    GYM_ENTRY_POINT,
    PARALLEL_ENTRY_POINT,
    TASK_IDS,
    VECTOR_ENTRY_POINT,
    register_gymnasium,
    register_pettingzoo,
)

__all__ = [
    "AEC_ENTRY_POINT",
    "ALL_IDS",
    "ENV_ID",
    "GYM_ENTRY_POINT",
    "PARALLEL_ENTRY_POINT",
    "TASK_IDS",
    "VECTOR_ENTRY_POINT",
    "register_envs",
]


def register_envs() -> None:
    """Register ``activetrack/ActiveTracking-v0`` and the tasks of :data:`TASK_IDS` with
    Gymnasium and PettingZoo now (:func:`~activetrack._registry.register_gymnasium`,
    :func:`~activetrack._registry.register_pettingzoo`); idempotent."""
    register_gymnasium()
    register_pettingzoo()
