"""PettingZoo's, Gymnasium's, SB3's, RLlib's and TorchRL's own checkers, for M = 1, 3 and
8 and on every registered id.

Every warning raised while a checker runs is collected and fails the test, except the one
saying that ``render_mode="human"`` has no display here (the suite runs headless). So the
checkers' warnings about our environments (infinite bounds, ignored reset options, ...)
are errors.
"""

import re
import warnings
from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pettingzoo
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import (
    api_test,
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
    seed_test,
    state_test,
)

from activetrack._registry import TWO_TEAM_ENTRY_POINTS
from activetrack.envs import ENV_ID, env, parallel_env
from activetrack.envs.registration import ALL_IDS

ALLOWED = re.compile(r"render_mode='human' needs an interactive matplotlib backend", re.I)

SIZES = [1, 3, 8]


def _config(m):
    return {"scenario": "homogeneous", "n_sensors": m}


#: PettingZoo's notes on agents whose observations differ in size: true of the two-team
#: games (a target observes less than a sensor), so allowed for their ids only.
HETEROGENEOUS = re.compile(
    r"Agents have different observation space sizes|Observations are different shapes"
)


def _run_checked(fn, *args, allowed=ALLOWED, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fn(*args, **kwargs)
    unexpected = [str(w.message) for w in caught if not allowed.search(str(w.message))]
    assert not unexpected, unexpected


def _allowed(env_id):
    """The warnings allowed for ``env_id``'s PettingZoo games."""
    if env_id in TWO_TEAM_ENTRY_POINTS:
        return re.compile(f"{ALLOWED.pattern}|{HETEROGENEOUS.pattern}", re.I)
    return ALLOWED


@pytest.mark.parametrize("m", SIZES)
def test_parallel_api(m):
    _run_checked(parallel_api_test, parallel_env(**_config(m)), num_cycles=200)


@pytest.mark.parametrize("m", SIZES)
def test_aec_api(m):
    _run_checked(api_test, env(**_config(m)), num_cycles=200)


@pytest.mark.parametrize("m", SIZES)
def test_seed_tests(m):
    _run_checked(parallel_seed_test, lambda: parallel_env(**_config(m)))
    _run_checked(seed_test, lambda: env(**_config(m)))


@pytest.mark.parametrize("m", SIZES)
def test_gymnasium_check_env(m):
    made = gym.make(ENV_ID, **_config(m))
    _run_checked(check_env, made.unwrapped)
    made.close()


def test_aec_env_is_the_converted_parallel_env():
    from pettingzoo.utils.conversions import parallel_to_aec_wrapper
    from pettingzoo.utils.wrappers import OrderEnforcingWrapper

    aec = env(scenario="paper")
    assert isinstance(aec, OrderEnforcingWrapper)
    assert isinstance(aec.env, parallel_to_aec_wrapper)
    aec.reset(seed=0)
    assert aec.state().shape == aec.state_space.shape == (24,)


# Every registered id (the paper and the tasks beyond it), made through the registries.
IDS = sorted(ALL_IDS)


def _parallel(env_id, **kw):
    return pettingzoo.make("parallel", env_id, **kw)


def _aec(env_id, **kw):
    return pettingzoo.make("aec", env_id, **kw)


@pytest.mark.parametrize("env_id", IDS)
def test_registered_ids_pass_the_pettingzoo_checkers(env_id):
    allowed = _allowed(env_id)
    _run_checked(parallel_api_test, _parallel(env_id), num_cycles=60, allowed=allowed)
    _run_checked(api_test, _aec(env_id), num_cycles=30, allowed=allowed)
    _run_checked(parallel_seed_test, lambda: _parallel(env_id), num_cycles=60, allowed=allowed)
    _run_checked(seed_test, lambda: _aec(env_id), num_cycles=60, allowed=allowed)
    _run_checked(state_test, _aec(env_id), _parallel(env_id), num_cycles=10, allowed=allowed)
    # max_cycles_test reads a module's parallel_env and env; max_cycles is n_steps.
    module = SimpleNamespace(
        parallel_env=lambda **kw: _parallel(env_id, **kw), env=lambda **kw: _aec(env_id, **kw)
    )
    _run_checked(max_cycles_test, module, allowed=allowed)


@pytest.mark.parametrize("env_id", IDS)
def test_registered_ids_pass_the_pettingzoo_render_test(env_id):
    # Five frames of every render mode; the ids differ in what they draw (several
    # targets, occluders, pose ellipses), so each id is rendered.
    _run_checked(render_test, lambda render_mode=None: _aec(env_id, render_mode=render_mode,
                                                            n_steps=6))  # fmt: skip


@pytest.mark.parametrize("env_id", IDS)
def test_registered_ids_pass_gymnasium_and_sb3_check_env(env_id):
    made = gym.make(env_id)
    assert made.unwrapped.scenario.name == ALL_IDS[env_id]
    _run_checked(check_env, made.unwrapped)
    sb3_check_env = pytest.importorskip("stable_baselines3.common.env_checker").check_env
    _run_checked(sb3_check_env, made.unwrapped, warn=True)
    made.close()
    vec = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (3, *made.observation_space.shape)
    assert vec.single_observation_space == made.observation_space
    vec.close()


@pytest.mark.parametrize("env_id", IDS)
def test_registered_ids_have_finite_spaces_that_hold_an_episode(env_id):
    # Finite everywhere, and every observation and state of a random episode inside
    # (checked entry by entry: the checkers test only a few steps).
    par = _parallel(env_id, n_steps=20)
    agent = par.possible_agents[0]
    for box in (par.observation_space(agent), par.state_space):
        assert np.isfinite(box.low).all() and np.isfinite(box.high).all()
    obs, _ = par.reset(seed=1)
    rng = np.random.default_rng(1)
    while par.agents:
        for a in par.agents:
            assert par.observation_space(a).contains(obs[a]), (env_id, a)
        assert par.state_space.contains(par.state())
        obs = par.step({a: rng.uniform(-1, 1, 2).astype(np.float32) for a in par.agents})[0]


@pytest.mark.parametrize("env_id", IDS)
def test_registered_ids_pass_the_rllib_env_check(env_id):
    pytest.importorskip("ray.rllib")
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
    from ray.rllib.utils.pre_checks.env import check_multiagent_environments

    env = ParallelPettingZooEnv(_parallel(env_id))
    _run_checked(check_multiagent_environments, env)


@pytest.mark.parametrize("env_id", IDS)
def test_registered_ids_pass_the_torchrl_spec_checks(env_id):
    libs = pytest.importorskip("torchrl.envs")
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    gym_env = libs.GymEnv(env_id, n_steps=4)
    _run_checked(check_env_specs, gym_env, seed=0)
    with warnings.catch_warnings():  # TorchRL's note on the PettingZoo versions it tests
        warnings.filterwarnings("ignore", "PettingZoo in TorchRL is tested", UserWarning)
        pz_env = PettingZooWrapper(_parallel(env_id, n_steps=4), use_mask=False)
    _run_checked(check_env_specs, pz_env, seed=0)
