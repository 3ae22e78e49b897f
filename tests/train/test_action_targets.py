"""Position targets (activetrack.train.action_targets): the network's point to the command.

Independent checks: the command's step is integrated numerically (the unicycle's ODE by
small Runge-Kutta steps, not the kinematics' closed-form chord); the projection onto the
reach set is compared with the nearest of a dense grid of commands' endpoints; GSR's
labels go command -> point -> target -> command; a saved policy acts as before saving and
moves the sensors in the env to the points its network asked for.
"""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import torch
from gymnasium import spaces

from activetrack.kinematics.disk import Disk
from activetrack.kinematics.unicycle import Unicycle
from activetrack.train.action_targets import PositionActions, check_target
from activetrack.train.imitation import ImitationConfig
from activetrack.train.networks import NetConfig, build_policy
from activetrack.train.policy_io import load_policy, save_policy
from activetrack.world.scenarios import make_scenario
from tests.core.helpers import rk4

UNI = Unicycle(0.0, 10.0, np.pi, dt=0.1)
WING = Unicycle(4.0, 10.0, 2.0 * np.pi / 3.0, dt=0.1)
UNIT = spaces.Box(-1.0, 1.0, (2,), np.float32)


def _integrate(k: Unicycle, action: np.ndarray, n: int = 2000) -> np.ndarray:
    """Return the endpoint of the unicycle's ODE from the origin facing +x under the
    normalized ``action``, by n classical Runge-Kutta steps."""
    v = k.v_min + 0.5 * (action[0] + 1.0) * (k.v_max - k.v_min)
    w = action[1] * k.w_max

    def f(s):
        return np.array([v * np.cos(s[2]), v * np.sin(s[2]), w])

    return rk4(f, np.zeros(3), k.dt, n)[-1, :2]


def _grid_endpoints(k: Unicycle, n: int = 401) -> np.ndarray:
    """Return the endpoints (n*n, 2) of a grid of commands (closed form of the arc, checked
    against the ODE in the test below), from the origin facing +x."""
    a0, a1 = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    v = k.v_min + 0.5 * (a0.ravel() + 1.0) * (k.v_max - k.v_min)
    w = a1.ravel() * k.w_max
    phi = 0.5 * w * k.dt
    chord = v * k.dt * np.where(phi == 0, 1.0, np.sin(phi) / np.where(phi == 0, 1.0, phi))
    return np.stack([chord * np.cos(phi), chord * np.sin(phi)], -1)


@pytest.mark.parametrize("k", [UNI, WING], ids=["unicycle", "fixed_wing"])
def test_the_command_reaches_the_wanted_point_when_reachable(k):
    head = PositionActions([k])
    rng = np.random.default_rng(0)
    # Reachable points: endpoints of random commands, by the ODE.
    cmds = rng.uniform(-1, 1, (12, 2))
    points = np.array([_integrate(k, c) for c in cmds])
    u = points / k.radius  # the heading frame at the origin facing +x
    actions = head.actions(u)
    for a, p in zip(actions, points, strict=True):
        np.testing.assert_allclose(_integrate(k, a), p, atol=1e-9 * k.radius)


@pytest.mark.parametrize("k", [UNI, WING], ids=["unicycle", "fixed_wing"])
def test_an_unreachable_point_gives_the_nearest_reachable_one(k):
    head = PositionActions([k])
    rng = np.random.default_rng(1)
    ang = rng.uniform(-np.pi, np.pi, 40)
    rad = rng.uniform(0.0, 1.0, 40)
    u = np.stack([rad * np.cos(ang), rad * np.sin(ang)], -1)
    grid = _grid_endpoints(k)
    # The grid's spacing in the endpoint plane: at most ~ radius * (2 / 400) * (pi/2).
    spacing = k.radius * 2.0 / 400 * 1.6
    for a, want in zip(head.actions(u), k.radius * u, strict=True):
        got = _integrate(k, a, n=400)
        best = np.min(np.hypot(*(grid - want).T))
        dist = np.hypot(*(got - want))
        # No command of the grid (a subset of the reach set) is nearer than ours, and the
        # grid comes within its spacing of every reachable point.
        assert best - spacing <= dist <= best + 1e-9


def test_a_point_behind_a_robot_that_can_stop_turns_it_in_place():
    head = PositionActions([UNI])
    a = head.actions(np.array([[-0.5, 0.2], [-0.5, -0.2], [-0.7, 0.0], [0.0, 0.0]]))
    # Every one is a standstill (v = 0: a0 = -1); the turn is the largest toward the side.
    np.testing.assert_array_equal(a[:, 0], -1.0)
    np.testing.assert_array_equal(a[:, 1], [1.0, -1.0, 1.0, 0.0])


