"""Fuzzed actions and positions in every environment: each works or raises a clear error.

For any input a user can pass (numbers of any size, NaN, inf, complex, strings, None,
ragged or mis-shaped sequences, missing or extra agents), a step either succeeds with
finite rewards and observations or raises a ``ValueError`` naming the agent (or the
argument), and the environment stays usable: a valid step afterwards succeeds.
"""

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from activetrack.envs import BatchedActiveTracking, CentralizedTrackingEnv, env, parallel_env

SETTINGS = settings(
    max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)

numbers = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(-(10**30), 10**30),
    st.complex_numbers(allow_nan=False, max_magnitude=10),
    st.booleans(),
)
values = st.one_of(
    st.lists(numbers, min_size=2, max_size=2),
    st.lists(numbers, min_size=0, max_size=4),
    st.tuples(st.floats(-1e308, 1e308), st.floats(-1e308, 1e308)),
    st.text(max_size=3),
    st.none(),
    st.lists(st.lists(st.floats(-2, 2), min_size=1, max_size=3), min_size=2, max_size=2),
)


def _finite(*arrays):
    return all(np.all(np.isfinite(np.asarray(a, dtype=np.float64))) for a in arrays)


@pytest.fixture(scope="module")
def par():
    return parallel_env("paper", n_steps=10**6)


@SETTINGS
@given(raw=st.dictionaries(st.sampled_from(["sensor_0", "sensor_1", "sensor_2", "x"]), values))
def test_parallel_env_actions(par, raw):
    par.reset(seed=0)
    for positions in (False, True):
        try:
            out = par.step_positions(raw) if positions else par.step(raw)
        except ValueError as exc:
            assert "agent" in str(exc) or "actions" in str(exc) or "positions" in str(exc)
        else:
            obs, rewards, *_ = out
            assert _finite(list(obs.values()), list(rewards.values()))
        obs, rewards, *_ = par.step({a: np.zeros(2) for a in par.agents})
        assert _finite(list(obs.values()), list(rewards.values()))


@SETTINGS
@given(raw=values)
def test_aec_env_action_of_one_agent(raw):
    aec = env("paper")
    aec.reset(seed=0)
    agent = aec.agent_selection
    try:
        aec.step(raw)
    except ValueError as exc:
        assert repr(agent) in str(exc)
        assert aec.agent_selection == agent  # nothing stored: the agent acts again
    for _ in range(2 * len(aec.agents)):  # the env stays usable for whole cycles
        obs, reward, term, trunc, _ = aec.last()
        assert _finite(obs, reward)
        aec.step(np.array([0.1, -0.2]))


@SETTINGS
@given(raw=st.one_of(values, st.lists(numbers, min_size=6, max_size=6)))
def test_gymnasium_view_joint_action(raw):
    cen = CentralizedTrackingEnv("paper")
    cen.reset(seed=0)
    try:
        obs, reward, *_ = cen.step(raw)
    except ValueError as exc:
        assert "action" in str(exc)
    else:
        assert _finite(obs, reward)
    obs, reward, *_ = cen.step(np.zeros(6))
    assert _finite(obs, reward)


@SETTINGS
@given(
    raw=st.one_of(
        st.lists(st.lists(numbers, min_size=6, max_size=6), min_size=3, max_size=3),
        st.lists(st.lists(numbers, min_size=0, max_size=7), min_size=0, max_size=4),
        st.floats(),
        st.text(max_size=2),
    )
)
def test_batched_env_actions(raw):
    b = BatchedActiveTracking(3, "paper")
    b.reset(seed=0)
    for step in (b.step, b.step_positions):
        try:
            obs, rewards, *_ = step(raw)
        except ValueError as exc:
            assert "actions" in str(exc) or "positions" in str(exc)
        else:
            assert _finite(obs, rewards)
    obs, rewards, *_ = b.step(np.zeros((3, 6)))
    assert _finite(obs, rewards)


def test_stepping_past_the_end_raises_in_every_view():
    p = parallel_env("paper", n_steps=2)
    c = CentralizedTrackingEnv("paper", n_steps=2)
    b = BatchedActiveTracking(2, "paper", autoreset_mode="Disabled", n_steps=2)
    p.reset(seed=0)
    c.reset(seed=0)
    b.reset(seed=0)
    for _ in range(2):
        p.step({a: np.zeros(2) for a in p.agents})
        c.step(np.zeros(6))
        b.step(np.zeros((2, 6)))
    with pytest.raises(RuntimeError, match="reset"):
        p.step({a: np.zeros(2) for a in p.possible_agents})
    with pytest.raises(RuntimeError, match="reset"):
        c.step(np.zeros(6))
    with pytest.raises(RuntimeError, match="reset"):
        b.step(np.zeros((2, 6)))
    b.reset(options={"reset_mask": np.array([True, True])})
    b.step(np.zeros((2, 6)))  # usable again after the reset


def test_unknown_reset_options_warn():
    for e in (parallel_env("paper"), CentralizedTrackingEnv("paper"), BatchedActiveTracking(2)):
        with pytest.warns(UserWarning, match="unknown options"):
            e.reset(seed=0, options={"bogus": 1})


def test_pettingzoo_probe_option_is_ignored_silently():
    # PettingZoo's api_test and parallel_api_test reset with options={"options": 1}.
    for e in (parallel_env("paper"), CentralizedTrackingEnv("paper"), BatchedActiveTracking(2)):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            e.reset(seed=0, options={"options": 1})
        with pytest.warns(UserWarning, match=r"unknown options \['bogus'\]"):
            e.reset(seed=0, options={"options": 1, "bogus": 2})
