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

A policy trained on position targets (:mod:`activetrack.train.action_targets`) saves its
team's kinematics as ``action_target`` in ``meta.json``; the loaded policy turns the
network's outputs into the env's commands (:meth:`LearnedPolicy.predict`), so it acts in
the env's action space like any other.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
import zlib
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.policies import ActorCriticPolicy

from activetrack.files import atomic_path
from activetrack.train.action_targets import PositionActions
from activetrack.train.networks import LOG_STD_RANGE, NetConfig, build_policy

FORMAT = "activetrack-policy/1"
VIEWS = ("shared", "centralized")
#: Limits checked before reading a policy file: meta.json's size, the observation and
#: action sizes, and the network's parameter count.
MAX_META_BYTES = 16_000_000
MAX_SPACE_SIZE = 65_536
MAX_PARAMETERS = 50_000_000


def _box_to_dict(space: gym.spaces.Box) -> dict[str, Any]:
    """Return the Box as standard JSON values (an infinite bound is null: unbounded)."""

    def finite(v: np.ndarray) -> list[float | None]:
        return [x if math.isfinite(x) else None for x in v.tolist()]

    return {
        "low": finite(space.low),
        "high": finite(space.high),
        "shape": list(space.shape),
        "dtype": str(space.dtype),
    }


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
    head: PositionActions | None = None,
) -> Path:
    """Write ``policy`` and its metadata to the single file ``path``; return the path.

    ``head``: the position targets the network predicts (shared view only), None when its
    outputs are the env's actions.

    The file is written to a temporary file beside ``path`` and renamed into place, so a
    failed write leaves the previous file.
    """
    if view not in VIEWS:
        raise ValueError(f"view must be one of {VIEWS}, got {view!r}")
    if head is not None and view != "shared":
        raise ValueError("position targets need the shared view (one sensor a row)")
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
        **({} if head is None else {"action_target": head.to_dict()}),
        "versions": {"torch": torch.__version__, "numpy": np.__version__},
    }
    buf = io.BytesIO()
    torch.save({k: v.detach().cpu() for k, v in policy.state_dict().items()}, buf)
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("meta.json", json.dumps(meta, indent=2, default=str, allow_nan=False))
        zf.writestr("policy.pth", buf.getvalue())
    return path


