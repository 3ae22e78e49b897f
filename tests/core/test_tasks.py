"""The tasks beyond the paper through the one world: K targets, sensor models, uncertain poses.

Each check compares with an independent computation: the paper's own arithmetic on a
one-target problem, per-target sums, the observation decoded by hand, the chi-square
distribution of a consistent filter's NEES over Monte Carlo runs (a band for the mean of
the runs' time-averaged NEES, :func:`tests.core.helpers.nees_band`, that a filter with its
measurement noise or its process noise 10% off leaves).
"""

import numpy as np
import pytest

from activetrack import PlanningProblem
from activetrack.models.objective import LOGDET, TRACE, WORST_TRACE
from activetrack.world import World, observation
from activetrack.world.scenarios import TASKS, make_scenario
from tests.core.helpers import misspecify_filter, nees_band

RUNS = 200
#: GSR's sweeps per step in the Monte Carlo runs (see :func:`_nees_runs`).
SWEEPS = 1


def test_every_task_is_a_valid_scenario_with_its_layout():
    for name in TASKS:
        sc = make_scenario(name)
        w = World(sc)
        w.reset(seeds=[0])
        obs = w.observe(0)
        K, M = sc.n_targets, sc.n_sensors
        # Detection flags (K per sensor block) and rays with limited sensing.
        d = 7 * K + 12 * M + (K * M if sc.limited_sensing else 0)
        rays = observation.RAYS if sc.has_occluders else 0  # each agent's own in its view
        if sc.capabilities.paper_observation:  # (the paper's sensors: the paper's layout)
            d, rays = 5 + 6 * M, 0
        # A kinematics with a heading (the unicycle tasks): each agent's (cos, sin) last.
        f = 0 if sc.kinematics is None else max(k.n_features for k in sc.kinematics_models)
        f += 3 * K if sc.route_observation else 0  # the route readings (urban_unicycle)
        f += K if sc.births is not None else 0  # the track flags (patrol)
        assert obs.shape == (M, d + rays + f), name
        assert w.state(0).shape == (d + M * rays + M * f + 1,)
        low, high = w.layout.bounds()
        assert np.all(obs >= low) and np.all(obs <= high)
    from activetrack.world.scenarios import EXTENSIONS

    # The paper's record names no field beyond the paper; a task's names what it uses.
    assert not set(EXTENSIONS) & set(make_scenario("paper").to_dict())
    assert make_scenario("two_targets").to_dict()["n_targets"] == 2


def test_extended_observation_decodes_to_the_world():
    w = World("mixed")
    w.reset(seeds=[3])
    w.step_actions(np.full((4, 2), 0.3))
    obs, L = w.observe(0), w.length_scale
    x, P = w.get("x_pred", 0), w.get("P_pred", 0)
    origin = x[:2]  # one target: the centroid is the prediction itself
    sc = w.scenario
    np.testing.assert_allclose(obs[0, :2], 0.0, atol=1e-7)
    np.testing.assert_allclose(np.exp(obs[0, 2:4]) * L, np.sqrt(np.diag(P)[:2]), rtol=1e-6)
    np.testing.assert_allclose(obs[0, 5:7], x[2:4] * sc.dt / L, rtol=1e-5)
    for agent in range(4):
        for slot in range(4):
            j = (agent + slot) % 4
            blk = obs[agent, 7 + 12 * slot : 7 + 12 * (slot + 1)]
            np.testing.assert_allclose(blk[:2] * L, w.get("fixes", 0)[j] - origin, rtol=1e-5)
            code = sc.sensor_models[j]
            assert blk[6 + code] == 1.0 and blk[6:9].sum() == 1.0
            sd2, st2 = sc.per_sensor("sigma_d2")[j], sc.per_sensor("sigma_theta2")[j]
            want_d = 0.5 * np.log(sd2 / L**2) if code != 2 else 0.0
            want_t = 0.5 * np.log(st2) if code != 1 else 0.0
            np.testing.assert_allclose(blk[2:4], [want_d, want_t], rtol=1e-6, atol=1e-7)


