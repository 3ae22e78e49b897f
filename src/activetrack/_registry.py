"""The environment ids, and their registration with Gymnasium and PettingZoo on ``import
activetrack`` without importing either framework.

``import activetrack`` makes the ids known, as ``import ale_py`` and ``import minigrid``
do, so ``gymnasium.make("activetrack/ActiveTracking-v0")`` and Gymnasium's idiom
``gymnasium.register_envs(activetrack)`` (a no-op that names the module) work. The core
must not load the frameworks (about 30 ms together, and the core is used without RL), so
:func:`install` registers with a framework that is already imported, and otherwise
registers the moment it is imported: a meta-path finder that wraps the framework's loader
and runs the registration once the framework's own ``__init__`` has finished. A framework
that is not installed is never imported, so nothing is registered and nothing fails.

Registration stores only entry-point strings (the environment modules are imported by
``make``). A spawned worker process (``multiprocessing`` "spawn", TorchRL's default)
starts with an empty registry: it re-imports the parent's main script, whose ``import
activetrack`` registers again; from a main that is no file (``python -c``, a notebook),
name the module in the id: ``gymnasium.make("activetrack:activetrack/ActiveTracking-v0")``.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # (importlib.abc alone costs ~20 ms at import)
    from collections.abc import Callable
    from importlib.machinery import ModuleSpec
    from types import ModuleType

#: The paper's environment id (Section V's setup, the ``paper`` preset).
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
    "activetrack/Maneuvering-v0": "maneuvering",
    "activetrack/Evader-v0": "evader",
    "activetrack/Unicycle-v0": "unicycle",
    "activetrack/FixedWing-v0": "fixed_wing",
    "activetrack/Crowded-v0": "crowded",
    "activetrack/UrbanUnicycle-v0": "urban_unicycle",
    "activetrack/Radio-v0": "radio",
    "activetrack/Swarm-v0": "swarm",
    "activetrack/UrbanRadio-v0": "urban_radio",
    "activetrack/Pursuit-v0": "pursuit",
    "activetrack/Patrol-v0": "patrol",
}
#: Every registered id and its preset (``ActiveTracking-v0`` is the paper).
ALL_IDS = {ENV_ID: "paper", **TASK_IDS}
GYM_ENTRY_POINT = "activetrack.envs.centralized:CentralizedTrackingEnv"
VECTOR_ENTRY_POINT = "activetrack.envs.batched:BatchedActiveTracking"
PARALLEL_ENTRY_POINT = "activetrack.envs.tracking_env:parallel_env"
AEC_ENTRY_POINT = "activetrack.envs.tracking_env:env"
#: Ids whose PettingZoo games have two teams (sensors and the targets as agents,
#: :mod:`activetrack.envs.pursuit`): their parallel and AEC entry points. Gymnasium's view
#: of them stays the sensors' (the targets move by their fallback behaviour).
TWO_TEAM_ENTRY_POINTS = {
    "activetrack/Pursuit-v0": (
        "activetrack.envs.pursuit:parallel_env",
        "activetrack.envs.pursuit:env",
    ),
}


def _kwargs(env_id: str) -> dict[str, Any]:
    """Return the id's keywords: none for the paper (its defaults), else its preset."""
    return {} if env_id == ENV_ID else {"scenario": ALL_IDS[env_id]}


def register_gymnasium() -> None:
    """Register every id of :data:`ALL_IDS` with Gymnasium (idempotent; imports it).

    The centralized single-agent view for ``gymnasium.make`` and
    :class:`~activetrack.envs.batched.BatchedActiveTracking` as the ``vector_entry_point``
    (``gymnasium.make_vec(ENV_ID, num_envs=N)`` steps N copies in one batched call). No
    ``max_episode_steps``: the environment truncates after ``scenario.n_steps`` itself, so
    ``gymnasium.make`` adds no second ``TimeLimit``.
    """
    import gymnasium

    for env_id in ALL_IDS:
        if env_id not in gymnasium.registry:
            gymnasium.register(
                id=env_id,
                entry_point=GYM_ENTRY_POINT,
                vector_entry_point=VECTOR_ENTRY_POINT,
                kwargs=_kwargs(env_id),
            )


