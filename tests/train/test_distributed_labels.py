"""Expert labels collected on Ray workers against the serial loop from the same seeds.

DAgger with two rounds covers both kinds of episode: the expert's rollouts (round 0, the
BC labels) and the mixture with the learner (round 1, the learner shipped to the
workers). The reference is the serial run, and beside it labels computed episode by
episode in fresh environments (so they cannot depend on the order the episodes ran in).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from activetrack.baselines.policies import GSRPolicy
from activetrack.cli import main
from activetrack.envs import parallel_env
from activetrack.train.imitation import ImitationConfig, rollout_labels, train_imitation
from activetrack.train.networks import NetConfig
from activetrack.train.utils import params_vector

ray = pytest.importorskip("ray")

CONFIG = ImitationConfig(
    episodes=6, epochs=2, iterations=2, beta=0.5, net=NetConfig(hidden=(16, 16))
)


@pytest.mark.slow
def test_labels_on_workers_equal_serial_labels():
    serial = train_imitation("paper", seed=5, config=CONFIG, n_steps=12)
    assert not ray.is_initialized()
    on_ray = train_imitation("paper", seed=5, config=CONFIG, n_steps=12, workers=2)
    assert not ray.is_initialized()  # the Ray it started is shut down

    assert len(serial.data) == CONFIG.episodes * 12 * 3
    np.testing.assert_array_equal(on_ray.data.obs, serial.data.obs)
    np.testing.assert_array_equal(on_ray.data.actions, serial.data.actions)
    assert on_ray.rollout_traces == serial.rollout_traces
    assert on_ray.losses == serial.losses  # so the same network was trained
    np.testing.assert_array_equal(params_vector(on_ray.policy), params_vector(serial.policy))


@pytest.mark.slow
def test_position_labels_on_workers_equal_serial_labels():
    # Unicycles' position targets: the head travels to the workers with the learner.
    serial = train_imitation("unicycle", seed=5, config=CONFIG, n_steps=8)
    on_ray = train_imitation("unicycle", seed=5, config=CONFIG, n_steps=8, workers=2)
    assert serial.head is not None and len(serial.data) == CONFIG.episodes * 8 * 3
    np.testing.assert_array_equal(on_ray.data.obs, serial.data.obs)
    np.testing.assert_array_equal(on_ray.data.actions, serial.data.actions)
    assert on_ray.rollout_traces == serial.rollout_traces


def test_an_episodes_labels_do_not_depend_on_the_episodes_before_it():
    """Round 1's labels, one fresh environment per episode, equal one loop over them all."""
    serial = train_imitation(
        "paper", seed=5, config=ImitationConfig(episodes=3, epochs=1, iterations=1), n_steps=6
    )
    seeds = [1_000_123, 1_000_456, 1_000_789]
    together, traces = rollout_labels(
        parallel_env("paper", n_steps=6), GSRPolicy(), seeds, _learner(serial.policy), 0.5
    )
    alone = [
        rollout_labels(
            parallel_env("paper", n_steps=6), GSRPolicy(), [s], _learner(serial.policy), 0.5
        )
        for s in reversed(seeds)
    ][::-1]
    np.testing.assert_array_equal(together.obs, np.concatenate([d.obs for d, _ in alone]))
    np.testing.assert_array_equal(together.actions, np.concatenate([d.actions for d, _ in alone]))
    assert traces == [t for _, tr in alone for t in tr]


def _learner(policy):
    from activetrack.train.imitation import learner_fn

    return learner_fn(policy)


def test_train_command_checks_workers_before_training(tmp_path, capsys):
    for method in ("bc", "dagger"):
        with pytest.raises(SystemExit) as exc:
            main(["train", method, "--out", str(tmp_path / method), "--workers", "0"])
        assert exc.value.code == 2
        assert "--workers: must be an integer >= 1" in capsys.readouterr().err
        code = main(["train", method, "--out", str(tmp_path / method), "--address", " "])
        assert code == 2
        assert "address must be a non-empty string" in capsys.readouterr().err
        assert not (tmp_path / method).exists()


def _without_timings(obj):
    """Return parsed JSON without the decision-time entries (``cpu_ms_per_decision`` and
    its alias ``ms_per_step``)."""
    if isinstance(obj, dict):
        timings = ("cpu_ms_per_decision", "ms_per_step")
        return {k: _without_timings(v) for k, v in obj.items() if k not in timings}
    if isinstance(obj, list):
        return [_without_timings(v) for v in obj]
    return obj


@pytest.mark.slow
def test_a_trained_policy_evaluated_on_workers_equals_serial(tmp_path):
    """The learned policy is shipped to the workers: same episodes as in this process."""
    common = ["--seed", "2", "--hidden", "16", "16", "--no-progress"]
    bc = ["train", "bc", *common, "--episodes", "1", "--epochs", "2"]
    assert main([*bc, "--out", str(tmp_path / "bc")]) == 0
    policy = str(tmp_path / "bc" / "policy.zip")
    ev = ["evaluate", "--policy", policy, "--episodes", "4", "--no-plot", "--no-progress"]
    assert main([*ev, "--out", str(tmp_path / "serial")]) == 0
    assert main([*ev, "--out", str(tmp_path / "ray"), "--workers", "2"]) == 0
    assert not ray.is_initialized()
    for name in ("results.json", "episodes.json"):
        serial = (tmp_path / "serial" / name).read_text()
        ray_side, serial_side = (
            _without_timings(json.loads((tmp_path / side / name).read_text()))
            for side in ("ray", "serial")
        )
        assert ray_side == serial_side, name  # everything but the decision times
    assert policy in serial  # the learned policy was evaluated, beside GSR
