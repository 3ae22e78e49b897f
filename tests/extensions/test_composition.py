"""The three public concept objects composed at once, as a user outside the library would.

A scenario whose second and third sensors measure by ``FadingRange`` (a new
``SensorModel``), whose sensors all move by ``Square`` (a new ``Kinematics``) and which is
scored by ``EOptimal`` (a new ``Objective``), the classes of the other extension tests,
run through every entry point: the World (single and batched), the PettingZoo parallel
and AEC envs, the Gymnasium env and its registration, the batched VectorEnv, GSR, the
look-ahead, ``simulate`` and the rollout driver; pickled and copied (Ray ships them to
workers); validated at the boundary. And two re-implementations that do not subclass a
built-in (range-and-bearing, the disk) against the built-ins they re-implement.

Each check is against an independent computation: the longhand largest eigenvalue of the
world's posterior, the square's reach written out, the same world stepped unpickled, the
built-in compiled paths.
"""

from __future__ import annotations

import copy
import json
import pickle
import warnings

import numpy as np
import pytest

import activetrack
from activetrack import Kinematics, SensorModel
from activetrack.world import World
from activetrack.world.problem import PlanningProblem
from tests.extensions.test_kinematics import Square
from tests.extensions.test_objective import EOptimal, largest_eig
from tests.extensions.test_sensor_model import FadingRange

H = 0.7  # the square's half-width


def composed(preset="paper", **kw):
    """Return ``preset`` with every new concept at once (the first sensor range-bearing)."""
    m = activetrack.make_scenario(preset).n_sensors
    team = ("range_bearing",) + (FadingRange(),) * (m - 1)
    return activetrack.make_scenario(
        preset, sensor_model=team, kinematics=Square(H), objective=EOptimal(), **kw
    )


def eoptimal_longhand(world, b=0):
    """Return the sum over targets of the largest eigenvalue of the world's posterior."""
    return sum(float(largest_eig(world.get("P", b, target=k))) for k in range(world.n_targets))


def in_squares(new, old):
    """Return whether every sensor moved at most ``H`` along each axis (the square)."""
    return bool(np.all(np.abs(np.asarray(new) - np.asarray(old)) <= H * (1 + 1e-12)))