class LearnedPolicy:
    """A trained network as a policy: ``predict(obs)`` on arrays, ``act(observations)`` on dicts.

    Attributes:
        policy: the SB3 ``ActorCriticPolicy`` (eval mode, CPU).
        meta: the metadata saved with it (kind, scenario, seed, training budget...).
        name: a label for tables (defaults to the file name).
        head: the position targets the network predicts (None: it predicts the actions).
    """

    def __init__(
        self,
        policy: ActorCriticPolicy,
        meta: dict[str, Any],
        name: str = "learned",
        head: PositionActions | None = None,
    ):
        self.policy = policy.eval()
        self.meta = meta
        self.name = name
        self.head = head

    @property
    def view(self) -> str:
        """Return ``"shared"`` or ``"centralized"``."""
        return self.meta.get("view", "shared")

    def predict(self, obs: np.ndarray) -> np.ndarray:
        """Return deterministic actions (N, A) for observations (N, D), clipped to the box;
        with position targets, the commands that reach the network's points (row ``i`` is
        sensor ``i mod M``: a team's rows, copy after copy)."""
        actions, _ = self.policy.predict(np.asarray(obs, dtype=np.float32), deterministic=True)
        if self.head is not None:
            return self.head.actions(actions).astype(np.float32)
        return actions

    def act_batch(self, observations: np.ndarray) -> np.ndarray:
        """Return the actions (N, M, A) of N teams' observations (N, M, D) in one forward
        pass (a batched world's :meth:`~activetrack.world.World.observe`)."""
        obs = np.asarray(observations, dtype=np.float32)
        if obs.ndim != 3:
            raise ValueError(f"act_batch needs observations (N, M, D), got shape {obs.shape}")
        n, m = obs.shape[:2]
        if self.head is not None and m != self.head.n_sensors:
            raise ValueError(
                f"this policy steers a team of {self.head.n_sensors} sensors, got {m} agents"
            )
        rows = obs.reshape(n * m, -1) if self.view == "shared" else obs.reshape(n, -1)
        return self.predict(rows).reshape(n, m, -1)

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Return every agent's action for the parallel env's observations ``{agent: obs}``."""
        agents = list(observations)
        stacked = np.stack([observations[a] for a in agents])
        if self.head is not None and len(agents) != self.head.n_sensors:
            raise ValueError(
                f"this policy steers a team of {self.head.n_sensors} sensors, got "
                f"{len(agents)} agents' observations"
            )
        if self.view == "shared":
            actions = self.predict(stacked)
        else:
            actions = self.predict(stacked.reshape(1, -1)).reshape(len(agents), -1)
        return {a: actions[j] for j, a in enumerate(agents)}

    def __repr__(self) -> str:
        return f"LearnedPolicy({self.name!r}, kind={self.meta.get('kind')!r}, view={self.view!r})"


def load_policy(path: str | Path) -> LearnedPolicy:
    """Return the :class:`LearnedPolicy` saved at ``path`` by :func:`save_policy`.

    Raises ``ValueError("<path>: <problem>")`` for any file that is not one: unreadable,
    not a zip, a member missing or too large, ``meta.json`` malformed (types, spaces,
    network sizes), ``policy.pth`` not a state dict of exactly the network ``meta.json``
    describes, or non-finite weights. Sizes are checked before anything is allocated.
    """
    path = Path(path)
    try:
        return _load_policy(path)
    except _PolicyFileError as exc:
        raise ValueError(f"{path}: {exc}") from exc.__cause__
    except Exception as exc:  # a crafted file found a failure no check above names
        first = (str(exc).strip().splitlines() or [""])[0][:200]
        raise ValueError(f"{path}: cannot be loaded ({type(exc).__name__}: {first})") from exc


class _PolicyFileError(Exception):
    """A problem with a policy file (turned into ``ValueError("<path>: <problem>")``)."""


def _member(zf: zipfile.ZipFile, name: str, max_bytes: int) -> bytes:
    """Return the member ``name`` of ``zf`` after checking its declared size."""
    try:
        info = zf.getinfo(name)
    except KeyError:
        raise _PolicyFileError(f"missing member {name!r} (has {zf.namelist()[:10]})") from None
    if info.file_size > max_bytes:
        raise _PolicyFileError(
            f"member {name!r} is {info.file_size} bytes, more than the {max_bytes} expected"
        )
    try:
        return zf.read(info)
    except (
        zipfile.BadZipFile,
        zipfile.LargeZipFile,
        zlib.error,  # a corrupt deflate stream
        OSError,
        EOFError,
        ValueError,
    ) as exc:
        raise _PolicyFileError(f"member {name!r} is corrupt ({exc})") from exc
    except (RuntimeError, NotImplementedError) as exc:  # encrypted, unknown compression
        raise _PolicyFileError(f"member {name!r} cannot be read ({exc})") from exc


def _load_policy(path: Path) -> LearnedPolicy:
    if not path.is_file():
        raise _PolicyFileError("no such file")
    try:
        zf = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, ValueError) as exc:
        raise _PolicyFileError(f"not a policy.zip (not a readable zip file: {exc})") from exc
    with zf:
        try:
            meta = json.loads(_member(zf, "meta.json", MAX_META_BYTES))
        except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
            raise _PolicyFileError(f"meta.json is not valid JSON ({exc})") from exc
        if isinstance(meta, dict) and meta.get("network") == "set":  # a team-size-free net
            return _load_set_policy(zf, meta, path)
        obs_space, act_space, net = _check_meta(meta)
        head = None
        if "action_target" in meta:
            try:
                head = PositionActions.from_dict(meta["action_target"])
            except (TypeError, ValueError) as exc:
                raise _PolicyFileError(f"meta.json: {exc}") from exc
            if meta.get("view", "shared") != "shared" or act_space.shape != (2,):
                raise _PolicyFileError(
                    "meta.json: position targets need the shared view and 2 actions"
                )
        shapes = net.expected_state_shapes(obs_space.shape[0], act_space.shape[0])
        numel = sum(math.prod(s) for s in shapes.values())
        if numel > MAX_PARAMETERS:
            raise _PolicyFileError(
                f"the network has {numel} parameters, more than {MAX_PARAMETERS}"
            )
        # float32 weights plus the pickle and zip structure of torch.save.
        raw = _member(zf, "policy.pth", 8 * numel + 1_000_000)
    try:
        state = torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a corrupt file
        # The unpickler's own reason, not torch's advice to load the file unsafely.
        _, found, rest = str(exc).partition("Unpickler error:")
        lines = [line.strip() for line in (rest if found else str(exc)).splitlines()]
        reason = next((line for line in lines if line), type(exc).__name__).split(". ")[0]
        raise _PolicyFileError(f"policy.pth is not a torch state dict ({reason[:200]})") from exc
    _check_state(state, shapes)
    policy = build_policy(obs_space, act_space, net)
    policy.load_state_dict(state)
    return LearnedPolicy(policy, meta, name=path.name, head=head)


def _load_set_policy(zf: zipfile.ZipFile, meta: dict, path: Path) -> Any:
    """Return the :class:`~activetrack.train.set_policy.SetPolicy` of a policy file whose
    ``meta.json`` says ``"network": "set"``, every size checked before allocating."""
    from activetrack.train import set_policy

    if meta.get("format") != FORMAT:
        raise _PolicyFileError(f"not an activetrack policy file (format {meta.get('format')!r})")
    try:
        net = set_policy.net_from_meta(meta, MAX_PARAMETERS)
    except (TypeError, ValueError) as exc:
        raise _PolicyFileError(f"meta.json: {exc}") from exc
    shapes = {k: tuple(v.shape) for k, v in net.state_dict().items()}
    numel = sum(math.prod(s) for s in shapes.values())
    raw = _member(zf, "policy.pth", 8 * numel + 1_000_000)
    try:
        state = torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many types for a corrupt file
        raise _PolicyFileError(
            f"policy.pth is not a torch state dict ({type(exc).__name__})"
        ) from exc
    _check_state(state, shapes)
    net.load_state_dict(state)
    return set_policy.SetPolicy(net, meta, name=path.name)


def _check_meta(meta: Any) -> tuple[gym.spaces.Box, gym.spaces.Box, NetConfig]:
    """Return the spaces and network of a policy file's metadata after checking them."""
    if not isinstance(meta, dict):
        raise _PolicyFileError(f"meta.json must hold a JSON object, got {type(meta).__name__}")
    if meta.get("format") != FORMAT:
        raise _PolicyFileError(f"not an activetrack policy file (format {meta.get('format')!r})")
    for key in ("net", "observation_space", "action_space"):
        if key not in meta:
            raise _PolicyFileError(f"meta.json has no {key!r}")
    if meta.get("view", "shared") not in VIEWS:
        raise _PolicyFileError(f"meta.json: view must be one of {VIEWS}, got {meta['view']!r}")
    if not isinstance(meta.get("scenario", {}), dict):
        raise _PolicyFileError("meta.json: scenario must be a JSON object")
    obs_space = _space_from_meta(meta["observation_space"], "observation_space")
    act_space = _space_from_meta(meta["action_space"], "action_space")
    try:
        net = NetConfig.from_dict(meta["net"])
    except (TypeError, ValueError) as exc:
        raise _PolicyFileError(f"meta.json: net: {exc}") from exc
    if net.action_gain is not None and act_space.shape[0] % 2:
        raise _PolicyFileError("meta.json: a saturated mean needs an even action size")
    return obs_space, act_space, net


