"""The conventions other RL libraries rely on: PettingZoo's tests, TorchRL's wrappers and
Gymnasium's ``make_vec``.

The TorchRL rollouts are checked against the environment stepped directly with the same
seed and actions (TorchRL converts to float32, hence the tolerance).
"""

import subprocess
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest

import activetrack.envs
from activetrack.envs import ENV_ID, BatchedActiveTracking, CentralizedTrackingEnv, parallel_env

CONFIG = dict(scenario="homogeneous", n_sensors=2, n_steps=5)
F32 = dict(rtol=1e-5, atol=1e-5)


def fixed_actions(n_steps: int, dim: int, seed: int = 1) -> np.ndarray:
    """Return reproducible actions in the action box [-1, 1]^dim, one row per step."""
    return np.random.default_rng(seed).uniform(-1, 1, (n_steps, dim)).astype(np.float32)


def replaying(actions, key):
    """Return a TorchRL policy writing the next row of ``actions`` under ``key``."""
    import torch

    rows = iter(actions)

    def policy(td):
        td[key] = torch.as_tensor(next(rows))
        return td

    return policy


def test_pettingzoo_max_cycles_test():
    from pettingzoo.test import max_cycles_test

    max_cycles_test(activetrack.envs)  # uses the module's parallel_env and env


def test_torchrl_gymenv_rollout_matches_the_environment():
    GymEnv = pytest.importorskip("torchrl.envs").GymEnv
    env = GymEnv(ENV_ID, **CONFIG)
    actions = fixed_actions(CONFIG["n_steps"], 2 * CONFIG["n_sensors"])
    td0 = env.reset(seed=7)
    td = env.rollout(10, policy=replaying(actions, "action"), auto_reset=False, tensordict=td0)

    ref = CentralizedTrackingEnv(**CONFIG)
    obs, _ = ref.reset(seed=7)
    steps = [ref.step(a) for a in actions]
    assert td.batch_size == (CONFIG["n_steps"],)  # stopped at the env's own truncation
    np.testing.assert_allclose(td["observation"][0].numpy(), obs, **F32)
    np.testing.assert_allclose(
        td["next", "reward"].squeeze(-1).numpy(), [s[1] for s in steps], **F32
    )
    np.testing.assert_allclose(td["next", "observation"][-1].numpy(), steps[-1][0], **F32)
    assert td["next", "truncated"].squeeze(-1).tolist() == [s[3] for s in steps]
    assert not td["next", "terminated"].any()


def test_torchrl_gymwrapper_over_the_batched_env_with_autoreset_disabled():
    # TorchRL's GymWrapper resets a VectorEnv's ended copies itself (reset_mask): the
    # batched env must run with autoreset_mode="Disabled", as its docstring says. (With
    # "SameStep" TorchRL's own extra reset() after reset(seed=...) loses the seeding.)
    GymWrapper = pytest.importorskip("torchrl.envs").GymWrapper
    n, steps = 3, 2 * CONFIG["n_steps"] + 2  # crosses two episode ends
    env = GymWrapper(BatchedActiveTracking(n, autoreset_mode="Disabled", **CONFIG))
    assert env.batch_size == (n,)
    m = CONFIG["n_sensors"]
    actions = fixed_actions(steps, n * 2 * m).reshape(steps, n, 2 * m)
    td0 = env.reset(seed=7)
    td = env.rollout(
        steps, policy=replaying(actions, "action"), auto_reset=False, tensordict=td0,
        break_when_any_done=False,
    )  # fmt: skip

    ref = BatchedActiveTracking(n, autoreset_mode="SameStep", **CONFIG)
    obs, _ = ref.reset(seed=7)
    out = [ref.step(a) for a in actions]
    assert td.batch_size == (n, steps)
    np.testing.assert_allclose(td["observation"][:, 0].numpy(), obs, **F32)
    rewards = np.stack([o[1] for o in out], axis=1)
    np.testing.assert_allclose(td["next", "reward"].squeeze(-1).numpy(), rewards, **F32)
    truncated = np.stack([o[3] for o in out], axis=1)
    assert td["next", "truncated"].squeeze(-1).numpy().tolist() == truncated.tolist()
    assert truncated.sum() == 2 * n


