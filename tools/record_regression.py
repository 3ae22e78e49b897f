"""Record the library's seeded results, to check that a refactor reproduces them exactly.

Every ``case_*`` function below computes one group of seeded results through the public
entry points a user calls (scenarios, the simulation runner and the planners of
``activetrack.baselines``, the PettingZoo, AEC, Gymnasium and batched environments, the
expert policies and the evaluation) and returns them as JSON values: Python floats
(float64, whose ``repr`` round-trips exactly), ints, bools, strings and lists. Nothing
reads private names or environment attributes: only observations, rewards,
terminations, truncations, infos, ``state()``, the runner's ``RunRecord`` and
``MonteCarloResult`` fields, the planners' results and ``planning_problem()`` (the
experts' documented view of an environment).

Float32 observations are stored as the shortest decimal that gives the same float32
back (checked value by value when encoding), which halves their size; comparing the
stored numbers is then comparing the float32 values bit for bit. Every agent sees the
same blocks in its own cyclic order, so observations are stored as the first agent's
(per copy in the batched environment) plus a SHA-256 of all agents' float32
observations per step; ``state()`` is stored in full.

Actions come from their own seeded generator (:func:`random_actions`): some chase the
predicted target (the rho projection runs where sensors can catch up), some are longer
than 1 (scaled onto the unit disk).

``python tools/record_regression.py`` writes ``tests/data/regression_bb51820.json``
(atomically: a temporary file in the same folder, then ``os.replace``) with the commit
it ran at (``git rev-parse HEAD``) and whether the library's files were as committed,
the versions of numpy and scipy, the BLAS build and the CPU, a description of every
case, and ``notes`` (observations about the values that the test does not compare);
``tests/test_regression.py`` recomputes every case with these same functions and
compares.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUT = REPO / "tests" / "data" / "regression_bb51820.json"

# Sizes chosen to keep the whole recording within a minute on one core.
PAPER_RUNS = 10
ENV_ID = "activetrack/ActiveTracking-v0"
BATCH_N = 5
BATCH_STEPS = 130  # 2.6 episodes of 50 steps
MAX_TRACE = 10.0  # between GSR's (about 2 m^2) and RM's (up to about 15 m^2) traces

# Encoding -------------------------------------------------------------------------------


def f64(a: Any) -> Any:
    """Return a float64 array (or scalar) as nested lists of Python floats."""
    return np.asarray(a, dtype=np.float64).tolist()


def f32(a: Any) -> Any:
    """Return a float32 array as nested lists of the shortest decimals of its values.

    Each number parses (as float64, then cast to float32) back to the same float32, which
    is checked here; a value for which that fails keeps its exact float64 value.
    """
    x = np.asarray(a)
    if x.dtype != np.float32:
        raise TypeError(f"f32 expects a float32 array, got {x.dtype}")
    short = x.astype(str).astype(np.float64)
    exact = x.astype(np.float64)
    same = short.astype(np.float32) == x
    same |= np.isnan(x) & np.isnan(short)
    return np.where(same, short, exact).tolist()


def digest(a: Any) -> str:
    """Return the SHA-256 of an array's dtype, shape and C-order bytes."""
    x = np.ascontiguousarray(a)
    h = hashlib.sha256(f"{x.dtype.str}{x.shape}".encode())
    h.update(x.tobytes())
    return h.hexdigest()


def info_values(info: dict[str, Any]) -> dict[str, Any]:
    """Return an environment info dict with numpy values made JSON-friendly."""
    out = {}
    for key, val in sorted(info.items()):
        if isinstance(val, np.ndarray):
            out[key] = val.tolist()
        elif isinstance(val, np.generic):
            out[key] = val.item()
        else:
            out[key] = val
    return out


# Actions --------------------------------------------------------------------------------

OBS_OWN = slice(5, 7)  # an agent's own (sensor - predicted target) / L in its observation


def random_actions(rng: np.random.Generator, own_rel: np.ndarray) -> np.ndarray:
    """Return actions (..., M, 2): a mix of chasing the predicted target and random moves.

    ``own_rel`` (..., M, 2) is each agent's own position relative to the predicted target
    as read from its observation. Per agent: with probability 0.4 it heads for the
    predicted target with a length in [0.5, 2] (into the rho disk when close: the
    projection runs), with 0.3 a uniform vector in [-1.5, 1.5]^2 (often longer than 1),
    otherwise a uniform vector in [-1, 1]^2.
    """
    own = np.asarray(own_rel, dtype=np.float64)
    shape = own.shape
    u = rng.random(shape[:-1])
    length = rng.uniform(0.5, 2.0, shape[:-1])
    wide = rng.uniform(-1.5, 1.5, shape)
    narrow = rng.uniform(-1.0, 1.0, shape)
    norm = np.maximum(np.hypot(own[..., 0], own[..., 1]), 1e-12)
    chase = -own / norm[..., None] * length[..., None]
    return np.where((u < 0.4)[..., None], chase, np.where((u < 0.7)[..., None], wide, narrow))


