"""Expert labels collected in one batched world against the serial loop from the same seeds.

DAgger with two rounds covers the expert's rollouts (round 0, the BC labels) and the
mixture with the learner (round 1: the same coins per episode, the learner acting on the
copies whose coin says so). The reference is the serial loop of
activetrack.train.imitation.rollout_labels in the parallel env.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.baselines.policies import LookaheadPolicy, RMPolicy
from activetrack.envs import parallel_env
from activetrack.train.imitation import (
    ImitationConfig,
    rollout_labels,
    rollout_labels_batched,
    train_imitation,
)
from activetrack.train.networks import NetConfig

CONFIG = ImitationConfig(
    episodes=6, epochs=2, iterations=2, beta=0.5, net=NetConfig(hidden=(16, 16))
)


def test_batched_dagger_labels_equal_the_serial_ones():
    serial = train_imitation("paper", seed=5, config=CONFIG, n_steps=12)
    batched = train_imitation("paper", seed=5, config=CONFIG, n_steps=12, batched=True)
    assert len(batched.data) == len(serial.data) == CONFIG.episodes * 12 * 3
    # Round 0 (the expert alone): GSR's plans agree to about 1e-8 m, far below the
    # float32 rounding of the stored observations and labels, which come out bit for bit
    # equal. Round 1: the learner acts on all its copies' observations in one call in the
    # batch and on one copy's M rows serially; float32 matrix products round differently
    # with the batch size (up to about one float32 epsilon on values of order 1), so its
    # moves, and the states and labels that follow, differ by rounding: at most 0.75
    # float32 epsilon (values up to 3.4 in size) here, allowed 2. The float64 rollout
    # traces inherit the moves' 1e-7 relative differences smoothed by the filter: 1.7e-10
    # relative here, allowed 1e-8.
    half = len(serial.data) // 2  # round 0's rows, then round 1's
    np.testing.assert_array_equal(batched.data.obs[:half], serial.data.obs[:half])
    np.testing.assert_array_equal(batched.data.actions[:half], serial.data.actions[:half])
    eps = float(np.finfo(np.float32).eps)
    np.testing.assert_allclose(batched.data.obs, serial.data.obs, rtol=2 * eps, atol=2 * eps)
    np.testing.assert_allclose(
        batched.data.actions, serial.data.actions, rtol=2 * eps, atol=2 * eps
    )
    np.testing.assert_allclose(batched.rollout_traces, serial.rollout_traces, rtol=1e-8)


def test_batched_position_labels_on_unicycles_equal_the_serial_ones():
    # Position targets (the default): labels are GSR's points in each robot's heading
    # frame, and round 1's learner acts through the kinematics' projection, one call for a
    # batch of copies' rows and for one copy's rows serially.
    serial = train_imitation("unicycle", seed=5, config=CONFIG, n_steps=12)
    batched = train_imitation("unicycle", seed=5, config=CONFIG, n_steps=12, batched=True)
    assert serial.head is not None and len(serial.data) == CONFIG.episodes * 12 * 3
    half = len(serial.data) // 2
    np.testing.assert_array_equal(batched.data.obs[:half], serial.data.obs[:half])
    np.testing.assert_array_equal(batched.data.actions[:half], serial.data.actions[:half])
    np.testing.assert_allclose(batched.data.obs, serial.data.obs, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(batched.data.actions, serial.data.actions, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(batched.rollout_traces, serial.rollout_traces, rtol=1e-6)


def test_batched_lookahead_labels_on_a_task_equal_the_serial_ones():
    seeds, kw = [31, 32], dict(n_steps=4)
    env = parallel_env("two_targets", **kw)
    serial, tr_s = rollout_labels(env, LookaheadPolicy(scenario=None, horizon=4), seeds)
    batched, tr_b = rollout_labels_batched(
        "two_targets", kw, LookaheadPolicy(scenario=None, horizon=4), seeds
    )
    np.testing.assert_allclose(batched.obs, serial.obs, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(batched.actions, serial.actions, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(tr_b, tr_s, rtol=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"batched": "yes"}, "batched must be True or False"),
        ({"batched": True, "expert": RMPolicy()}, "batched deterministic expert"),
    ],
)
def test_batched_is_checked(kwargs, message):
    with pytest.raises(ValueError, match=message):
        train_imitation("paper", seed=0, config=CONFIG, n_steps=3, **kwargs)
