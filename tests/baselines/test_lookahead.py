"""Tests of the receding-horizon planner (activetrack.baselines.lookahead).

Independent computations: the EKF of activetrack.estimation.ekf driven as the world drives it (the
filter's square-root update and prediction) for the planning model's covariances and for
GSR's rollout score; the world's own state for the recovered prediction and for the
explicit path that the problem's prediction must reproduce bit for bit; the world's
constraint check (PlanningProblem.violation) for feasibility; GSR on the same seeds for
the realized minimum-distance violations.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.baselines import GSR, Lookahead, LookaheadPlanner, LookaheadPolicy
from activetrack.baselines import horizon_model as hm
from activetrack.baselines.lookahead import run_batched
from activetrack.baselines.prediction_tracker import PredictionTracker
from activetrack.estimation import ekf
from activetrack.models.motion import constant_velocity, predict
from activetrack.world import World
from activetrack.world.problem import PlanningProblem
from tests.core.helpers import range_bearing


def _random_state(rng: np.random.Generator, m: int = 3):
    """Return a random prediction (x, P), the CV model and a planning problem around it."""
    model = constant_velocity(q=float(rng.uniform(0.5, 20.0)), dt=0.1)
    A = rng.normal(size=(4, 4))
    P = A @ A.T * rng.uniform(0.05, 3.0) + np.diag([0.05, 0.05, 0.5, 0.5])
    P = 0.5 * (P + P.T)
    x = np.concatenate([rng.uniform(-5, 5, 2), rng.uniform(-10, 10, 2)])
    dist = rng.uniform(1.0, 25.0, m)
    ang = rng.uniform(0.0, 2 * np.pi, m)
    sensors = x[:2] + dist[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    problem = PlanningProblem(
        prior_cov=P[:2, :2],
        target=x[:2],
        sensors=sensors,
        r=rng.uniform(0.5, 1.5, m),
        rho=rng.uniform(0.5, 2.5, m),
        sigma_d2=rng.uniform(0.5, 5.0, m),
        sigma_theta2=rng.uniform(0.05, 1.0, m),
    )
    return x, P, model, problem


def _filter_along(plan, x, P, model, problem, orientation=0.0):
    """Return the filter's (priors, posteriors) along ``plan`` (M, H, 2): the target moves
    exactly as predicted, measurements are noise-free, as the world's step drives the EKF."""
    priors, posts = [], []
    for h in range(plan.shape[1]):
        sensors = plan[:, h]
        z = range_bearing(x[:2], sensors, orientation, wrap=True)
        priors.append(P)
        x_post, P_post = ekf.update(
            x, P, z, sensors, problem.sigma_d2, problem.sigma_theta2, orientation
        )
        np.testing.assert_allclose(x_post, x, rtol=0, atol=1e-9 * (1 + np.abs(x).max()))
        posts.append(P_post)
        x, P = predict(x_post, P_post, model.Phi, model.Q)
    return np.array(priors), np.array(posts)


def test_model_covariances_equal_the_filter():
    rng = np.random.default_rng(0)
    for _ in range(50):
        x, P, model, problem = _random_state(rng)
        H = int(rng.integers(1, 15))
        plan = problem.sensors[:, None] + rng.normal(0, 3.0, (problem.n_sensors, H, 2))
        orientation = rng.uniform(-1, 1, problem.n_sensors)
        priors, posts = _filter_along(plan, x, P, model, problem, orientation)
        means = hm.predicted_means(x, model.Phi, H)
        Y = hm.path_information(plan, means[:, :2], problem.sigma_d2, problem.sigma_theta2).sum(
            axis=0
        )
        score, traces, model_posts = hm.rollout(
            P, Y, model.Phi, model.Q, np.ones(H), return_covariances=True
        )
        scale = np.abs(posts).max(axis=(1, 2))[:, None, None]
        assert np.all(np.abs(model_posts - posts) <= 1e-9 * scale)
        pscale = np.abs(priors).max(axis=(1, 2))[:, None, None]
        model_priors = hm.prior_sequence(P, Y, model.Phi, model.Q)
        assert np.all(np.abs(model_priors - priors) <= 1e-9 * pscale)
        np.testing.assert_allclose(traces, np.trace(posts[:, :2, :2], axis1=1, axis2=2), 1e-9)
        np.testing.assert_allclose(score, traces.sum(), 1e-12)