# Simulation runner ----------------------------------------------------------------------


def record_of(rec: Any) -> dict[str, Any]:
    """Return every field of a ``RunRecord`` except the planning times."""
    return {
        "seed": rec.seed,
        "terminated": bool(rec.terminated),
        "trace": f64(rec.trace),
        "error": f64(rec.error),
        "nees": f64(rec.nees),
        "violation": f64(rec.violation),
        "true_states": f64(rec.true_states),
        "estimates": f64(rec.estimates),
        "sensors": f64(rec.sensors),
        "position_covs": f64(rec.position_covs),
        "mean_trace": rec.mean_trace,
        "rmse": rec.rmse,
        "mean_nees": rec.mean_nees,
    }


def monte_carlo_of(res: Any) -> dict[str, Any]:
    """Return a ``MonteCarloResult``: per-run values, ``summary()`` without timings, records."""
    summary = {k: v for k, v in res.summary().items() if not k.startswith("plan_time")}
    return {
        "name": res.name,
        "seeds": list(res.seeds),
        "mean_trace": f64(res.mean_trace),
        "rmse": f64(res.rmse),
        "nees": f64(res.nees),
        "max_violation": res.max_violation,
        "n_terminated": res.n_terminated,
        "n_plan_times": int(np.size(res.plan_times)),
        "summary": summary,
        "records": [record_of(r) for r in res.records],
    }


def study(scenario: Any, planners: dict[str, Any], runs: int, seed: int) -> dict[str, Any]:
    """Return ``run_monte_carlo`` of ``planners`` (first run's trajectories kept)."""
    from activetrack.baselines import run_monte_carlo

    results = run_monte_carlo(scenario, planners, runs, seed, progress=False, keep_records=1)
    return {name: monte_carlo_of(res) for name, res in results.items()}


def ca_scenario() -> Any:
    """Return the paper's team tracking a constant-acceleration target."""
    import activetrack

    return activetrack.make_scenario(
        "paper",
        motion="ca",
        x0=(0.0, 0.0, -8.0, 6.0, 0.0, 0.0),
        x0_hat=(2.0, -2.0, 0.0, 0.0, 0.0, 0.0),
        P0=(4.0, 4.0, 100.0, 100.0, 10.0, 10.0),
    )


def case_paper_study() -> dict[str, Any]:
    from activetrack import make_scenario
    from activetrack.baselines import GBES, GSR, RandomMotion

    planners = {
        "gsr": GSR(),
        "gsr-restarts": GSR(restarts=True),
        "gbes": GBES(),
        "rm": RandomMotion(),
    }
    return study(make_scenario("paper"), planners, PAPER_RUNS, 0)


def case_cli_simulate() -> dict[str, Any]:
    from activetrack import cli

    with tempfile.TemporaryDirectory() as tmp:
        argv = ["simulate", "--scenario", "paper", "--planner", "gsr", "--planner", "rm"]
        argv += ["--runs", "3", "--seed", "5", "--out", tmp, "--no-plot", "--no-progress"]
        with contextlib.redirect_stdout(io.StringIO()):
            code = cli.main(argv)
        data = json.loads((Path(tmp) / "results.json").read_text())
    for summary in data.values():
        for key in [k for k in summary if k.startswith("plan_time")]:
            del summary[key]
    return {"exit_code": code, "results_json": data}


def case_homogeneous_study() -> dict[str, Any]:
    from activetrack import make_scenario
    from activetrack.baselines import GSR, RandomMotion

    return study(make_scenario("homogeneous"), {"gsr": GSR(), "rm": RandomMotion()}, 3, 0)


def case_ca_motion() -> dict[str, Any]:
    from activetrack.baselines import GSR, RandomMotion

    return study(ca_scenario(), {"gsr": GSR(), "rm": RandomMotion()}, 3, 0)


def case_max_trace_runner() -> dict[str, Any]:
    from activetrack import make_scenario
    from activetrack.baselines import RandomMotion, simulate

    sc = make_scenario("paper", max_trace=MAX_TRACE)
    out = study(sc, {"rm": RandomMotion()}, 6, 0)
    out["runs"] = [record_of(simulate(sc, RandomMotion(), s)) for s in range(6)]
    return out


# Single environments --------------------------------------------------------------------


def agent_infos(infos: dict[str, dict[str, Any]], agents: list[str]) -> dict[str, list[Any]]:
    """Return the agents' infos as one list per key, in agent order."""
    per_agent = [info_values(infos[a]) for a in agents]
    return {key: [i[key] for i in per_agent] for key in per_agent[0]}


def parallel_obs(obs: dict[str, np.ndarray], agents: list[str]) -> dict[str, Any]:
    """Return the first agent's observation and a digest of all agents' (stacked)."""
    return {"first": f32(obs[agents[0]]), "sha256": digest(np.stack([obs[a] for a in agents]))}


