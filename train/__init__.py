"""Learning to track: imitation of the GSR expert and PPO (the ``[rl]`` extra).

- :mod:`~activetrack.train.sb3_vecenv`: :class:`SharedPolicyVecEnv`, the SB3 ``VecEnv``
  over copies of the tracking game with parameter sharing (one slot per sensor);
- :mod:`~activetrack.train.networks`: :class:`TrackingPolicy`, the SB3 ``ActorCriticPolicy``
  (architecture :class:`NetConfig`) shared by every method;
- :mod:`~activetrack.train.imitation`: behaviour cloning and DAgger on GSR's labels;
- :mod:`~activetrack.train.ppo`: SB3 PPO from scratch or from an imitation warm start;
- :mod:`~activetrack.train.policy_io`: the single-file ``policy.zip`` that
  ``activetrack evaluate`` loads (:func:`save_policy`, :func:`load_policy`);
- :mod:`~activetrack.train.utils`: one torch thread by default, seeding.

Example (BC on 40 GSR episodes, about 20 s on two CPU cores)::

    from activetrack.baselines.evaluation import evaluate
    from activetrack.train import ImitationConfig, load_policy, save_policy, train_imitation

    cfg = ImitationConfig(episodes=40, epochs=60)
    result = train_imitation("paper", seed=0, config=cfg)
    save_policy("bc/policy.zip", result.policy, cfg.net, kind="bc", scenario={}, seed=0)
    evaluate({"bc": load_policy("bc/policy.zip")}, "paper", episodes=20, seed=1000)
"""

from activetrack.train.imitation import ImitationConfig, ImitationResult, train_imitation
from activetrack.train.networks import NetConfig, TrackingPolicy, build_policy
from activetrack.train.policy_io import LearnedPolicy, load_policy, save_policy
from activetrack.train.ppo import PPOConfig, PPOResult, train_ppo
from activetrack.train.sb3_vecenv import (
    BatchedCopies,
    ParallelCopies,
    SharedPolicyVecEnv,
    make_shared_vec_env,
)
from activetrack.train.utils import configure_torch, seed_everything

__all__ = [
    "BatchedCopies",
    "ImitationConfig",
    "ImitationResult",
    "LearnedPolicy",
    "NetConfig",
    "PPOConfig",
    "PPOResult",
    "ParallelCopies",
    "SharedPolicyVecEnv",
    "TrackingPolicy",
    "build_policy",
    "configure_torch",
    "load_policy",
    "make_shared_vec_env",
    "save_policy",
    "seed_everything",
    "train_imitation",
    "train_ppo",
]
