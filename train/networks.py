"""The policy network: an SB3 ``ActorCriticPolicy`` (MLP, tanh) shared by BC, DAgger and PPO.

Imitation trains this very class, so a behaviour-cloned network drops into
``PPO(TrackingPolicy, ...).policy`` by ``load_state_dict`` and PPO fine-tunes it.

The action head. GSR moves a sensor at full speed almost always (the sensors are no faster
than the target and fall behind). A linear Gaussian mean fitted by least squares shrinks
wherever the expert's direction is ambiguous (two nearly equally good directions average
to a short vector), so the cloned sensors slow down and lose ground for good (the README
gives the cost). :class:`TrackingPolicy` therefore saturates the mean radially, per sensor:
``s(m) = m / max(|m|, 1/K)`` is the unit vector of ``m`` outside the small ball
``|m| < 1/K`` and ``K m`` inside it (so a sensor can still slow down or stop). The
Gaussian, PPO's sampling and the deterministic action all use ``s(m)``, which lies in the
unit disk, so SB3's clipping to the box never bends it. ``action_gain=None`` restores
SB3's plain linear mean.

The frame. ``frame="sight"`` gives the network each agent's observation in its own
line-of-sight frame and turns its move back (:mod:`activetrack.train.frames`): the mean
action is then exactly equivariant to rotations of the plane, as the paper's loop is.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import Any

import gymnasium as gym
import torch
from stable_baselines3.common.policies import ActorCriticPolicy
from torch import nn

from activetrack.train.frames import FRAMES, SightFrame, from_frame
from activetrack.train.utils import check_bool, check_choice, check_float, check_int

ACTIVATIONS: dict[str, type[nn.Module]] = {"tanh": nn.Tanh, "relu": nn.ReLU, "elu": nn.ELU}
#: Largest hidden layer and most hidden layers accepted (files and command line alike).
MAX_UNITS, MAX_LAYERS = 4096, 8
#: Accepted range of the initial log standard deviation.
LOG_STD_RANGE = (-20.0, 5.0)


@dataclass(frozen=True)
class NetConfig:
    """Architecture of the actor-critic MLP.

    Every field is checked on construction (ValueError naming it): at most
    :data:`MAX_LAYERS` hidden layers of 1 to :data:`MAX_UNITS` units, a finite
    ``log_std_init`` in :data:`LOG_STD_RANGE`, ``action_gain`` > 0 or None.

    Attributes:
        hidden: hidden layer sizes, the same for the actor and the critic (separate nets).
        activation: one of :data:`ACTIVATIONS`.
        log_std_init: initial log standard deviation of the Gaussian actions. The action box
            is [-1, 1], so SB3's default 0 (std 1) is mostly noise; -1 (std 0.37) explores
            without drowning a warm-started policy.
        ortho_init: SB3's orthogonal initialization.
        action_gain: the saturation gain K of the mean action (see the module docstring);
            None for SB3's linear mean.
        frame: ``"world"`` (the observation as the env gives it) or ``"sight"`` (each
            agent's line-of-sight frame, :mod:`activetrack.train.frames`: the paper's
            observation layout and the shared view only).
    """

    hidden: tuple[int, ...] = (256, 256)
    activation: str = "tanh"
    log_std_init: float = -1.0
    ortho_init: bool = True
    action_gain: float | None = 100.0
    frame: str = "world"

    def __post_init__(self) -> None:
        hidden = self.hidden
        if isinstance(hidden, (str, bytes)) or not hasattr(hidden, "__iter__"):
            raise ValueError(f"hidden must be a sequence of layer sizes, got {hidden!r}")
        hidden = tuple(hidden)
        if len(hidden) > MAX_LAYERS:
            raise ValueError(f"hidden must have at most {MAX_LAYERS} layers, got {len(hidden)}")
        hidden = tuple(check_int("hidden", h, 1, MAX_UNITS) for h in hidden)
        set_ = object.__setattr__  # frozen: store the converted values
        set_(self, "hidden", hidden)
        set_(self, "activation", check_choice("activation", self.activation, sorted(ACTIVATIONS)))
        set_(self, "log_std_init", check_float("log_std_init", self.log_std_init, *LOG_STD_RANGE))
        set_(self, "ortho_init", check_bool("ortho_init", self.ortho_init))
        if self.action_gain is not None:
            gain = check_float("action_gain", self.action_gain, 0, low_open=True)
            set_(self, "action_gain", gain)
        set_(self, "frame", check_choice("frame", self.frame, FRAMES))

    def policy_kwargs(self) -> dict[str, Any]:
        """Return the ``policy_kwargs`` of ``PPO("MlpPolicy", ...)`` for this architecture."""
        return {
            "net_arch": {"pi": list(self.hidden), "vf": list(self.hidden)},
            "activation_fn": ACTIVATIONS[self.activation],
            "log_std_init": self.log_std_init,
            "ortho_init": self.ortho_init,
            "action_gain": self.action_gain,
            "frame": self.frame,
        }

    def to_dict(self) -> dict[str, Any]:
        """Return the configuration as JSON-friendly values."""
        d = asdict(self)
        d["hidden"] = list(self.hidden)
        return d

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> NetConfig:
        """Return the configuration saved by :meth:`to_dict` (ValueError if it is malformed)."""
        if not isinstance(d, dict):
            raise ValueError(f"a network configuration must be a JSON object, got {d!r}")
        unknown = sorted(set(d) - {f.name for f in fields(cls)})
        if unknown:
            raise ValueError(f"unknown network configuration fields {unknown}")
        return cls(**d)

    @classmethod
    def coerce(cls, value: Any) -> NetConfig:
        """Return ``value`` as a NetConfig (a dict is read by :meth:`from_dict`), or raise
        ValueError naming the field ``net``: the check every training config shares."""
        if isinstance(value, dict):
            value = cls.from_dict(value)
        if not isinstance(value, cls):
            raise ValueError(f"net must be a NetConfig, got {value!r}")
        return value

    def expected_state_shapes(self, obs_dim: int, act_dim: int) -> dict[str, tuple[int, ...]]:
        """Return the shape of every entry of :func:`build_policy`'s state dict, by key.

        Computed without building the network (SB3's MLP: ``Linear`` layers at even
        indices of ``policy_net``/``value_net``, activations between them), so a policy
        file can be checked before anything is allocated.
        """
        shapes: dict[str, tuple[int, ...]] = {"log_std": (act_dim,)}
        for branch in ("policy_net", "value_net"):
            last = obs_dim
            for i, h in enumerate(self.hidden):
                shapes[f"mlp_extractor.{branch}.{2 * i}.weight"] = (h, last)
                shapes[f"mlp_extractor.{branch}.{2 * i}.bias"] = (h,)
                last = h
        last = self.hidden[-1] if self.hidden else obs_dim
        shapes["action_net.weight"] = (act_dim, last)
        shapes["action_net.bias"] = (act_dim,)
        shapes["value_net.weight"] = (1, last)
        shapes["value_net.bias"] = (1,)
        return shapes


DEFAULT_NET = NetConfig()


def saturate(mean: torch.Tensor, gain: float) -> torch.Tensor:
    """Return ``m / max(|m|, 1/gain)`` for each consecutive pair (a sensor's move) of ``mean``."""
    pairs = mean.reshape(*mean.shape[:-1], -1, 2)
    norm = torch.linalg.vector_norm(pairs, dim=-1, keepdim=True)
    return (pairs / norm.clamp_min(1.0 / gain)).reshape(mean.shape)


class TrackingPolicy(ActorCriticPolicy):
    """SB3 ``ActorCriticPolicy`` whose Gaussian mean is radially saturated per sensor.

    Args:
        action_gain: the gain K of :func:`saturate`; None keeps SB3's linear mean.
        *args: as for ``ActorCriticPolicy``.
        **kwargs: as for ``ActorCriticPolicy`` (no gSDE: a diagonal Gaussian).
    """

    def __init__(
        self,
        *args: Any,
        action_gain: float | None = 100.0,
        frame: str = "world",
        **kwargs: Any,
    ) -> None:
        if kwargs.get("use_sde"):
            raise ValueError("TrackingPolicy supports the diagonal Gaussian only (use_sde=False)")
        self.action_gain = action_gain
        self.frame = check_choice("frame", frame, FRAMES)
        if self.frame == "sight":
            kwargs["features_extractor_class"] = SightFrame
            kwargs["share_features_extractor"] = True  # one extractor: the head's frames
        super().__init__(*args, **kwargs)
        if action_gain is not None and self.action_space.shape[-1] % 2:
            raise ValueError("a saturated mean needs actions made of 2D moves")
        if self.frame == "sight" and self.action_space.shape != (2,):
            raise ValueError(
                f"frame 'sight' needs one sensor's move a row (shared view, 2 actions),"
                f" got actions of shape {self.action_space.shape}"
            )

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data["action_gain"] = self.action_gain
        data["frame"] = self.frame
        return data

    def action_mean(self, latent_pi: torch.Tensor) -> torch.Tensor:
        """Return the (saturated) mean action of the actor's latent features, in the world
        frame (with ``frame="sight"``: turned back from the frames of the batch the
        features extractor saw last, which is ``latent_pi``'s batch)."""
        mean = self.action_net(latent_pi)
        mean = mean if self.action_gain is None else saturate(mean, self.action_gain)
        if self.frame == "sight":
            mean = from_frame(mean, self.features_extractor.rotation)
        return mean

    def _get_action_dist_from_latent(self, latent_pi: torch.Tensor) -> Any:
        # Every SB3 path (rollouts, evaluate_actions, predict) builds its distribution here.
        return self.action_dist.proba_distribution(self.action_mean(latent_pi), self.log_std)


def build_policy(
    observation_space: gym.spaces.Box,
    action_space: gym.spaces.Box,
    net: NetConfig = DEFAULT_NET,
    lr: float = 3e-4,
) -> TrackingPolicy:
    """Return a fresh :class:`TrackingPolicy` with the architecture ``net`` (on the CPU)."""
    return TrackingPolicy(
        observation_space, action_space, lr_schedule=lambda _: lr, **net.policy_kwargs()
    )


def mean_action(policy: TrackingPolicy, obs: torch.Tensor) -> torch.Tensor:
    """Return the policy's mean action (the deterministic action) for a batch of observations.

    This is the actor path only (features -> actor MLP -> ``action_net`` -> saturation):
    the part that imitation trains and that PPO's deterministic ``predict`` uses.
    """
    features = policy.extract_features(obs, policy.pi_features_extractor)
    return policy.action_mean(policy.mlp_extractor.forward_actor(features))


def actor_parameters(policy: ActorCriticPolicy) -> list[nn.Parameter]:
    """Return the parameters that determine the mean action (the actor MLP and head)."""
    params = list(policy.mlp_extractor.policy_net.parameters())
    params += list(policy.action_net.parameters())
    # The default FlattenExtractor has no parameters; a learned one would be shared or not.
    params += list(policy.pi_features_extractor.parameters())
    return params


__all__ = [
    "ACTIVATIONS",
    "DEFAULT_NET",
    "MAX_LAYERS",
    "MAX_UNITS",
    "NetConfig",
    "TrackingPolicy",
    "actor_parameters",
    "build_policy",
    "mean_action",
    "saturate",
]