def parallel_episodes(
    env: Any, seed: int, action_seed: int, episodes: int = 2, float32_actions: bool = False
) -> list[dict[str, Any]]:
    """Return ``episodes`` episodes of a parallel env: reset(seed) first, then reset()."""
    rng = np.random.default_rng(action_seed)
    out = []
    for ep in range(episodes):
        obs, infos = env.reset(seed=seed if ep == 0 else None)
        agents = list(env.agents)
        steps = []
        rec = {
            "agents": agents,
            "reset_obs": parallel_obs(obs, agents),
            "reset_infos": agent_infos(infos, agents),
            "reset_state": f32(env.state()),
            "steps": steps,
        }
        while env.agents:
            live = list(env.agents)
            own = np.array([obs[a][OBS_OWN] for a in live])
            acts = random_actions(rng, own)
            if float32_actions:
                acts = acts.astype(np.float32)
            obs, rewards, terms, truncs, infos = env.step(dict(zip(live, acts, strict=True)))
            steps.append(
                {
                    "rewards": [rewards[a] for a in live],
                    "terminations": [terms[a] for a in live],
                    "truncations": [truncs[a] for a in live],
                    "infos": agent_infos(infos, live),
                    "obs": parallel_obs(obs, live),
                    "state": f32(env.state()),
                    "agents_after": list(env.agents),
                }
            )
        out.append(rec)
    return out


def parallel_case(seed: int, action_seed: int, scenario: str, **overrides: Any) -> dict[str, Any]:
    from activetrack import envs

    env = envs.parallel_env(scenario, **overrides)
    try:
        return {"episodes": parallel_episodes(env, seed, action_seed)}
    finally:
        env.close()


def case_parallel_paper() -> dict[str, Any]:
    return parallel_case(3, 101, "paper")


def case_parallel_homogeneous() -> dict[str, Any]:
    return parallel_case(4, 102, "homogeneous")


# Five sensors started close to a slow target, so the chasing actions enter the rho disk.
# A slow target (small initial velocity variance and process noise): the chasers keep up.
M5_OVERRIDES = {
    "n_sensors": 5,
    "rho": 1.5,
    "sensor_center": (2.0, -2.0),
    "sensor_radius": 4.0,
    "P0": (4.0, 4.0, 1.0, 1.0),
    "q": 1.0,
}


def case_parallel_m5() -> dict[str, Any]:
    return parallel_case(5, 103, "homogeneous", **M5_OVERRIDES)


def case_parallel_max_trace() -> dict[str, Any]:
    return parallel_case(6, 104, "paper", max_trace=MAX_TRACE)


def case_aec() -> dict[str, Any]:
    from activetrack import envs

    env = envs.env("paper")
    rng = np.random.default_rng(105)
    env.reset(seed=7)
    steps = []
    for agent in env.agent_iter():
        obs, reward, term, trunc, info = env.last()
        if term or trunc:
            action = None
        else:
            action = random_actions(rng, obs[OBS_OWN][None])[0].astype(np.float32)
        steps.append(
            {
                "agent": agent,
                "obs": f32(obs),
                "reward": reward,
                "termination": term,
                "truncation": trunc,
                "info": info_values(info),
                "state": f32(env.state()),
            }
        )
        env.step(action)
    env.close()
    return {"steps": steps}


def case_gymnasium_centralized() -> dict[str, Any]:
    import gymnasium

    import activetrack.envs  # noqa: F401  (registers the id)

    env = gymnasium.make(ENV_ID, scenario="homogeneous", n_sensors=3)
    m = 3
    rng = np.random.default_rng(106)
    obs, info = env.reset(seed=8)
    out = {"reset_obs": f32(obs), "reset_info": info_values(info), "steps": []}
    done = False
    while not done:
        own = obs.reshape(m, -1)[:, OBS_OWN]
        action = random_actions(rng, own).reshape(-1).astype(np.float32)
        obs, reward, term, trunc, info = env.step(action)
        out["steps"].append(
            {
                "obs": f32(obs),
                "reward": reward,
                "terminated": term,
                "truncated": trunc,
                "info": info_values(info),
            }
        )
        done = term or trunc
    env.close()
    return out


# Batched environment --------------------------------------------------------------------


def batched_obs(obs: np.ndarray, m: int) -> dict[str, Any]:
    """Return agent 0's block of every copy's joint observation and a digest of all."""
    d = obs.shape[-1] // m
    return {"agent0": f32(obs[:, :d]), "sha256": digest(obs)}


