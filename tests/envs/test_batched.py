"""The batched environment against the longhand loop per copy, and Gymnasium's autoreset modes."""

import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

from activetrack.envs.batched import BatchedActiveTracking
from activetrack.envs.centralized import CentralizedTrackingEnv
from tests.envs.reference import ReferenceLoop

TOL = dict(rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    "scenario, overrides",
    [("paper", {"n_steps": 7}), ("homogeneous", {"n_steps": 5, "n_sensors": 2})],
)
def test_next_step_autoreset_follows_the_longhand_loop_per_copy(scenario, overrides):
    # Each copy against the independent longhand loop seeded seed + i: rewards, and the
    # NEXT_STEP protocol (the step after an episode ends returns reward 0 and the first
    # observation of the next episode, whose draws continue the copy's generator).
    N, seed = 4, 42
    overrides = {**overrides, "target_init": "fixed"}
    batched = BatchedActiveTracking(N, scenario=scenario, noise_block=3, **overrides)
    sc = batched.scenario
    refs = [ReferenceLoop(sc, seed + i) for i in range(N)]
    batched.reset(seed=seed)
    rng = np.random.default_rng(0)
    m = batched.n_sensors
    done = np.zeros(N, dtype=bool)
    for _ in range(23):  # crosses several episode ends
        a = rng.uniform(-0.5, 0.5, (N, m, 2))
        _, rew, term, trunc, _ = batched.step(a.reshape(N, -1))
        for i, ref in enumerate(refs):
            if done[i]:
                ref.restart()
                assert rew[i] == 0.0 and not trunc[i]
            else:
                assert rew[i] == pytest.approx(ref.step(a[i]), rel=1e-9)
            np.testing.assert_allclose(batched.sensors[i], ref.sensors, rtol=0, atol=1e-12)
            np.testing.assert_allclose(batched.P_pred[i], ref.P_pred, rtol=1e-8, atol=1e-12)
        assert not term.any()
        done = trunc.copy()


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


# ------------------------------------------------------------ sizes bounded (issue 35)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(num_envs=10**12),
        dict(num_envs=4, noise_block=10**9),
        dict(num_envs=1, n_sensors=10_000),
        dict(num_envs=1, scenario="two_targets", n_sensors=2000, n_targets=100,
             x0=[(0.0, 0.0, 1.0, 1.0)] * 100, x0_hat=[(0.0, 0.0, 1.0, 1.0)] * 100),
    ],
)  # fmt: skip
def test_sizes_beyond_the_memory_bound_are_refused_naming_them(kwargs):
    from activetrack.world import WORLD_BYTES_MAX

    with pytest.raises(ValueError, match=r"^num_copies \(num_envs\) x noise_block") as info:
        BatchedActiveTracking(**kwargs)
    assert f"{WORLD_BYTES_MAX / 2**30:g} GiB" in str(info.value)


@pytest.mark.parametrize(
    "n, m, k, block", [(1, 400, 1, 64), (2, 200, 10, 64), (64, 4, 1, 256), (1, 50, 20, 64)]
)
def test_the_memory_estimate_bounds_the_measured_peak(n, m, k, block):
    import tracemalloc

    from activetrack.world import world_bytes

    kw = dict(n_sensors=m, noise_block=block)
    if k > 1:
        kw.update(scenario="two_targets", n_targets=k, x0=[(0.0, 0.0, 1.0, 1.0)] * k,
                  x0_hat=[(0.0, 0.0, 1.0, 1.0)] * k)  # fmt: skip
    else:
        kw.update(scenario="homogeneous")

    def run():
        env = BatchedActiveTracking(n, **kw)
        env.reset(seed=0)
        env.step(env.action_space.sample())

    run()  # compiled and imported before measuring
    tracemalloc.start()
    try:
        run()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak <= world_bytes(n, block, m, k, 4)
