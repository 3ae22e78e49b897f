"""The parallel environment against the longhand loop and the documented layout."""

import copy
import pickle

import numpy as np
import pytest
from gymnasium.utils import seeding

from activetrack import make_scenario
from activetrack.envs import parallel_env
from activetrack.world.observation import decode_sensors, decode_target

from .reference import ReferenceLoop


def _small_actions(rng, m):
    """Return actions of norm <= 0.3: sensors start ~18 m away, so nothing is projected."""
    a = rng.uniform(-0.2, 0.2, (m, 2))
    return a.astype(np.float32).astype(np.float64)


@pytest.mark.parametrize(
    "config",
    [
        {"scenario": "paper"},
        {"scenario": "homogeneous", "n_sensors": 5, "target_init": "fixed", "reward_scale": 2.5},
    ],
)
def test_episode_matches_longhand_loop(config):
    env = parallel_env(**config)
    sc = env.scenario
    ref = ReferenceLoop(sc, seed=7)
    obs, _ = env.reset(seed=7)
    np.testing.assert_allclose(env.sensors, ref.sensors, rtol=0, atol=1e-12)
    # Timeline: the first observation already carries the prediction P(1|0).
    np.testing.assert_allclose(env.P_pred, ref.P_pred, rtol=1e-12)
    rng = np.random.default_rng(0)
    steps = 0
    while env.agents:
        a = _small_actions(rng, sc.n_sensors)
        _, rewards, terms, truncs, infos = env.step(dict(zip(env.agents, a, strict=True)))
        expected = ref.step(a)
        steps += 1
        assert set(rewards.values()) == {rewards["sensor_0"]}  # shared reward
        np.testing.assert_allclose(rewards["sensor_0"], expected, rtol=1e-9)
        np.testing.assert_allclose(env.sensors, ref.sensors, rtol=0, atol=1e-12)
        np.testing.assert_allclose(env.x_true, ref.x_true, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(env.x_hat, ref.x_hat, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(env.P, ref.P, rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(env.P_pred, ref.P_pred, rtol=1e-8, atol=1e-12)
        assert infos["sensor_0"]["trace"] == pytest.approx(-expected / sc.reward_scale, rel=1e-9)
        assert not any(terms.values())
    assert steps == sc.n_steps
    assert all(truncs.values()) and env.agents == []


def test_gaussian_start_draws_after_the_sensors():
    env = parallel_env(scenario="homogeneous", n_sensors=4)
    env.reset(seed=3)
    sc = env.scenario
    rng = np.random.default_rng(3)
    rng.random((4, 2))
    x_true = np.array(sc.x0_hat) + np.linalg.cholesky(np.diag(sc.P0)) @ rng.standard_normal(4)
    np.testing.assert_allclose(env.x_true, x_true, rtol=1e-12)


def test_observation_layout_element_by_element():
    st2 = [0.25, 0.5, 0.5, 1.0]
    env = parallel_env(
        scenario="paper", n_sensors=4, sigma_d2=(1.0, 2.0, 3.0, 4.0), sigma_theta2=st2
    )
    obs, _ = env.reset(seed=1)
    for _ in range(5):
        obs, *_ = env.step({a: np.array([-0.7, 0.2]) for a in env.agents})
    L = float(np.hypot(20 - 2, 0 + 2) + 5)  # paper: |sensor_center - x0_hat| + radius
    assert env.length_scale == pytest.approx(L)
    P, x = env.P_pred, env.x_pred
    sd2 = [1.0, 2.0, 3.0, 4.0]
    target = [
        np.log(np.sqrt(P[0, 0]) / L),
        np.log(np.sqrt(P[1, 1]) / L),
        P[0, 1] / np.sqrt(P[0, 0] * P[1, 1]),
        x[2] * 0.1 / L,
        x[3] * 0.1 / L,
    ]
    for i, agent in enumerate(env.possible_agents):
        o = obs[agent]
        assert o.dtype == np.float32 and o.shape == (5 + 6 * 4,)
        np.testing.assert_allclose(o[:5], target, rtol=1e-6, atol=1e-7)
        for j in range(4):
            s = (i + j) % 4  # own block first, then the others in cyclic order
            block = o[5 + 6 * j : 11 + 6 * j]
            expected = [
                (env.sensors[s, 0] - x[0]) / L,
                (env.sensors[s, 1] - x[1]) / L,
                np.log(np.sqrt(sd2[s]) / L),
                np.log(np.sqrt(st2[s])),
                10.0 * 0.1 / L,
                2.0 / L,
            ]
            np.testing.assert_allclose(block, expected, rtol=1e-6, atol=1e-7)
        assert env.observation_space(agent).contains(o)


def test_observation_decodes_to_the_planning_problem():
    env = parallel_env(scenario="homogeneous", n_sensors=3, rho=1.5)
    obs, _ = env.reset(seed=2)
    obs, *_ = env.step({a: np.array([0.3, -0.4]) for a in env.agents})
    problem = env.planning_problem()
    L = env.length_scale
    o = obs["sensor_1"]
    P11, v = decode_target(o[:5], env.scenario.dt, L)
    np.testing.assert_allclose(P11, problem.prior_cov, rtol=1e-5)
    np.testing.assert_allclose(v, env.x_pred[2:4], rtol=1e-5, atol=1e-6)
    blocks = decode_sensors(o[5:].reshape(3, 6), L)
    order = [1, 2, 0]
    np.testing.assert_allclose(blocks["rel"], problem.rel_sensors[order], rtol=1e-5)
    for key in ("sigma_d2", "sigma_theta2", "r", "rho"):
        np.testing.assert_allclose(blocks[key], getattr(problem, key)[order], rtol=1e-5)


def test_planning_problem_and_state():
    env = parallel_env(scenario="paper")
    obs, _ = env.reset(seed=4)
    env.step({a: np.array([0.1, 0.1]) for a in env.agents})
    p = env.planning_problem()
    np.testing.assert_array_equal(p.prior_cov, env.P_pred[:2, :2])
    np.testing.assert_array_equal(p.target, env.x_pred[:2])
    np.testing.assert_array_equal(p.sensors, env.sensors)
    np.testing.assert_array_equal(p.r, [1.0, 1.0, 1.0])
    np.testing.assert_array_equal(p.sigma_d2, [2.0, 4.0, 4.0])
    np.testing.assert_array_equal(p.sigma_theta2, [0.25, 0.5, 0.5])
    state = env.state()
    o0 = env.step({a: np.zeros(2) for a in env.agents})[0]["sensor_0"]
    state = env.state()
    assert state.shape == (6 + 6 * 3,) and state.dtype == np.float32
    np.testing.assert_array_equal(state[:-1], o0)  # sensor blocks in index order
    assert state[-1] == pytest.approx(2 / 50)
    assert env.state_space.contains(state)


def test_seeding_is_bit_for_bit_and_matches_default_rng():
    def episode(env, seed):
        obs, _ = env.reset(seed=seed)
        out = [np.concatenate(list(obs.values()))]
        rng = np.random.default_rng(9)
        while env.agents:
            obs, rew, *_ = env.step({a: rng.uniform(-1, 1, 2) for a in env.agents})
            out.append(np.concatenate(list(obs.values())))
            out.append(np.array([rew["sensor_0"]]))
        return np.concatenate(out)

    a, b = parallel_env(), parallel_env()
    np.testing.assert_array_equal(episode(a, 5), episode(b, 5))
    assert not np.array_equal(episode(a, 5), episode(a, 6))
    # The env's generator is default_rng(seed): the same stream as gymnasium's seeding.
    g, _ = seeding.np_random(5)
    np.testing.assert_array_equal(g.random((3, 2)), np.random.default_rng(5).random((3, 2)))
    a.reset(seed=5)
    assert a.np_random.bit_generator.state == _after_reset_draws(5, 3)
    # reset() without a seed continues the generator rather than re-seeding it
    a.reset(seed=5)
    first = a.sensors.copy()
    a.reset()
    assert not np.array_equal(a.sensors, first)


def _after_reset_draws(seed, m):
    rng = np.random.default_rng(seed)
    rng.random((m, 2))  # the paper's start is fixed: only the sensors are drawn
    return rng.bit_generator.state


def test_truncation_termination_and_reward_scale():
    env = parallel_env(scenario="paper", n_steps=3, reward_scale=0.5)
    env.reset(seed=0)
    for k in range(3):
        _, rew, term, trunc, info = env.step({a: np.zeros(2) for a in env.agents})
        assert rew["sensor_2"] == pytest.approx(-0.5 * info["sensor_2"]["trace"])
        assert all(v == (k == 2) for v in trunc.values())
        assert not any(term.values())
    assert env.agents == []
    with pytest.raises(RuntimeError, match="reset"):
        env.step({})
    env = parallel_env(scenario="paper", max_trace=1e-3)
    env.reset(seed=0)
    _, _, term, trunc, info = env.step({a: np.zeros(2) for a in env.agents})
    assert all(term.values()) and not any(trunc.values())
    assert info["sensor_0"]["max_trace_exceeded"] and env.agents == []


def test_projection_is_counted_and_keeps_rho():
    env = parallel_env(scenario="paper", n_steps=40, vmax=30.0)  # faster than the target
    env.reset(seed=0)
    count = np.zeros(3, int)
    while env.agents:
        before = env.x_pred[:2].copy()
        toward = before - env.sensors
        a = toward / np.linalg.norm(toward, axis=1, keepdims=True)  # straight at the target
        _, _, _, _, infos = env.step(dict(zip(env.agents, a, strict=True)))
        dist = np.linalg.norm(env.sensors - before, axis=1)
        assert np.all(dist >= 2.0 * (1 - 1e-12))
        flags = np.array([infos[ag]["projected"] for ag in env.possible_agents])
        count += flags
        assert [infos[ag]["n_projected"] for ag in env.possible_agents] == count.tolist()
    assert count.min() > 0  # every sensor reached the rho disk and was held off it


def test_float32_and_float64_actions_agree():
    a32 = {f"sensor_{i}": np.array([0.25, -0.5], np.float32) for i in range(3)}
    a64 = {k: v.astype(np.float64) for k, v in a32.items()}
    e1, e2 = parallel_env(), parallel_env()
    e1.reset(seed=1)
    e2.reset(seed=1)
    o1 = e1.step(a32)[0]
    o2 = e2.step(a64)[0]
    np.testing.assert_array_equal(o1["sensor_1"], o2["sensor_1"])
    e3 = parallel_env()
    e3.reset(seed=1)
    e3.step({k: [0.25, -0.5] for k in a32})  # plain lists are accepted too
    np.testing.assert_array_equal(e3.sensors, e1.sensors)


@pytest.mark.parametrize(
    "actions, match",
    [
        ({"sensor_0": [np.nan, 0.0], "sensor_1": [0, 0], "sensor_2": [0, 0]}, "'sensor_0'"),
        ({"sensor_0": [0, 0], "sensor_1": [0, 0], "sensor_2": [0, np.inf]}, "'sensor_2'.*finite"),
        ({"sensor_0": [0, 0], "sensor_2": [0, 0]}, "missing action for agent 'sensor_1'"),
        ({"sensor_0": [0, 0, 0], "sensor_1": [0, 0], "sensor_2": [0, 0]}, "'sensor_0'.*shape"),
        ([[0, 0]] * 3, "dict"),
    ],
)
def test_bad_actions_raise_naming_the_agent(actions, match):
    env = parallel_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        env.step(actions)


def test_observing_an_unknown_agent_names_the_agents():
    env = parallel_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"agent must be one of \['sensor_0'"):
        env.observe("sensor_9")


@pytest.mark.parametrize(
    "config, field",
    [
        ({"n_sensors": 0}, "n_sensors"),
        ({"scenario": "nope"}, "scenario"),
        ({"bogus": 1}, "bogus"),
        ({"render_mode": "video"}, "render_mode"),
        ({"sigma_d2": (1.0, 2.0)}, "sigma_d2"),
        ({"rho": -1.0}, "rho"),
        ({"n_steps": 0}, "n_steps"),
        ({"reward_scale": 0.0}, "reward_scale"),
    ],
)
def test_config_errors_name_the_field(config, field):
    with pytest.raises(ValueError, match=field):
        parallel_env(**config)


def test_overrides_and_scenario_objects():
    env = parallel_env(scenario="homogeneous", n_sensors=8, rho=1.5)
    assert env.possible_agents == [f"sensor_{i}" for i in range(8)]
    np.testing.assert_array_equal(env.params.rho, np.full(8, 1.5))
    assert env.observation_space("sensor_7").shape == (5 + 6 * 8,)
    sc = make_scenario("paper", n_steps=7)
    assert parallel_env(scenario=sc).scenario == sc


def test_pickle_and_deepcopy_continue_identically():
    env = parallel_env(scenario="paper", render_mode="rgb_array")
    env.reset(seed=3)
    for _ in range(4):
        env.step({a: np.array([0.2, 0.3]) for a in env.agents})
    env.render()  # a live matplotlib figure must not break pickling
    clones = [pickle.loads(pickle.dumps(env)), copy.deepcopy(env)]
    actions = {a: np.array([-0.4, 0.1]) for a in env.agents}
    expected = env.step(actions)
    for clone in clones:
        got = clone.step(actions)
        np.testing.assert_array_equal(got[0]["sensor_2"], expected[0]["sensor_2"])
        assert got[1] == expected[1]
        assert clone.render().shape == env.render().shape


@pytest.mark.slow
def test_ten_thousand_random_steps_stay_finite_and_spd():
    env = parallel_env(scenario="paper", n_steps=10_000)
    env.reset(seed=0)
    for agent in env.possible_agents:
        env.action_space(agent).seed(1)
    steps = 0
    while env.agents:
        obs, rew, *_ = env.step({a: env.action_space(a).sample() for a in env.agents})
        P = env.P
        assert np.array_equal(P, P.T)
        np.linalg.cholesky(P)  # raises unless positive definite
        np.linalg.cholesky(env.P_pred)
        assert np.isfinite(rew["sensor_0"])
        assert all(np.isfinite(o).all() for o in obs.values())
        steps += 1
    assert steps == 10_000
    assert np.isfinite(env.state()).all()


def test_array_core_matches_the_dict_api():
    a, b = parallel_env(scenario="paper", n_steps=4), parallel_env(scenario="paper", n_steps=4)
    obs_a = a.reset_arrays(seed=2)
    obs_b, _ = b.reset(seed=2)
    assert a.agents == b.agents == a.possible_agents
    np.testing.assert_array_equal(obs_a, np.stack(list(obs_b.values())))
    for k in range(4):
        act = np.full((3, 2), 0.1 * k)
        obs_a, rew, term, trunc = a.step_arrays(act)
        obs_b, rew_b, term_b, trunc_b, _ = b.step(dict(zip(b.agents, act, strict=True)))
        np.testing.assert_array_equal(obs_a, np.stack(list(obs_b.values())))
        assert (rew, term, trunc) == (rew_b["sensor_0"], term_b["sensor_0"], trunc_b["sensor_0"])
        assert a.agents == b.agents
    assert a.agents == [] and trunc