def batched_case(
    scenario: str,
    mode: str,
    seed: int,
    action_seed: int,
    n: int = BATCH_N,
    steps: int = BATCH_STEPS,
    compare_singles: bool = True,
    **overrides: Any,
) -> dict[str, Any]:
    """Return a NEXT_STEP or SAME_STEP run of the batched env with random actions.

    With ``compare_singles`` the same actions also drive N single environments (seeded
    ``seed + i``, reset without a seed when an episode ends, as the batched copy is), and
    whether copy i equals single env i bit for bit is recorded per step, as data.
    """
    from activetrack import envs

    env = envs.BatchedActiveTracking(n, scenario, autoreset_mode=mode, **overrides)
    m = env.n_sensors
    rng = np.random.default_rng(action_seed)
    obs, infos = env.reset(seed=seed)
    singles = (
        [envs.parallel_env(scenario, **overrides) for _ in range(n)] if compare_singles else []
    )
    single_obs = [s.reset(seed=seed + i)[0] for i, s in enumerate(singles)]
    out: dict[str, Any] = {"reset": batched_obs(obs, m), "reset_infos": info_values(infos)}
    if singles:
        out["reset_equals_single"] = [
            bool(np.array_equal(obs[i], joint(single_obs[i]))) for i in range(n)
        ]
    rows = []
    for _ in range(steps):
        own = obs.reshape(n, m, -1)[:, :, OBS_OWN]
        a = random_actions(rng, own).reshape(n, 2 * m)
        obs, rewards, term, trunc, infos = env.step(a)
        row = {
            "obs": batched_obs(obs, m),
            "rewards": f64(rewards),
            "terminated": term.tolist(),
            "truncated": trunc.tolist(),
            "trace": f64(infos["trace"]),
            "step": infos["step"].tolist(),
        }
        if "final_obs" in infos:
            row["final_obs"] = [
                None if fo is None else f32(np.asarray(fo)) for fo in infos["final_obs"]
            ]
            row["_final_obs"] = infos["_final_obs"].tolist()
            row["final_info_trace"] = f64(infos["final_info"]["trace"])
            row["final_info__trace"] = infos["final_info"]["_trace"].tolist()
        if singles:
            row["equals_single"] = step_singles(singles, a.reshape(n, m, 2), obs, rewards, mode)
        rows.append(row)
    out["steps"] = rows
    for s in singles:
        s.close()
    env.close()
    return out


def joint(obs: dict[str, np.ndarray]) -> np.ndarray:
    """Return a parallel env's observations concatenated in agent order."""
    return np.concatenate([obs[a] for a in sorted(obs, key=lambda a: int(a.split("_")[1]))])


def step_singles(
    singles: list[Any], actions: np.ndarray, obs: np.ndarray, rewards: np.ndarray, mode: str
) -> dict[str, list[Any]]:
    """Step single envs like the batched copies; return per copy how far apart they are.

    ``equal``: observations and reward bit for bit; ``obs_diff``: the largest absolute
    difference of the observations; ``reward_diff``: of the rewards.
    """
    equal, obs_diff, reward_diff = [], [], []
    for i, env in enumerate(singles):
        if not env.agents:  # NEXT_STEP: this step resets the copy, reward 0
            o, _ = env.reset()
            r = 0.0
        else:
            o, rw, _, _, _ = env.step(dict(zip(env.agents, actions[i], strict=True)))
            r = next(iter(rw.values()))
            if mode == "SameStep" and not env.agents:
                o, _ = env.reset()
        equal.append(bool(np.array_equal(obs[i], joint(o)) and rewards[i] == r))
        obs_diff.append(float(np.max(np.abs(obs[i].astype(float) - joint(o)))))
        reward_diff.append(abs(float(rewards[i]) - r))
    return {"equal": equal, "obs_diff": obs_diff, "reward_diff": reward_diff}


def case_batched_next_step_paper() -> dict[str, Any]:
    return batched_case("paper", "NextStep", 10, 201)


def case_batched_next_step_homogeneous() -> dict[str, Any]:
    return batched_case("homogeneous", "NextStep", 20, 202)


def case_batched_same_step_paper() -> dict[str, Any]:
    return batched_case("paper", "SameStep", 30, 203)


def case_batched_same_step_homogeneous() -> dict[str, Any]:
    return batched_case("homogeneous", "SameStep", 40, 204, **M5_OVERRIDES)


def case_batched_max_trace() -> dict[str, Any]:
    return batched_case("paper", "NextStep", 50, 205, n=4, steps=80, max_trace=MAX_TRACE)


def case_batched_disabled() -> dict[str, Any]:
    """DISABLED autoreset: done copies reset by mask; a mid-episode reset with seeds."""
    from activetrack import envs

    n, steps = BATCH_N, BATCH_STEPS
    env = envs.BatchedActiveTracking(n, "homogeneous", autoreset_mode="Disabled")
    m = env.n_sensors
    rng = np.random.default_rng(206)
    obs, infos = env.reset(seed=60)
    out: dict[str, Any] = {"reset": batched_obs(obs, m), "steps": []}
    for k in range(steps):
        own = obs.reshape(n, m, -1)[:, :, OBS_OWN]
        obs, rewards, term, trunc, infos = env.step(random_actions(rng, own).reshape(n, 2 * m))
        row: dict[str, Any] = {
            "obs": batched_obs(obs, m),
            "rewards": f64(rewards),
            "terminated": term.tolist(),
            "truncated": trunc.tolist(),
            "trace": f64(infos["trace"]),
            "step": infos["step"].tolist(),
        }
        done = term | trunc
        if k == 30:  # mid-episode: copies 1-3, two new seeds and one continuing generator
            mask = np.array([False, True, True, True, False])
            obs, infos = env.reset(seed=[None, 600, None, 601, None], options={"reset_mask": mask})
            row["reset_mask"] = mask.tolist()
        elif done.any():
            obs, infos = env.reset(options={"reset_mask": done})
            row["reset_mask"] = done.tolist()
        if "reset_mask" in row:
            row["reset_obs"] = batched_obs(obs, m)
            row["reset_trace"] = f64(infos["trace"])
            row["reset_step"] = infos["step"].tolist()
        out["steps"].append(row)
    env.close()
    return out