def _gsr_rollout_score(x, P, model, problem, H, weights, margin, tail=0, tail_weight=1.0):
    """Return GSR's rollout score through the filter (independent of horizon_model), GSR
    keeping ``rho + margin * sigma`` (sigma from the largest eigenvalue of P11); with a
    ``tail``, the team then keeps its last planned position relative to the predicted
    target (the same information) for ``tail`` more steps, each weighted ``tail_weight``
    times the last step."""
    gsr = GSR()
    rho = problem.rho + margin * np.sqrt(np.linalg.eigvalsh(P[:2, :2]).max())
    weights = np.concatenate([weights, np.full(tail, tail_weight * weights[-1])])
    sensors, total = problem.sensors, 0.0
    for h in range(H + tail):
        step = PlanningProblem(
            prior_cov=P[:2, :2],
            target=x[:2],
            sensors=sensors,
            r=problem.r,
            rho=rho,
            sigma_d2=problem.sigma_d2,
            sigma_theta2=problem.sigma_theta2,
        )
        if h < H:
            sensors = gsr.plan(step)
            offset = sensors - x[:2]
        else:  # past the horizon: the same place relative to the predicted target
            sensors = x[:2] + offset
        z = range_bearing(x[:2], sensors, 0.0)
        x, P_post = ekf.update(x, P, z, sensors, problem.sigma_d2, problem.sigma_theta2)
        total += weights[h] * (P_post[0, 0] + P_post[1, 1])
        x, P = predict(x, P_post, model.Phi, model.Q)
    return total


@pytest.mark.parametrize(
    ("discount", "margin", "tail", "pairs"),
    [(1.0, 0.0, 0, 0), (0.9, 0.0, 0, 0), (1.0, 0.5, 0, 0), (1.0, 0.5, 3, 0), (0.9, 0.0, 2, 1)],
)
def test_model_score_never_above_gsr_rollout(discount, margin, tail, pairs):
    rng = np.random.default_rng(1)
    for _ in range(40):
        x, P, model, problem = _random_state(rng, int(rng.integers(1, 5)))
        H = int(rng.integers(1, 12))
        la = Lookahead(
            horizon=H, discount=discount, headings=8, bearings=4, margin=margin, tail=tail,
            tail_weight=2.0, pair_passes=pairs,
        )  # fmt: skip
        previous = problem.sensors[:, None] + rng.normal(0, 2.0, (problem.n_sensors, H, 2))
        res = la.plan_prediction(problem, x, P, model.Phi, model.Q, previous)
        weights = discount ** np.arange(H)
        ref = _gsr_rollout_score(x, P, model, problem, H, weights, margin, tail, 2.0)
        assert res.score <= res.gsr_score
        # GSR stops at a relative improvement of 1e-9 per sweep: rollouts from priors that
        # agree to rounding agree to about that.
        np.testing.assert_allclose(res.gsr_score, ref, rtol=1e-7)
        assert res.score <= ref * (1 + 1e-7)


def test_pair_passes_end_where_no_joint_move_of_two_sensors_is_better(monkeypatch):
    # Brute force over every pair of options of every pair of sensors, one team candidate
    # scored at a time: with two sensors that is every team (the exhaustive optimum).
    seen = {}
    descend = Lookahead._descend

    def spy(self, info, valid, scorer, previous):
        out = descend(self, info, valid, scorer, previous)
        seen.update(info=info[0][0], valid=valid[0], scorer=scorer, choice=out[0][0])
        return out

    monkeypatch.setattr(Lookahead, "_descend", spy)
    rng = np.random.default_rng(7)
    for trial in range(12):
        m = 2 + trial % 2
        x, P, model, problem = _random_state(rng, m)
        res = Lookahead(horizon=4, headings=6, bearings=2, pair_passes=5).plan_prediction(
            problem, x, P, model.Phi, model.Q
        )
        info, valid, scorer, choice = (seen[k] for k in ("info", "valid", "scorer", "choice"))
        best = np.inf
        for i in range(m):
            for j in range(i + 1, m):
                for a in range(info.shape[1]):
                    for b in range(info.shape[1]):
                        team = list(choice)
                        team[i], team[j] = a, b
                        if all(valid[k, team[k]] for k in range(m)):
                            Y = sum(info[k, team[k]] for k in range(m))
                            best = min(best, float(scorer([Y[None, None]])[0, 0]))
        assert res.score <= best * (1 + 1e-12)
        if m == 2:
            np.testing.assert_allclose(res.score, best, rtol=1e-12)
        plain = Lookahead(horizon=4, headings=6, bearings=2, pair_passes=0)
        assert res.score <= plain.plan_prediction(problem, x, P, model.Phi, model.Q).score


