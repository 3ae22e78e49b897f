"""Imitation of GSR on the ``paper`` preset: BC quality, DAgger on the same label budget.

Both are measured on 20 held-out seeds (1000..1019; training episodes use seeds >= 10^6)
against GSR and random motion evaluated on the very same seeds.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.baselines.evaluation import evaluate
from activetrack.train.imitation import (
    TRAIN_SEED_LOW,
    Dataset,
    ImitationConfig,
    fit,
    rollout_labels,
    train_imitation,
    train_seeds,
)
from activetrack.train.networks import NetConfig, build_policy
from activetrack.train.policy_io import LearnedPolicy

EVAL_SEED, EVAL_EPISODES = 1000, 20
#: The tests' budget: 40 GSR episodes (6000 labels), smaller than the CLI's default of 100.
BC_TEST = ImitationConfig(episodes=40, epochs=60)
DAGGER_TEST = ImitationConfig(episodes=40, epochs=30, iterations=4)


class _Learned(LearnedPolicy):
    def __init__(self, policy):
        super().__init__(policy, {"view": "shared"})


@pytest.fixture(scope="module")
def references():
    """GSR's and RM's per-episode mean traces on the held-out seeds."""
    gsr, rm = evaluate(
        {"gsr": "gsr", "rm": "rm"}, "paper", EVAL_EPISODES, EVAL_SEED, progress=False
    )
    return gsr.mean_trace, rm.mean_trace


@pytest.fixture(scope="module")
def bc():
    return train_imitation("paper", seed=0, config=BC_TEST)


@pytest.fixture(scope="module")
def bc_trace(bc):
    """The BC policy's (seed 0) per-episode mean traces on the held-out seeds (evaluated
    once for both tests below)."""
    return _mean_trace(bc.policy)


def _mean_trace(policy) -> np.ndarray:
    # evaluate() adds GSR's episodes (unused here, `references` has them): batched=True
    # runs those in one batched world; the learned policy runs episode by episode either way.
    (res,) = [
        r
        for r in evaluate(
            {"learned": _Learned(policy)},
            "paper",
            EVAL_EPISODES,
            EVAL_SEED,
            progress=False,
            batched=True,
        )
        if r.policy == "learned"
    ]
    return res.mean_trace


def test_training_seeds_are_held_out():
    seeds = train_seeds(0, 500)
    assert len(set(seeds)) == 500 and min(seeds) >= TRAIN_SEED_LOW
    assert seeds == train_seeds(0, 500) and seeds != train_seeds(1, 500)


def test_expert_labels_are_gsr_actions():
    """A dataset row is (observation, GSR action) of one agent at one step."""
    from activetrack.baselines import GSR
    from activetrack.baselines.policies import GSRPolicy
    from activetrack.envs import parallel_env

    env = parallel_env("paper")
    data, traces = rollout_labels(env, GSRPolicy(), [TRAIN_SEED_LOW])
    assert len(data) == 50 * 3 and data.obs.dtype == np.float32
    env.reset(seed=TRAIN_SEED_LOW)
    problem = env.planning_problem()
    expect = (GSR().plan(problem, np.random.default_rng(0)) - problem.sensors) / problem.r[:, None]
    np.testing.assert_allclose(data.actions[:3], expect, rtol=1e-5, atol=1e-6)
    assert traces[0] > 0


def test_fit_reduces_the_loss_and_is_deterministic():
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(512, 23)).astype(np.float32)
    w = rng.normal(size=(23, 2))
    act = np.tanh(obs @ w / 5).astype(np.float32)
    data = Dataset(obs, act)
    from gymnasium import spaces

    o = spaces.Box(-np.inf, np.inf, (23,), np.float32)
    a = spaces.Box(-1.0, 1.0, (2,), np.float32)
    import torch

    out = []
    for _ in range(2):
        torch.manual_seed(0)
        pol = build_policy(o, a, NetConfig(hidden=(32, 32), action_gain=None))
        losses = fit(
            pol, data, epochs=30, batch_size=64, lr=3e-3, generator=torch.Generator().manual_seed(0)
        )
        out.append(losses)
    assert out[0] == out[1]
    assert out[0][-1] < 0.2 * out[0][0]


@pytest.mark.slow
def test_bc_is_close_to_gsr_and_better_than_rm(bc, bc_trace, references):
    result = bc
    gsr, rm = references
    assert len(result.data) == BC_TEST.episodes * 50 * 3
    trace = bc_trace
    ratio = trace.mean() / gsr.mean()
    print(f"BC {trace.mean():.4f}, GSR {gsr.mean():.4f} (ratio {ratio:.3f}), RM {rm.mean():.4f}")
    assert ratio < 1.15
    assert trace.mean() < rm.mean()


@pytest.mark.slow
def test_dagger_on_bcs_label_budget_beats_rm_and_its_median_run_is_within_10pc_of_gsr(
    bc, bc_trace, references
):
    """DAgger spends exactly BC's expert-label budget (40 episodes x 50 steps x 3 agents).
    On the 20 held-out seeds (paired 95% Student-t intervals over the episodes):

    - the policy of each of three training seeds tracks better than random motion: the
      interval of the mean of DAgger_i - RM_i lies below 0;
    - per episode, the median of the three policies' traces is within 10% of GSR's on
      average: the interval of the mean of median_i - 1.1 GSR_i lies below 0 (10%, the
      modelling error the project's tests must detect). The median, because one training
      run in three may fail (seed 2 of this budget scores about 43% above GSR).

    Not claimed: an order between DAgger and BC. Their difference is dominated by the
    training seed, which three seeds per method cannot establish; the README reports DAgger
    not better than BC at equal labels. The paired intervals of DAgger - BC (seed 0's BC)
    are printed (``pytest -s tests/train/test_imitation.py -k dagger``), not asserted.
    """
    gsr, rm = references
    traces = []
    for seed in (0, 1, 2):
        result = train_imitation("paper", seed=seed, config=DAGGER_TEST)
        assert len(result.data) == len(bc.data) == BC_TEST.episodes * 50 * 3
        trace = _mean_trace(result.policy)
        traces.append(trace)
        low, high = _paired_interval(trace - rm)
        bc_low, bc_high = _paired_interval(trace - bc_trace)
        print(
            f"DAgger seed {seed}: {trace.mean():.4f} (GSR {gsr.mean():.4f}, BC seed 0 "
            f"{bc_trace.mean():.4f}, RM {rm.mean():.4f}); DAgger - RM [{low:.3f}, "
            f"{high:.3f}], DAgger - BC [{bc_low:.3f}, {bc_high:.3f}]"
        )
        assert high < 0, f"DAgger seed {seed} is not better than RM: [{low}, {high}]"
    median = np.median(traces, axis=0)
    low, high = _paired_interval(median - 1.1 * gsr)
    print(f"median of DAgger's runs {median.mean():.4f}; median - 1.1 GSR [{low:.3f}, {high:.3f}]")
    assert high < 0, f"DAgger's median run is not within 10% of GSR: [{low}, {high}]"


def _paired_interval(diff: np.ndarray, level: float = 0.95) -> tuple[float, float]:
    """Return the Student-t ``level`` interval of the mean of paired differences."""
    from scipy import stats

    half = stats.t.ppf(0.5 + level / 2, len(diff) - 1) * stats.sem(diff)
    return float(diff.mean() - half), float(diff.mean() + half)
