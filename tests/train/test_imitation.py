"""Imitation of GSR on the ``paper`` preset: BC quality, DAgger vs BC on the same label budget.

Both are measured on 20 held-out seeds (1000..1019; training episodes use seeds >= 10^6)
against GSR and random motion evaluated on the very same seeds.
"""

from __future__ import annotations

import time

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
    t0 = time.perf_counter()
    result = train_imitation("paper", seed=0, config=BC_TEST)
    return result, time.perf_counter() - t0


@pytest.fixture(scope="module")
def bc_trace(bc):
    """The BC policy's (seed 0) per-episode mean traces on the held-out seeds (evaluated
    once for both tests below)."""
    result, _ = bc
    return _mean_trace(result.policy)


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
def test_bc_is_fast_close_to_gsr_and_better_than_rm(bc, bc_trace, references):
    result, seconds = bc
    gsr, rm = references
    assert seconds < 60, f"BC took {seconds:.1f} s"
    assert len(result.data) == BC_TEST.episodes * 50 * 3
    trace = bc_trace
    ratio = trace.mean() / gsr.mean()
    print(f"BC {trace.mean():.4f}, GSR {gsr.mean():.4f} (ratio {ratio:.3f}), RM {rm.mean():.4f}")
    assert ratio < 1.15
    assert trace.mean() < rm.mean()


@pytest.mark.slow
def test_dagger_at_least_as_good_as_bc_on_the_same_label_budget(bc, bc_trace, references):
    """Same expert-label budget (40 episodes x 50 steps x 3 agents), same 20 held-out seeds,
    the median over three training seeds of each.

    Tolerance: DAgger's median may exceed BC's by at most 5%. One training run is too noisy
    to compare: this test prints (``pytest -s tests/train/test_imitation.py -k dagger``)
    DAgger 3.24, 2.36, 2.41 and BC 2.33, 2.35, 2.56 for seeds 0, 1, 2 (GSR 2.27), where the
    single-seed version of it printed DAgger 2.30 and BC 2.31 one commit earlier (27d4a82),
    before changes of 1e-15 in the world's arithmetic that move GSR's labels by about 1e-7:
    a DAgger run sometimes fails badly, and DAgger is not reliably better than BC on this
    preset (see the README).
    """
    bc_result, _ = bc
    gsr, _ = references
    # The five other trainings, serially (scale-out goes through Ray, not a process pool;
    # under `make test` the second core runs the plain-Python kernel tests anyway).
    jobs = [("bc", 1), ("bc", 2), ("dagger", 0), ("dagger", 1), ("dagger", 2)]
    done = {job: _train_and_measure(*job) for job in jobs}
    done["bc", 0] = (len(bc_result.data), float(bc_trace.mean()))
    bc_traces, dagger_traces = [], []
    for seed in (0, 1, 2):
        (bc_labels, bc_mean), (dagger_labels, dagger_mean) = done["bc", seed], done["dagger", seed]
        assert dagger_labels == bc_labels
        bc_traces.append(bc_mean)
        dagger_traces.append(dagger_mean)
    print(f"DAgger {dagger_traces} BC {bc_traces} GSR {gsr.mean():.4f}")
    assert np.median(dagger_traces) <= 1.05 * np.median(bc_traces)


def _train_and_measure(method: str, seed: int) -> tuple[int, float]:
    """Return the label count and the mean trace on the held-out seeds of BC or DAgger
    (the tests' budgets) trained from ``seed``."""
    result = train_imitation("paper", seed=seed, config=BC_TEST if method == "bc" else DAGGER_TEST)
    return len(result.data), float(_mean_trace(result.policy).mean())