def test_two_target_problem_scores_are_per_target_sums_of_the_paper_objective():
    w = World("two_targets")
    w.reset(seeds=[1])
    w.step_actions(np.zeros((4, 2)))
    problem = w.planning_problem(0)
    assert problem.multi_target and problem.n_targets == 2
    rng = np.random.default_rng(0)
    cand = problem.sensors + rng.normal(size=(50, 4, 2))
    singles = [
        PlanningProblem(
            w.get("P_pred", 0, k)[:2, :2],
            w.get("x_pred", 0, k)[:2],
            problem.sensors,
            problem.r,
            problem.rho,
            problem.sigma_d2,
            problem.sigma_theta2,
        )  # fmt: skip
        for k in range(2)
    ]
    per = np.stack([s.score(cand) for s in singles], -1)  # the paper's arithmetic
    np.testing.assert_allclose(problem.score(cand), per.sum(-1), rtol=1e-12)
    for obj, combine in ((WORST_TRACE, np.max), (TRACE, np.sum)):
        p2 = PlanningProblem(
            problem.prior_cov, problem.target, problem.sensors, problem.r, problem.rho,
            problem.sigma_d2, problem.sigma_theta2, objective=obj, multi_target=True,
        )  # fmt: skip
        np.testing.assert_allclose(p2.score(cand), combine(per, -1), rtol=1e-12)
    p3 = PlanningProblem(
        problem.prior_cov, problem.target, problem.sensors, problem.r, problem.rho,
        problem.sigma_d2, problem.sigma_theta2, objective=LOGDET, multi_target=True,
    )  # fmt: skip
    # log det of each posterior covariance: eq. (17)'s information written with unit
    # vectors u (along the line of sight) and v (across it), inverted by numpy.
    want = 0.0
    for s in singles:
        rel = cand - s.target
        n2 = rel[..., 0] ** 2 + rel[..., 1] ** 2
        Y = np.linalg.inv(s.prior_cov)[None].repeat(len(cand), 0)
        for i in range(4):
            u = rel[:, i] / np.sqrt(n2[:, i])[:, None]
            v = np.stack([u[:, 1], -u[:, 0]], -1)
            Y = Y + np.einsum("bi,bj->bij", u, u) / s.sigma_d2[i]
            Y = Y + np.einsum("bi,bj->bij", v, v) / (s.sigma_theta2[i] * n2[:, i, None, None])
        want = want + np.log(np.linalg.det(np.linalg.inv(Y)))
    np.testing.assert_allclose(p3.score(cand), want, rtol=1e-10)


def test_every_sensor_keeps_rho_from_every_target():
    w = World("two_targets", 64)
    w.reset(seeds=list(range(64)))
    rng = np.random.default_rng(2)
    for _ in range(30):
        targets = np.stack([w.get("x_pred", None, k)[:, :2] for k in range(2)], 1)
        before = np.linalg.norm(w.sensors[:, None] - targets[:, :, None], axis=-1)
        w.step_actions(rng.uniform(-1, 1, (64, 4, 2)))
        d = np.linalg.norm(w.sensors[:, None] - targets[:, :, None], axis=-1)
        # Outside every rho disk, unless a disk could not be left in one step (reach 1 m).
        unreachable = (before + 1.0 < 2.0).any(axis=1, keepdims=True)
        assert np.all((d >= 2.0 * (1 - 1e-9)) | unreachable)


