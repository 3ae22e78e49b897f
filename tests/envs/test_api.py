"""PettingZoo's and Gymnasium's own API checkers, for M = 1, 3 and 8.

Every warning the checkers raise is collected; only the advisory ones about unbounded
observation entries (positions and log-variances are unbounded by nature) and about
``render_mode="human"`` without a display are allowed.
"""

import re
import warnings

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, seed_test

from activetrack.envs import ENV_ID, env, parallel_env
from activetrack.envs.registration import ALL_IDS

ALLOWED = re.compile(
    r"observation space (maximum|minimum) value is -?infinity"
    r"|(maximum|minimum) observation space value is -?infinity"
    r"|render_mode='human' needs an interactive matplotlib backend"
    r"|reset\(\) ignores unknown options \['options'\]",  # PettingZoo's probe
    re.I,
)

SIZES = [1, 3, 8]


def _config(m):
    return {"scenario": "homogeneous", "n_sensors": m}


def _run_checked(fn, *args, **kwargs):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fn(*args, **kwargs)
    unexpected = [str(w.message) for w in caught if not ALLOWED.search(str(w.message))]
    assert not unexpected, unexpected


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


@pytest.mark.parametrize("env_id", IDS)
def test_registered_ids_pass_the_pettingzoo_checkers(env_id):
    import pettingzoo

    _run_checked(parallel_api_test, pettingzoo.make("parallel", env_id), num_cycles=60)
    _run_checked(api_test, pettingzoo.make("aec", env_id), num_cycles=30)
    _run_checked(parallel_seed_test, lambda: pettingzoo.make("parallel", env_id))
    _run_checked(seed_test, lambda: pettingzoo.make("aec", env_id))


@pytest.mark.parametrize("env_id", IDS)
def test_registered_ids_pass_gymnasium_check_env(env_id):
    made = gym.make(env_id)
    assert made.unwrapped.scenario.name == ALL_IDS[env_id]
    _run_checked(check_env, made.unwrapped)
    made.close()
    vec = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    obs, _ = vec.reset(seed=0)
    assert obs.shape == (3, *made.observation_space.shape)
    vec.close()
