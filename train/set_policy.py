"""A permutation-invariant policy for decentralized teams of any size, trained by imitation
of distributed GSR (issue 37).

A decentralized agent's observation (the scenario field ``team_observation``;
:mod:`activetrack.world.team_observation`) is its own part (its K target blocks and its
sensor block), ``M - 1`` neighbour blocks (a mask, then the sender's sensor block and its
predicted target positions; zeros when nothing was received) and its own tail. The
network reads the neighbour blocks as a *set*:

- each block is encoded by one MLP ``phi`` (shared by the blocks);
- the encodings are pooled with the mask: their masked mean and masked maximum, and one
  attention read-out whose query comes from the agent's own part (a masked softmax over
  the received blocks);
- a head MLP maps the own part's encoding and the pooled set to the mean action, saturated
  radially per sensor as :func:`activetrack.train.networks.saturate` does.

Every pooling is symmetric in the blocks and ignores the masked ones, so the output does
not depend on the neighbours' order or number: a network trained on teams of 4 runs
unchanged on teams of 32 (the observation's length tells ``M``).

:func:`train_set_dagger` trains it by DAgger on the expert's labels (the actions that
reach the expert's positions; :func:`activetrack.train.imitation.rollout_labels_batched`),
:class:`SetPolicy` is the trained policy (``act(observations)``, for ``activetrack
evaluate``), saved with :func:`save_set_policy` in a ``policy.zip`` that
:func:`activetrack.train.policy_io.load_policy` reads back.
"""

from __future__ import annotations

import io
import json
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import torch
from torch import nn

from activetrack.train.networks import saturate
from activetrack.train.utils import check_float, check_int

#: The ``network`` entry of a set policy's ``meta.json``.
NETWORK = "set"
#: Largest hidden width accepted (files and arguments alike).
MAX_HIDDEN = 1024


