"""The batched environment against N single environments, and Gymnasium's autoreset modes."""

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from activetrack.envs.batched import BatchedActiveTracking
from activetrack.envs.centralized import CentralizedTrackingEnv

TOL = dict(rtol=1e-12, atol=1e-12)


def run_singles(singles, actions):
    """Step single envs with NEXT_STEP autoreset semantics; return obs, rewards, flags."""
    obs, rew, term, trunc = [], [], [], []
    for i, e in enumerate(singles):
        if e.done:
            o, _ = e.reset()
            r, te, tr = 0.0, False, False
        else:
            o, r, te, tr, _ = e.step(actions[i])
        e.done = te or tr
        obs.append(o)
        rew.append(r)
        term.append(te)
        trunc.append(tr)
    return np.stack(obs), np.array(rew), np.array(term), np.array(trunc)


@pytest.mark.parametrize(
    "scenario, overrides",
    [("paper", {"n_steps": 7}), ("homogeneous", {"n_steps": 5, "n_sensors": 2})],
)
def test_batched_reproduces_single_envs_across_autoresets(scenario, overrides):
    N, seed = 5, 42
    batched = BatchedActiveTracking(N, scenario=scenario, noise_block=3, **overrides)
    singles = [CentralizedTrackingEnv(scenario, **overrides) for _ in range(N)]
    obs_b, _ = batched.reset(seed=seed)
    obs_s = np.stack([e.reset(seed=seed + i)[0] for i, e in enumerate(singles)])
    for e in singles:
        e.done = False
    np.testing.assert_allclose(obs_b, obs_s, **TOL)
    rng = np.random.default_rng(0)
    m = batched.n_sensors
    for _ in range(23):  # crosses several episode ends
        a = rng.uniform(-1.3, 1.3, (N, 2 * m))  # some beyond the unit disk
        obs_b, rew_b, term_b, trunc_b, _ = batched.step(a)
        obs_s, rew_s, term_s, trunc_s = run_singles(singles, a)
        np.testing.assert_allclose(obs_b, obs_s, **TOL)
        np.testing.assert_allclose(rew_b, rew_s, **TOL)
        np.testing.assert_array_equal(term_b, term_s)
        np.testing.assert_array_equal(trunc_b, trunc_s)
        for i, e in enumerate(singles):
            np.testing.assert_allclose(batched.x_true[i], e.env.x_true, **TOL)
            np.testing.assert_allclose(batched.P_pred[i], e.env.P_pred, **TOL)
            np.testing.assert_allclose(batched.sensors[i], e.env.sensors, **TOL)


def test_same_step_autoreset_reports_final_observation():
    N = 3
    b = BatchedActiveTracking(N, autoreset_mode=AutoresetMode.SAME_STEP, n_steps=4)
    singles = [CentralizedTrackingEnv("paper", n_steps=4) for _ in range(N)]
    b.reset(seed=7)
    for i, e in enumerate(singles):
        e.reset(seed=7 + i)
    a = np.zeros((N, 6))
    for _ in range(4):
        obs, rew, term, trunc, infos = b.step(a)
        last = [e.step(a[i]) for i, e in enumerate(singles)]
    assert trunc.all() and not term.any()
    np.testing.assert_allclose(
        np.stack(list(infos["final_obs"])), np.stack([x[0] for x in last]), **TOL
    )
    np.testing.assert_allclose(rew, [x[1] for x in last], **TOL)
    first = np.stack([e.reset()[0] for e in singles])
    np.testing.assert_allclose(obs, first, **TOL)  # already the next episode's start
    assert np.all(b.k == 0)


def test_next_step_autoreset_returns_reset_observation_with_zero_reward():
    b = BatchedActiveTracking(2, n_steps=2)
    b.reset(seed=0)
    a = np.zeros((2, 6))
    b.step(a)
    _, _, _, trunc, _ = b.step(a)
    assert trunc.all()
    obs, rew, term, trunc, _ = b.step(a)
    assert np.all(rew == 0.0) and not term.any() and not trunc.any()
    assert np.all(b.k == 0)
    ref = CentralizedTrackingEnv("paper", n_steps=2)
    ref.reset(seed=1)
    ref.step(a[1])
    ref.step(a[1])
    np.testing.assert_allclose(obs[1], ref.reset()[0], **TOL)


def test_disabled_mode_resets_only_masked_copies():
    b = BatchedActiveTracking(3, autoreset_mode="Disabled", n_steps=50)
    b.reset(seed=3)
    for _ in range(3):
        b.step(np.zeros((3, 6)))
    before = b.sensors.copy()
    b.reset(options={"reset_mask": np.array([False, True, False])})
    assert list(b.k) == [3, 0, 3]
    np.testing.assert_array_equal(b.sensors[[0, 2]], before[[0, 2]])


def test_spaces_and_errors():
    b = BatchedActiveTracking(4, n_sensors=2, sigma_d2=1.0, sigma_theta2=0.1)
    obs, _ = b.reset(seed=0)
    assert obs.shape == b.observation_space.shape and obs.dtype == np.float32
    assert b.action_space.shape == (4, 4)
    assert all(b.single_observation_space.contains(o) for o in obs)
    obs_agents, *_ = b.step_agents(np.zeros((4, 2, 2)))
    assert obs_agents.shape == (4, 2, 5 + 12)
    with pytest.raises(ValueError, match="actions"):
        b.step(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="finite"):
        b.step(np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="num_envs"):
        BatchedActiveTracking(0)
    with pytest.raises(ValueError, match="autoreset_mode"):
        BatchedActiveTracking(2, autoreset_mode="sometimes")
    with pytest.raises(ValueError, match="rho"):
        BatchedActiveTracking(2, rho=-1.0)
