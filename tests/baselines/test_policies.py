"""Expert policies drive the environments through ``step_positions``, like the runner.

The environments and :func:`activetrack.baselines.simulation.simulate` are adapters over
one loop (:class:`activetrack.world.World`) with the world generator ``default_rng(seed)``
and the planner generator ``default_rng([seed, 1])``; an expert's positions are executed
as planned, so an episode through an environment equals the runner's run bit for bit.
The loop itself is checked against an independent longhand loop in
``tests/core/test_world.py``.
"""

import importlib
import pathlib
import re

import gymnasium as gym
import numpy as np
import pytest

from activetrack import make_scenario
from activetrack.baselines.policies import PlannerPolicy
from activetrack.envs import ENV_ID, env, parallel_env
from activetrack.kinematics.sensor_motion import actions_to_reach

simulation = pytest.importorskip("activetrack.baselines.simulation")


def _planner(name):
    """Return a fresh planner exported by activetrack.baselines.

    Skips only while the planner is not written at all; fails if its class exists in the
    package but is not exported (so these tests cannot silently skip forever).
    """
    baselines = importlib.import_module("activetrack.baselines")
    if hasattr(baselines, name):
        return getattr(baselines, name)()
    package = pathlib.Path(baselines.__file__).parent
    defined = re.compile(rf"^class {name}\b", re.M)
    written = any(defined.search(p.read_text()) for p in package.glob("*.py"))
    if written:
        pytest.fail(f"activetrack.baselines defines {name} but does not export it")
    pytest.skip(f"activetrack.baselines.{name} is not written yet")


def _policy_class(name):
    from activetrack.baselines import policies

    return getattr(policies, name)


def _run_env(sc, policy, seed):
    e = parallel_env(scenario=sc)
    e.reset(seed=seed)
    sensors, trues, ests, covs, rewards = [e.sensors], [e.x_true], [e.x_hat], [e.P[:2, :2]], []
    while e.agents:
        _, rew, *_ = e.step_positions(policy.plan(e.planning_problem()))
        rewards.append(rew["sensor_0"])
        sensors.append(e.sensors)
        trues.append(e.x_true)
        ests.append(e.x_hat)
        covs.append(e.P[:2, :2])
    return tuple(map(np.array, (sensors, trues, ests, covs, rewards)))


CASES = [
    ("GSR", "GSRPolicy", {"scenario": "paper"}, [0, 1, 2]),
    ("GSR", "GSRPolicy", {"scenario": "homogeneous", "n_sensors": 5}, [3]),
    ("RandomMotion", "RMPolicy", {"scenario": "paper"}, [0, 1]),
    ("RandomMotion", "RMPolicy", {"scenario": "homogeneous", "n_sensors": 8}, [3]),
    ("GBES", "GBESPolicy", {"scenario": "paper", "n_steps": 20}, [0]),
]


@pytest.mark.parametrize("planner_name, policy_name, config, seeds", CASES)
def test_env_reproduces_the_simulation_runner(planner_name, policy_name, config, seeds):
    sc = make_scenario(config.pop("scenario"), **config)
    for seed in seeds:
        record = simulation.simulate(sc, _planner(planner_name), seed)
        policy = _policy_class(policy_name)(seed=seed)
        sensors, trues, ests, covs, rewards = _run_env(sc, policy, seed)
        assert len(rewards) == len(record.trace) == sc.n_steps
        np.testing.assert_array_equal(trues, record.true_states)  # the same world draws
        np.testing.assert_array_equal(sensors, record.sensors)
        np.testing.assert_array_equal(ests, record.estimates)
        np.testing.assert_array_equal(covs, record.position_covs)
        np.testing.assert_array_equal(-rewards, record.trace)


def test_policy_owns_a_runner_seeded_generator():
    rm = _planner("RandomMotion")
    policy = PlannerPolicy(rm, seed=7)
    np.testing.assert_array_equal(policy.rng.random(4), np.random.default_rng([7, 1]).random(4))
    policy.reset(seed=7)
    np.testing.assert_array_equal(policy.rng.random(4), np.random.default_rng([7, 1]).random(4))


def test_actions_to_reach_give_the_planned_positions_through_the_actions_path():
    # For users who need actions (e.g. imitation labels): the actions behind an expert's
    # positions move the sensors there through step(), to rounding.
    expert = PlannerPolicy(_planner("RandomMotion"), seed=0)
    e = parallel_env(scenario="homogeneous", n_sensors=4)
    e.reset(seed=0)
    while e.agents:
        problem = e.planning_problem()
        planned = expert.plan(problem)
        a = actions_to_reach(planned, problem.sensors, problem.r)
        assert np.all(np.hypot(a[:, 0], a[:, 1]) <= 1 + 1e-12)
        e.step(dict(zip(e.agents, a, strict=True)))
        np.testing.assert_allclose(e.sensors, planned, rtol=0, atol=1e-12)
        assert problem.violation(e.sensors).max() < 1e-9


