"""True targets that follow a behaviour in the world (the scenario field ``target_behaviour``,
:mod:`activetrack.world.behaviours`): the field's validation and record; the filter's own
model given explicitly against the default world bit for bit; a maneuvering target's true
trajectory against the behaviour stepped by hand from the same generators; an evader's
distance to the nearest sensor against geometry; batched copies against single ones bit for
bit; the draws' layout kept (paired runs); the single-model EKF's NEES against its band on a
maneuvering target."""

from __future__ import annotations

import numpy as np
import pytest

from activetrack import Evasive, FilterModel, Maneuvering, StopAndGo, World, make_scenario
from activetrack.models.motion import make_model
from tests.core.helpers import nees_band

DT = 0.1
TURNS = Maneuvering([0.0, 3.0, -3.0], [[0.8, 0.1, 0.1], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8]],
                    10.0, DT, initial=[0.5, 0.25, 0.25])  # fmt: skip
FIELDS = ("x_true", "x_hat", "P", "x_pred", "P_pred", "sensors", "trace", "k")


def _actions(rng, n, m):
    return rng.uniform(-1.0, 1.0, (n, m, 2)) if n > 1 else rng.uniform(-1.0, 1.0, (m, 2))


# The field ----------------------------------------------------------------------------------
def test_default_is_none_and_not_recorded():
    sc = make_scenario("paper")
    assert sc.target_behaviour is None and sc.capabilities.filter_targets
    assert "target_behaviour" not in sc.to_dict()
    assert World("paper").target_modes is None


def test_field_is_checked_stored_and_recorded():
    sc = make_scenario("paper", target_behaviour=TURNS)
    assert sc.target_behaviour is TURNS
    assert not sc.capabilities.filter_targets and not sc.capabilities.fused_step
    assert sc.to_dict()["target_behaviour"] == {
        "name": "maneuvering", "class": "activetrack.models.behaviour.Maneuvering"}  # fmt: skip
    # equal behaviours: equal scenarios; one per target, all equal, is stored as one
    assert sc == make_scenario("paper", target_behaviour=TURNS.__class__(
        TURNS.turn_rates, TURNS.transition, TURNS.q, TURNS.dt, TURNS.initial))  # fmt: skip
    two = make_scenario("two_targets", target_behaviour=(TURNS, TURNS))
    assert two.target_behaviour is TURNS
    mixed = make_scenario("two_targets", target_behaviour=(TURNS, Evasive(5.0, DT)))
    assert isinstance(mixed.target_behaviour, tuple)
    assert [r["name"] for r in mixed.to_dict()["target_behaviour"]] == ["maneuvering", "evasive"]


@pytest.mark.parametrize(
    ("value", "match"),
    [
        ("maneuvering", "target_behaviour must be None, an activetrack.TargetBehaviour"),
        # a state dimension other than the target model's (the "ca" model's 6)
        (TURNS, r"target_behaviour \(target 0\).*dimension 6"),
        (FilterModel(make_model("cv", 10.0, DT)), r"target_behaviour \(target 0\).*4.*6"),
    ],
)
def test_bad_values_name_the_field(value, match):
    kw = {"motion": "ca", "x0": (0.0,) * 6, "x0_hat": (0.0,) * 6, "P0": (4.0,) * 6}
    with pytest.raises(ValueError, match=match):
        make_scenario("paper", target_behaviour=value, **kw)


def test_a_behaviour_of_another_time_step_names_the_field():
    # the task's behaviour was built for dt = 0.1: another dt would move the target in
    # steps of 0.1 s while the filter predicts over dt
    with pytest.raises(ValueError, match=r"target_behaviour \(target 0\).*0\.1.*dt \(0\.05\)"):
        make_scenario("maneuvering", dt=0.05)
    with pytest.raises(ValueError, match=r"target_behaviour .*time step 0\.2"):
        make_scenario("paper", target_behaviour=FilterModel(make_model("cv", 10.0, 0.2)))
    assert make_scenario("maneuvering", dt=0.05, target_behaviour=None).target_behaviour is None


def test_wrong_count_names_the_field():
    with pytest.raises(ValueError, match=r"target_behaviour .* one per target \(2\), got 3"):
        make_scenario("two_targets", target_behaviour=(TURNS,) * 3)