def case_batched_step_agents() -> dict[str, Any]:
    """``step_agents``: per-agent observations (N, M, D) for parameter-sharing learners."""
    from activetrack import envs

    env = envs.BatchedActiveTracking(3, "homogeneous", n_sensors=2)
    rng = np.random.default_rng(207)
    obs, _ = env.reset(seed=70)
    obs = obs.reshape(3, 2, -1)
    rows = []
    for _ in range(60):
        obs, rewards, term, trunc, infos = env.step_agents(random_actions(rng, obs[:, :, OBS_OWN]))
        rows.append(
            {
                "obs": f32(obs),
                "rewards": f64(rewards),
                "terminated": term.tolist(),
                "truncated": trunc.tolist(),
                "trace": f64(infos["trace"]),
            }
        )
    env.close()
    return {"steps": rows}


# Expert policies in the environments ----------------------------------------------------


def expert_episode(policy_cls: type, seed: int, scenario: str = "paper") -> dict[str, Any]:
    """Return one episode of an expert policy in the parallel env (seeded like the runner)."""
    from activetrack import envs

    env = envs.parallel_env(scenario)
    policy = policy_cls(seed=seed)
    obs, infos = env.reset(seed=seed)
    first = env.possible_agents[0]
    sensors = [f64(env.planning_problem().sensors)]
    rewards, traces, errors, projected = [], [], [], []
    while env.agents:
        # Since the one-world refactor an expert's positions are executed directly (the
        # recording at bb51820 went through actions_to_reach and back: exact there).
        obs, rew, _, _, infos = env.step_positions(policy.plan(env.planning_problem()))
        rewards.append(rew[first])
        traces.append(infos[first]["trace"])
        errors.append(infos[first]["position_error"])
        projected.append([infos[a]["n_projected"] for a in env.possible_agents])
        sensors.append(f64(env.planning_problem().sensors))
    env.close()
    return {
        "rewards": rewards,
        "trace": traces,
        "position_error": errors,
        "n_projected": projected,
        "sensors": sensors,
        "last_obs": f32(joint(obs)),
    }


def expert_case(name: str) -> dict[str, Any]:
    from activetrack.baselines import policies

    cls = {"gsr": policies.GSRPolicy, "gbes": policies.GBESPolicy, "rm": policies.RMPolicy}[name]
    return {f"seed_{s}": expert_episode(cls, s) for s in (0, 1)}


def case_expert_gsr() -> dict[str, Any]:
    return expert_case("gsr")


def case_expert_gbes() -> dict[str, Any]:
    return expert_case("gbes")


def case_expert_rm() -> dict[str, Any]:
    return expert_case("rm")


def case_expert_batched_gsr() -> dict[str, Any]:
    from activetrack import envs
    from activetrack.baselines import GSRPolicy

    n = 4
    env = envs.BatchedActiveTracking(n, "paper")
    m = env.n_sensors
    policy = GSRPolicy()
    obs, _ = env.reset(seed=80)
    rows = []
    for _ in range(60):
        # At bb51820: BatchedGSRPolicy().act(env) actions through env.step (round trip).
        obs, rewards, term, trunc, infos = env.step_positions(policy.plan(env.planning_problem()))
        obs = obs.reshape(n, -1)
        rows.append(
            {
                "obs": batched_obs(obs, m),
                "rewards": f64(rewards),
                "terminated": term.tolist(),
                "truncated": trunc.tolist(),
                "trace": f64(infos["trace"]),
            }
        )
    env.close()
    return {"steps": rows}


# Evaluation -----------------------------------------------------------------------------


def evaluation_of(results: list[Any]) -> dict[str, Any]:
    from activetrack.baselines.evaluation import summaries

    return {
        "results": [
            {
                "policy": r.policy,
                "seeds": list(r.seeds),
                "mean_trace": f64(r.mean_trace),
                "rmse": f64(r.rmse),
                "returns": f64(r.returns),
                "requested": bool(r.requested),
            }
            for r in results
        ],
        # Without the entries added after the recording: ``ms_per_step`` (wall clock) and
        # ``nees`` (checked against the simulation runner in tests/baselines).
        "summaries": [
            {k: v for k, v in row.items() if k not in ("ms_per_step", "nees")}
            for row in summaries(results)
        ],
    }