# 1. Every entry point --------------------------------------------------------------------
@pytest.mark.parametrize("preset", ["paper", "two_targets"])
def test_world_single_and_batched_with_every_new_concept(preset):
    sc = composed(preset)
    caps = sc.capabilities
    assert not (caps.builtin_sensors or caps.disk_kinematics or caps.trace_objective)
    one, four = World(sc, 1), World(sc, 4)
    one.reset(seeds=[3])
    four.reset(seeds=[5, 3, 7, 9])
    rng = np.random.default_rng(0)
    for _ in range(8):
        before = four.get("sensors")
        wanted = before + rng.uniform(-1.5, 1.5, before.shape)  # some beyond the square
        res = four.step(wanted)
        one.step(wanted[1])
        assert in_squares(four.get("sensors"), before)
        for b in range(4):
            assert four.score[b] == pytest.approx(eoptimal_longhand(four, b), rel=1e-10)
        np.testing.assert_allclose(res.reward, -sc.reward_scale * four.score, rtol=1e-12)
        # Copy 1 of the batch is the episode of the single world (seed 3).
        np.testing.assert_allclose(one.get("P", 0), four.get("P", 1), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(one.get("sensors", 0), four.get("sensors", 1), rtol=1e-14)


def test_pettingzoo_parallel_and_aec_api_tests():
    from pettingzoo.test import api_test, parallel_api_test

    from activetrack.envs import env, parallel_env

    parallel_api_test(parallel_env(composed()), num_cycles=30)
    api_test(env(composed()), num_cycles=30)
    # The agents' action space is the square's (metres), and an action moves by it.
    penv = parallel_env(composed())
    penv.reset(seed=0)
    space = penv.action_space("sensor_0")
    np.testing.assert_array_equal(space.low, np.float32([-H, -H]))
    np.testing.assert_array_equal(space.high, np.float32([H, H]))
    before = penv.world.get("sensors", 0)
    a = np.array([[0.5, -0.2], [-0.7, 0.7], [0.1, 0.0]])
    _, rewards, *_ = penv.step({f"sensor_{i}": a[i].astype(np.float32) for i in range(3)})
    for r in rewards.values():  # every agent's reward: minus the objective, not the trace
        assert r == pytest.approx(-eoptimal_longhand(penv.world), rel=1e-10)
    np.testing.assert_allclose(penv.world.get("sensors", 0), before + a.astype(np.float32),
                               rtol=0, atol=1e-12)  # fmt: skip


def test_gymnasium_env_checker_make_and_vector_env():
    import gymnasium
    import pettingzoo
    from gymnasium.utils.env_checker import check_env

    from activetrack.envs import BatchedActiveTracking, CentralizedTrackingEnv

    check_env(CentralizedTrackingEnv(composed()), skip_render_check=True)
    cenv = CentralizedTrackingEnv(composed())
    cenv.reset(seed=2)
    _, reward, *_ = cenv.step(np.zeros(6, np.float32))
    assert reward == pytest.approx(-eoptimal_longhand(cenv.env.world), rel=1e-10)
    e = gymnasium.make("activetrack/ActiveTracking-v0", scenario=composed())
    e.reset(seed=0)
    assert isinstance(e.unwrapped.scenario.objective, EOptimal)
    # The scenario's fields as keywords, as the registration forwards them.
    p = pettingzoo.make("parallel", "activetrack/ActiveTracking-v0", scenario=composed())
    assert p.scenario == composed()
    k = gymnasium.make(
        "activetrack/ActiveTracking-v0", sensor_model=composed().sensor_model,
        kinematics=Square(H), objective=EOptimal(),
    )  # fmt: skip
    assert k.unwrapped.scenario == composed()
    made = gymnasium.make_vec(
        "activetrack/ActiveTracking-v0", num_envs=2, kinematics=Square(H),
        sensor_model=composed().sensor_model, objective=EOptimal(),
    )  # fmt: skip
    assert made.scenario == composed()
    # reset(seed=s) twice: the same episodes.
    runs = []
    for _ in range(2):
        obs, _ = made.reset(seed=9)
        rng = np.random.default_rng(1)
        out = [obs]
        for _ in range(5):
            obs, rew, *_ = made.step(rng.uniform(-H, H, (2, 6)).astype(np.float32))
            out += [obs, rew]
        runs.append(out)
    for x, y in zip(*runs, strict=True):
        np.testing.assert_array_equal(x, y)
    vec = BatchedActiveTracking(4, composed())
    vec.reset(seed=1)
    for _ in range(3):
        before = vec.world.get("sensors")
        _, reward, *_ = vec.step(vec.action_space.sample())
        assert in_squares(vec.world.get("sensors"), before)
        want = [-eoptimal_longhand(vec.world, b) for b in range(4)]
        np.testing.assert_allclose(reward, want, rtol=1e-6)  # float32 rewards


def test_gsr_lookahead_simulate_and_rollout():
    from activetrack.baselines import rollout
    from activetrack.baselines.gsr import GSR
    from activetrack.baselines.lookahead import LookaheadPlanner
    from activetrack.baselines.simulation import simulate

    sc = composed(n_steps=4)
    for planner in (GSR(), LookaheadPlanner(horizon=2, headings=6)):
        w = World(sc, 2)
        w.reset(seeds=[0, 1])
        for _ in range(3):
            problem = w.planning_problem()
            plan = planner.plan(problem)
            assert np.max(problem.violation(plan)) <= 1e-9
            assert in_squares(plan, w.get("sensors"))
            w.step(plan)
    rec = simulate(sc, GSR(), 0)
    assert len(rec.trace) == sc.n_steps

    class Record(rollout.Recorder):
        def step(self, step):
            scores.append(step.world.score.copy())

    scores = []
    w = World(sc, 3)
    rollout.rollout(w, rollout.PlannerAgent(GSR()), [0, 1, 2], Record(), batched=True)
    assert len(scores) == sc.n_steps
    np.testing.assert_allclose(scores[-1], [eoptimal_longhand(w, b) for b in range(3)],
                               rtol=1e-10)  # fmt: skip


# 2. Pickling, copies, equality, records, reproducibility -----------------------------------
def test_scenario_with_new_concepts_equals_its_pickle_and_its_twin():
    sc = composed()
    twin = composed()
    for other in (twin, pickle.loads(pickle.dumps(sc)), copy.deepcopy(sc)):
        assert other == sc and hash(other) == hash(sc)
    assert len({sc, twin}) == 1
    assert Square(H) == Square(H) and Square(H) != Square(0.5)
    assert EOptimal() == EOptimal() and hash(EOptimal()) == hash(EOptimal())
    assert composed() != composed().replace(kinematics=Square(0.5))
    record = json.loads(json.dumps(sc.to_dict()))
    assert record["objective"]["name"] == "e_optimal"
    assert [k["name"] for k in record["kinematics"]] == ["square"] * 3
    assert record["kinematics"][0]["radius"] == pytest.approx(H * np.sqrt(2), rel=1e-15)


def test_problems_of_equal_scenarios_and_pickled_problems_stack():
    """Ray's workers send problems back pickled: equal objects must stack."""
    a, b = World(composed(), 1), World(composed(), 1)
    a.reset(seeds=[0])
    b.reset(seeds=[1])
    pa, pb = a.planning_problem(0), b.planning_problem(0)
    both = PlanningProblem.stack([pa, pickle.loads(pickle.dumps(pb))])
    np.testing.assert_allclose(both.score(both.sensors), [pa.score(pa.sensors),
                               pb.score(pb.sensors)], rtol=1e-14)  # fmt: skip
    paper = World("paper", 1)
    paper.reset(seeds=[0])
    q = paper.planning_problem(0)
    PlanningProblem.stack([q, pickle.loads(pickle.dumps(q))])


def test_pickled_and_copied_worlds_and_envs_continue_identically():
    from activetrack.envs import CentralizedTrackingEnv, parallel_env

    w = World(composed(), 2)
    w.reset(seeds=[0, 1])
    w.step(w.get("sensors") + 0.3)
    clones = [pickle.loads(pickle.dumps(w)), copy.deepcopy(w)]
    rewards = [x.step(x.get("sensors") - 0.2).reward for x in [w, *clones]]
    for r in rewards[1:]:
        np.testing.assert_array_equal(r, rewards[0])
    # An env reset twice with the same seed runs the same episode.
    for make in (lambda: CentralizedTrackingEnv(composed()), lambda: parallel_env(composed())):
        env = pickle.loads(pickle.dumps(make()))
        runs = []
        for _ in range(2):
            obs, _ = env.reset(seed=11)
            rng = np.random.default_rng(2)
            out = [obs]
            for _ in range(6):
                if isinstance(obs, dict):
                    act = {a: rng.uniform(-H, H, 2).astype(np.float32) for a in env.agents}
                else:
                    act = rng.uniform(-H, H, env.action_space.shape).astype(np.float32)
                obs, rew, *_ = env.step(act)
                out += [obs, rew]
            runs.append(out)
        for x, y in zip(*runs, strict=True):
            if isinstance(x, dict):
                assert x.keys() == y.keys()
                for key in x:
                    np.testing.assert_array_equal(x[key], y[key])
            else:
                np.testing.assert_array_equal(x, y)


# 3. Validation at the boundary ----------------------------------------------------------------
@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("kinematics", Square),
        ("kinematics", (Square(H),) * 2),
        ("kinematics", (Square(H), "disk", Square(H))),
        ("sensor_model", (FadingRange,) * 3),
        ("sensor_model", (FadingRange(),) * 2),
        ("objective", EOptimal),
    ],
)
def test_wrong_types_name_their_field(field, value):
    with pytest.raises(ValueError, match=field):
        activetrack.make_scenario("paper", **{field: value})