# The filter's own model, given explicitly --------------------------------------------------
def _run(world, steps, seed=5):
    """Return the states of ``world`` after each of ``steps`` random steps."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps):
        world.step_actions(_actions(rng, world.num_copies, world.n_sensors))
        out.append({k: np.array(world.get(k), dtype=np.float64) for k in FIELDS})
    return out


def _same(a, b):
    for sa, sb in zip(a, b, strict=True):
        for k in FIELDS:
            assert np.array_equal(sa[k], sb[k]), k


@pytest.mark.parametrize("n", [1, 3])
def test_filter_model_equals_the_default_world_bit_for_bit(n):
    seeds = [11, 12, 13][:n]
    # two targets: the default world moves them stage by stage too, by the same kernel
    sc = make_scenario("two_targets")
    given = World(sc, n, target_behaviour=tuple(FilterModel(m) for m in sc.target_models))
    default = World(sc, n)
    given.reset(seeds=seeds), default.reset(seeds=seeds)
    _same(_run(given, 12), _run(default, 12))
    # the paper: its default step is one compiled call, which rounds differently from the
    # stage-by-stage step; against the default world made to step stage by stage, exact
    given = World("paper", n, target_behaviour=FilterModel(make_scenario("paper").model))
    staged = World("paper", n)
    staged._fused = staged._per_target = False
    given.reset(seeds=seeds), staged.reset(seeds=seeds)
    _same(_run(given, 12), _run(staged, 12))


# A maneuvering target, stepped by hand ------------------------------------------------------
@pytest.mark.parametrize("n", [1, 3])
def test_maneuvering_trajectory_equals_the_behaviour_stepped_by_hand(n):
    seeds = [21, 22, 23][:n]
    world = World("paper", n, target_behaviour=TURNS)
    world.reset(seeds=seeds)
    states = _run(world, 30)
    x0 = np.asarray(make_scenario("paper").x0)
    for j, seed in enumerate(seeds):
        (gen,) = np.random.default_rng(seed).spawn(1)  # the world's copy j, spawned at reset
        x, mode = x0, TURNS.initial_mode(gen)
        modes = set()
        for s in states:
            x, mode = TURNS.step(x, gen, None, mode)
            assert np.array_equal(s["x_true"][j], x)
            modes.add(mode)
        assert modes == {0, 1, 2}  # every mode visited: the switch is exercised
        assert world.target_modes[j, 0] == mode


def test_a_behaviour_keeps_the_streams_draws():
    """The copy's generator ends where the default world's does: the same normals were
    drawn (the process noise unused), so measurement noise is paired across behaviours."""
    ends = []
    for beh in (None, TURNS, Evasive(10.0, DT)):
        w = World("paper", 2, target_behaviour=beh)
        w.reset(seeds=[3, 4])
        _run(w, 7)
        w.reset()  # puts back the block's unused normals
        ends.append([w.rng(i).bit_generator.state for i in range(2)])
    assert ends[0] == ends[1] == ends[2]


# An evader ----------------------------------------------------------------------------------
def test_evader_runs_from_the_nearest_sensor_at_its_speed():
    speed = 6.0
    world = World("homogeneous", target_behaviour=Evasive(speed, DT))
    world.reset(seeds=[8])
    rng = np.random.default_rng(1)
    m = world.n_sensors
    for _ in range(25):
        x, sensors = world.get("x_true", 0).copy(), world.get("sensors", 0).copy()
        toward = x[:2] - sensors
        world.step_actions(toward / np.linalg.norm(toward, axis=1, keepdims=True)
                           + 0.1 * rng.standard_normal((m, 2)))  # fmt: skip
        y = world.get("x_true", 0)
        d0 = np.linalg.norm(x[:2] - sensors, axis=1)
        i = int(np.argmin(d0))  # the nearest sensor at the step's start
        # geometry: straight away from it, so the distance grows by speed dt exactly
        assert np.linalg.norm(y[:2] - sensors[i]) == pytest.approx(d0[i] + speed * DT, rel=1e-12)
        assert np.linalg.norm(y[2:]) == pytest.approx(speed, rel=1e-12)
    assert world.target_modes[0, 0] == 1  # fleeing


# Batched copies against single ones ---------------------------------------------------------
@pytest.mark.parametrize(
    "beh", [TURNS, Evasive(8.0, DT, detection_range=15.0), StopAndGo(5.0, 0.2, 0.3, 10.0, DT)]
)
def test_batched_copies_equal_single_ones_bit_for_bit(beh):
    seeds = [31, 32, 33]
    batched = World("homogeneous", 3, target_behaviour=beh)
    singles = [World("homogeneous", target_behaviour=beh) for _ in seeds]
    batched.reset(seeds=seeds)
    for w, s in zip(singles, seeds, strict=True):
        w.reset(seeds=[s])
    rng = np.random.default_rng(2)
    m = batched.n_sensors
    for step in range(20):
        a = rng.uniform(-1.0, 1.0, (3, m, 2))
        live = None if step % 4 else np.array([0, 2])  # some steps only two copies
        batched.step_actions(a, live)
        for j, w in enumerate(singles):
            if live is None or j in live:
                w.step_actions(a[j])
        if step == 9:  # a new episode for copy 1 mid-way
            batched.reset([1])
            singles[1].reset()
        for j, w in enumerate(singles):
            for k in ("x_true", "x_hat", "P", "sensors"):
                assert np.array_equal(batched.get(k, j), w.get(k, 0)), (step, j, k)
            assert batched.target_modes[j, 0] == w.target_modes[0, 0]


# The single-model EKF against a maneuvering target ------------------------------------------
def _mean_nees(beh, runs=100, steps=40):
    """Return each run's time-averaged NEES (full state, dim 4) of the world's EKF."""
    w = World("homogeneous", runs, target_behaviour=beh, n_steps=steps)
    w.reset(seeds=list(range(1000, 1000 + runs)))
    total = np.zeros(runs)
    for _ in range(steps):
        w.step_actions(np.zeros((runs, w.n_sensors, 2)))  # the sensors hold still
        e = w.get("x_true") - w.get("x_hat")
        total += np.einsum("ni,nij,nj->n", e, np.linalg.inv(w.get("P")), e)
    return total / steps


def test_single_model_filter_is_inconsistent_against_a_maneuvering_target():
    # the filter's own target: the mean NEES is in its band (the same statistic and seeds)
    lo, hi = nees_band(control := _mean_nees(None), dim=4)
    assert lo <= control.mean() <= hi
    # the target turns at 3 rad/s (a 10 m/s target: 30 m/s^2), which the CV filter does not model
    turns = _mean_nees(TURNS)
    lo, hi = nees_band(turns, dim=4)
    assert turns.mean() > hi, (turns.mean(), hi)


def test_the_tasks_behaviours_print_as_their_construction():
    from activetrack.world.presets import EVADER, MANEUVERING

    for b in (MANEUVERING, EVADER, TURNS):  # the docs' preset tables show this text
        assert eval(repr(b), {"Maneuvering": Maneuvering, "Evasive": Evasive}) == b