def case_evaluation() -> dict[str, Any]:
    from activetrack.baselines.evaluation import evaluate

    return evaluation_of(evaluate(["gsr", "gbes", "rm"], "paper", 5, 1000, progress=False))


def case_evaluation_reference() -> dict[str, Any]:
    """Only RM asked for: GSR is added as the ratio's reference (``requested=False``)."""
    from activetrack.baselines.evaluation import evaluate

    return evaluation_of(evaluate(["rm"], "homogeneous", 2, 2000, progress=False))


# Planners on fixed problems -------------------------------------------------------------

PLANNER_SIZES = (1, 2, 3, 5)
PROBLEMS_PER_SIZE = 13  # 52 problems


def case_planners() -> dict[str, Any]:
    from activetrack.baselines import GBES, GSR, RandomMotion, random_problem

    gsr, gsr_r, rm = GSR(), GSR(restarts=True), RandomMotion()
    out = []
    for m in PLANNER_SIZES:
        # The paper's grid spacing has 1e10+ combinations for five sensors: coarser there.
        gbes = GBES() if m <= 3 else GBES(spacing=0.3)
        for j in range(PROBLEMS_PER_SIZE):
            k = 100 * m + j
            problem = random_problem(np.random.default_rng(k), n_sensors=m)
            a = gsr.plan_with_info(problem)
            b = gsr_r.plan_with_info(problem)
            g = gbes.search(problem)
            out.append(
                {
                    "seed": k,
                    "n_sensors": m,
                    "gsr": {
                        "positions": f64(a.positions),
                        "value": a.value,
                        "sweeps": a.sweeps,
                        "n_solves": a.n_solves,
                        "start": a.start,
                        "converged": a.converged,
                        "warm_value": a.warm_value,
                        "warm_feasible": a.warm_feasible,
                        "plan": f64(gsr.plan(problem)),
                    },
                    "gsr_restarts": {
                        "positions": f64(b.positions),
                        "value": b.value,
                        "sweeps": b.sweeps,
                        "n_solves": b.n_solves,
                        "start": b.start,
                        "converged": b.converged,
                    },
                    "gbes": {
                        "spacing": gbes.spacing,
                        "positions": f64(g.positions),
                        "value": g.value,
                        "n_combinations": g.n_combinations,
                        "n_evaluated": g.n_evaluated,
                        "plan": f64(gbes.plan(problem)),
                    },
                    "rm": f64(rm.plan(problem, np.random.default_rng([k, 7]))),
                    "objective_of_gsr": f64(problem.trace(a.positions)),
                }
            )
    return {"problems": out}


def case_batched_gsr() -> dict[str, Any]:
    from activetrack.baselines import GSR, random_problem
    from activetrack.world.problem import PlanningProblem

    out = {}
    for m, count in ((3, 200), (5, 40)):
        probs = [random_problem(np.random.default_rng(5000 + 10 * m + k), m) for k in range(count)]
        stack = {
            f: np.stack([getattr(p, f) for p in probs])
            for f in ("prior_cov", "target", "sensors", "r", "rho", "sigma_d2", "sigma_theta2")
        }
        # GSR on the batched problem: one compiled sweep over the copies (gsr.relax_batch).
        res = GSR().plan_with_info(PlanningProblem(**stack))
        out[f"m{m}"] = {
            "positions": f64(res.positions),
            "value": f64(res.value),
            "sweeps": np.asarray(res.sweeps).tolist(),
        }
    return out


# Registry ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """One recorded group of results: its function, description and whether it is slow."""

    compute: Callable[[], dict[str, Any]]
    description: str
    slow: bool = False