class FarNaN(FadingRange):
    """Finite on the validation's probe (5 m away), NaN beyond 12 m: a bug found late."""

    name = "far_nan"

    def function(self, target, sensor, orientation=0.0):
        z = super().function(target, sensor, orientation)
        z[..., 0] = np.where(z[..., 0] > 12.0, np.nan, z[..., 0])
        return z


class FarNaNSquare(Square):
    """Finite on the validation's probe (near the origin), NaN beyond x = 21.5."""

    name = "far_nan_square"

    def clip(self, wanted, position):
        out = super().clip(wanted, position)
        return np.where(np.asarray(position)[..., :1] > 21.5, np.nan, out)

    def apply(self, actions, position):
        out = super().apply(actions, position)
        return np.where(np.asarray(position)[..., :1] > 21.5, np.nan, out)


def test_a_model_that_returns_nan_mid_episode_is_named_not_silent():
    sc = activetrack.make_scenario("paper", sensor_model=("range_bearing", FarNaN(), FarNaN()))
    w = World(sc, 1)
    w.reset(seeds=[0])
    with pytest.raises(ValueError, match="sensor_model 'far_nan'"):
        for _ in range(sc.n_steps):  # the sensors start ~20 m from the target
            w.step(w.get("sensors", 0))
            assert np.all(np.isfinite(w.get("P", 0)))