def test_torchrl_pettingzoo_wrapper_rollout_matches_the_environment():
    PettingZooWrapper = pytest.importorskip("torchrl.envs.libs.pettingzoo").PettingZooWrapper
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "PettingZoo in TorchRL is tested", UserWarning)
        env = PettingZooWrapper(parallel_env(**CONFIG), use_mask=False)
    m, n = CONFIG["n_sensors"], CONFIG["n_steps"]
    assert env.group_map == {"sensor": [f"sensor_{i}" for i in range(m)]}
    actions = fixed_actions(n, 2 * m).reshape(n, m, 2)
    td0 = env.reset(seed=7)
    td = env.rollout(10, policy=replaying(actions, ("sensor", "action")), auto_reset=False,
                     tensordict=td0)  # fmt: skip

    ref = parallel_env(**CONFIG)
    obs, _ = ref.reset(seed=7)
    agents = ref.possible_agents
    steps = [ref.step({a: act[i] for i, a in enumerate(agents)}) for act in actions]
    assert td.batch_size == (n,)
    np.testing.assert_allclose(
        td["sensor", "observation"][0].numpy(), np.stack([obs[a] for a in agents]), **F32
    )
    rewards = np.array([[s[1][a] for a in agents] for s in steps])
    np.testing.assert_allclose(td["next", "sensor", "reward"].squeeze(-1).numpy(), rewards, **F32)
    assert td["next", "truncated"].squeeze(-1).tolist() == [all(s[3].values()) for s in steps]


def test_gymnasium_make_vec_reaches_the_batched_env():
    vec = gym.make_vec(ENV_ID, num_envs=4, vectorization_mode="vector_entry_point", **CONFIG)
    assert isinstance(vec, BatchedActiveTracking) and vec.num_envs == 4
    assert vec.scenario.n_steps == CONFIG["n_steps"]  # keywords reach the scenario
    default = gym.make_vec(ENV_ID, num_envs=2, **CONFIG)  # the vector entry point is preferred
    assert isinstance(default, BatchedActiveTracking)
    # Copy i is seeded with s + i: its first observation is a single env's with that seed.
    obs, _ = vec.reset(seed=3)
    singles = [CentralizedTrackingEnv(**CONFIG).reset(seed=3 + i)[0] for i in range(4)]
    np.testing.assert_allclose(obs, np.stack(singles), rtol=0, atol=0)


def test_gymnasium_make_in_a_fresh_interpreter_without_importing_activetrack(tmp_path):
    # Gymnasium has no plugin loading: the "module:id" form imports activetrack.envs.
    code = (
        "import sys, gymnasium as gym\n"
        "assert 'activetrack' not in sys.modules\n"
        f"env = gym.make('activetrack.envs:{ENV_ID}', scenario='homogeneous', n_sensors=2)\n"
        "obs, _ = env.reset(seed=0)\n"
        "print(type(env.unwrapped).__name__, obs.shape)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    # M = 2 sensors observe 5 + 6M = 17 values each: 34 concatenated.
    assert out.stdout.split() == ["CentralizedTrackingEnv", "(34,)"]


def test_import_activetrack_pulls_in_neither_gymnasium_nor_pettingzoo(tmp_path):
    code = (
        "import sys, activetrack\n"
        "print([m for m in ('gymnasium', 'pettingzoo') if m in sys.modules])\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, check=True
    )
    assert out.stdout.strip() == "[]"


def _run_vec(vec, actions, seed=0):
    """Return the (obs, reward, terminated, truncated, infos) of every step of ``vec``."""
    out = [vec.reset(seed=seed)]
    for a in actions:
        out.append(vec.step(a))
    vec.close()
    return out


@pytest.mark.parametrize("mode", ["next_step", "same_step"])
@pytest.mark.parametrize(
    "keywords",
    [{"max_trace": 3.5}, {"max_episode_steps": 4}],
    ids=["terminations", "max_episode_steps"],
)
def test_make_vec_batched_equals_the_sync_vector_of_single_envs(mode, keywords):
    # The sync vector env steps gym.make's single environments (a TimeLimit for
    # max_episode_steps), one step of noise a call: the batched env, drawing noise in
    # blocks, must give the same numbers and infos across early episode ends.
    kw = {**CONFIG, "n_steps": 9, **keywords}
    vk = {"autoreset_mode": gym.vector.AutoresetMode(mode.capitalize().replace("_s", "S"))}
    actions = fixed_actions(30, 4).reshape(30, 1, 4).repeat(3, axis=1)
    actions[:, 1] *= -1.0
    batched = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point",
                           autoreset_mode=vk["autoreset_mode"], **kw)  # fmt: skip
    sync = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="sync", vector_kwargs=vk, **kw)
    ours, theirs = _run_vec(batched, actions), _run_vec(sync, actions)
    ends = 0
    for a, b in zip(ours, theirs, strict=True):
        np.testing.assert_array_equal(a[0], b[0])
        for got, want in zip(a[1:-1], b[1:-1], strict=True):
            np.testing.assert_array_equal(got, want)
        infos, expected = a[-1], b[-1]
        assert sorted(infos) == sorted(expected)
        for key in ("step", "trace", "position_error", "n_projected", "max_trace_exceeded"):
            # position_error: NumPy's hypot here, Python's math.hypot in the single env.
            tol = 1e-15 if key == "position_error" else 0.0
            np.testing.assert_allclose(infos[key], np.stack(expected[key]), rtol=tol, atol=0)
            np.testing.assert_array_equal(infos["_" + key], expected["_" + key])
        if "final_info" in expected:
            np.testing.assert_array_equal(infos["_final_info"], expected["_final_info"])
            done = expected["_final_info"]
            for key in ("trace", "max_trace_exceeded"):
                np.testing.assert_array_equal(
                    infos["final_info"][key][done], expected["final_info"][key][done]
                )
        if len(a) == 5:
            ends += int(np.count_nonzero(a[2] | a[3]))
    assert ends >= 3


