"""The line-of-sight frame: a policy that is equivariant to rotations of the plane.

The paper's loop (eq. 1-16) has no preferred direction: rotate every position, velocity and
covariance about the predicted target and the best moves rotate with them (the cost of
eq. 17 depends on the geometry only through distances and the angles between sensors, the
prediction's velocity and its covariance's axes). A network that sees the world frame must
learn this symmetry from data, once for every heading; one that sees each agent's own
frame gets it for free.

:class:`SightFrame` is that frame as an SB3 features extractor on the paper's observation
layout (:mod:`activetrack.world.observation`, ``5 + 6M`` entries): the agent's
line of sight ``c_i`` (its own position relative to the predicted target, entries 5-6) is
the frame's first axis ``e1 = c_i / |c_i|``, ``e2`` is ``e1`` turned by +90 degrees, and
``R = [e1 e2]``. Every vector of the observation (the predicted velocity, each sensor's
``c_j``) becomes ``R^T v`` and the predicted position covariance ``P`` becomes
``R^T P R``, re-encoded as the layout's ``ln sigma_x, ln sigma_y, corr``. The network's
move ``a'`` is turned back into the world frame, ``a = R a'``
(:meth:`activetrack.train.networks.TrackingPolicy.action_mean`). The map from the
observation to the mean (deterministic) action is then exactly rotation-equivariant
(tests/train/test_frames.py rotates whole worlds and compares): the policy that BC, DAgger,
``train pathwise`` and ``evaluate`` use. PPO's exploration noise keeps one standard
deviation per world axis, so its sampled actions are equivariant only while the two are
equal (as they start).

:func:`check_frame` is the check every trainer makes before it builds a network: the frame
reads the paper's observation layout only, which a size alone does not identify.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

#: The frames a :class:`~activetrack.train.networks.NetConfig` may name.
FRAMES = ("world", "sight")
#: Smallest variance (in L^2) of the covariance in the frame: a standard deviation of 1e-6 L.
_VAR_FLOOR = 1e-12


def check_paper_layout(dim: int) -> int:
    """Return the team size ``M`` of a paper-layout observation of ``dim`` entries
    (``5 + 6M``), or raise ValueError: the line-of-sight frame reads that layout only."""
    if dim < 11 or (dim - 5) % 6:
        raise ValueError(
            "frame 'sight' needs the paper's observation layout (5 + 6M entries: one target,"
            f" range-and-bearing sensors, shared view), got {dim} entries"
        )
    return (dim - 5) // 6


def check_frame(frame: str, scenario: Any, **overrides: Any) -> None:
    """Raise ValueError unless a network of frame ``frame`` can read the observations of
    ``scenario`` (a preset name or a Scenario, with the scenario field ``overrides``):
    ``"sight"`` needs the paper's layout with nothing appended (no kinematic features,
    rays, route readings or flags)."""
    if frame != "sight":
        return
    from activetrack.world.observation import layout_of
    from activetrack.world.scenarios import make_scenario

    sc = make_scenario(scenario, **overrides)
    layout = layout_of(sc)
    extra = layout.flags + layout.rays + layout.motion + layout.route + layout.tracks
    if layout.extended or extra:
        raise ValueError(
            "frame 'sight' needs the paper's observation layout (one target, range-and-bearing"
            f" sensors at known positions, nothing appended); scenario {sc.name!r} has "
            + ("the extended layout" if layout.extended else f"{extra} appended entries")
        )


def sight_rotation(obs: torch.Tensor) -> torch.Tensor:
    """Return ``R = [e1 e2]`` (rows, 2, 2) of each observation row: ``e1`` along the agent's
    line of sight (entries 5-6), ``e2`` a quarter turn counter-clockwise from it; the
    identity where the line of sight has no direction (the agent on the prediction)."""
    c = obs[:, 5:7]
    # |c_i| >= rho > 0 after every move (eq. 14); a zero c has no frame: the world's.
    norm = torch.linalg.vector_norm(c, dim=-1, keepdim=True)
    degenerate = norm < 1e-9
    world_x = torch.tensor([1.0, 0.0], dtype=obs.dtype)
    e1 = torch.where(degenerate, world_x, c / norm.clamp_min(1e-9))
    e2 = torch.stack([-e1[:, 1], e1[:, 0]], -1)
    return torch.stack([e1, e2], -1)


def to_frame(obs: torch.Tensor, rotation: torch.Tensor) -> torch.Tensor:
    """Return the observations (rows, 5 + 6M) with every vector and the covariance
    expressed in the frames ``rotation`` (rows, 2, 2) (see the module docstring)."""
    m = check_paper_layout(obs.shape[-1])
    sx, sy, corr = obs[:, 0].exp(), obs[:, 1].exp(), obs[:, 2]
    cov = torch.stack([sx * sx, corr * sx * sy, corr * sx * sy, sy * sy], -1).reshape(-1, 2, 2)
    cov = rotation.transpose(1, 2) @ cov @ rotation
    # A correlation of +-1 (a rounded or clipped input) makes P singular, and a frame axis
    # along its null direction would have a zero variance: floored, so the log is finite.
    vx, vy = cov[:, 0, 0].clamp_min(_VAR_FLOOR), cov[:, 1, 1].clamp_min(_VAR_FLOOR)
    corr = (cov[:, 0, 1] / (vx * vy).sqrt()).clamp(-1.0, 1.0)
    target = torch.stack([0.5 * vx.log(), 0.5 * vy.log(), corr], -1)
    velocity = (obs[:, None, 3:5] @ rotation)[:, 0]  # v^T R = (R^T v)^T
    seats = obs[:, 5:].reshape(-1, m, 6)
    positions = seats[..., :2] @ rotation  # each row c_j^T R
    seats = torch.cat([positions, seats[..., 2:]], -1).reshape(obs.shape[0], 6 * m)
    return torch.cat([target, velocity, seats], -1)


def from_frame(actions: torch.Tensor, rotation: torch.Tensor) -> torch.Tensor:
    """Return the world-frame moves ``R a'`` of moves ``actions`` (rows, 2) in the frames
    ``rotation``."""
    return (rotation @ actions[..., None])[..., 0]


class SightFrame(BaseFeaturesExtractor):
    """SB3 features extractor: the observation in each agent's line-of-sight frame.

    The frames of the last batch it saw stay in :attr:`rotation` for the action head,
    which turns the network's moves back into the world frame. Every SB3 path (``forward``,
    ``evaluate_actions``, ``get_distribution``, ``predict``) calls the extractor on a batch
    immediately before building that batch's action distribution, so the head always sees
    the frames of its own observations.
    """

    def __init__(self, observation_space: gym.spaces.Box) -> None:
        dim = int(observation_space.shape[0])
        check_paper_layout(dim)
        super().__init__(observation_space, features_dim=dim)
        self.rotation: torch.Tensor | None = None

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        obs = observations.reshape(observations.shape[0], -1)
        # The frame is computed in float64: observations are float32 in SB3, and the
        # covariance's re-encoding divides by small variances.
        rotation = sight_rotation(obs.double())
        self.rotation = rotation.to(obs.dtype)
        return to_frame(obs.double(), rotation).to(obs.dtype)


__all__ = [
    "FRAMES",
    "SightFrame",
    "check_frame",
    "check_paper_layout",
    "from_frame",
    "sight_rotation",
    "to_frame",
]