@pytest.mark.parametrize("by", ["positions", "actions"])
def test_a_kinematics_that_returns_nan_mid_episode_is_named_not_silent(by):
    w = World(activetrack.make_scenario("paper", kinematics=FarNaNSquare(H)), 1)
    w.reset(seeds=[0])
    with pytest.raises(ValueError, match="far_nan_square"):
        for _ in range(10):  # x grows by H a step from ~20
            if by == "actions":
                w.step_actions(np.tile([H, 0.0], (3, 1)))
            else:
                w.step(w.get("sensors", 0) + [H, 0.0])
            assert np.all(np.isfinite(w.get("sensors", 0)))


class NaNProject(Square):
    """Finite clip and apply; its projection out of a ``rho`` disk NaN."""

    name = "nan_project"

    def project(self, wanted, position, targets, rho):
        return np.full(2, np.nan)


def test_a_kinematics_whose_projection_is_nan_is_named_not_silent():
    w = World(activetrack.make_scenario("paper", kinematics=NaNProject(30.0)), 1)
    w.reset(seeds=[0])
    target = w.planning_problem(0).target  # the predicted target the rho rule keeps off
    with pytest.raises(ValueError, match="nan_project"):
        w.step(np.repeat(np.reshape(target, (1, 2)), 3, 0))  # every sensor onto it


class LateNaNObjective(EOptimal):
    """Finite on the validation's probe; NaN once it has scored ``after`` times."""

    name = "late_nan"

    def __init__(self, after):
        self.after, self.calls = after, 0

    def of_entries(self, a, b, c):
        self.calls += 1
        return super().of_entries(a, b, c) * (np.nan if self.calls > self.after else 1.0)


def test_an_objective_that_returns_nan_mid_episode_is_named_not_silent():
    w = World(activetrack.make_scenario("paper", objective=LateNaNObjective(after=10**9)), 1)
    w.objective.after = w.objective.calls + 3  # NaN from the 4th score on
    w.reset(seeds=[0])
    with pytest.raises(ValueError, match="objective 'late_nan'"):
        for _ in range(6):
            res = w.step(w.get("sensors", 0))
            assert np.isfinite(res.reward)


@pytest.mark.parametrize(("preset", "objective"), [("paper", "logdet"),
                                                   ("two_targets", "worst_trace")])  # fmt: skip
def test_vector_env_rewards_the_scenarios_objective(preset, objective):
    """The batched env's reward is the World's (minus the objective), as the parallel env's."""
    from activetrack.envs import BatchedActiveTracking

    sc = activetrack.make_scenario(preset, objective=objective)
    vec = BatchedActiveTracking(3, sc)
    ref = World(sc, 3)
    vec.reset(seed=4)
    ref.reset(seeds=list(vec.np_random_seed))
    rng = np.random.default_rng(0)
    for _ in range(4):
        a = rng.uniform(-1, 1, (3, sc.n_sensors, 2))
        _, reward, *_ = vec.step(a.reshape(3, -1))
        want = ref.step_actions(a).reward
        np.testing.assert_allclose(reward, want, rtol=1e-6)
        # Longhand: log det or the worst trace of each target's posterior block.
        per_target = np.array([[ref.get("P", b, target=k)[:2, :2] for k in range(sc.n_targets)]
                               for b in range(3)])  # fmt: skip
        if objective == "logdet":
            value = np.linalg.slogdet(per_target)[1].sum(-1)
        else:
            value = np.trace(per_target, axis1=-2, axis2=-1).max(-1)
        np.testing.assert_allclose(reward, -value, rtol=1e-6)