CASES: dict[str, Case] = {
    "paper_study": Case(
        case_paper_study,
        f"run_monte_carlo('paper', gsr, gsr-restarts, gbes, rm; {PAPER_RUNS} runs from seed 0): "
        "per-run mean trace, RMSE, NEES, max violation, n_terminated, summary() without "
        "timings, and each planner's first run (trajectories, estimates, sensors, covs)",
        slow=True,
    ),
    "cli_simulate": Case(
        case_cli_simulate,
        "`activetrack simulate --scenario paper --planner gsr --planner rm --runs 3 --seed 5`: "
        "results.json without the plan_time_* entries",
    ),
    "homogeneous_study": Case(
        case_homogeneous_study,
        "run_monte_carlo('homogeneous' (gaussian target init, M=4), gsr and rm, 3 runs from 0)",
    ),
    "ca_motion": Case(
        case_ca_motion,
        "run_monte_carlo(paper team, motion='ca' with 6-state x0/x0_hat/P0, gsr and rm, 3 runs)",
    ),
    "max_trace_runner": Case(
        case_max_trace_runner,
        f"paper with max_trace={MAX_TRACE}, rm, seeds 0..5: runs that terminate early "
        "(run_monte_carlo and simulate)",
    ),
    "parallel_paper": Case(
        case_parallel_paper,
        "parallel_env('paper'): reset(seed=3) and reset() episodes with seeded random actions "
        "(chasing the predicted target, longer than 1, uniform): obs, state(), rewards, flags, "
        "infos",
    ),
    "parallel_homogeneous": Case(
        case_parallel_homogeneous, "parallel_env('homogeneous'): as parallel_paper, seed 4"
    ),
    "parallel_m5": Case(
        case_parallel_m5,
        f"parallel_env('homogeneous', {M5_OVERRIDES}) (sensors start near the target so the "
        "rho projection runs): as parallel_paper, seed 5",
    ),
    "parallel_max_trace": Case(
        case_parallel_max_trace,
        f"parallel_env('paper', max_trace={MAX_TRACE}): episodes that terminate early, seed 6",
    ),
    "aec": Case(
        case_aec,
        "env('paper') (AEC), reset(seed=7), float32 random actions: every agent_iter step's "
        "last() and state()",
    ),
    "gymnasium_centralized": Case(
        case_gymnasium_centralized,
        f"gymnasium.make('{ENV_ID}', scenario='homogeneous', n_sensors=3), reset(seed=8), "
        "float32 random joint actions: obs, rewards, flags, infos",
    ),
    "batched_next_step_paper": Case(
        case_batched_next_step_paper,
        f"BatchedActiveTracking({BATCH_N}, 'paper', NEXT_STEP), reset(seed=10), {BATCH_STEPS} "
        "random steps: agent 0's obs block per copy + SHA-256 of all obs, rewards, flags, "
        "trace, step; and per step whether copy i equals parallel_env seeded 10 + i",
    ),
    "batched_next_step_homogeneous": Case(
        case_batched_next_step_homogeneous, "as batched_next_step_paper on 'homogeneous', seed 20"
    ),
    "batched_same_step_paper": Case(
        case_batched_same_step_paper,
        "as batched_next_step_paper in SAME_STEP mode, seed 30, with final_obs and final_info",
    ),
    "batched_same_step_homogeneous": Case(
        case_batched_same_step_homogeneous,
        f"as batched_same_step_paper on 'homogeneous' with {M5_OVERRIDES} (the rho "
        "projection runs), seed 40",
    ),
    "batched_max_trace": Case(
        case_batched_max_trace,
        f"BatchedActiveTracking(4, 'paper', NEXT_STEP, max_trace={MAX_TRACE}), seed 50, "
        "80 steps: copies that terminate early (and their next episodes)",
    ),
    "batched_disabled": Case(
        case_batched_disabled,
        f"BatchedActiveTracking({BATCH_N}, 'homogeneous', DISABLED), reset(seed=60): done copies "
        "reset with reset_mask; at step 31 reset(seed=[None, 600, None, 601, None], "
        "reset_mask=[F, T, T, T, F])",
    ),
    "batched_step_agents": Case(
        case_batched_step_agents,
        "BatchedActiveTracking(3, 'homogeneous', n_sensors=2).step_agents: per-agent obs, 60 steps",
    ),
    "expert_gsr": Case(
        case_expert_gsr,
        "GSRPolicy(seed=s).act(env) in parallel_env('paper') reset(seed=s), s = 0, 1: rewards, "
        "trace, position error, n_projected, planning_problem().sensors per step, last obs",
    ),
    "expert_gbes": Case(case_expert_gbes, "as expert_gsr with GBESPolicy"),
    "expert_rm": Case(case_expert_rm, "as expert_gsr with RMPolicy"),
    "expert_batched_gsr": Case(
        case_expert_batched_gsr,
        "BatchedGSRPolicy().act(env) in BatchedActiveTracking(4, 'paper'), reset(seed=80), "
        "60 steps",
    ),
    "evaluation": Case(
        case_evaluation,
        "evaluate(['gsr', 'gbes', 'rm'], 'paper', episodes=5, seed=1000): per-episode mean "
        "trace, RMSE, return; summaries() (95% intervals, bootstrap ratio to GSR)",
        slow=True,
    ),
    "evaluation_reference": Case(
        case_evaluation_reference,
        "evaluate(['rm'], 'homogeneous', episodes=2, seed=2000): GSR added as the reference",
    ),
    "planners": Case(
        case_planners,
        f"random_problem(default_rng(100 M + j), n_sensors=M), M in {PLANNER_SIZES}, "
        f"j < {PROBLEMS_PER_SIZE}: GSR and GSR(restarts=True) plan_with_info, GBES search "
        "(spacing 0.3 m for M = 5), RandomMotion with default_rng([k, 7])",
    ),
    "batched_gsr": Case(
        case_batched_gsr,
        "GSR().plan_with_info on a batched PlanningProblem (recorded: BatchedGSR().plan_batch) "
        "of 200 random problems with M = 3 and 40 with M = 5 "
        "(random_problem(default_rng(5000 + 10 M + k))): positions, value, sweeps",
    ),
}


# Recording --------------------------------------------------------------------------------


def git_commit() -> str:
    """Return the commit the working tree is at (``git rev-parse HEAD``)."""
    return subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=REPO, capture_output=True, text=True, check=True
    ).stdout.strip()


