"""Registration with Gymnasium and PettingZoo."""

import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pettingzoo
import pytest

from activetrack.envs import ENV_ID, TrackingParallelEnv, register_envs


def test_registered_everywhere_and_idempotent():
    assert gym.spec(ENV_ID).max_episode_steps is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # re-registering must not warn "Overriding"
        register_envs()
        register_envs()


@pytest.mark.skipif(not hasattr(pettingzoo, "register"), reason="PettingZoo without registry")
def test_pettingzoo_make():
    par = pettingzoo.make("parallel", ENV_ID, scenario="homogeneous", n_sensors=2)
    assert isinstance(par, TrackingParallelEnv) and par.max_num_agents == 2
    aec = pettingzoo.make("aec", ENV_ID, scenario="paper")
    aec.reset(seed=0)
    assert aec.agent_selection == "sensor_0"
    aec.step(np.zeros(2, np.float32))
    assert aec.agent_selection == "sensor_1"


def test_gymnasium_module_prefix_in_a_fresh_interpreter():
    # "module:id" imports activetrack.envs (which registers) before looking the id up.
    code = (
        "import gymnasium as gym; "
        f"e = gym.make('activetrack.envs:{ENV_ID}', n_steps=2); "
        "print(e.reset(seed=0)[0].shape)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "(69,)"