# 4. Old names -------------------------------------------------------------------------------
def test_old_names_keep_working():
    from activetrack.models.sensor_models import SensorModel as Old

    assert (Old.RANGE_BEARING, Old.RANGE, Old.BEARING) == (0, 1, 2)
    assert activetrack.SensorModel.RANGE == 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # the old path warns
        import activetrack.sensor_models as alias
    assert alias.SensorModel.BEARING == 2
    sc = activetrack.make_scenario("paper", sensor_model=(Old.RANGE_BEARING.name.lower(),) * 3)
    assert sc == activetrack.make_scenario("paper")


# 5. Re-implementations of the built-ins --------------------------------------------------------
class MyRangeBearing(SensorModel):
    """Eq. (4) and its Jacobian eq. (9), written out (not a built-in's subclass)."""

    name = "my_range_bearing"
    slots = (True, True)
    angular = (False, True)

    def function(self, target, sensor, orientation=0.0):
        d = np.asarray(target, float) - np.asarray(sensor, float)
        bearing = np.arctan2(d[..., 1], d[..., 0]) - np.asarray(orientation, float)
        return np.stack([np.hypot(d[..., 0], d[..., 1]), bearing], -1)

    def jacobian(self, target, sensor, orientation=0.0):
        d = np.asarray(target, float) - np.asarray(sensor, float)
        d2 = d[..., 0] ** 2 + d[..., 1] ** 2
        n = np.sqrt(d2)
        row0 = np.stack([d[..., 0] / n, d[..., 1] / n], -1)
        row1 = np.stack([-d[..., 1] / d2, d[..., 0] / d2], -1)
        return np.stack([row0, row1], -2)


class MyDisk(Kinematics):
    """The disk of radius ``r`` written out (not ``Disk``'s subclass)."""

    name = "my_disk"

    def __init__(self, r):
        self.r = float(r)

    @property
    def radius(self):
        return self.r

    def reaches(self, points, position):
        d = np.asarray(points, float) - np.asarray(position, float)
        return np.hypot(d[..., 0], d[..., 1]) <= self.r * (1 + 1e-12)

    def clip(self, wanted, position):
        w, p = np.asarray(wanted, float), np.asarray(position, float)
        n = np.hypot(*np.moveaxis(w - p, -1, 0))[..., None]
        return np.where(n > self.r * (1 + 1e-12), p + (w - p) * (self.r / np.maximum(n, 1e-300)), w)

    def reach_boundary(self, position, spacing):
        n = max(8, int(np.ceil(2 * np.pi * self.r / spacing)))
        t = np.linspace(-np.pi, np.pi, n, endpoint=False)
        return np.asarray(position, float) + self.r * np.stack([np.cos(t), np.sin(t)], -1)