def test_world_get_targets_axis_and_per_target_fields():
    w = World("two_targets", 3)
    w.reset(seeds=[0, 1, 2])
    assert w.get("x_hat").shape == (3, 2, 4)
    assert w.get("P_pred", 1).shape == (2, 4, 4)
    np.testing.assert_array_equal(w.get("x_hat", None, 1), w.get("x_hat")[:, 1])
    with pytest.raises(ValueError, match="target must be an integer"):
        w.get("x_hat", 0, 2)
    one = World("two_targets")
    one.reset(seeds=[0])
    np.testing.assert_array_equal(one.get("x_true", 0, 1), w.get("x_true", 0, 1))


def _nees_runs(
    name: str,
    runs: int = RUNS,
    r_scale: float = 1.0,
    q_scale: float = 1.0,
    whole_state: bool = False,
    **overrides,
) -> np.ndarray:
    """Return the position NEES (steps, runs, K) of ``runs`` GSR-driven episodes of a task,
    the filter assuming ``r_scale`` times the true measurement noise and ``q_scale`` times
    the true process noise; ``whole_state``: the NEES of the whole state ``e^T P^{-1} e``
    (n degrees of freedom: 4 for the constant-velocity target) instead, solved here.

    GSR stops after its first sweep (:data:`SWEEPS`): the sensors go where GSR sends them
    (each to its optimum given the others, close to rho, where the measurements are most
    nonlinear), and the filter, not the plan's last digits, is what these runs test. The
    mean NEES with 1 sweep / 3 sweeps / converged: range_only 2.0365 / 2.0335 / 2.0294,
    two_targets 2.0678 and 2.0194 / 2.0435 and 2.0329 / 2.0406 and 2.0328; bearing_only
    2.099 / 2.100, mixed 2.045 / 2.037, uncertain_poses 2.070 / 2.097; the filter ignoring
    the fix errors 4.90 / 4.22 (far above the band either way). One sweep takes about a
    third of three sweeps' time (two_targets, GSR's numeric multi-target solver: 16 s
    instead of 26-48 s).
    """
    from activetrack.baselines import GSR

    w = World(name, runs, **overrides)
    if r_scale != 1.0 or q_scale != 1.0:
        misspecify_filter(w, r_scale=r_scale, q_scale=q_scale)
    w.reset(seeds=list(range(20_000, 20_000 + runs)))
    planner, out = GSR(max_sweeps=SWEEPS), []
    while not w.truncated.all():
        w.step(planner.plan(w.planning_problem()))
        if not whole_state:
            out.append(w.position_nees(per_target=True))
            continue
        per_target = []
        for k in range(w.n_targets):
            e = w.get("x_true", None, k) - w.get("x_hat", None, k)
            per_target.append(
                np.einsum("ri,ri->r", e, np.linalg.solve(w.get("P", None, k), e[..., None])[..., 0])
            )
        out.append(np.stack(per_target, -1))
    return np.array(out)


@pytest.mark.slow
@pytest.mark.parametrize(
    "name",  # (a target that maneuvers or evades makes the filter inconsistent: by design,
    # as does the paper's fixed true start away from the prior mean: the unicycle tasks)
    [t for t in TASKS if not make_scenario(t).limited_sensing
     and make_scenario(t).capabilities.filter_targets
     and make_scenario(t).target_init == "gaussian"
     # (the decentralized tasks: every robot's filter, tests/core/test_team_filters.py)
     and make_scenario(t).communication is None],
)  # fmt: skip
def test_filter_is_consistent_on_every_task(name):
    # The mean over 200 runs of each run's time-averaged position NEES (per target) lies
    # in the 99% band of that statistic (tests.core.helpers.nees_band: runs independent,
    # steps not). On these seeds the mean is 1.75 standard errors above 2 on bearing_only,
    # 1.8 on uncertain_poses, 1.9 and 0.5 on two_targets, 1.3 on mixed, 1.05 on
    # range_only (the band: 2.6): the EKF's linearization leaves the nonlinear tasks' NEES
    # 2-5% high, which 200 runs about resolve (two_targets' second target on seeds
    # 40000.. is 3.1 above). A 10% error in R: the next test. (The urban tasks:
    # tests/core/test_sensing_limits.py, 200 random-motion runs each; GSR's 200 runs take
    # minutes there, docs/tasks.md gives their figure and command.)
    run_means = _nees_runs(name).mean(axis=0)
    for k in range(run_means.shape[-1]):
        lo, hi = nees_band(run_means[:, k])
        mean = float(run_means[:, k].mean())
        assert lo <= mean <= hi, (name, k, mean, (lo, hi))


