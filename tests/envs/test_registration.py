"""Registration with Gymnasium and PettingZoo."""

import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pettingzoo

from activetrack.envs import ENV_ID, TrackingParallelEnv, register_envs


def run_fresh(code: str, cwd) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter (nothing imported yet) outside the repository."""
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=cwd)


def test_registered_everywhere_and_idempotent():
    spec = gym.spec(ENV_ID)
    assert spec.max_episode_steps is None  # the env truncates itself: no second TimeLimit
    assert spec.vector_entry_point == "activetrack.envs.batched:BatchedActiveTracking"
    assert ENV_ID in pettingzoo.parallel_registry and ENV_ID in pettingzoo.aec_registry
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # re-registering must not warn "Overriding"
        register_envs()
        register_envs()


def test_pettingzoo_make():
    par = pettingzoo.make("parallel", ENV_ID, scenario="homogeneous", n_sensors=2)
    assert isinstance(par, TrackingParallelEnv) and par.max_num_agents == 2
    aec = pettingzoo.make("aec", ENV_ID, scenario="paper")
    aec.reset(seed=0)
    assert aec.agent_selection == "sensor_0"
    aec.step(np.zeros(2, np.float32))
    assert aec.agent_selection == "sensor_1"


def test_gymnasium_module_prefix_in_a_fresh_interpreter(tmp_path):
    # "module:id" imports activetrack.envs (which registers) before looking the id up;
    # the paper preset has M = 3 sensors, so the joint observation is M (5 + 6M) = 69 long.
    code = (
        "import gymnasium as gym; "
        f"e = gym.make('activetrack.envs:{ENV_ID}', n_steps=2); "
        "v = gym.make_vec('activetrack.envs:" + ENV_ID + "', num_envs=2); "
        "print(e.reset(seed=0)[0].shape, type(v).__name__, v.reset(seed=0)[0].shape)"
    )
    out = run_fresh(code, tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "(69,) BatchedActiveTracking (2, 69)"


def test_bare_id_needs_the_module_prefix_in_a_fresh_interpreter(tmp_path):
    # Gymnasium (>= 1.0) loads no plugins, so nothing registers the id until
    # activetrack.envs is imported; this is why the docs give the "module:id" form.
    code = f"import gymnasium as gym; gym.make('{ENV_ID}')"
    out = run_fresh(code, tmp_path)
    assert out.returncode != 0 and "Namespace activetrack not found" in out.stderr