def library_clean() -> bool:
    """Return whether the library's files are as committed (no local changes)."""
    out = subprocess.run(
        ["git", "status", "--porcelain", "--", "src", "envs", "baselines", "pyproject.toml"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    return not out.strip()


def cpu_model() -> str:
    """Return the CPU model name (results of BLAS kernels may depend on it)."""
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor()


def blas_config() -> str:
    """Return numpy's BLAS build configuration (e.g. OpenBLAS version and target)."""
    with contextlib.suppress(Exception):
        blas = np.show_config(mode="dicts")["Build Dependencies"]["blas"]
        return str(blas.get("openblas configuration") or blas.get("name"))
    return "unknown"


def compute(name: str) -> Any:
    """Return case ``name`` as it reads back from JSON (tuples become lists)."""
    return json.loads(json.dumps(CASES[name].compute(), allow_nan=False))


def record(names: list[str] | None = None, verbose: bool = True) -> dict[str, Any]:
    """Return the recording: metadata and every case's values."""
    import scipy

    data: dict[str, Any] = {
        "commit": git_commit(),
        "library_clean": library_clean(),
        "command": "python tools/record_regression.py",
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "python": sys.version.split()[0],
        "machine": platform.machine(),
        "cpu": cpu_model(),
        "blas": blas_config(),
        "descriptions": {},
        "cases": {},
    }
    for name in names or list(CASES):
        t0 = time.perf_counter()
        data["cases"][name] = compute(name)
        data["descriptions"][name] = CASES[name].description
        if verbose:
            print(f"{name:32s} {time.perf_counter() - t0:6.1f} s", file=sys.stderr)
    return data


def notes(cases: dict[str, Any]) -> dict[str, Any]:
    """Return observations about the recorded values (stored, never compared by the test)."""
    out: dict[str, Any] = {}
    for name, case in cases.items():
        if name.startswith("parallel_"):
            out[name] = [
                {
                    "steps": len(ep["steps"]),
                    "terminated": ep["steps"][-1]["terminations"][0],
                    "n_projected": ep["steps"][-1]["infos"]["n_projected"],
                }
                for ep in case["episodes"]
            ]
        if (
            name.startswith("batched_")
            and case.get("steps")
            and "equals_single" in case["steps"][0]
        ):
            eq = np.array([row["equals_single"]["equal"] for row in case["steps"]])
            rd = np.array([row["equals_single"]["reward_diff"] for row in case["steps"]])
            rw = np.abs([row["rewards"] for row in case["steps"]])
            first = np.argmax(np.array([r["terminated"] for r in case["steps"]]).any(1))
            out[name] = {
                "reset_equals_single": case["reset_equals_single"],
                "steps_equal_single_per_copy": eq.sum(0).tolist(),
                "steps": len(eq),
                "terminated_any": int(sum(any(r["terminated"]) for r in case["steps"])),
                "max_reward_rel_diff": float(np.max(rd / np.maximum(rw, 1e-300))),
                "max_obs_abs_diff": float(
                    max(max(row["equals_single"]["obs_diff"]) for row in case["steps"])
                ),
                "first_termination_step": int(first) + 1 if case["steps"] else None,
            }
    study = cases.get("paper_study")
    for planner in ("gsr", "gbes", "rm"):
        expert = cases.get(f"expert_{planner}")
        if study is None or expert is None:
            continue
        rec = study[planner]["records"][0]  # seed 0
        ep = expert["seed_0"]
        rew = np.array(ep["rewards"])
        tr = np.array(rec["trace"])
        sens_env, sens_run = np.array(ep["sensors"]), np.array(rec["sensors"])
        out[f"expert_{planner}_vs_runner_seed0"] = {
            "trace_bit_equal": bool(np.array_equal(-rew, tr)),
            "trace_max_rel_diff": float(np.max(np.abs(-rew - tr) / tr)),
            "sensors_bit_equal": bool(np.array_equal(sens_env, sens_run)),
            "sensors_max_abs_diff": float(np.max(np.abs(sens_env - sens_run))),
        }
    return out


def write_json(data: dict[str, Any], path: Path) -> None:
    """Write ``data`` to ``path`` atomically (a temporary file in the folder, then rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, separators=(",", ":"), allow_nan=False)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def main(argv: list[str] | None = None) -> int:
    """Record every case (or ``--case`` ones) and write the JSON file."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output JSON file")
    parser.add_argument("--case", action="append", choices=sorted(CASES), help="only these")
    args = parser.parse_args(argv)
    data = record(args.case)
    if args.out == DEFAULT_OUT and not data["commit"].startswith("bb51820"):
        print(
            f"warning: recording at {data['commit']}, not bb51820: the test expects bb51820's "
            "values; use --out for another file",
            file=sys.stderr,
        )
    data["notes"] = notes(data["cases"])
    print(json.dumps(data["notes"], indent=1), file=sys.stderr)
    write_json(data, args.out)
    print(f"wrote {args.out} ({args.out.stat().st_size / 1e6:.2f} MB) at {data['commit']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
