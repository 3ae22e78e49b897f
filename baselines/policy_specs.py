"""Which policy a name or a policy file means: the planners' experts by name, trained
policies through the installed policy file loaders.

A policy is an expert with ``plan(problem) -> next positions`` (e.g.
:class:`~activetrack.baselines.policies.GSRPolicy`), anything with
``act(observations) -> {agent: action}`` (e.g. a learned policy), or a name: ``gsr``,
``gsr-restarts`` (``GSR(restarts=True)``), ``gbes``, ``rm``, ``lookahead``,
``gsr-single-model`` and ``lookahead-single-model`` (GSR and the look-ahead planning from
the IMM's mode 0 alone, ``prediction=0``: :mod:`activetrack.world.planning_prediction`;
with the EKF they are ``gsr`` and ``lookahead``), ``distributed-gsr`` (GSR by message
passing inside each connected group of a decentralized team, each robot on its own
estimate: :mod:`activetrack.baselines.distributed_gsr`), ``distributed-lookahead`` (the
look-ahead per connected group, by its leader on its own estimate:
:mod:`activetrack.baselines.group_planner`), or the path of a policy file, e.g. a
trained ``policy.zip``.

Policy files load through the entry-point group :data:`POLICY_LOADERS`
(``activetrack.policy_loaders`` in ``pyproject.toml``): an entry named for a file suffix
(``zip``) names a function ``path -> policy``; the train layer provides ``zip``
(:func:`activetrack.train.policy_io.load_policy`). Why: ``evaluate(["runs/x/policy.zip"])``
keeps loading trained policies while baselines, below train, never imports it, and other
packages can add their own formats.
"""

from __future__ import annotations

import importlib.metadata
from pathlib import Path
from typing import Any

import numpy as np

#: Names that resolve to the planners' expert policies.
EXPERT_NAMES = (
    "gsr",
    "gsr-restarts",
    "gbes",
    "rm",
    "lookahead",
    "gsr-single-model",
    "lookahead-single-model",
    "distributed-gsr",
    "distributed-lookahead",
)
#: The entry-point group of the policy file loaders: name = the file suffix without its
#: dot (lower case), value = ``module:function`` taking the path and returning a policy.
POLICY_LOADERS = "activetrack.policy_loaders"


def resolve_policy(spec: Any) -> Any:
    """Return a policy object for a name, a policy file path or an object.

    An object is an expert (``plan(problem) -> positions``) or maps observations to
    actions (``act(observations) -> {agent: action}``).
    """
    if not isinstance(spec, (str, Path)):
        if not (callable(getattr(spec, "plan", None)) or callable(getattr(spec, "act", None))):
            raise TypeError(
                f"a policy needs plan(problem) or act(observations), got {type(spec).__name__}"
            )
        return spec
    name = str(spec)
    if name.lower() in EXPERT_NAMES:
        from activetrack.baselines import policies

        return {
            "gsr": policies.GSRPolicy,
            "gsr-restarts": lambda: policies.GSRPolicy(restarts=True),
            "gbes": policies.GBESPolicy,
            "rm": policies.RMPolicy,
            # It plans from the prediction each problem carries, for any scenario (the
            # scenario, here the matching preset, serves problems without one only).
            "lookahead": lambda: policies.LookaheadPolicy(scenario=None),
            # The IMM's first mode's prediction alone (maneuvering's constant velocity).
            "gsr-single-model": lambda: policies.GSRPolicy(prediction=0),
            "lookahead-single-model": lambda: policies.LookaheadPolicy(scenario=None, prediction=0),
            # Each robot on its own estimate, inside its connected group (issue 37).
            "distributed-gsr": policies.DistributedGSRPolicy,
            "distributed-lookahead": policies.DistributedLookaheadPolicy,
        }[name.lower()]()
    path = Path(name)
    if not path.exists() and (path.suffix or len(path.parts) > 1):  # meant as a file
        raise ValueError(f"{name}: no such policy file")
    if not path.is_file():
        raise ValueError(
            f"unknown policy {name!r}: use one of {list(EXPERT_NAMES)} or the path of a "
            "policy.zip written by 'activetrack train'"
        )
    return policy_loader(path)(path)


def policy_loaders() -> dict[str, importlib.metadata.EntryPoint]:
    """Return the installed policy file loaders, ``{suffix: entry point}``
    (:data:`POLICY_LOADERS`; not yet imported)."""
    found = importlib.metadata.entry_points(group=POLICY_LOADERS)
    return {ep.name.lower(): ep for ep in found}


def policy_loader(path: Path) -> Any:
    """Return the function that loads the policy file ``path`` (by its suffix).

    Raises ``ValueError`` when no installed loader takes the suffix, ``ImportError``
    (naming the loader) when the loader's module cannot be imported.
    """
    suffix = path.suffix.lower().removeprefix(".")
    loaders = policy_loaders()
    if suffix not in loaders:
        # None at all: an install made before the group existed (reinstall registers it).
        known = ", ".join(f".{s}" for s in sorted(loaders)) or "none; reinstall activetrack"
        what = f"'.{suffix}' files" if suffix else "files without a suffix"
        raise ValueError(
            f"{path}: no policy loader for {what} (installed: {known}; loaders register "
            f"under the entry-point group {POLICY_LOADERS!r})"
        )
    entry = loaders[suffix]
    try:
        return entry.load()
    except ImportError as exc:
        # Our loaders' own errors that already say what to install keep their word.
        ours = entry.value.startswith("activetrack.train") and "pip install" not in str(exc)
        hint = "; the train layer needs the [rl] extra: pip install 'activetrack[rl]'"
        raise ImportError(
            f"{path}: its loader {entry.value} cannot be imported ({exc}){hint if ours else ''}"
        ) from exc


def check_compatible(policy: Any, env: Any, label: str) -> None:
    """Raise ValueError if a learned policy's observation size does not fit ``env``."""
    meta = getattr(policy, "meta", None)
    if not meta or "observation_space" not in meta:
        return
    size = int(np.prod(meta["observation_space"]["shape"]))
    per_agent = env.observation_space(env.possible_agents[0]).shape[0]
    expected = per_agent * (env.n_sensors if meta.get("view") == "centralized" else 1)
    if size != expected:
        raise ValueError(
            f"{label}: trained on observations of size {size}, this scenario has {expected} "
            f"(trained on scenario {meta.get('scenario', {}).get('name')!r})"
        )