def _gsr_steps(name: str, n_steps: int = 6):
    """Return GSR's planned positions and the team's states over a few steps of an
    episode of the preset ``name``: [(positions (M, 2), states (M, 3), problem)]."""
    from activetrack.baselines.policies import GSRPolicy
    from activetrack.envs import parallel_env
    from activetrack.kinematics.team import actions_to_reach

    env = parallel_env(name)
    env.reset(seed=5)
    gsr = GSRPolicy()
    out = []
    for _ in range(n_steps):
        problem = env.planning_problem()
        pos = np.asarray(gsr.plan(problem), np.float64)
        states = problem.sensor_states
        cmd = actions_to_reach(problem.kinematics, pos, states, problem.r)
        out.append((cmd, states))
        env.step({a: cmd[i].astype(np.float32) for i, a in enumerate(env.agents)})
    env.close()
    return out


@pytest.mark.parametrize("name", ["unicycle", "fixed_wing"])
def test_gsr_labels_round_trip_command_position_command(name):
    sc = make_scenario(name)
    head = PositionActions.from_scenario(sc)
    k = sc.kinematics_models[0]
    turned = 0
    for cmd, states in _gsr_steps(name):
        points = k.apply(cmd, states)  # GSR's command -> its point (the kinematics' arc)
        u = head.labels(points, states)
        assert np.all(np.hypot(*u.T) <= 1.0 + 1e-12)
        back = head.actions(u)
        np.testing.assert_allclose(back, cmd, rtol=0, atol=1e-9)
        turned += int(np.any(np.abs(cmd[:, 1]) > 0.05))
    assert turned > 0  # the episode's labels include turns (not only straight runs)


def test_labels_are_the_planned_point_in_the_heading_frame_over_the_reach():
    head = PositionActions([UNI, Disk(2.0)])
    states = np.array([[1.0, 2.0, np.pi / 2], [5.0, 5.0, 0.0]])
    points = np.array([[1.0, 2.5], [6.0, 5.0]])
    # Straight ahead of a robot facing +y by 0.5 m (reach 1 m); the disk's step in the world.
    np.testing.assert_allclose(head.labels(points, states), [[0.5, 0.0], [0.5, 0.0]], atol=1e-15)


def test_a_team_of_disks_keeps_the_command_target():
    assert PositionActions.from_scenario(make_scenario("paper")) is None
    assert PositionActions.from_scenario(make_scenario("crowded")) is None
    assert PositionActions.from_scenario(make_scenario("unicycle")) is not None


def test_rows_are_sensors_copy_after_copy():
    head = PositionActions([UNI, WING])
    u = np.array([[0.9, 0.05], [0.9, 0.05]])
    one = np.concatenate(
        [PositionActions([UNI]).actions(u[:1]), PositionActions([WING]).actions(u[1:])]
    )
    np.testing.assert_array_equal(head.actions(np.concatenate([u, u])), np.concatenate([one, one]))
    with pytest.raises(ValueError, match="multiple of the team size 2"):
        head.actions(u[:1])


def test_saved_policy_acts_identically_and_reaches_its_points(tmp_path):
    from activetrack.envs import parallel_env

    sc = make_scenario("unicycle")
    head = PositionActions.from_scenario(sc)
    env = parallel_env("unicycle")
    obs, _ = env.reset(seed=3)
    agents = list(env.agents)
    torch.manual_seed(0)
    policy = build_policy(env.observation_space(agents[0]), UNIT, NetConfig(hidden=(16, 16)))
    path = save_policy(
        tmp_path / "policy.zip", policy, NetConfig(hidden=(16, 16)), kind="dagger",
        scenario=sc.to_dict(), seed=0, head=head,
    )  # fmt: skip
    loaded = load_policy(path)
    acts = loaded.act(obs)
    # The network's own points, before saving: into the env's commands by the head.
    stacked = np.stack([obs[a] for a in agents])
    u = policy.predict(stacked, deterministic=True)[0]
    np.testing.assert_array_equal(
        np.stack([acts[a] for a in agents]), head.actions(u).astype(np.float32)
    )
    # In the env, every sensor moves to the nearest reachable point of its wanted point.
    before = env.unwrapped.world.sensor_states(0).copy()
    env.step(acts)
    after = env.unwrapped.world.sensor_states(0)
    k = sc.kinematics_models[0]
    for j in range(len(agents)):
        th = before[j, 2]
        rot = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        want = before[j, :2] + rot @ (k.radius * u[j].astype(np.float64))
        grid = before[j, :2] + _grid_endpoints(k) @ rot.T
        best = np.min(np.hypot(*(grid - want).T))
        # float32 actions: the step is the point's to ~1e-6 of the reach.
        assert np.hypot(*(after[j, :2] - want)) <= best + 2e-5 * k.radius
    env.close()