def test_same_trajectory_in_aec_and_centralized_envs():
    sc = make_scenario("paper", n_steps=15)
    sensors_par, *_ = _run_env(sc, PlannerPolicy(_planner("RandomMotion"), seed=2), 2)

    aec = env(scenario=sc)
    aec.reset(seed=2)
    policy = PlannerPolicy(_planner("RandomMotion"), seed=2)
    got = [aec.unwrapped.sensors]
    for agent in aec.agent_iter():
        _, _, term, trunc, _ = aec.last()
        if term or trunc:
            aec.step(None)
            continue
        if agent == "sensor_0":  # plan once per cycle, when the cycle starts
            problem = aec.unwrapped.planning_problem()
            actions = actions_to_reach(policy.plan(problem), problem.sensors, problem.r)
        aec.step(actions[aec.unwrapped.possible_agents.index(agent)])
        if agent == aec.unwrapped.possible_agents[-1]:
            got.append(aec.unwrapped.sensors)
    np.testing.assert_allclose(np.array(got), sensors_par, rtol=0, atol=1e-12)  # via actions

    cen = gym.make(ENV_ID, scenario=sc)
    cen.reset(seed=2)
    policy = PlannerPolicy(_planner("RandomMotion"), seed=2)
    got = [cen.unwrapped.env.sensors]
    done = False
    while not done:
        *_, term, trunc, _ = cen.unwrapped.step_positions(
            policy.plan(cen.unwrapped.planning_problem())
        )
        got.append(cen.unwrapped.env.sensors)
        done = term or trunc
    np.testing.assert_array_equal(np.array(got), sensors_par)


# Which prediction an expert plans from (activetrack.world.planning_prediction) ----------
def _imm_world(spec, n=2, seeds=(5, 6), **overrides):
    from activetrack.world import World

    w = World("maneuvering", n, estimator=spec, **overrides)
    w.reset(seeds=list(seeds))
    return w


def test_with_one_mode_the_mixture_and_the_single_model_plan_alike():
    # An IMM of one mode (the filter's own model) is its own mixture: GSR planning from
    # the mixture and from mode 0 drive the same episodes; so does the look-ahead.
    from activetrack import IMMSpec
    from activetrack.baselines.policies import GSRPolicy, LookaheadPolicy

    sc = make_scenario("maneuvering")
    spec = IMMSpec([sc.target_models[0]], [[1.0]])
    for make, n_steps in ((GSRPolicy, sc.n_steps), (LookaheadPolicy, 3)):
        worlds = [_imm_world(spec) for _ in range(2)]
        policies = [make(seed=0), make(seed=0, prediction=0)]
        for _ in range(n_steps):
            plans = [p.plan(w.planning_problem()) for p, w in zip(policies, worlds, strict=True)]
            np.testing.assert_array_equal(plans[0], plans[1])
            for w, plan in zip(worlds, plans, strict=True):
                w.step(plan)
        np.testing.assert_array_equal(worlds[0].sensors, worlds[1].sensors)


def test_the_planner_sees_the_chosen_modes_prediction():
    # The problem the planner gets, against the mode's prediction read off the world's
    # problem by hand; the look-ahead's plan is its plan of the problem built by hand at
    # that prediction (PlanningProblem.from_prediction, no choice involved).
    from activetrack import IMMSpec
    from activetrack.baselines.policies import LookaheadPolicy
    from activetrack.world.presets import MANEUVERING
    from activetrack.world.problem import PlanningProblem, Prediction

    w = _imm_world(IMMSpec.from_behaviour(MANEUVERING), n=1, seeds=(2,))
    for _ in range(5):
        w.step_actions(np.full((1, w.n_sensors, 2), 0.4))
    problem = w.planning_problem(0)
    modes, q = problem.prediction.modes, problem.prediction
    seen = []

    class Recording:
        def plan(self, prob, rng):
            seen.append(prob)
            return prob.sensors

    for j in (0, 1, 2):
        PlannerPolicy(Recording(), seed=0, prediction=j).plan(problem)
        np.testing.assert_array_equal(seen[-1].target, modes.means[j, :2])
        np.testing.assert_array_equal(seen[-1].prior_cov, modes.covs[j, :2, :2])
        np.testing.assert_array_equal(seen[-1].sensors, problem.sensors)
    PlannerPolicy(Recording(), seed=0).plan(problem)
    assert seen[-1] is problem
    by_hand = PlanningProblem.from_prediction(
        Prediction(modes.means[0], modes.covs[0], q.Phi, q.Q),
        sensors=problem.sensors, r=problem.r, rho=problem.rho, sigma_d2=problem.sigma_d2,
        sigma_theta2=problem.sigma_theta2,
    )  # fmt: skip
    single = LookaheadPolicy(seed=0, scenario=None, prediction=0).plan(problem)
    np.testing.assert_array_equal(single, LookaheadPolicy(seed=0, scenario=None).plan(by_hand))
    mixture = LookaheadPolicy(seed=0, scenario=None).plan(problem)
    assert np.max(np.abs(single - mixture)) > 1e-6  # the choice reached the look-ahead


def test_the_single_model_names_and_bad_predictions():
    from activetrack import IMMSpec
    from activetrack.baselines.policies import GSRPolicy, LookaheadPolicy, RMPolicy
    from activetrack.baselines.policy_specs import resolve_policy
    from activetrack.world.presets import MANEUVERING

    gsr, ahead = resolve_policy("gsr-single-model"), resolve_policy("lookahead-single-model")
    assert isinstance(gsr, GSRPolicy) and gsr.prediction == 0
    assert isinstance(ahead, LookaheadPolicy) and ahead.prediction == 0
    assert resolve_policy("gsr").prediction == "mixture"
    for bad in ("cv", -1, 0.0, True):
        with pytest.raises(ValueError, match="prediction must be 'mixture' or a mode index"):
            GSRPolicy(prediction=bad)
        with pytest.raises(ValueError, match="prediction must be 'mixture' or a mode index"):
            LookaheadPolicy(prediction=bad)
    problem = _imm_world(IMMSpec.from_behaviour(MANEUVERING), n=1, seeds=(0,)).planning_problem(0)
    with pytest.raises(ValueError, match=r"mode index in \[0, 2\]"):
        RMPolicy(seed=0, prediction=3).check(problem)  # before any episode (evaluate)
    with pytest.raises(ValueError, match=r"mode index in \[0, 2\]"):
        GSRPolicy(seed=0, prediction=3).plan(problem)