def _feasible(problem: PlanningProblem, positions: np.ndarray) -> bool:
    """Return whether every position satisfies the world's constraints (eq. 15-16), except
    sensors that cannot keep rho at all (they go to the farthest reachable point)."""
    viol = problem.violation(positions)
    c = problem.rel_sensors
    cannot = np.hypot(c[..., 0], c[..., 1]) + problem.r < problem.rho
    scale = 1e-9 * (1.0 + np.abs(problem.rel_sensors).max())
    return bool(np.all((viol <= scale) | cannot))


@pytest.mark.parametrize("scenario", ["paper", "homogeneous"])
def test_planned_positions_feasible_in_100_episodes(scenario):
    world = World(scenario, 100, n_steps=12)
    world.reset(seeds=list(range(2000, 2100)))
    la = Lookahead(horizon=6, headings=8, bearings=4, margin=0.5)
    prev = None
    while not world.truncated.all():
        problem = world.planning_problem()
        res = la.plan_prediction(
            problem, world.x_pred, world.P_pred, world.params.Phi, world.params.Q, prev
        )
        assert _feasible(problem, res.positions)
        # Every later step of the plan is feasible about that step's predicted target.
        means = hm.predicted_means(world.x_pred, world.params.Phi, la.horizon)
        for h in range(1, la.horizon):
            step = PlanningProblem(
                prior_cov=problem.prior_cov,
                target=means[:, h, :2],
                sensors=res.plan[:, :, h - 1],
                r=problem.r,
                rho=problem.rho,
                sigma_d2=problem.sigma_d2,
                sigma_theta2=problem.sigma_theta2,
            )
            assert _feasible(step, res.plan[:, :, h])
        prev = res.plan
        world.step(res.positions)
        # The world executed the plan unchanged (a sensor that cannot keep rho is flagged
        # as projected, onto the same farthest reachable point).
        np.testing.assert_allclose(world.sensors, res.positions, rtol=0, atol=1e-9)


def test_tracker_recovers_the_world_prediction():
    for scenario in ("paper", "homogeneous"):
        world = World(scenario, 1)
        tracker = PredictionTracker(None)
        gsr = GSR()
        for seed in range(3):
            world.reset(seeds=[seed])
            first = True
            while not world.truncated[0]:
                problem = world.planning_problem(0)
                x, P, new = tracker.observe(problem)
                assert new == first
                first = False
                x_w, P_w = world.get("x_pred", 0), world.get("P_pred", 0)
                np.testing.assert_allclose(x, x_w, rtol=1e-9, atol=1e-9)
                np.testing.assert_allclose(P, P_w, rtol=1e-9, atol=1e-12)
                world.step(gsr.plan(problem)[None])
        assert tracker.scenario.name == scenario


def test_tracker_rejects_a_foreign_problem():
    tracker = PredictionTracker("paper")
    world = World("paper", 1, q=3.0)
    world.reset(seeds=[0])
    with pytest.raises(ValueError, match="neither continues the episode nor starts one"):
        tracker.observe(world.planning_problem(0))


def _without_prediction(problem: PlanningProblem) -> PlanningProblem:
    """Return ``problem`` as built by hand from the position blocks only (no prediction)."""
    return PlanningProblem(
        problem.prior_cov,
        problem.target,
        problem.sensors,
        problem.r,
        problem.rho,
        problem.sigma_d2,
        problem.sigma_theta2,
    )


def test_policy_from_the_problem_prediction_equals_the_explicit_and_the_tracker_paths():
    world = World("paper", 1)
    world.reset(seeds=[1000])  # the first of the README's evaluation seeds
    settings = dict(horizon=10, headings=16, bearings=0)
    policy = LookaheadPolicy(**settings)
    direct = Lookahead(**settings)
    prev = None
    while not world.truncated[0]:
        problem = world.planning_problem(0)
        got = policy.plan(problem)
        # Today's explicit path: the world's state passed by hand, the same warm start.
        res = direct.plan_prediction(
            problem,
            world.get("x_pred", 0),
            world.get("P_pred", 0),
            world.params.Phi,
            world.params.Q,
            prev,
        )
        prev = res.plan
        np.testing.assert_array_equal(got, res.positions)
        world.step(got[None])