def test_batched_render_gives_every_copys_frame_as_the_sync_vector_env():
    # Gymnasium's VectorEnv.render returns one frame per sub-environment (its vector
    # RecordVideo and HumanRendering wrappers rely on it): the same frames as the sync
    # vector env of single envs, across an episode's end (5 steps) and the autoreset.
    actions = fixed_actions(7, 4).reshape(7, 1, 4).repeat(2, axis=1)
    actions[:, 1] *= -1.0
    vec = gym.make_vec(ENV_ID, num_envs=2, render_mode="rgb_array", **CONFIG)
    sync = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="sync", render_mode="rgb_array",
                        **CONFIG)  # fmt: skip
    vec.reset(seed=5)
    sync.reset(seed=5)
    for a in [None, *actions]:
        if a is not None:
            vec.step(a)
            sync.step(a)
        frames, expected = vec.render(), sync.render()
        assert isinstance(frames, tuple) and len(frames) == 2
        for got, want in zip(frames, expected, strict=True):
            np.testing.assert_array_equal(got, want)
            assert got.dtype == np.uint8 and got.ndim == 3
    vec.close()
    sync.close()


def test_a_partial_reset_reports_the_reset_copies_and_seeds_as_sync():
    kw = {**CONFIG, "n_steps": 9, "max_trace": 3.5}
    vk = {"autoreset_mode": gym.vector.AutoresetMode.DISABLED}
    vec = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point", **vk, **kw)
    sync = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="sync", vector_kwargs=vk, **kw)
    for env in (vec, sync):
        env.reset(seed=[4, None, 6])
    assert vec.unwrapped.np_random_seed[::2] == sync.np_random_seed[::2] == (4, 6)
    assert vec.unwrapped.np_random_seed[1] == -1  # never seeded: unknown
    act = fixed_actions(1, 4).repeat(3, axis=0)
    np.testing.assert_array_equal(vec.step(act)[2], sync.step(act)[2])  # who ended on max_trace
    mask = np.array([False, True, False])
    ours, theirs = (
        vec.reset(seed=[None, 8, None], options={"reset_mask": mask}),
        sync.reset(seed=[None, 8, None], options={"reset_mask": mask}),
    )
    np.testing.assert_array_equal(ours[0], theirs[0])
    for key in ("step", "trace", "max_trace_exceeded"):
        np.testing.assert_array_equal(ours[1]["_" + key], theirs[1]["_" + key])
        np.testing.assert_array_equal(ours[1][key][mask], np.stack(theirs[1][key])[mask])
    assert vec.unwrapped.np_random_seed == (4, 8, 6)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"render_mode": "ascii"}, "render_mode"),
        ({"max_episode_steps": 0}, "max_episode_steps"),
        ({"max_episode_steps": "5"}, "max_episode_steps"),
    ],
)
def test_bad_gymnasium_keywords_of_the_batched_env_name_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        gym.make_vec(ENV_ID, num_envs=2, **kwargs)


