"""The one closed loop, :class:`activetrack.world.World`, against independent references.

The reference is the longhand loop of ``tests/envs/reference.py`` (written from the paper:
hand-discretized CV model, the EKF with the full 2M x 2M innovation covariance, the
documented draw order), run once per copy with that copy's seed. Every copy of a batched
world must follow its own reference, across episode ends and with noise drawn in blocks.
"""

import numpy as np
import pytest
from scipy import stats

import activetrack as at
from activetrack.world import World
from tests.envs.reference import ReferenceLoop

CONFIGS = [
    {"scenario": "paper", "n_steps": 7},
    {"scenario": "homogeneous", "n_sensors": 5, "target_init": "fixed", "n_steps": 6},
]


def _small_actions(rng, n, m):
    """Return actions well inside the unit disk that keep the sensors far from rho."""
    return rng.uniform(-0.5, 0.5, (n, m, 2))


@pytest.mark.parametrize("config", CONFIGS)
@pytest.mark.parametrize("n_copies, block", [(1, None), (4, 3), (3, 64)])
def test_every_copy_follows_the_longhand_loop_across_episodes(config, n_copies, block):
    sc = at.make_scenario(
        config["scenario"], **{k: v for k, v in config.items() if k != "scenario"}
    )
    world = World(sc, n_copies, noise_block=block)
    seeds = [11 + 5 * i for i in range(n_copies)]
    world.reset(seeds=seeds)
    refs = [ReferenceLoop(sc, s) for s in seeds]
    rng = np.random.default_rng(0)
    for _ in range(2 * sc.n_steps + 3):  # three episodes, restarted when they end
        a = _small_actions(rng, n_copies, sc.n_sensors)
        res = world.step_actions(a)
        expected = np.array([ref.step(a[i]) for i, ref in enumerate(refs)])
        np.testing.assert_allclose(np.atleast_1d(res.reward), expected, rtol=1e-9)
        for i, ref in enumerate(refs):
            np.testing.assert_allclose(world.sensors[i], ref.sensors, rtol=0, atol=1e-12)
            np.testing.assert_allclose(world.x_true[i], ref.x_true, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(world.x_hat[i], ref.x_hat, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(world.P[i], ref.P, rtol=1e-8, atol=1e-12)
            np.testing.assert_allclose(world.P_pred[i], ref.P_pred, rtol=1e-8, atol=1e-12)
        ended = np.flatnonzero(world.truncated)
        if ended.size:
            assert np.all(world.k[ended] == sc.n_steps)
            world.reset(ended)  # the generators continue, as the references' do
            for i in ended:
                refs[i].restart()


@pytest.mark.parametrize("cut", ["reset", "max_trace", "max_steps"])
def test_episodes_cut_short_leave_every_stream_where_the_longhand_loop_leaves_it(cut):
    # Episodes that end before the copy's block of normals is used up: reset mid-episode,
    # terminated on max_trace (a bound the trace crosses after a few steps), or truncated
    # by max_steps. The references draw one step a call and restart where the copy does.
    extra = {"max_trace": 3.0} if cut == "max_trace" else {}
    sc = at.make_scenario("paper", n_steps=9, **extra)
    world = World(sc, 3, noise_block=64, max_steps=4 if cut == "max_steps" else None)
    seeds = [3, 8, 13]
    world.reset(seeds=seeds)
    refs = [ReferenceLoop(sc, s) for s in seeds]
    rng = np.random.default_rng(1)
    ends = 0
    for k in range(25):
        a = _small_actions(rng, 3, sc.n_sensors)
        res = world.step_actions(a)
        expected = [ref.step(a[i]) for i, ref in enumerate(refs)]
        np.testing.assert_allclose(res.reward, expected, rtol=1e-9)
        for i, ref in enumerate(refs):
            np.testing.assert_allclose(world.x_true[i], ref.x_true, rtol=1e-9, atol=1e-9)
        done = world.terminated | world.truncated
        if cut == "reset":
            done = done | (np.arange(3) == k % 3)  # a copy in turn, mid-episode
        if cut == "max_trace":
            trace = np.array([ref.P[0, 0] + ref.P[1, 1] for ref in refs])
            np.testing.assert_array_equal(world.terminated, trace > 3.0)
        if cut == "max_steps":
            np.testing.assert_array_equal(world.truncated, world.k == 4)
        ends += np.count_nonzero(done & (world.k < sc.n_steps))
        world.reset(done)
        for i in np.flatnonzero(done):
            refs[i].restart()
    assert ends >= 6  # the episodes did end early, with normals of their blocks unused


def test_a_step_leaves_the_other_copies_untouched():
    world = World("paper", 3)
    world.reset(seeds=[0, 1, 2])
    before = {k: getattr(world, k).copy() for k in ("x_true", "P", "sensors", "k")}
    state = world.rng(1).bit_generator.state
    world.step_actions(np.full((3, 3, 2), 0.3), live=np.array([True, False, True]))
    for key, old in before.items():
        np.testing.assert_array_equal(getattr(world, key)[1], old[1])
        assert not np.array_equal(getattr(world, key)[0], old[0])
    assert world.rng(1).bit_generator.state == state  # no draw for a copy that did not step


def test_episode_end_and_stepping_an_ended_copy_raises():
    world = World("paper", 2, n_steps=3, max_trace=1e9)
    with pytest.raises(RuntimeError, match="reset"):
        world.step_actions(np.zeros((2, 3, 2)))  # never reset
    world.reset(seeds=[0, 1])
    for k in range(3):
        res = world.step_actions(np.zeros((2, 3, 2)))
        assert list(res.truncated) == [k == 2, k == 2]
        assert not res.terminated.any()
    with pytest.raises(RuntimeError, match=r"\[0, 1\]"):
        world.step_actions(np.zeros((2, 3, 2)))
    # Termination: the score of eq. (17) above max_trace ends the episode at once.
    world = World("paper", 1, max_trace=1.0)
    world.reset(seeds=[0])
    res = world.step_actions(np.zeros((1, 3, 2)))
    assert res.terminated and res.reward == -world.trace[0] and world.trace[0] > 1.0
    # The trace is the trace of the posterior position block (independent: np.trace).
    assert world.trace[0] == pytest.approx(np.trace(world.P[0, :2, :2]), rel=1e-15)


def test_initial_sensors_uniform_by_area():
    sc = at.make_scenario("paper", n_sensors=1, sigma_d2=1.0, sigma_theta2=1.0)
    world = World(sc, 4000)
    world.reset(seeds=range(4000))
    pts = world.sensors[:, 0]
    rad = np.linalg.norm(pts - np.array(sc.sensor_center), axis=1) / sc.sensor_radius
    assert stats.kstest(rad**2, "uniform").pvalue > 1e-3  # uniform by area: rad^2 ~ U(0, 1)
    ang = np.arctan2(*(pts - sc.sensor_center).T[::-1])
    assert stats.kstest((ang + np.pi) / (2 * np.pi), "uniform").pvalue > 1e-3


def test_gaussian_start_is_drawn_from_the_prior():
    sc = at.make_scenario("homogeneous", P0=(4.0, 9.0, 1.0, 1.0))
    world = World(sc, 5000)
    world.reset(seeds=range(5000))
    dev = world.x_true - np.asarray(sc.x0_hat)
    # Independent: for x ~ N(x0_hat, P0), (x - x0_hat)^T P0^{-1} (x - x0_hat) ~ chi2(4).
    d2 = np.einsum("ni,ij,nj->n", dev, np.linalg.inv(np.diag(sc.P0)), dev)
    assert stats.kstest(d2, stats.chi2(4).cdf).pvalue > 1e-3
    assert np.all(world.x_hat == np.asarray(sc.x0_hat))


def test_reset_state_is_a_copy_of_the_scenario():
    sc = at.make_scenario("paper", P0=(4.0, 9.0, 1.0, 1.0))
    P0 = sc.initial_cov
    np.testing.assert_array_equal(P0, np.diag([4.0, 9.0, 1.0, 1.0]))
    P0[0, 0] = -1.0  # a caller that mutates its copy does not change the scenario
    world = World(sc)
    world.reset(seeds=[0])
    world.P[0, 1, 1] = 0.0  # a caller that writes into the state does not change the scenario
    assert sc.initial_cov[1, 1] == 9.0
    np.testing.assert_array_equal(world.P[0, :1, :1], [[4.0]])


def test_positions_and_actions_reach_the_same_move():
    world_a, world_p = World("paper", 2), World("paper", 2)
    world_a.reset(seeds=[3, 4])
    world_p.reset(seeds=[3, 4])
    rng = np.random.default_rng(1)
    for _ in range(10):
        a = rng.uniform(-1.0, 1.0, (2, 3, 2)) / np.sqrt(2.0)  # inside the unit disk
        r = world_a.params.r
        world_a.step_actions(a)
        world_p.step(world_p.sensors + a * r[:, None])
        np.testing.assert_allclose(world_p.sensors, world_a.sensors, rtol=0, atol=1e-12)
        np.testing.assert_allclose(world_p.P, world_a.P, rtol=1e-12)


def test_observe_and_planning_problem_per_copy():
    world = World("homogeneous", 3, n_sensors=4)
    world.reset(seeds=[0, 1, 2])
    world.step_actions(np.full((3, 4, 2), 0.3))
    obs, state = world.observe(), world.state()
    assert obs.shape == (3, 4, 29) and obs.dtype == np.float32 and state.shape == (3, 30)
    for i in range(3):
        P, _ = at.world.observation.decode_target(
            obs[i, 0, :5], world.scenario.dt, world.length_scale
        )
        np.testing.assert_allclose(P, world.P_pred[i, :2, :2], rtol=1e-6)  # float32
        problem = world.planning_problem(i)
        np.testing.assert_array_equal(problem.target, world.x_pred[i, :2])
        np.testing.assert_array_equal(problem.sensors, world.sensors[i])
        assert state[i, -1] == np.float32(1 / world.scenario.n_steps)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"num_copies": 0}, "num_copies"),
        ({"num_copies": True}, "num_copies"),
        ({"num_copies": 2, "noise_block": 0}, "noise_block"),
        ({"num_copies": 2, "max_steps": 0}, "max_steps"),
        ({"num_copies": 2, "max_steps": 2.5}, "max_steps"),
    ],
)
def test_bad_world_arguments_name_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        World("paper", **kwargs)


def test_bad_copy_selections_raise():
    world = World("paper", 3)
    with pytest.raises(ValueError, match="indices"):
        world.reset([0, 0])
    with pytest.raises(ValueError, match="indices"):
        world.reset([3])
    with pytest.raises(ValueError, match="mask"):
        world.reset(np.array([True, False]))
    with pytest.raises(ValueError, match="seeds"):
        world.reset([0, 1], seeds=[1])


def test_unknown_state_field_names_the_choices():
    with pytest.raises(ValueError, match="x_true"):
        World("paper").get("x_ture")