def test_prediction_path_matches_the_tracker_path_on_a_paper_episode():
    # The tracker replays the covariance (to rounding: its single-copy EKF update and the
    # world's batched one round differently in the last bits) and recovers the velocity
    # from a 2x2 linear solve (to about 1e-14 m/s), so plans agree to GSR's tolerance
    # (relative 1e-9 on the objective), not bit for bit.
    world = World("paper", 1)
    world.reset(seeds=[1000])
    settings = dict(horizon=10, headings=16, bearings=0)
    from_prediction = LookaheadPlanner(None, **settings)
    from_tracker = LookaheadPlanner("paper", **settings)
    tracker = PredictionTracker("paper")
    while not world.truncated[0]:
        problem = world.planning_problem(0)
        hand = _without_prediction(problem)
        assert hand.prediction is None
        x, P, _ = tracker.observe(hand)
        np.testing.assert_allclose(P, problem.prediction.cov, rtol=1e-13, atol=0)
        np.testing.assert_allclose(x, problem.prediction.mean, rtol=0, atol=1e-12)
        got = from_prediction.plan(problem)
        ref = from_tracker.plan(hand)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-6)
        world.step(got[None])


def test_planner_plans_problems_in_any_order_and_of_any_scenario():
    # A non-preset scenario (the tracker could not recognize it) and problems of three
    # episodes in shuffled order: each plan is the plan from the problem alone.
    world = World("paper", 3, n_steps=5, q=3.0, rho=(1.0, 1.5, 0.5))
    world.reset(seeds=[1, 2, 3])
    problems = []
    rng = np.random.default_rng(0)
    while not world.truncated.all():
        problem = world.planning_problem()
        problems += [problem[i] for i in range(3)]
        world.step_actions(rng.uniform(-1, 1, (3, 3, 2)))
    planner = LookaheadPlanner(None, horizon=5, headings=8)
    fresh = Lookahead(horizon=5, headings=8)
    for j in rng.permutation(len(problems)):
        got = planner.plan(problems[j])
        np.testing.assert_array_equal(got, fresh.plan_prediction(problems[j]).positions)
        assert _feasible(problems[j], got)


def test_plan_prediction_reads_the_problem_prediction_or_says_what_is_missing():
    world = World("homogeneous", 2, n_steps=3)
    world.reset(seeds=[4, 5])
    problem = world.planning_problem()
    la = Lookahead(horizon=4, headings=8)
    explicit = la.plan_prediction(
        problem, world.x_pred, world.P_pred, world.params.Phi, world.params.Q
    )
    np.testing.assert_array_equal(la.plan_prediction(problem).positions, explicit.positions)
    with pytest.raises(ValueError, match="prediction is None"):
        la.plan_prediction(_without_prediction(problem))
    with pytest.raises(ValueError, match="all of x_pred"):
        la.plan_prediction(problem, world.x_pred)


def test_batched_planner_equals_copy_by_copy():
    world = World("homogeneous", 3, n_steps=4)
    world.reset(seeds=[7, 8, 9])
    planner = LookaheadPlanner("homogeneous", horizon=4, headings=8, bearings=4)
    singles = [LookaheadPlanner("homogeneous", horizon=4, headings=8, bearings=4) for _ in range(3)]
    while not world.truncated.all():
        problem = world.planning_problem()
        batch = planner.plan(problem)
        one = np.stack([s.plan(problem[i]) for i, s in enumerate(singles)])
        np.testing.assert_allclose(batch, one, rtol=0, atol=1e-7)
        world.step(batch)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("horizon", 0),
        ("horizon", 10**20),
        ("discount", 0.0),
        ("discount", 1.5),
        ("headings", -1),
        ("headings", 10**9),
        ("passes", 101),
        ("margin", -1.0),
    ],
)
def test_settings_are_checked(field, value):
    with pytest.raises(ValueError, match=field):
        Lookahead(**{field: value})


