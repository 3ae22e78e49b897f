"""Save and load a trained policy as one file (``policy.zip``) that ``evaluate`` can run.

The zip holds ``meta.json`` (format tag, how it was trained: kind, scenario, seed, budget,
network architecture, spaces, view) and ``policy.pth`` (the state dict of the SB3
``ActorCriticPolicy``). BC, DAgger and PPO all write this format, so a policy of any of
them evaluates the same way and can warm-start PPO (``activetrack train ppo --init``).

:class:`LearnedPolicy` runs the network deterministically (the clipped Gaussian mean):

- ``view="shared"`` (parameter sharing): every agent's observation goes through the one
  network and yields that agent's action;
- ``view="centralized"``: the agents' observations, concatenated in agent order (the
  centralized Gymnasium view's observation), yield the joint action, split per agent.
"""

from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.policies import ActorCriticPolicy

from activetrack.train.networks import NetConfig, build_policy

FORMAT = "activetrack-policy/1"
VIEWS = ("shared", "centralized")


def _box_to_dict(space: gym.spaces.Box) -> dict[str, Any]:
    return {
        "low": space.low.tolist(),
        "high": space.high.tolist(),
        "shape": list(space.shape),
        "dtype": str(space.dtype),
    }


def _box_from_dict(d: dict[str, Any]) -> gym.spaces.Box:
    def arr(v: list) -> np.ndarray:
        # JSON has no inf: Python's json writes/reads Infinity, keep it that way.
        return np.asarray(v, dtype=d["dtype"]).reshape(d["shape"])

    return gym.spaces.Box(arr(d["low"]), arr(d["high"]), dtype=np.dtype(d["dtype"]))


def save_policy(
    path: str | Path,
    policy: ActorCriticPolicy,
    net: NetConfig,
    *,
    kind: str,
    scenario: dict[str, Any],
    seed: int | None,
    view: str = "shared",
    train_config: dict[str, Any] | None = None,
) -> Path:
    """Write ``policy`` and its metadata to the single file ``path``; return the path."""
    if view not in VIEWS:
        raise ValueError(f"view must be one of {VIEWS}, got {view!r}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = {
        "format": FORMAT,
        "kind": kind,
        "view": view,
        "seed": seed,
        "scenario": scenario,
        "net": net.to_dict(),
        "observation_space": _box_to_dict(policy.observation_space),
        "action_space": _box_to_dict(policy.action_space),
        "train_config": train_config or {},
        "versions": {"torch": torch.__version__, "numpy": np.__version__},
    }
    buf = io.BytesIO()
    torch.save({k: v.detach().cpu() for k, v in policy.state_dict().items()}, buf)
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("meta.json", json.dumps(meta, indent=2, default=str))
        zf.writestr("policy.pth", buf.getvalue())
    return path


class LearnedPolicy:
    """A trained network as a policy: ``predict(obs)`` on arrays, ``act(observations)`` on dicts.

    Attributes:
        policy: the SB3 ``ActorCriticPolicy`` (eval mode, CPU).
        meta: the metadata saved with it (kind, scenario, seed, training budget...).
        name: a label for tables (defaults to the file name).
    """

    def __init__(self, policy: ActorCriticPolicy, meta: dict[str, Any], name: str = "learned"):
        self.policy = policy.eval()
        self.meta = meta
        self.name = name

    @property
    def view(self) -> str:
        """Return ``"shared"`` or ``"centralized"``."""
        return self.meta.get("view", "shared")

    def predict(self, obs: np.ndarray) -> np.ndarray:
        """Return deterministic actions (N, A) for observations (N, D), clipped to the box."""
        actions, _ = self.policy.predict(np.asarray(obs, dtype=np.float32), deterministic=True)
        return actions

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Return every agent's action for the parallel env's observations ``{agent: obs}``."""
        agents = list(observations)
        stacked = np.stack([observations[a] for a in agents])
        if self.view == "shared":
            actions = self.predict(stacked)
        else:
            actions = self.predict(stacked.reshape(1, -1)).reshape(len(agents), -1)
        return {a: actions[j] for j, a in enumerate(agents)}

    def __repr__(self) -> str:
        return f"LearnedPolicy({self.name!r}, kind={self.meta.get('kind')!r}, view={self.view!r})"


def load_policy(path: str | Path) -> LearnedPolicy:
    """Return the :class:`LearnedPolicy` saved at ``path`` by :func:`save_policy`."""
    path = Path(path)
    with zipfile.ZipFile(path) as zf:
        meta = json.loads(zf.read("meta.json"))
        if meta.get("format") != FORMAT:
            raise ValueError(
                f"{path}: not an activetrack policy file (format {meta.get('format')!r})"
            )
        state = torch.load(io.BytesIO(zf.read("policy.pth")), map_location="cpu", weights_only=True)
    policy = build_policy(
        _box_from_dict(meta["observation_space"]),
        _box_from_dict(meta["action_space"]),
        NetConfig.from_dict(meta["net"]),
    )
    policy.load_state_dict(state)
    return LearnedPolicy(policy, meta, name=path.name)