def test_policy_file_with_a_bad_action_target_is_refused(tmp_path):
    sc = make_scenario("unicycle")
    head = PositionActions.from_scenario(sc)
    obs = spaces.Box(-np.inf, np.inf, (25,), np.float32)
    policy = build_policy(obs, UNIT, NetConfig(hidden=(8,)))
    path = save_policy(
        tmp_path / "p.zip", policy, NetConfig(hidden=(8,)), kind="bc", scenario={}, seed=0,
        head=head,
    )  # fmt: skip
    with zipfile.ZipFile(path) as zf:
        meta, pth = json.loads(zf.read("meta.json")), zf.read("policy.pth")
    bad_values = [
        {"target": "position", "frame": "world", "sensors": meta["action_target"]["sensors"]},
        {"target": "position", "frame": "heading", "sensors": []},
        {"target": "position", "frame": "heading", "sensors": [{"name": "unicycle"}]},
        {"target": "position", "frame": "heading",
         "sensors": [{"name": "unicycle", "v_min": 0, "v_max": 10, "w_max": 100, "dt": 0.1}]},
        {"target": "position", "frame": "heading", "sensors": [{"name": "disk", "radius": -1}]},
        "position",
    ]  # fmt: skip
    for bad in bad_values:
        meta["action_target"] = bad
        out = tmp_path / "bad.zip"
        with zipfile.ZipFile(out, "w") as zf:
            zf.writestr("meta.json", json.dumps(meta))
            zf.writestr("policy.pth", pth)
        with pytest.raises(ValueError, match=r"bad\.zip: meta\.json: "):
            load_policy(out)


def test_position_targets_refuse_other_kinematics_and_the_config_checks_target():
    from activetrack.kinematics.double_integrator import DoubleIntegrator

    with pytest.raises(ValueError, match="position targets support Disk and Unicycle"):
        PositionActions([DoubleIntegrator(10.0, 50.0, dt=0.1)])
    with pytest.raises(ValueError, match="dt is not set"):
        PositionActions([Unicycle(0.0, 1.0, 1.0)])
    with pytest.raises(ValueError, match=r"target must be one of \['command', 'position'\]"):
        ImitationConfig(target="point")
    assert check_target("command") == "command"
    assert ImitationConfig().target == "position"


def test_train_and_evaluate_a_position_target_policy_from_the_command_line(tmp_path, capsys):
    from activetrack.cli import main

    out = tmp_path / "bc"
    argv = ["train", "bc", "--scenario", "unicycle", "--seed", "1", "--hidden", "8"]
    assert (
        main([*argv, "--episodes", "1", "--epochs", "1", "--no-progress", "--out", str(out)]) == 0
    )
    config = json.loads((out / "config.json").read_text())
    assert config["target"] == "position"
    loaded = load_policy(out / "policy.zip")
    assert (
        loaded.head == loaded.head
        and loaded.head.models == make_scenario("unicycle").kinematics_models
    )
    ev = tmp_path / "ev"
    code = main(
        ["evaluate", "--scenario", "unicycle", "--policy", str(out / "policy.zip"), "--episodes",
         "2", "--seed", "1000", "--no-plot", "--no-progress", "--out", str(ev)]
    )  # fmt: skip
    assert code == 0
    rows = json.loads((ev / "results.json").read_text())
    assert len(rows) == 2 and all(np.isfinite(r["mean_trace"]) for r in rows)
    # PPO samples commands: it refuses to warm-start from a network that predicts points.
    capsys.readouterr()
    ppo = tmp_path / "ppo"
    assert main(["train", "ppo", "--scenario", "unicycle", "--init", str(out / "policy.zip"),
                 "--out", str(ppo)]) == 2  # fmt: skip
    assert "predicts position targets" in capsys.readouterr().err and not ppo.exists()
    # An unknown target is an argparse error.
    with pytest.raises(SystemExit):
        main(["train", "bc", "--target", "point", "--out", str(tmp_path / "x")])
    assert "invalid choice: 'point'" in capsys.readouterr().err