def test_rewritten_range_bearing_filters_as_the_built_in():
    mine = activetrack.make_scenario("paper", sensor_model=(MyRangeBearing(),) * 3)
    assert not mine.capabilities.builtin_sensors
    a, b = World(mine, 2), World("paper", 2)
    a.reset(seeds=[0, 1])
    b.reset(seeds=[0, 1])
    rng = np.random.default_rng(0)
    for _ in range(20):
        wanted = b.get("sensors") + rng.uniform(-1, 1, (2, 3, 2))
        ra, rb = a.step(wanted), b.step(wanted)
        np.testing.assert_allclose(a.get("P"), b.get("P"), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(a.get("x_hat"), b.get("x_hat"), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(ra.reward, rb.reward, rtol=1e-9)


@pytest.mark.parametrize("which", ["sensor", "kinematics"])
def test_rewritten_models_plan_with_gsr_as_the_built_ins(which):
    """GSR plans a re-implementation by its numerical steps and the built-in by the
    analytic solver: the same optimum. The objective agrees to rounding; the positions to
    the optimum's conditioning (a relative value error e moves a point by ~sqrt(e) times
    the length scale: sqrt(1e-16) * 10 m ~ 1e-7 m, so 1e-6 m)."""
    from activetrack.baselines.gsr import GSR

    kw = {"sensor_model": (MyRangeBearing(),) * 3} if which == "sensor" else {
        "kinematics": MyDisk(1.0)}  # fmt: skip
    mine = activetrack.make_scenario("paper", **kw)
    a, b = World(mine, 1), World("paper", 1)
    a.reset(seeds=[0])
    b.reset(seeds=[0])
    for _ in range(20):
        qa, qb = a.planning_problem(0), b.planning_problem(0)
        pa, pb = GSR(tol=1e-12).plan(qa), GSR(tol=1e-12).plan(qb)
        assert float(qb.score(pa)) == pytest.approx(float(qb.score(pb)), rel=1e-12)
        np.testing.assert_allclose(pa, pb, rtol=0, atol=1e-6)
        a.step(pb)
        b.step(pb)
        np.testing.assert_allclose(a.get("sensors", 0), b.get("sensors", 0), rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.get("P", 0), b.get("P", 0), rtol=1e-9, atol=1e-12)


def test_evaluation_writes_a_record_of_new_concepts_passed_as_overrides(tmp_path):
    """The evaluation's ``episodes.json`` records the overrides; objects of one's own as the
    scenario records them (by name and class), not a crash of ``json`` after the episodes."""
    from activetrack.baselines.evaluation import run_evaluation

    team = composed().sensor_model
    run_evaluation(["gsr"], "paper", episodes=2, out_dir=tmp_path / "out", plot=False,
                   progress=False, n_steps=3, kinematics=Square(H), objective=EOptimal(),
                   sensor_model=team)  # fmt: skip
    meta = json.loads((tmp_path / "out" / "episodes.json").read_text())
    text = json.dumps(meta)
    for name in ('"square"', '"e_optimal"', '"fading_range"'):
        assert name in text
    want = json.loads(json.dumps(composed(n_steps=3).to_dict()))
    for key in ("kinematics", "objective", "sensor_model", "n_steps"):
        assert key in text and json.dumps(want[key]) in text


def test_lookahead_run_batched_with_two_targets_against_a_longhand_loop():
    """``run_batched``'s mean trace and deepest violation of the true targets (every target,
    K = 2) against the same GSR episodes stepped and measured by hand."""
    from activetrack.baselines.gsr import GSR
    from activetrack.baselines.lookahead import run_batched

    # Squares of half-width 8 reach the targets within the episode: the true targets come
    # inside rho (GSR keeps rho from the predicted ones), so ``deepest`` is not all 0.
    sc = composed("two_targets", n_steps=4).replace(kinematics=Square(8.0))
    seeds = [0, 1]
    mean_trace, deepest = run_batched(sc, seeds)
    assert np.all(deepest > 0.1)
    w = World(sc, len(seeds))
    w.reset(seeds=seeds)
    traces, worst = [], np.zeros(len(seeds))
    rho = np.broadcast_to(sc.rho, (sc.n_sensors,))
    for _ in range(sc.n_steps):
        w.step(GSR().plan(w.planning_problem()))
        traces.append([sum(np.trace(w.get("P", b, target=k)[:2, :2]) for k in range(2))
                       for b in range(len(seeds))])  # fmt: skip
        for b in range(len(seeds)):
            for k in range(2):
                t = w.get("x_true", b, target=k)[:2]
                for i in range(sc.n_sensors):
                    gap = rho[i] - np.hypot(*(w.get("sensors", b)[i] - t))
                    worst[b] = max(worst[b], gap)
    np.testing.assert_allclose(mean_trace, np.mean(traces, axis=0), rtol=1e-12)
    np.testing.assert_allclose(deepest, worst, rtol=1e-12, atol=1e-15)
