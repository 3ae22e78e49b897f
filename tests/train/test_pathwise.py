"""Gradients through the filter: the torch loop against the library's own move, filter,
prediction and observation, its gradient against finite differences, its statistics
against the world's, and training that measurably improves a policy."""

from __future__ import annotations

import json
import zipfile

import numpy as np
import pytest
import torch

from activetrack.estimation import ekf
from activetrack.kinematics.sensor_motion import apply_actions
from activetrack.models.motion import predict
from activetrack.train.networks import NetConfig, build_policy, mean_action
from activetrack.train.pathwise import (
    LoopSimulator,
    PathwiseConfig,
    check_paper_loop,
    paper_loop_presets,
    train_pathwise,
)
from activetrack.train.policy_io import load_policy, save_policy
from activetrack.world import World
from activetrack.world.scenarios import make_scenario

SC = make_scenario("paper")


@pytest.fixture(scope="module")
def sim() -> LoopSimulator:
    return LoopSimulator(SC)


def _tensor(a: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(np.asarray(a, dtype=np.float64))


def test_observation_is_the_environments(sim):
    world = World(SC, 6)
    world.reset(seeds=list(range(6)))
    rng = np.random.default_rng(3)
    for _ in range(4):
        got = sim.observe(*(_tensor(world.get(k)) for k in ("sensors", "x_pred", "P_pred")))
        want = world.observe()  # float32
        np.testing.assert_allclose(got.numpy(), want, rtol=1e-6, atol=1e-6)
        world.step_actions(rng.uniform(-1.3, 1.3, (6, SC.n_sensors, 2)))


def test_move_is_apply_actions_in_every_case(sim):
    # Sensors scattered around the predicted target: moves that end outside the rho disk,
    # inside it (radial push or a circle intersection), and sensors already so deep inside
    # that no reachable point is feasible.
    rng = np.random.default_rng(0)
    n = 4000
    sensors = rng.normal(0.0, 2.5, (n, SC.n_sensors, 2))
    target = rng.normal(0.0, 0.5, (n, 2))
    x_pred = np.concatenate([target, rng.normal(0.0, 5.0, (n, 2))], -1)
    actions = rng.uniform(-1.5, 1.5, (n, SC.n_sensors, 2))
    want, projected = apply_actions(actions, sensors, target, SC.r, SC.per_sensor("rho"))
    c = np.linalg.norm(sensors - target[:, None], axis=-1)
    assert projected.mean() > 0.1 and (c + SC.r < SC.per_sensor("rho")).sum() > 50
    got = sim.move(_tensor(actions), _tensor(sensors), _tensor(x_pred)).numpy()
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


def test_update_and_prediction_are_the_filters(sim):
    rng = np.random.default_rng(1)
    n = 500
    A = rng.normal(size=(n, 4, 4))
    P = A @ A.transpose(0, 2, 1) + np.eye(4)
    x = rng.normal(0.0, 3.0, (n, 4))
    sensors = rng.normal(0.0, 6.0, (n, SC.n_sensors, 2))
    z = np.stack(
        [rng.uniform(1, 10, (n, SC.n_sensors)), rng.uniform(-np.pi, np.pi, (n, SC.n_sensors))], -1
    )
    x1, P1 = ekf.update(x, P, z, sensors, SC.per_sensor("sigma_d2"), SC.per_sensor("sigma_theta2"))
    x2, P2 = sim.update(_tensor(x), _tensor(P), _tensor(sensors), _tensor(z))
    np.testing.assert_allclose(x2.numpy(), x1, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(P2.numpy(), P1, rtol=1e-10, atol=1e-10)
    params = World(SC, 1).params.targets[0]
    x3, P3 = predict(x1, P1, params.Phi, params.Q)
    x4, P4 = sim.predict(_tensor(x1), _tensor(P1))
    np.testing.assert_allclose(x4.numpy(), x3, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(P4.numpy(), P3, rtol=1e-12, atol=1e-12)


def test_episode_gradient_matches_finite_differences():
    # A short episode (4 steps) of a linear float64 policy: d(mean trace)/dW by autograd
    # against central differences (torch.autograd.gradcheck), the noise held fixed.
    sim = LoopSimulator(make_scenario("paper", n_steps=4))
    obs_dim = 5 + 6 * SC.n_sensors
    W0 = torch.from_numpy(np.random.default_rng(2).normal(0.0, 0.3, (obs_dim, 2)))

    def mean_trace(W: torch.Tensor) -> torch.Tensor:
        traces, _ = sim.rollout(lambda o: o @ W, np.random.default_rng(5), 3)
        return traces.mean()

    assert torch.autograd.gradcheck(mean_trace, (W0.clone().requires_grad_(),), atol=1e-5)


def test_truncated_gradient_is_the_windows_own():
    # horizon h: each step's trace is differentiated through the actions of its own window
    # only. Independently: the full gradient of a rollout whose policy uses the weights W
    # from the window's first step on (the fixed W0 before it), summed over the windows.
    sim = LoopSimulator(make_scenario("paper", n_steps=5))
    obs_dim = 5 + 6 * SC.n_sensors
    W0 = torch.from_numpy(np.random.default_rng(3).normal(0.0, 0.3, (obs_dim, 2)))
    h = 2

    def truncated(W: torch.Tensor) -> torch.Tensor:
        traces, _ = sim.rollout(lambda o: o @ W, np.random.default_rng(6), 3, horizon=h)
        return traces.mean()

    def from_step(W: torch.Tensor, first: int) -> torch.Tensor:
        calls = iter(range(sim.n_steps))
        actor = lambda o: o @ (W if next(calls) >= first else W0)  # noqa: E731
        traces, _ = sim.rollout(actor, np.random.default_rng(6), 3)
        return traces[:, first : first + h].sum() / traces.numel()

    W = W0.clone().requires_grad_()
    (got,) = torch.autograd.grad(truncated(W), W)
    windows = sum(from_step(W, s) for s in range(0, sim.n_steps, h))
    (want,) = torch.autograd.grad(windows, W)
    assert got.abs().max() > 1e-3  # a gradient to compare, not zeros
    torch.testing.assert_close(got, want, rtol=1e-10, atol=1e-12)
    full, _ = sim.rollout(lambda o: o @ W0, np.random.default_rng(6), 3)
    torch.testing.assert_close(truncated(W0), full.mean())  # values unchanged
    whole, _ = sim.rollout(lambda o: o @ W, np.random.default_rng(6), 3)
    (untruncated,) = torch.autograd.grad(whole.mean(), W)
    assert not torch.allclose(got, untruncated, rtol=1e-3)  # the truncation matters here


def _toward_target(obs: torch.Tensor) -> torch.Tensor:
    """A fixed policy: every sensor heads for the predicted target (entries 5, 6: its
    position relative to it)."""
    rel = obs[:, 5:7]
    return -rel / torch.linalg.vector_norm(rel, dim=-1, keepdim=True)


def _world_traces(actor, seeds: list[int]) -> np.ndarray:
    """Return each episode's mean trace of ``actor`` run in the library's World."""
    world = World(SC, len(seeds))
    world.reset(seeds=seeds)
    traces = []
    for _ in range(SC.n_steps):
        obs = torch.from_numpy(world.observe().astype(np.float64))
        act = actor(obs.reshape(-1, obs.shape[-1])).reshape(len(seeds), SC.n_sensors, 2)
        world.step_actions(act.detach().numpy())
        traces.append(world.get("trace"))
    return np.mean(traces, axis=0)


def test_loop_statistics_are_the_worlds(sim):
    # The same policy in both loops, independent noise: the mean over episodes of the
    # episode's mean trace agrees within 4 standard errors of the difference. The fixed
    # policy's episode means spread by about 40% of their mean, so with 3000 episodes a
    # side the band is about 4% of the mean (checked below): a 10% error in a noise
    # variance (measured: 5.8 standard errors) or in the order of the steps fails.
    n = 3000
    world = _world_traces(_toward_target, list(range(n)))
    with torch.no_grad():
        own = sim.rollout(_toward_target, np.random.default_rng(11), n)[0].mean(-1).numpy()
    se = np.hypot(world.std(ddof=1) / np.sqrt(n), own.std(ddof=1) / np.sqrt(n))
    assert 4 * se < 0.05 * world.mean()
    assert abs(own.mean() - world.mean()) < 4 * se


def test_target_moves_with_the_process_noise_q(sim):
    # (The trace does not see the true target's noise.) 20000 one-step moves from one
    # state: the sample mean is Phi x (4 standard errors) and the sample covariance Q, each
    # entry within 5 standard errors of its Monte Carlo estimate (Var of the (i, j) sample
    # covariance ~ (Q_ii Q_jj + Q_ij^2) / n); a 10% error in q moves the diagonal by 10
    # standard errors.
    n = 20_000
    x = _tensor([[1.0, -2.0, 3.0, 0.5]]).expand(n, 4)
    w = _tensor(np.random.default_rng(4).standard_normal((n, 4)))
    moved = sim.move_target(x, w).numpy()
    params = World(SC, 1).params.targets[0]
    Q, mean = params.Q, params.Phi @ x[0].numpy()
    d = moved - mean
    assert np.all(np.abs(d.mean(0)) < 4 * np.sqrt(np.diag(Q) / n))
    cov = d.T @ d / n
    se = np.sqrt((np.outer(np.diag(Q), np.diag(Q)) + Q**2) / n)
    assert np.all(np.abs(cov - Q) < 5 * se)
    assert np.all(0.1 * np.diag(Q) > 9 * np.diag(se))


def test_only_the_papers_loop():
    assert "paper" in paper_loop_presets() and "two_targets" not in paper_loop_presets()
    with pytest.raises(ValueError, match="n_targets must be 1"):
        check_paper_loop(make_scenario("two_targets"))
    with pytest.raises(ValueError, match="p_detect"):
        LoopSimulator(make_scenario("paper", p_detect=0.5))


@pytest.mark.parametrize(
    ("field", "value"),
    [("batch", 0), ("lr", 0.0), ("iterations", -1), ("eval_episodes", 0), ("horizon", 0)],
)
def test_config_is_checked(field, value):
    with pytest.raises(ValueError, match=field):
        PathwiseConfig(**{field: value})


def test_training_improves_a_policy_on_held_out_episodes(tmp_path):
    # A small untrained network, then 40 steps through the filter. The policies' episode
    # mean traces on 60 episodes outside training and validation, paired: the upper end
    # of the 99% t-interval of (trained - start) must be below 0.
    from activetrack.envs import parallel_env

    env = parallel_env("paper")
    agent = env.possible_agents[0]
    torch.manual_seed(0)
    net = NetConfig(hidden=(32, 32))
    start = build_policy(env.observation_space(agent), env.action_space(agent), net)
    init = save_policy(tmp_path / "start.zip", start, net, kind="bc", scenario=SC.to_dict(), seed=0)
    cfg = PathwiseConfig(iterations=40, batch=16, lr=3e-3, eval_every=20, eval_episodes=10)
    result = train_pathwise("paper", init, tmp_path / "run", cfg, progress=False)
    trained = load_policy(result.policy_path)
    assert trained.meta["kind"] == "pathwise" and result.validation[0][0] == 0
    written = json.loads((tmp_path / "run" / "validation.json").read_text())
    assert [it for it, _ in written["curve"]] == [0, 20, 40]
    seconds = written["train_seconds"]  # the time axis of a time-to-level figure
    assert len(seconds) == 3 and seconds[0] == 0.0 and seconds[1] > 0.0
    assert seconds[2] > seconds[1]

    def actor(policy):
        return lambda o: mean_action(policy, o.float()).double()

    seeds = list(range(70_000, 70_060))
    with torch.no_grad():
        before = _world_traces(actor(load_policy(init).policy), seeds)
        after = _world_traces(actor(trained.policy), seeds)
    diff = after - before
    from scipy import stats

    upper = diff.mean() + stats.t.ppf(0.995, diff.size - 1) * diff.std(ddof=1) / np.sqrt(diff.size)
    assert upper < 0.0, (before.mean(), after.mean())


def test_fresh_start_is_seeded_and_reproducible(tmp_path):
    # From a fresh network (no policy file): the same seed gives the same trained
    # parameters and validation curve; another seed another network.
    cfg = PathwiseConfig(iterations=3, batch=4, lr=1e-3, eval_every=3, eval_episodes=2)
    net = NetConfig(hidden=(16, 16))

    def run(seed: int, name: str):
        c = PathwiseConfig(**{**cfg.__dict__, "seed": seed})
        r = train_pathwise("paper", None, tmp_path / name, c, progress=False, net=net)
        state = load_policy(r.policy_path).policy.state_dict()
        return r.validation, torch.cat([v.flatten() for v in state.values()])

    (va, a), (vb, b), (_, c) = run(3, "a"), run(3, "b"), run(4, "c")
    assert va == vb and torch.equal(a, b) and not torch.equal(a, c)
    with pytest.raises(ValueError, match="init=None"):
        train_pathwise("paper", tmp_path / "a" / "policy.zip", tmp_path / "d", cfg, net=net)


def test_command_trains_and_evaluate_loads_the_policy(tmp_path, capsys):
    from activetrack.baselines.evaluation import evaluate
    from activetrack.cli import main

    out = tmp_path / "pw"
    argv = ["train", "pathwise", "--iterations", "2", "--batch", "2", "--eval-every", "2"]
    argv += ["--eval-episodes", "2", "--hidden", "8", "--frame", "sight", "--no-progress"]
    argv += ["--out", str(out)]
    assert main(argv) == 0
    assert "pathwise: 2 iterations of 2 episodes" in capsys.readouterr().out
    with zipfile.ZipFile(out / "policy.zip") as zf:
        assert json.loads(zf.read("meta.json"))["net"]["frame"] == "sight"
    rows = evaluate([str(out / "policy.zip")], "paper", episodes=2, seed=5, progress=False)
    assert np.all(np.isfinite(rows[-1].mean_trace))
    # refused before training: a results folder, a scenario beyond the paper's loop, a
    # bad budget
    assert main(argv) == 2
    assert "--overwrite" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["train", "pathwise", "--scenario", "two_targets", "--out", str(tmp_path / "x")])
    assert main(["train", "pathwise", "--batch", "0", "--out", str(tmp_path / "y")]) == 2
    assert "batch" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["--grad-clip", "0"], "grad_clip"),
        (["--eval-every", "0"], "eval_every"),
        (["--threads", "0"], "threads"),
        (["--hidden", "0"], "hidden"),
        (["--lr", "nan"], "lr"),
        (["--iterations", "0"], "iterations"),
        (["--horizon", "0"], "horizon"),
        (["--init", "missing.zip"], "missing.zip"),
        (["--init", "missing.zip", "--hidden", "8"], "--hidden"),
        (["--init", "missing.zip", "--frame", "sight"], "--frame"),
    ],
)
def test_command_refuses_bad_input_before_writing(tmp_path, capsys, argv, named):
    from activetrack.cli import main

    out = tmp_path / "pw"
    assert main(["train", "pathwise", *argv, "--out", str(out)]) == 2
    assert named in capsys.readouterr().err
    assert not out.exists()