@dataclass(frozen=True)
class SetLayout:
    """Where the parts of a decentralized observation are: ``own`` entries, neighbour blocks
    of ``block`` entries (the mask first), then ``tail`` entries
    (:func:`activetrack.world.team_observation.sizes`)."""

    own: int
    block: int
    tail: int

    def __post_init__(self) -> None:
        for name in ("own", "block", "tail"):
            object.__setattr__(self, name, check_int(name, getattr(self, name), 0, 1 << 20))
        if self.own < 1 or self.block < 2:
            raise ValueError(f"own must be >= 1 and block >= 2, got {self.own}, {self.block}")

    @classmethod
    def of_world(cls, world: Any) -> SetLayout:
        """Return the layout of ``world``'s decentralized observation."""
        from activetrack.world import team_observation

        own, block, tail, _ = team_observation.sizes(world)
        return cls(own, block, tail)

    def split(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Return ``(own + tail (R, own + tail), blocks (R, M - 1, block - 1), mask (R, M -
        1))`` of observations (R, D); ValueError if D fits no team size."""
        d = obs.shape[-1]
        rest = d - self.own - self.tail
        if rest < 0 or rest % self.block:
            raise ValueError(
                f"observations of {d} entries are not own ({self.own}) + neighbour blocks of "
                f"{self.block} + tail ({self.tail})"
            )
        n = rest // self.block
        own = torch.cat([obs[:, : self.own], obs[:, d - self.tail :]], -1)
        blocks = obs[:, self.own : self.own + n * self.block].reshape(-1, n, self.block)
        return own, blocks[..., 1:], blocks[..., 0] > 0.5


def _mlp(sizes: list[int]) -> nn.Sequential:
    """Return Linear-Tanh layers through ``sizes`` (no activation after the last)."""
    layers: list[nn.Module] = []
    for a, b in zip(sizes[:-1], sizes[1:], strict=True):
        layers += [nn.Linear(a, b), nn.Tanh()]
    return nn.Sequential(*layers[:-1])


class SetPolicyNet(nn.Module):
    """The network: observations (R, D) of any team size -> mean actions (R, 2)."""

    def __init__(self, layout: SetLayout, hidden: int = 128, action_gain: float = 100.0) -> None:
        super().__init__()
        self.layout = layout
        self.hidden = check_int("hidden", hidden, 1, MAX_HIDDEN)
        self.action_gain = check_float("action_gain", action_gain, 0, low_open=True)
        h = self.hidden
        self.phi = _mlp([layout.block - 1, h, h])
        self.own = _mlp([layout.own + layout.tail, h, h])
        self.query = nn.Linear(h, h)
        self.head = _mlp([4 * h, h, h, 2])

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        own, blocks, mask = self.layout.split(obs)
        e = torch.tanh(self.own(own))  # (R, h)
        z = torch.tanh(self.phi(blocks))  # (R, n, h)
        m = mask.unsqueeze(-1).to(z.dtype)
        count = m.sum(1)
        mean = (z * m).sum(1) / count.clamp(min=1.0)
        big = torch.finfo(z.dtype).max
        top = torch.where(m > 0, z, torch.full_like(z, -big)).amax(1) if z.shape[1] else e * 0
        top = torch.where(count > 0, top, torch.zeros_like(top))
        score = (z * self.query(e).unsqueeze(1)).sum(-1) / self.hidden**0.5  # (R, n)
        score = torch.where(mask, score, torch.full_like(score, -big))
        weight = torch.softmax(score, -1) * mask if z.shape[1] else score
        attend = (weight.unsqueeze(-1) * z).sum(1)
        return saturate(self.head(torch.cat([e, mean, top, attend], -1)), self.action_gain)


class SetPolicy:
    """A trained :class:`SetPolicyNet` as a policy: ``predict`` on arrays, ``act`` on the
    parallel env's observation dicts, any team size."""

    def __init__(self, net: SetPolicyNet, meta: dict[str, Any], name: str = "set") -> None:
        self.net, self.meta, self.name = net.eval(), meta, name

    def predict(self, obs: np.ndarray) -> np.ndarray:
        """Return the deterministic actions (R, 2) for observations (R, D), in [-1, 1]."""
        with torch.no_grad():
            out = self.net(torch.as_tensor(np.asarray(obs, np.float32)))
        return out.clamp(-1.0, 1.0).numpy()

    def act(self, observations: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Return every agent's action for ``{agent: observation}``."""
        agents = list(observations)
        actions = self.predict(np.stack([observations[a] for a in agents]))
        return {a: actions[j] for j, a in enumerate(agents)}

    def __repr__(self) -> str:
        return f"SetPolicy({self.name!r}, hidden={self.net.hidden})"


def fit(
    net: SetPolicyNet,
    obs: np.ndarray,
    actions: np.ndarray,
    epochs: int,
    generator: torch.Generator,
    batch_size: int = 256,
    lr: float = 1e-3,
) -> list[float]:
    """Train ``net``'s mean action on ``(obs, actions)`` by MSE; return each epoch's mean loss."""
    x, y = torch.as_tensor(obs), torch.as_tensor(actions)
    n = len(x)
    steps = max(1, -(-n // batch_size))
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, epochs * steps, eta_min=0.1 * lr)
    net.train()
    losses = []
    for _ in range(epochs):
        perm, total = torch.randperm(n, generator=generator), 0.0
        for b in range(steps):
            idx = perm[b * batch_size : (b + 1) * batch_size]
            loss = nn.functional.mse_loss(net(x[idx]), y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(idx)
        losses.append(total / n)
    net.eval()
    return losses


@dataclass(frozen=True)
class SetDaggerConfig:
    """DAgger's budget: ``episodes`` per iteration, ``iterations`` (the first pure expert,
    then the learner acts with probability ``1 - beta``, ``beta`` halving), ``epochs`` of
    fitting on the aggregate after each, the network's ``hidden`` width."""

    episodes: int = 40
    iterations: int = 4
    epochs: int = 30
    hidden: int = 128
    lr: float = 1e-3

    def __post_init__(self) -> None:
        for name, top in (("episodes", 100_000), ("iterations", 1000), ("epochs", 100_000)):
            object.__setattr__(self, name, check_int(name, getattr(self, name), 1, top))
        object.__setattr__(self, "hidden", check_int("hidden", self.hidden, 1, MAX_HIDDEN))
        object.__setattr__(self, "lr", check_float("lr", self.lr, 0, 1, low_open=True))


def train_set_dagger(
    scenario: Any,
    overrides: dict[str, Any],
    expert: Any,
    seed: int,
    config: SetDaggerConfig = SetDaggerConfig(),
    on_iteration: Any = None,
) -> tuple[SetPolicy, list[float]]:
    """Return the set policy trained by DAgger on ``expert``'s labels in ``scenario``
    (with ``overrides``; the decentralized observation is switched on) and each
    iteration's mean trace of the episodes it ran (seeds ``seed * 100_000 + ...``,
    disjoint from the held-out 1000..1099 for seeds >= 1)."""
    from activetrack.baselines.policy_specs import resolve_policy
    from activetrack.train.imitation import rollout_labels_batched
    from activetrack.world import World

    overrides = {**overrides, "team_observation": True}
    layout = SetLayout.of_world(World(scenario, 1, **overrides))
    torch.manual_seed(seed)
    net = SetPolicyNet(layout, config.hidden)
    policy = SetPolicy(net, {})
    expert = resolve_policy(expert)
    gen = torch.Generator().manual_seed(seed)
    obs_all, act_all, traces = [], [], []
    for it in range(config.iterations):
        seeds = [seed * 100_000 + it * config.episodes + e for e in range(config.episodes)]
        learner = None if it == 0 else policy.predict
        beta = 1.0 if it == 0 else 0.5**it
        data, tr = rollout_labels_batched(scenario, overrides, expert, seeds, learner, beta)
        obs_all.append(data.obs)
        act_all.append(data.actions)
        traces.append(float(np.mean(tr)))
        fit(net, np.concatenate(obs_all), np.concatenate(act_all), config.epochs, gen, lr=config.lr)
        if on_iteration is not None:
            on_iteration(it, traces[-1])
    trained_on = {"scenario": str(scenario), "overrides": {k: str(v) for k, v in overrides.items()}}
    meta = {
        "network": NETWORK, "layout": asdict(layout), "hidden": config.hidden,
        "action_gain": net.action_gain, "seed": seed, "config": asdict(config),
        "trained_on": trained_on,
    }  # fmt: skip
    policy.meta = meta
    return policy, traces


def save_set_policy(path: Any, policy: SetPolicy) -> Any:
    """Write ``policy`` to ``path`` (a ``policy.zip``: ``meta.json`` and ``policy.pth``),
    atomically; return the path."""
    import zipfile

    from activetrack.files import atomic_path
    from activetrack.train.policy_io import FORMAT

    buf = io.BytesIO()
    torch.save({k: v.detach().cpu() for k, v in policy.net.state_dict().items()}, buf)
    meta = {"format": FORMAT, **policy.meta}
    with atomic_path(path) as tmp, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("meta.json", json.dumps(meta, indent=2, allow_nan=False))
        zf.writestr("policy.pth", buf.getvalue())
    return path


def parameter_count(layout: SetLayout, hidden: int) -> int:
    """Return the number of parameters of ``SetPolicyNet(layout, hidden)`` (computed, not
    built: a file's sizes are checked before anything is allocated)."""
    h = hidden
    phi = (layout.block - 1) * h + h + h * h + h
    own = (layout.own + layout.tail) * h + h + h * h + h
    return phi + own + (h * h + h) + (4 * h * h + h) + (h * h + h) + (2 * h + 2)


def net_from_meta(meta: dict[str, Any], max_parameters: int) -> SetPolicyNet:
    """Return the untrained network a set policy's ``meta.json`` describes (ValueError if
    it is malformed or has more than ``max_parameters`` parameters)."""
    lay = meta.get("layout")
    if not isinstance(lay, dict) or set(lay) != {"own", "block", "tail"}:
        raise ValueError("layout must be an object with own, block and tail")
    layout = SetLayout(**lay)
    hidden = check_int("hidden", meta.get("hidden"), 1, MAX_HIDDEN)
    numel = parameter_count(layout, hidden)
    if numel > max_parameters:
        raise ValueError(f"the network has {numel} parameters, more than {max_parameters}")
    return SetPolicyNet(layout, hidden, meta.get("action_gain"))