@pytest.mark.parametrize("seed", [-1, 1.5, "a", True, [1, 2], np.float64(3)])
def test_bad_seeds_name_the_seed(seed):
    for env in (parallel_env(), CentralizedTrackingEnv()):
        with pytest.raises(ValueError, match="seed must be None or an integer >= 0"):
            env.reset(seed=seed)
    batched = BatchedActiveTracking(3)
    with pytest.raises(ValueError, match="seed"):
        batched.reset(seed=seed)
    with pytest.raises(ValueError, match=r"seed\[1\] must be None or an integer >= 0"):
        batched.reset(seed=[0, -1, 2])


@pytest.mark.parametrize("preset", ["paper", "mixed", "uncertain_poses"])
def test_sensor_constant_entries_lie_in_the_ranges_a_scenario_accepts(preset):
    # Entries 2-5 of every sensor block: ln(sigma_d / L) and ln(sigma_theta) within the
    # scenario's accepted variance ranges (0 too in the extended layout: a sensor without
    # that measurement), r / L and rho / L in [0, 1] as L >= rho + r.
    from activetrack.world import scenarios

    env = parallel_env(preset)
    L, layout = env.length_scale, env.world.layout
    d2, t2 = scenarios.SIGMA_D2_RANGE, scenarios.SIGMA_THETA2_RANGE
    low = [np.log(d2[0]) / 2 - np.log(L), np.log(t2[0]) / 2, 0.0, 0.0]
    high = [np.log(d2[1]) / 2 - np.log(L), np.log(t2[1]) / 2, 1.0, 1.0]
    if layout.extended:
        low, high = np.minimum(low, 0.0), np.maximum(high, 0.0)
    box = env.observation_space(env.possible_agents[0])
    obs, _ = env.reset(seed=0)
    for j in range(env.scenario.n_sensors):
        at = layout.target_dim + layout.sensor_dim * j + 2
        np.testing.assert_allclose(box.low[at : at + 4], low, rtol=1e-6)
        np.testing.assert_allclose(box.high[at : at + 4], high, rtol=1e-6)
        assert (box.low[at : at + 4] < box.high[at : at + 4]).all()  # no degenerate entry
        if layout.extended:  # the pose standard deviations: sqrt(POSE_COV_MAX) / L at most
            assert box.high[at + 7] == box.high[at + 8] == np.float32(1e4 / L)
    assert all(box.contains(o) for o in obs.values())


def test_unbounded_entries_are_clipped_at_the_documented_bounds():
    from activetrack.world import observation as ob

    # A target far off, fast, with a huge and a tiny variance, and one near: the near
    # one's entries are the formulas exactly, the far one's the formulas clipped.
    L, dt = 2.0, 0.5
    near = np.array([1.0, -2.0, 0.3, 0.4]), np.diag([0.5, 2.0, 1.0, 1.0])
    far = np.array([3e7, -3e7, 8e6, -8e6]), np.diag([1e50, 1e-50, 1.0, 1.0])
    sensors = np.array([[0.0, 0.0], [5.0, 1.0]])
    for (x, P), clipped in ((near, False), (far, True)):
        target, sensor = ob.features([x], [P], sensors, np.zeros((2, 4)), dt, L, False)
        want_t = [0.5 * np.log(P[0, 0] / L**2), 0.5 * np.log(P[1, 1] / L**2), 0.0,
                  x[2] * dt / L, x[3] * dt / L]  # fmt: skip
        want_s = (sensors - x[:2]) / L
        if clipped:
            want_t = np.clip(want_t, [-50, -50, -1, -1e6, -1e6], [50, 50, 1, 1e6, 1e6])
            want_s = np.clip(want_s, -1e6, 1e6)
            assert np.abs(want_t).max() == 1e6 and np.abs(want_s).max() == 1e6  # reached
        np.testing.assert_allclose(target, want_t, rtol=1e-15, atol=0)
        np.testing.assert_allclose(sensor[:, :2], want_s, rtol=1e-15, atol=0)
    low, high = ob.observation_bounds(2)
    assert (low[:2] == -50).all() and (high[3:5] == 1e6).all() and (high[5:7] == 1e6).all()