def register_pettingzoo() -> None:
    """Register every id of :data:`ALL_IDS` with PettingZoo, the parallel and AEC games
    for ``pettingzoo.make("parallel" | "aec", id)`` (idempotent; imports it). A PettingZoo
    older than 1.27 has no registry: nothing is registered."""
    import pettingzoo

    if not hasattr(pettingzoo, "register"):
        return
    for env_id in ALL_IDS:
        parallel, aec = TWO_TEAM_ENTRY_POINTS.get(env_id, (PARALLEL_ENTRY_POINT, AEC_ENTRY_POINT))
        if env_id not in pettingzoo.parallel_registry:
            pettingzoo.register("parallel", env_id, entry_point=parallel, kwargs=_kwargs(env_id))
        if env_id not in pettingzoo.aec_registry:
            pettingzoo.register("aec", env_id, entry_point=aec, kwargs=_kwargs(env_id))


#: Framework module -> its registration, run when the module is (or has been) imported.
REGISTRATIONS: dict[str, Callable[[], None]] = {
    "gymnasium": register_gymnasium,
    "pettingzoo": register_pettingzoo,
}


class _Loader:
    """A framework's loader that runs the registration after the module's own code.

    It hands the module its real loader back before executing it, so that nothing
    downstream (``module.__loader__``, ``module.__spec__.loader``) sees this wrapper.
    """

    def __init__(self, loader: Any, spec: ModuleSpec, finder: _RegisterOnImport) -> None:
        self._loader, self._spec, self._finder = loader, spec, finder

    def __getattr__(self, name: str) -> Any:
        return getattr(self._loader, name)

    def create_module(self, spec: ModuleSpec) -> ModuleType | None:
        return self._loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        self._spec.loader = module.__loader__ = self._loader
        self._loader.exec_module(module)
        self._finder.imported(self._spec.name)


class _RegisterOnImport:
    """A meta-path finder (the protocol of ``importlib.abc.MetaPathFinder``) that finds
    nothing itself: for a framework of :data:`REGISTRATIONS` not yet imported it asks the
    finders after it and wraps the loader they return (:class:`_Loader`)."""

    def __init__(self) -> None:
        self.pending = dict(REGISTRATIONS)

    def find_spec(self, fullname: str, path: Any, target: Any = None) -> ModuleSpec | None:
        # Only looked up, not popped: a lookup is no import (TorchRL and others probe with
        # importlib.util.find_spec), the registration waits for the module's execution.
        if fullname not in self.pending:
            return None
        for finder in list(sys.meta_path):
            find = getattr(finder, "find_spec", None)
            if finder is self or find is None:
                continue
            spec = find(fullname, path, target)
            if spec is not None:
                break
        else:
            return None  # not installed: registration skipped
        if spec.loader is not None and hasattr(spec.loader, "exec_module"):
            spec.loader = _Loader(spec.loader, spec, self)  # type: ignore[assignment]
        return spec

    def imported(self, fullname: str) -> None:
        """Run the registration of the framework ``fullname`` (once), which has just been
        imported; leave the import system once every framework is done."""
        register = self.pending.pop(fullname, None)
        if not self.pending:
            uninstall()
        if register is not None:
            register()


_FINDER: _RegisterOnImport | None = None


def install() -> None:
    """Register with each framework of :data:`REGISTRATIONS` now if it is imported, else
    when it is imported (:class:`_RegisterOnImport`); idempotent."""
    global _FINDER
    if _FINDER is not None:
        return
    finder = _RegisterOnImport()
    for name in list(finder.pending):
        if name in sys.modules:
            finder.pending.pop(name)()
    if finder.pending:
        _FINDER = finder
        sys.meta_path.insert(0, finder)


def uninstall() -> None:
    """Remove the finder of :func:`install` from ``sys.meta_path`` (registrations made stay)."""
    global _FINDER
    if _FINDER is not None and _FINDER in sys.meta_path:
        sys.meta_path.remove(_FINDER)