@pytest.mark.slow
@pytest.mark.parametrize("r_scale", [1.0, 0.9, 1.1])
def test_nees_band_catches_a_filter_with_its_measurement_noise_10_percent_off(r_scale):
    # The paper's preset, 400 runs (a few seconds): the true filter's statistic inside the
    # 99% band (0.4 standard errors above 2), the filter assuming 0.9 R or 1.1 R outside
    # it (about +9% and -7% in the mean NEES: 6.2 and -5.1 standard errors). The band of
    # one chi-square draw per run these tests used before, chi2.ppf([0.025, 0.975],
    # 2 runs) / runs = [1.81, 2.20] for 400 runs, holds both (2.19 and 1.86).
    run_means = _nees_runs("paper", runs=2 * RUNS, r_scale=r_scale).mean(axis=(0, 2))
    lo, hi = nees_band(run_means)
    mean = float(run_means.mean())
    assert (lo <= mean <= hi) == (r_scale == 1.0), (r_scale, mean, (lo, hi))


@pytest.mark.slow
@pytest.mark.parametrize("q_scale", [1.0, 0.9, 1.1])
def test_nees_band_catches_a_filter_with_its_process_noise_10_percent_off(q_scale):
    """The filter assuming 0.9 Q or 1.1 Q leaves the 99% band of the statistic tested (the
    mean over runs of each run's time-averaged NEES, :func:`nees_band`); the true one
    stays in it. The setting, measured on the paper's preset with 400 runs:

    - The whole state's NEES (4 degrees of freedom), not the position's: the sensors
      measure the position at every step, so Q moves the position's NEES by only 1-2%
      (after 100 steps: 2.037 true, 2.080 at 0.9 Q, 2.002 at 1.1 Q, standard error 0.021:
      1.1 Q sits 1.7 standard errors below the true filter's, and the EKF's own 2% excess
      over 2 hides it; thousands of runs would be needed). The velocity, which no sensor
      measures, is estimated through Q: the whole state's NEES moves 4-5%.
    - 100 steps, not 50: in the first steps the prior's velocity variance (100 m^2/s^2)
      still dominates Q's share; after 50 steps the whole-state means are 3.93 true (1.5
      standard errors below 4), 4.11 at 0.9 Q (2.2 above: inside the band), 3.78 at 1.1 Q.
      After 100 steps: 4.012 true (0.3 standard errors from 4), 4.210 at 0.9 Q (+5.9) and
      3.846 at 1.1 Q (-4.8), with the band's half-width 2.6 standard errors. About 3 s per
      case.
    """
    runs = _nees_runs("paper", runs=2 * RUNS, q_scale=q_scale, whole_state=True, n_steps=100).mean(
        axis=(0, 2)
    )
    lo, hi = nees_band(runs, dim=4)
    mean = float(runs.mean())
    assert (lo <= mean <= hi) == (q_scale == 1.0), (q_scale, mean, (lo, hi))


@pytest.mark.slow
def test_a_filter_ignoring_pose_uncertainty_is_not_consistent():
    # The same 200 runs with a filter that ignores the fix errors: above the band of its
    # statistic (its mean NEES is about 4.9, 4.5 standard errors above 2, where the
    # accounting filter's is about 2.07).
    run_means = _nees_runs("uncertain_poses", account_pose=False).mean(axis=(0, 2))
    _, hi = nees_band(run_means)
    assert run_means.mean() > hi, run_means.mean()
