"""Registration with Gymnasium and PettingZoo."""

import json
import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pettingzoo
import pytest

from activetrack.envs import ENV_ID, TrackingParallelEnv, register_envs
from activetrack.envs.registration import ALL_IDS

TASK = "activetrack/BearingOnly-v0"


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


# In a fresh interpreter: import activetrack (which must not load the frameworks), then
# import them in either order, and make every id through both registries. The probe
# importlib.util.find_spec("gymnasium") is what TorchRL does at import: a lookup that is
# no import must not use up the registration.
FRESH_MAKE = """
import importlib.util, json, sys
{before}
import activetrack
loaded = [m for m in ("gymnasium", "pettingzoo") if m in sys.modules]
importlib.util.find_spec("gymnasium")
{after}
gym.register_envs(activetrack)  # Gymnasium's idiom (a no-op naming the module)
made = {{}}
for env_id in {ids!r}:
    g = gym.make(env_id).unwrapped
    p = pettingzoo.make("parallel", env_id)
    a = pettingzoo.make("aec", env_id)
    made[env_id] = [g.scenario.name, p.scenario.name, a.unwrapped.scenario.name]
print(json.dumps([loaded, made]))
"""
BEFORE_AFTER = {
    "frameworks imported after activetrack": ("", "import pettingzoo, gymnasium as gym"),
    "gymnasium alone after activetrack": ("", "import gymnasium as gym; import pettingzoo"),
    "frameworks imported before activetrack": ("import gymnasium as gym, pettingzoo", ""),
}


@pytest.mark.parametrize("order", BEFORE_AFTER)
def test_import_activetrack_registers_every_id_with_both_frameworks(order, tmp_path):
    before, after = BEFORE_AFTER[order]
    out = run_fresh(FRESH_MAKE.format(before=before, after=after, ids=list(ALL_IDS)), tmp_path)
    assert out.returncode == 0, out.stderr
    loaded, made = json.loads(out.stdout.strip().splitlines()[-1])
    # activetrack itself loads neither framework; they are there only if imported before it.
    assert loaded == (["gymnasium", "pettingzoo"] if before else [])
    assert made == {env_id: [preset] * 3 for env_id, preset in ALL_IDS.items()}


def test_gymnasium_imported_alone_registers_only_with_gymnasium(tmp_path):
    # The hook registers with the framework being imported: importing gymnasium must not
    # drag pettingzoo in.
    code = (
        "import sys, activetrack, gymnasium as gym\n"
        f"print('pettingzoo' in sys.modules, {ENV_ID!r} in gym.registry)\n"
    )
    out = run_fresh(code, tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "True"]


def test_the_module_prefix_imports_activetrack_in_a_fresh_interpreter(tmp_path):
    # Where nothing imported activetrack (a spawned worker of a `python -c` main), the id
    # may name the module: gymnasium imports it, which registers.
    code = (
        "import gymnasium as gym\n"
        f"e = gym.make('activetrack:{TASK}')\n"
        "print(e.unwrapped.scenario.name)\n"
    )
    out = run_fresh(code, tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == ALL_IDS[TASK]


def test_activetrack_imports_and_works_without_gymnasium_and_pettingzoo(tmp_path):
    # A finder in front of the import system plays the frameworks' absence: importing
    # them raises ModuleNotFoundError as when they are not installed. The core imports,
    # registers nothing, fails on nothing, and computes.
    code = (
        "import sys\n"
        "class Absent:\n"
        "    def find_spec(self, name, path, target=None):\n"
        "        if name.split('.')[0] in ('gymnasium', 'pettingzoo'):\n"
        "            raise ModuleNotFoundError(f'No module named {name!r}', name=name)\n"
        "sys.meta_path.insert(0, Absent())\n"
        "import activetrack\n"
        "sc = activetrack.make_scenario('paper')\n"
        "print(sc.n_sensors)\n"
        "try:\n"
        "    import gymnasium\n"
        "except ModuleNotFoundError as e:\n"
        "    print('absent', e.name)\n"
    )
    out = run_fresh(code, tmp_path)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["3", "absent", "gymnasium"]
    assert out.stderr == ""


SPAWNED = """
import activetrack  # registers, again in each spawned worker (which re-imports this file)

if __name__ == "__main__":
    import json
    import multiprocessing

    from torchrl.envs import GymEnv

    env = GymEnv({env_id!r}, num_envs=2, scenario="homogeneous", n_sensors=2, n_steps=3)
    td = env.reset(seed=3)
    print(json.dumps([multiprocessing.get_start_method(), list(env.batch_size),
                      td["observation"].tolist()]))
    env.close()
"""


@pytest.mark.slow  # two spawned workers each import torch and torchrl
def test_torchrl_gymenv_with_spawned_workers(tmp_path):
    pytest.importorskip("torchrl")
    script = tmp_path / "main.py"
    script.write_text(SPAWNED.format(env_id=ENV_ID))
    out = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, cwd=tmp_path
    )
    assert out.returncode == 0, out.stderr
    method, batch, obs = json.loads(out.stdout.strip().splitlines()[-1])
    assert method == "spawn" and batch == [2]
    # Gymnasium's AsyncVectorEnv seeds copy i with seed + i: each row is a single env's.
    for i, row in enumerate(obs):
        ref, _ = gym.make(ENV_ID, scenario="homogeneous", n_sensors=2, n_steps=3).reset(seed=3 + i)
        np.testing.assert_allclose(row, ref, rtol=1e-6, atol=0)