def _space_from_meta(d: Any, key: str) -> gym.spaces.Box:
    """Return the flat float Box saved by :func:`_box_to_dict` under ``key``, checked."""
    where = f"meta.json: {key}"
    if not isinstance(d, dict) or not {"low", "high", "shape", "dtype"} <= d.keys():
        raise _PolicyFileError(f"{where} must be an object with low, high, shape and dtype")
    shape = d["shape"]
    if (
        not isinstance(shape, list)
        or len(shape) != 1
        or not isinstance(shape[0], int)
        or isinstance(shape[0], bool)
        or not 1 <= shape[0] <= MAX_SPACE_SIZE
    ):
        raise _PolicyFileError(
            f"{where}: shape must be [n] with 1 <= n <= {MAX_SPACE_SIZE}, got {shape!r}"
        )
    if d["dtype"] not in ("float32", "float64"):
        raise _PolicyFileError(f"{where}: dtype must be float32 or float64, got {d['dtype']!r}")
    bounds = []
    for name, unbounded in (("low", -math.inf), ("high", math.inf)):
        v = d[name]
        if isinstance(v, list):  # null: unbounded (files written before also hold Infinity)
            v = [unbounded if x is None else x for x in v]
        if (
            not isinstance(v, list)
            or len(v) != shape[0]
            or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
        ):
            raise _PolicyFileError(
                f"{where}: {name} must be a list of {shape[0]} numbers (null: unbounded)"
            )
        try:  # float() first: an integer too large for a float is out of range, not inf
            values = [float(x) for x in v]
            bounds.append(np.asarray(values, dtype=d["dtype"]))
        except (OverflowError, ValueError) as exc:
            raise _PolicyFileError(f"{where}: {name} is out of range ({exc})") from exc
        if np.isnan(bounds[-1]).any():
            raise _PolicyFileError(
                f"{where}: {name} must be a list of {shape[0]} numbers (null: unbounded)"
            )
    if np.any(bounds[0] > bounds[1]):
        raise _PolicyFileError(f"{where}: low must not exceed high")
    return gym.spaces.Box(bounds[0], bounds[1], dtype=np.dtype(d["dtype"]))


