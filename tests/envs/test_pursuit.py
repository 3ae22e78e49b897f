"""The two-team game ``activetrack/Pursuit-v0``: zero-sum rewards, the targets'
observation read back from the world, the targets' actions as their motion, and errors
naming the agent or the field. (PettingZoo's checkers run on it in test_api.py.)"""

import math

import numpy as np
import pettingzoo
import pytest

import activetrack  # noqa: F401  (registers the ids)
from activetrack import Controlled, make_scenario
from activetrack.envs.pursuit import PursuitParallelEnv
from activetrack.envs.tracking_env import TrackingParallelEnv

ID = "activetrack/Pursuit-v0"


def test_the_registered_game_has_two_opposed_teams():
    env = pettingzoo.make("parallel", ID)
    assert env.possible_agents == ["sensor_0", "sensor_1", "sensor_2", "sensor_3", "target_0"]
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(0)
    while env.agents:
        x = env.unwrapped.world.get("x_true", 0)[:2].copy()
        act = {a: rng.uniform(-1, 1, 2) for a in env.agents}
        obs, rew, term, trunc, infos = env.step(act)
        # Zero-sum, and the sensors' reward is minus the posterior trace (eq. 12, 17).
        trace = infos["sensor_0"]["trace"]
        assert rew["target_0"] == -rew["sensor_0"] == pytest.approx(trace, rel=1e-12)
        # The target moved by its action: speed * dt * a, a inside the unit disk.
        a = act["target_0"] / max(1.0, float(np.hypot(*act["target_0"])))
        np.testing.assert_allclose(env.unwrapped.world.get("x_true", 0)[:2], x + a, atol=1e-12)
        assert term["target_0"] == term["sensor_0"] and trunc["target_0"] == trunc["sensor_0"]
    assert trunc["target_0"] and not env.agents


def test_the_target_observation_is_the_world_s_state_in_its_layout():
    env = PursuitParallelEnv()
    obs, _ = env.reset(seed=5)
    env.step({a: env.action_space(a).sample() for a in env.agents})
    o = env.observe("target_0").astype(np.float64)
    w = env.world
    L, x, s = w.length_scale, w.get("x_true", 0), w.get("sensors", 0)
    m = 4
    np.testing.assert_allclose(o[:2], x[:2] / L, rtol=1e-6)
    np.testing.assert_allclose(o[2:4], x[2:4] / 10.0, rtol=1e-6)
    np.testing.assert_allclose(o[4 : 4 + 2 * m], ((s - x[:2]) / L).ravel(), rtol=1e-6, atol=1e-7)
    assert o[4 + 2 * m] == pytest.approx(math.log(float(w.get("trace", 0)) / L**2), rel=1e-6)
    assert o[5 + 2 * m] == pytest.approx(1 / 50) and o[6 + 2 * m] == 1.0
    assert env.observation_space("target_0").contains(env.observe("target_0"))


def test_gsr_sensors_against_the_fallback_are_the_evader_task():
    # step_positions without target actions: the target is the scripted evader, so the
    # sensors' rewards are the evader task's tracking game's, bit for bit.
    from activetrack.baselines import GSRPolicy

    pursuit, evader = PursuitParallelEnv(), TrackingParallelEnv("evader")
    pursuit.reset(seed=11)
    evader.reset(seed=11)
    gsr = GSRPolicy(seed=0)
    for _ in range(10):
        plan = gsr.plan(evader.planning_problem())
        np.testing.assert_array_equal(plan, gsr.plan(pursuit.planning_problem()))
        r1 = pursuit.step_positions(plan)[1]
        r2 = evader.step_positions(plan)[1]
        assert r1["sensor_0"] == r2["sensor_0"] == -r1["target_0"]


def test_errors_name_the_agent_or_the_field():
    env = PursuitParallelEnv()
    env.reset(seed=0)
    act = {a: np.zeros(2) for a in env.agents}
    with pytest.raises(ValueError, match="target_0"):
        env.step({**act, "target_0": np.array([np.nan, 0.0])})
    with pytest.raises(ValueError, match="missing action for agent 'target_0'"):
        env.step({a: v for a, v in act.items() if a != "target_0"})
    with pytest.raises(ValueError, match="target_behaviour"):
        PursuitParallelEnv("evader")
    # Several targets, one controlled: one target agent, for the controlled one.
    two = make_scenario("two_targets", target_behaviour=(
        Controlled(10.0, 0.1), make_scenario("evader").target_behaviour))  # fmt: skip
    env2 = PursuitParallelEnv(two)
    assert env2.target_agents == ["target_0"]
    obs, _ = env2.reset(seed=0)
    assert env2.observation_space("target_0").contains(obs["target_0"])


def test_with_limited_sensing_a_target_observes_which_sensors_detected_it():
    sc = make_scenario("urban", target_behaviour=Controlled(5.0, 0.1))
    env = PursuitParallelEnv(sc)
    env.reset(seed=2)
    rng = np.random.default_rng(2)
    seen = []
    for _ in range(30):
        obs = env.step({a: rng.uniform(-1, 1, 2) for a in env.agents})[0]
        flags = obs["target_0"][-4:]
        np.testing.assert_array_equal(flags, env.world.get("detected", 0)[0].astype(np.float32))
        seen.append(flags)
    assert 0 < np.mean(seen) < 1  # both cases occur (a test of the flags, not a constant)
    assert env.observation_space("target_0").shape == (7 + 2 * 4 + 4,)
