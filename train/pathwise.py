"""Policy gradients through the filter: a policy trained by differentiating the episode's
mean trace through the tracking loop itself.

On the paper's setup (Section III) one step of the loop is a smooth function of the
sensors' next positions: the move (eq. 13-16: the action scaled by the reach, pushed out
of the ``rho`` disk around the predicted target), the target's motion (eq. 1), the
measurements (eq. 4), the EKF's update linearized at the prediction (eq. 5-11) and its
prediction (eq. 3). With the target's process noise and the measurement noise drawn
beforehand and held fixed (the reparameterization, or pathwise, gradient), the episode's
mean trace ``(1/K) sum_k tr P(k|k)_11`` is a differentiable function of the policy's
parameters, and its gradient is exact for the sampled noise; averaged over a batch of
episodes it is an unbiased estimate of the gradient of the expected mean trace wherever
the projection of eq. (14) is not switching. This gradient sees every step's effect on
every later covariance (through the estimate's and the covariance's recursions), which the
score-function gradient of PPO recovers only through the rewards' noise; it is the route
to improving on an imitated planner by the few percent that separate good policies.

:class:`LoopSimulator` is that loop in torch (float64, batched over episodes), with the
observation of :mod:`activetrack.world.observation` (the paper's layout), so the policy
sees exactly what it sees in the environment; its steps are tested against the library's
own move, filter and observation (tests/train/test_pathwise.py). :func:`train_pathwise`
starts from a policy file (BC of the look-ahead planner, for example), takes Adam steps on
the batch mean trace, validates the deterministic policy in the real environment on
validation seeds every ``eval_every`` iterations, keeps the best, and writes
``policy.zip`` like every other trainer. Only the paper's measurement setup is supported
(one target, range-and-bearing sensors at known positions, single EKF, no occluders,
kinematics or team rules): the scenarios whose ``is_paper_model`` is true and which add
nothing to the loop beyond eq. (1)-(16).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from activetrack.files import prepare_output_dir
from activetrack.train.policy_io import load_policy, save_policy
from activetrack.train.ppo import VALIDATION_SEED, validation_trace
from activetrack.train.utils import (
    DEFAULT_THREADS,
    check_float,
    check_int,
    configure_torch,
    seed_everything,
)

#: The scenario fields that must keep their paper values (the loop of eq. 1-16 only).
_PAPER_LOOP = {
    "n_targets": 1,
    "sensor_model": "range_bearing",
    "pose_cov": 0.0,
    "max_range": None,
    "p_detect": 1.0,
    "occluders": (),
    "random_occluders": 0,
    "filter_iterations": 1,
    "kinematics": None,
    "target_behaviour": None,
    "estimator": "ekf",
    "d_sep": 0.0,
    "communication": None,
    "births": None,
    "objective": "trace",
    "motion": "cv",
    "max_trace": None,
}


def check_paper_loop(scenario: Any) -> None:
    """Raise ValueError naming the first field that takes ``scenario`` beyond eq. (1)-(16)."""
    for name, value in _PAPER_LOOP.items():
        if getattr(scenario, name) != value:
            raise ValueError(
                f"pathwise training supports the paper's loop only: {name} must be {value!r},"
                f" got {getattr(scenario, name)!r}"
            )
    if np.any(np.asarray(scenario.orientation, dtype=np.float64) != 0.0):
        raise ValueError("pathwise training supports the paper's loop only: orientation must be 0")


def paper_loop_presets() -> tuple[str, ...]:
    """Return the presets :class:`LoopSimulator` supports (the paper's loop)."""
    from activetrack.world.scenarios import PRESETS, make_scenario

    def supported(name: str) -> bool:
        try:
            check_paper_loop(make_scenario(name))
        except ValueError:
            return False
        return True

    return tuple(sorted(name for name in PRESETS if supported(name)))


def _t(a: Any) -> torch.Tensor:
    return torch.as_tensor(np.asarray(a, dtype=np.float64))


class LoopSimulator:
    """The paper's tracking loop in torch, batched over episodes (see the module docstring).

    State of ``n`` episodes: ``sensors`` (n, M, 2), ``x_true`` (n, 4) and the prediction
    ``x_pred`` (n, 4), ``P_pred`` (n, 4, 4). Every method is differentiable in its tensor
    arguments.
    """

    def __init__(self, scenario: Any) -> None:
        from activetrack.world import World
        from activetrack.world.observation import length_scale, sensor_constants

        check_paper_loop(scenario)
        sc = scenario
        params = World(sc, 1).params.targets[0]
        self.scenario = sc
        self.m = sc.n_sensors
        self.n_steps = sc.n_steps
        self.dt = float(sc.dt)
        self.L = length_scale(sc)
        self.Phi, self.Q = _t(params.Phi), _t(params.Q)
        self.Q_factor = torch.linalg.cholesky(self.Q)
        sd2, st2 = sc.per_sensor("sigma_d2"), sc.per_sensor("sigma_theta2")
        self.wd, self.wt = _t(1.0 / sd2), _t(1.0 / st2)
        self.noise_std = torch.stack([_t(np.sqrt(sd2)), _t(np.sqrt(st2))], -1)  # (M, 2)
        self.r, self.rho = _t(sc.r), _t(sc.per_sensor("rho"))
        rho_np = sc.per_sensor("rho")
        self.constants = _t(sensor_constants(sd2, st2, sc.r, rho_np, self.L))  # (M, 4)
        self.x0 = _t(sc.target_states("x0")[0])
        self.x0_hat = _t(sc.target_states("x0_hat")[0])
        self.P0 = _t(sc.initial_covs[0])
        self.gaussian = sc.target_init == "gaussian"
        self.center = _t(sc.sensor_center)
        self.radius = float(sc.sensor_radius)
        # agent i sees sensors i, i+1, ... (mod M)
        self.order = torch.tensor(
            [[(i + j) % self.m for j in range(self.m)] for i in range(self.m)]
        )

    # The loop's pieces ---------------------------------------------------------------
    def predict(self, x: torch.Tensor, P: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Return eq. (3)'s ``(Phi x, Phi P Phi^T + Q)``."""
        return x @ self.Phi.T, self.Phi @ P @ self.Phi.T + self.Q

    def start(self, rng: np.random.Generator, n: int) -> dict[str, torch.Tensor]:
        """Return the start of ``n`` episodes: sensors uniform (by area) in the start disk,
        the target at ``x0`` (or drawn from the prior), the prediction from the prior."""
        u = _t(rng.random((n, self.m, 2)))
        radius = self.radius * torch.sqrt(u[..., 0])
        angle = 2.0 * torch.pi * u[..., 1]
        sensors = self.center + radius[..., None] * torch.stack([angle.cos(), angle.sin()], -1)
        if self.gaussian:
            g = _t(rng.standard_normal((n, 4)))
            x_true = self.x0_hat + g @ torch.linalg.cholesky(self.P0).T
        else:
            x_true = self.x0.expand(n, 4).clone()
        x_pred, P_pred = self.predict(self.x0_hat.expand(n, 4), self.P0.expand(n, 4, 4))
        return {"sensors": sensors, "x_true": x_true, "x_pred": x_pred, "P_pred": P_pred}

    def observe(
        self, sensors: torch.Tensor, x_pred: torch.Tensor, P_pred: torch.Tensor
    ) -> torch.Tensor:
        """Return every agent's observation (n, M, 5 + 6M), the paper's layout of
        :mod:`activetrack.world.observation` (without its far-out clips)."""
        sx, sy = P_pred[:, 0, 0].sqrt(), P_pred[:, 1, 1].sqrt()
        target = torch.stack(
            [
                torch.log(sx / self.L),
                torch.log(sy / self.L),
                P_pred[:, 0, 1] / (sx * sy),
                x_pred[:, 2] * self.dt / self.L,
                x_pred[:, 3] * self.dt / self.L,
            ],
            -1,
        )
        rel = (sensors - x_pred[:, None, :2]) / self.L  # (n, M, 2)
        blocks = torch.cat([rel, self.constants.expand(rel.shape[0], -1, -1)], -1)  # (n, M, 6)
        seats = blocks[:, self.order].flatten(-2)  # (n, M, 6M)
        return torch.cat([target[:, None, :].expand(-1, self.m, -1), seats], -1)

    def move(
        self, actions: torch.Tensor, sensors: torch.Tensor, x_pred: torch.Tensor
    ) -> torch.Tensor:
        """Return eq. (13)-(16)'s next positions for actions in units of the reach."""
        norm = torch.linalg.vector_norm(actions, dim=-1, keepdim=True)
        a = actions / norm.clamp_min(1.0)
        r, rho = self.r[:, None], self.rho[:, None]
        new = sensors + r * a
        t = x_pred[:, None, :2]
        d = new - t
        dist = torch.linalg.vector_norm(d, dim=-1, keepdim=True)
        inside = dist < rho
        if not bool(inside.any()):
            return new
        radial = t + rho * d / dist.clamp_min(1e-12)
        c = sensors - t  # the sensor relative to the target
        cn = torch.linalg.vector_norm(c, dim=-1, keepdim=True).clamp_min(1e-12)
        # The circles |p| = rho and |p - c| = r meet at p = (a_ c + h J c) / |c|
        along = (rho**2 - r**2 + cn**2) / (2.0 * cn)
        h = (rho**2 - along**2).clamp_min(0.0).sqrt()
        u = c / cn
        perp = torch.stack([-u[..., 1], u[..., 0]], -1)
        pa, pb = t + along * u + h * perp, t + along * u - h * perp
        nearer = torch.where(
            torch.linalg.vector_norm(pa - new, dim=-1, keepdim=True)
            <= torch.linalg.vector_norm(pb - new, dim=-1, keepdim=True),
            pa,
            pb,
        )
        reachable = torch.linalg.vector_norm(radial - sensors, dim=-1, keepdim=True) <= r
        projected = torch.where(reachable, radial, nearer)
        # No feasible point (||c|| + r < rho): the reachable point farthest from the target.
        projected = torch.where(cn + r < rho, sensors + r * u, projected)
        return torch.where(inside, projected, new)

    def move_target(self, x_true: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
        """Return eq. (1)'s next true state ``Phi x + Q^(1/2) w`` for standard normals ``w``."""
        return x_true @ self.Phi.T + w @ self.Q_factor.T

    def measure(
        self, x_true: torch.Tensor, sensors: torch.Tensor, eps: torch.Tensor
    ) -> torch.Tensor:
        """Return eq. (4)'s ranges and bearings (n, M, 2) with standard normals ``eps``."""
        d = x_true[:, None, :2] - sensors
        z = torch.stack(
            [torch.linalg.vector_norm(d, dim=-1), torch.atan2(d[..., 1], d[..., 0])], -1
        )
        return z + self.noise_std * eps

    def update(
        self, x: torch.Tensor, P: torch.Tensor, sensors: torch.Tensor, z: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Return eq. (11)'s posterior linearized at the prediction, in information form:
        ``Y = sum_i H_i^T R_i^-1 H_i`` (eq. 12), ``b = sum_i H_i^T R_i^-1 nu_i``,
        ``x+ = x + P[:, :2] (I + Y P11)^-1 b``, ``P+ = P - P[:, :2] (I + Y P11)^-1 Y P[:2]``."""
        d = x[:, None, :2] - sensors
        n2 = (d * d).sum(-1)
        dist = n2.sqrt()
        u = d / dist[..., None]  # d range / d p_T
        v = torch.stack([-d[..., 1], d[..., 0]], -1) / n2[..., None]  # d bearing / d p_T
        nu_d = z[..., 0] - dist
        nu_t = z[..., 1] - torch.atan2(d[..., 1], d[..., 0])
        nu_t = torch.atan2(torch.sin(nu_t), torch.cos(nu_t))  # wrapped (a smooth map)
        Y = torch.einsum("nm,nmi,nmj->nij", self.wd.expand_as(n2), u, u)
        Y = Y + torch.einsum("nm,nmi,nmj->nij", self.wt.expand_as(n2), v, v)
        b = (self.wd * nu_d)[..., None] * u + (self.wt * nu_t)[..., None] * v
        b = b.sum(1)
        Pxp = P[:, :, :2]
        S = torch.eye(2, dtype=P.dtype) + Y @ P[:, :2, :2]
        G = Pxp @ torch.linalg.inv(S)  # (n, 4, 2)
        x_post = x + (G @ b[..., None])[..., 0]
        P_post = P - G @ Y @ Pxp.transpose(1, 2)
        return x_post, 0.5 * (P_post + P_post.transpose(1, 2))

    def rollout(
        self, actor: Any, rng: np.random.Generator, n: int, horizon: int | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Return ``(traces, errors)``: each step's ``tr P(k|k)_11`` and squared position
        error ``||p_T(k) - p_hat_T(k|k)||^2`` (n, n_steps) of ``n`` episodes of the
        deterministic policy ``actor`` (a map from (rows, obs_dim) float64 observations to
        (rows, 2) float64 actions), differentiable in its parameters. The start, the
        target's noise and the measurement noise are drawn from ``rng`` first.

        ``horizon`` truncates the gradient: the loop's state (sensors, prediction) is
        detached every ``horizon`` steps, so a step's trace is differentiated only through
        the actions of its own window; 1 is the myopic (one-step) objective that GSR
        optimizes by relaxation, None the whole episode. The values are unchanged."""
        s = self.start(rng, n)
        w = _t(rng.standard_normal((self.n_steps, n, 4)))
        e = _t(rng.standard_normal((self.n_steps, n, self.m, 2)))
        sensors, x_true, x_pred, P_pred = s["sensors"], s["x_true"], s["x_pred"], s["P_pred"]
        traces, errors = [], []
        for k in range(self.n_steps):
            if horizon is not None and k % horizon == 0:
                sensors, x_pred, P_pred = sensors.detach(), x_pred.detach(), P_pred.detach()
            obs = self.observe(sensors, x_pred, P_pred)
            actions = actor(obs.reshape(n * self.m, -1)).reshape(n, self.m, 2)
            sensors = self.move(actions, sensors, x_pred)
            x_true = self.move_target(x_true, w[k])
            z = self.measure(x_true, sensors, e[k])
            x_post, P_post = self.update(x_pred, P_pred, sensors, z)
            traces.append(P_post[:, 0, 0] + P_post[:, 1, 1])
            errors.append(((x_post[:, :2] - x_true[:, :2]) ** 2).sum(-1))
            x_pred, P_pred = self.predict(x_post, P_post)
        return torch.stack(traces, -1), torch.stack(errors, -1)


@dataclass
class PathwiseConfig:
    """Settings of :func:`train_pathwise`.

    Attributes:
        iterations: Adam steps [1, 1e6].
        batch: episodes per step [1, 65536] (fresh noise every step).
        lr: Adam's learning rate (0, 1].
        grad_clip: the gradient's largest global norm (0, 1e6].
        eval_every: validate every this many steps [1, 1e6] (and at the start and end).
        eval_episodes: validation episodes, seeds 500000, ... [1, 100000].
        horizon: steps the gradient reaches back [1, 10000], or None for the whole episode
            (see :meth:`LoopSimulator.rollout`).
        seed: the noise's and torch's seed [0, 2^63).
        threads: torch's CPU threads [1, 256].
    """

    iterations: int = 800
    batch: int = 128
    lr: float = 2e-4
    grad_clip: float = 1.0
    eval_every: int = 50
    eval_episodes: int = 200
    horizon: int | None = None
    seed: int = 0
    threads: int = DEFAULT_THREADS

    def __post_init__(self) -> None:
        self.iterations = check_int("iterations", self.iterations, 1, 10**6)
        self.batch = check_int("batch", self.batch, 1, 65536)
        self.lr = check_float("lr", self.lr, 0.0, 1.0, low_open=True)
        self.grad_clip = check_float("grad_clip", self.grad_clip, 0.0, 1e6, low_open=True)
        self.eval_every = check_int("eval_every", self.eval_every, 1, 10**6)
        self.eval_episodes = check_int("eval_episodes", self.eval_episodes, 1, 100_000)
        if self.horizon is not None:
            self.horizon = check_int("horizon", self.horizon, 1, 10_000)
        self.seed = check_int("seed", self.seed, 0, 2**63 - 1)
        self.threads = check_int("threads", self.threads, 1, 256)


@dataclass
class PathwiseResult:
    """What :func:`train_pathwise` returns: the policy file, the validation curve
    ``[(iteration, mean trace), ...]`` (the start's at 0), the best iteration and the wall
    time in seconds."""

    policy_path: Path
    validation: list[tuple[int, float]]
    best_iteration: int
    seconds: float


#: What a run writes into its folder.
OUTPUTS = ("policy.zip", "validation.json", "config.json")


def _start_policy(init: str | Path | None, scenario: Any, net: Any) -> tuple[Any, Any]:
    """Return ``(policy, net config)``: the actor of the file ``init``, or (None) a fresh
    network of ``net`` (default :data:`activetrack.train.networks.DEFAULT_NET`)."""
    from activetrack.envs import parallel_env
    from activetrack.train.networks import DEFAULT_NET, NetConfig, build_policy

    if init is None:
        env = parallel_env(scenario)
        agent = env.possible_agents[0]
        net = NetConfig.coerce(net) if net is not None else DEFAULT_NET
        return build_policy(env.observation_space(agent), env.action_space(agent), net), net
    if net is not None:
        raise ValueError("net sets the network of a fresh start: give init=None")
    learned = load_policy(init)
    if learned.view != "shared" or learned.head is not None:
        raise ValueError(f"{init}: pathwise training needs a shared-view policy of actions")
    return learned.policy, NetConfig.from_dict(learned.meta["net"])


def train_pathwise(
    scenario: Any,
    init: str | Path | None,
    out_dir: str | Path,
    config: PathwiseConfig | None = None,
    progress: bool = True,
    overwrite: bool = False,
    net: Any = None,
) -> PathwiseResult:
    """Train a policy by gradients through the loop; return the result.

    ``init``: the policy file to start from (its network), or None for a fresh network
    of ``net`` (a :class:`~activetrack.train.networks.NetConfig`, default 2x256 tanh)
    seeded by ``config.seed``: then only the reward's gradient teaches it (no expert).
    Writes ``policy.zip`` (the best validated policy, kind ``"pathwise"``),
    ``validation.json`` (the validation curve, and ``train_seconds``: the training time
    at each of its points, validations excluded) and ``config.json`` into ``out_dir``,
    all at the end (a folder holding them is refused unless ``overwrite``).
    """
    from tqdm.auto import tqdm

    from activetrack.train.networks import actor_parameters, mean_action
    from activetrack.world.scenarios import make_scenario

    cfg = config or PathwiseConfig()
    if not isinstance(cfg, PathwiseConfig):
        raise TypeError(f"config must be a PathwiseConfig, got {type(cfg).__name__}")
    sc = make_scenario(scenario)
    sim = LoopSimulator(sc)
    seed_everything(cfg.seed)  # (a fresh network's initial weights)
    policy, net_config = _start_policy(init, sc, net)
    with prepare_output_dir(out_dir, OUTPUTS, overwrite) as outputs:  # locked for the run
        configure_torch(cfg.threads)
        policy.train()
        rng = np.random.default_rng([cfg.seed, 7])
        params = actor_parameters(policy)
        opt = torch.optim.Adam(params, lr=cfg.lr)
        start = time.perf_counter()
        best = validation_trace(policy, sc, cfg.eval_episodes, batched=True)
        curve = [(0, best)]
        clock = [0.0]  # training seconds at each validation (the validations' own excluded)
        trained = 0.0
        best_state = {k: v.clone() for k, v in policy.state_dict().items()}
        best_it = 0
        bar = tqdm(range(1, cfg.iterations + 1), desc="pathwise", disable=not progress)
        for it in bar:
            tick = time.perf_counter()
            actor = lambda o: mean_action(policy, o.float()).double()  # noqa: E731
            traces, _ = sim.rollout(actor, rng, cfg.batch, cfg.horizon)
            loss = traces.mean()
            opt.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(params, cfg.grad_clip)
            opt.step()
            trained += time.perf_counter() - tick
            bar.set_postfix(batch_trace=f"{float(loss.detach()):.3f}", best=f"{best:.4f}")
            if it % cfg.eval_every == 0 or it == cfg.iterations:
                value = validation_trace(policy, sc, cfg.eval_episodes, batched=True)
                curve.append((it, value))
                clock.append(trained)
                if value < best:  # strictly better on the same validation episodes
                    best, best_it = value, it
                    best_state = {k: v.clone() for k, v in policy.state_dict().items()}
        seconds = time.perf_counter() - start
        policy.load_state_dict(best_state)
        start_file = None if init is None else str(init)
        train_config = {
            **asdict(cfg), "init": start_file, "best_iteration": best_it, "seconds": seconds,
        }  # fmt: skip
        save_policy(
            outputs.staged("policy.zip"),
            policy,
            net_config,
            kind="pathwise",
            scenario=sc.to_dict(),
            seed=cfg.seed,
            train_config=train_config,
        )
        outputs.write_json(
            "validation.json",
            {"validation_seed": VALIDATION_SEED, "curve": curve, "train_seconds": clock},
        )
        outputs.write_json("config.json", {"scenario": sc.to_dict(), **train_config})
        path = outputs.commit()["policy.zip"]
    return PathwiseResult(Path(path), curve, best_it, seconds)