def _check_state(state: Any, shapes: dict[str, tuple[int, ...]]) -> None:
    """Check that ``state`` holds exactly the finite float tensors of the given shapes."""
    if not isinstance(state, dict):
        raise _PolicyFileError(f"policy.pth must hold a state dict, got {type(state).__name__}")
    missing = sorted(set(shapes) - set(state))
    extra = sorted(set(state) - set(shapes), key=str)
    if missing or extra:
        raise _PolicyFileError(
            "policy.pth does not match the network of meta.json "
            f"(missing {missing[:5]}, unexpected {extra[:5]})"
        )
    for key, want in shapes.items():
        t = state[key]
        if not isinstance(t, torch.Tensor) or not t.is_floating_point():
            raise _PolicyFileError(f"policy.pth: {key} is not a float tensor")
        # Only dense CPU tensors have values to check (a sparse or meta tensor has none
        # that torch.isfinite can read).
        if t.layout != torch.strided or t.device.type != "cpu":
            raise _PolicyFileError(
                f"policy.pth: {key} must be a dense CPU tensor, got layout {t.layout} on "
                f"device {t.device.type!r}"
            )
        if tuple(t.shape) != want:
            raise _PolicyFileError(
                f"policy.pth: {key} has shape {tuple(t.shape)}, the network of meta.json "
                f"needs {want}"
            )
        if not bool(torch.isfinite(t).all()):
            raise _PolicyFileError(f"policy.pth: {key} holds NaN or infinite weights")
        low, high = LOG_STD_RANGE  # the network's own range (its log_std_init's)
        if key == "log_std" and not bool(((t >= low) & (t <= high)).all()):
            raise _PolicyFileError(
                f"policy.pth: log_std must be in [{low:g}, {high:g}], got "
                f"{t.min().item():g}..{t.max().item():g}"
            )