@pytest.mark.slow
def test_realized_violations_no_worse_than_gsr():
    seeds = list(range(1000, 1100))  # the README's held-out evaluation seeds
    gsr = run_batched("paper", seeds)[1]
    la = run_batched("paper", seeds, Lookahead())[1]
    assert np.count_nonzero(la > 0) <= np.count_nonzero(gsr > 0)
    assert la.max() <= gsr.max()


def test_simulate_and_evaluate_commands_run_the_lookahead(tmp_path, capsys):
    import json

    from activetrack.cli import main

    out = tmp_path / "sim"
    argv = ["simulate", "--planner", "gsr", "--planner", "lookahead", "--runs", "2"]
    argv += ["--steps", "3", "--lookahead-horizon", "4", "--no-plot", "--no-progress"]
    assert main([*argv, "--out", str(out)]) == 0
    results = json.loads((out / "results.json").read_text())
    assert results["lookahead"]["config"]["planner"]["horizon"] == 4
    assert results["lookahead"]["max_violation"] <= results["gsr"]["max_violation"] + 1e-9
    out = tmp_path / "eval"
    argv = ["evaluate", "--scenario", "homogeneous", "--policy", "lookahead", "--episodes", "1"]
    assert main([*argv, "--no-plot", "--no-progress", "--out", str(out)]) == 0
    rows = json.loads((out / "results.json").read_text())
    assert [r["policy"] for r in rows] == ["lookahead", "gsr"]


def test_evaluate_resolves_lookahead_for_a_preset_and_any_scenario():
    from activetrack.baselines.evaluation import evaluate

    res = evaluate(["lookahead", "gsr"], "homogeneous", episodes=2, progress=False, n_steps=4)
    assert res[0].policy == "lookahead" and np.all(np.isfinite(res[0].mean_trace))
    # Not a preset: before problems carried their prediction this raised.
    res = evaluate(["lookahead"], "paper", episodes=2, progress=False, n_steps=4, q=3.0)
    assert res[0].policy == "lookahead" and np.all(np.isfinite(res[0].mean_trace))


@pytest.mark.slow
def test_lookahead_beats_gsr_in_closed_loop_paired_over_episodes():
    # GSR and the look-ahead policy (its defaults) on the same 60 seeds of the paper
    # preset, through the batched evaluation (evaluate(batched=True), the README's path;
    # seeds from the validation range 2000.., not the README's evaluation seeds 1000..).
    # Per episode the ratio of the mean posterior traces, look-ahead / GSR: the episodes
    # are independent, so the t-interval of the mean ratio is the paired 95% interval, and
    # its upper end must be below 1. Offline, 60 episodes from 2000, 3000 and 5000: mean
    # ratio 0.971, 0.960, 0.969 (standard deviation 0.045), upper ends 0.982, 0.972,
    # 0.981; the README: 0.954-0.961 on 100 to 1000 episodes.
    from scipy import stats

    from activetrack.baselines.evaluation import evaluate

    n = 60
    policies = ["gsr", "lookahead"]
    gsr, la = evaluate(policies, "paper", episodes=n, seed=2000, batched=True, progress=False)
    assert (gsr.policy, la.policy) == ("gsr", "lookahead")
    ratio = la.mean_trace / gsr.mean_trace
    upper = ratio.mean() + stats.t.ppf(0.975, n - 1) * ratio.std(ddof=1) / np.sqrt(n)
    assert upper < 1.0, (ratio.mean(), upper)


def test_settings_beyond_the_work_bound_are_refused_naming_them():
    from activetrack.baselines.lookahead import WORK_MAX

    with pytest.raises(ValueError, match=r"^headings, bearings, horizon"):
        Lookahead(headings=4096)
    # The bound, written out: (horizon + tail) x options x (passes + pair_passes x options).
    h, t = 10, 3
    opts = 276  # largest options count with (h + t) * o * (1 + o) <= WORK_MAX
    assert (h + t) * opts * (1 + opts) <= WORK_MAX < (h + t) * (opts + 1) * (2 + opts)
    Lookahead(horizon=h, tail=t, headings=opts - 2)
    with pytest.raises(ValueError, match=r"^headings"):
        Lookahead(horizon=h, tail=t, headings=opts - 1)
    Lookahead(headings=4096, pair_passes=0, passes=1, horizon=10)  # linear in the options
