"""The IMM filter as the world's estimator (the scenario field ``estimator``,
:mod:`activetrack.world.imm_tracking`), against independent computations: with one mode
(the filter's own model) the IMM world is the default EKF world bit for bit (mixing and
combining one mode change nothing, and the update is the same EKF on the same sensors);
on ``maneuvering`` with GSR driving the sensors, the NEES of the IMM's posterior and of its
predicted mixture (what the planners plan with) lie in their bands where the default
EKF's are above them; a world of N copies equals N worlds of one; bad specs name the field.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack import (
    Evasive,
    IMMFilter,
    IMMSpec,
    Maneuvering,
    constant_acceleration,
    constant_velocity,
)
from activetrack.world import World
from activetrack.world.presets import MANEUVERING
from activetrack.world.scenarios import make_scenario
from tests.core.helpers import nees_band

FIELDS = ("x_hat", "P", "x_pred", "P_pred")


def _one_mode(sc):
    return IMMSpec([sc.model], [[1.0]])


@pytest.mark.parametrize(
    ("name", "overrides"),
    [
        ("paper", {}),  # the fused compiled step against the IMM's stage-by-stage one
        ("mixed", {}),  # range, bearing and range-and-bearing sensors
        ("two_targets", {}),  # one IMM per target
        ("uncertain_poses", {}),  # the filter's pose noise
        ("urban", {}),  # occluders, ranges: the detections mask
        ("paper", {"p_detect": 0.6, "filter_iterations": 3}),  # missed detections, iterated
    ],
)
def test_one_mode_imm_world_is_the_ekf_world_bit_for_bit(name, overrides):
    sc = make_scenario(name, **overrides)
    n = 3
    ekf, imm = World(sc, n), World(sc, n, estimator=_one_mode(sc))
    for w in (ekf, imm):
        w.reset(seeds=[5, 6, 7])
    rng = np.random.default_rng(1)
    for _ in range(sc.n_steps):
        actions = rng.uniform(-1.0, 1.0, (n, sc.n_sensors, 2))
        for w in (ekf, imm):
            w.step_actions(actions)
        for k in range(sc.n_targets):
            for f in FIELDS:
                np.testing.assert_array_equal(imm.get(f, None, k), ekf.get(f, None, k), f)
    probs = imm.mode_probabilities
    assert ekf.mode_probabilities is None and len(probs) == sc.n_targets
    assert all(np.array_equal(p, np.ones((n, 1))) for p in probs)


@pytest.mark.parametrize("overrides", [{}, {"p_detect": 0.6}])
def test_imm_world_is_the_imm_filter_on_the_worlds_measurements(monkeypatch, overrides):
    # The world's IMM against the validated stateful activetrack.IMMFilter (itself tested
    # against the exact Gaussian-sum posterior, tests/core/test_imm.py) fed the very
    # measurements the world drew (recorded from its measurement function) and the sensors
    # that detected the target: the posterior mixture is x_hat/P, the predicted mixture
    # x_pred/P_pred, the mode probabilities the filter's, at every step.
    from activetrack.world import tracking

    drawn = []
    measure = tracking.measure

    def recorded(*args):
        z = measure(*args)
        drawn.append(z)
        return z

    monkeypatch.setattr(tracking, "measure", recorded)
    sc = make_scenario("maneuvering", **overrides)
    spec = IMMSpec.from_behaviour(MANEUVERING)
    w = World(sc, estimator=spec)
    w.reset(seeds=[4])
    f = IMMFilter(spec.models, spec.transition, sc.x0_hat, sc.initial_cov, spec.initial)
    f.predict()
    np.testing.assert_array_equal(w.get("x_pred", 0), f.x)
    np.testing.assert_array_equal(w.get("P_pred", 0), f.P)
    rng, missed = np.random.default_rng(2), 0
    sd2, st2 = sc.per_sensor("sigma_d2"), sc.per_sensor("sigma_theta2")
    for _ in range(sc.n_steps):
        w.step_actions(rng.uniform(-1.0, 1.0, (sc.n_sensors, 2)))
        seen = w.get("detected", 0)[0]
        missed += int(np.count_nonzero(~seen))
        f.update(drawn[-1][0], w.get("sensors", 0), sd2, st2, sensors=seen)
        np.testing.assert_array_equal(w.mode_probabilities[0], f.mu)
        np.testing.assert_array_equal(w.get("x_hat", 0), f.x)
        np.testing.assert_array_equal(w.get("P", 0), f.P)
        f.predict()
        np.testing.assert_array_equal(w.get("x_pred", 0), f.x)
        np.testing.assert_array_equal(w.get("P_pred", 0), f.P)
    assert len(drawn) == sc.n_steps and (missed > 0) == ("p_detect" in overrides)


def _position_nees(x, x_hat, P):
    """Return e^T P11^{-1} e of each run's position error (solved here)."""
    e = (x - x_hat)[:, :2]
    return np.einsum("ri,ri->r", e, np.linalg.solve(P[:, :2, :2], e[..., None])[..., 0])


def _nees_runs(estimator, runs):
    """Return each run's time-averaged position NEES of the posterior and of the one-step
    prediction ``x_pred``/``P_pred`` against the next true state, on ``maneuvering`` with
    GSR (one sweep, as tests/core/test_tasks.py) moving the sensors on what the estimator
    predicts."""
    from activetrack.baselines import GSR

    w = World("maneuvering", runs, estimator=estimator)
    w.reset(seeds=list(range(20_000, 20_000 + runs)))
    planner, post, pred = GSR(max_sweeps=1), [], []
    while not w.truncated.all():
        x_pred, P_pred = w.get("x_pred"), w.get("P_pred")
        w.step(planner.plan(w.planning_problem()))
        post.append(_position_nees(w.get("x_true"), w.get("x_hat"), w.get("P")))
        pred.append(_position_nees(w.get("x_true"), x_pred, P_pred))
    return np.mean(post, axis=0), np.mean(pred, axis=0)


def test_imm_world_is_consistent_on_maneuvering_where_the_ekf_world_is_not():
    # The statistic: the mean over 200 runs of each run's time-averaged position NEES, its
    # 99% band tests.core.helpers.nees_band's (runs i.i.d., a t-interval around 2). On
    # these seeds (2 s each): the IMM 2.021 (posterior) and 2.021 (prediction), bands
    # about 2 +- 0.098; the constant-velocity EKF 3.48 and 4.01, above its bands.
    runs = 200
    imm_post, imm_pred = _nees_runs(IMMSpec.from_behaviour(MANEUVERING), runs)
    ekf_post, ekf_pred = _nees_runs("ekf", runs)
    for stat in (imm_post, imm_pred):
        lo, hi = nees_band(stat)
        # The band is tight enough that a covariance 10% off (NEES x 1/1.1 or 1.1) fails.
        assert 2 / 1.1 < lo and hi < 2 * 1.1, (lo, hi)
        assert lo <= stat.mean() <= hi, (stat.mean(), lo, hi)
    for stat in (ekf_post, ekf_pred):
        _, hi = nees_band(stat)
        assert stat.mean() > hi, (stat.mean(), hi)


def test_batched_imm_world_is_single_worlds_bit_for_bit():
    # Three copies stepped together (some steps only a subset, one copy reset mid-way)
    # against three worlds of one copy each, with the same moves and seeds.
    spec = IMMSpec.from_behaviour(MANEUVERING)
    n, seeds = 3, [11, 12, 13]
    batch = World("maneuvering", n, estimator=spec)
    singles = [World("maneuvering", estimator=spec) for _ in range(n)]
    batch.reset(seeds=seeds)
    for w, s in zip(singles, seeds, strict=True):
        w.reset(seeds=[s])
    rng = np.random.default_rng(3)
    m = batch.n_sensors
    for step in range(30):
        actions = rng.uniform(-1.0, 1.0, (n, m, 2))
        live = np.array([True, step % 3 != 1, step % 2 == 0])
        if step == 12:
            batch.reset([1], seeds=[99])
            singles[1].reset(seeds=[99])
        batch.step_actions(actions, live)
        for i in np.flatnonzero(live):
            singles[i].step_actions(actions[i])
        for i, w in enumerate(singles):
            for f in FIELDS:
                np.testing.assert_array_equal(batch.get(f, i), w.get(f, 0), f)
            np.testing.assert_array_equal(batch.mode_probabilities[0][i], w.mode_probabilities[0])
            np.testing.assert_array_equal(batch.observe(i), w.observe(0))
    # The mode probabilities left the prior (mode 0) and are distributions.
    mu = batch.mode_probabilities[0]
    np.testing.assert_allclose(mu.sum(axis=-1), 1.0, rtol=0, atol=1e-12)
    assert np.all(mu[:, 0] < 1.0)


def test_the_default_is_the_ekf_and_the_record_names_the_imm():
    sc = make_scenario("maneuvering")
    assert sc.estimator == "ekf" and "estimator" not in sc.to_dict()
    spec = IMMSpec.from_behaviour(MANEUVERING)
    assert spec == IMMSpec(MANEUVERING.models, MANEUVERING.transition, [1.0, 0.0, 0.0])
    assert spec != IMMSpec(MANEUVERING.models, MANEUVERING.transition)  # uniform initial
    imm = make_scenario("maneuvering", estimator=spec)
    assert imm == make_scenario("maneuvering", estimator=IMMSpec.from_behaviour(MANEUVERING))
    assert imm == make_scenario("maneuvering", estimator="imm")  # the behaviour's mode set
    assert imm.to_dict()["estimator"] == {
        "name": "imm",
        "models": [mdl.name for mdl in MANEUVERING.models],
        "transition": MANEUVERING.transition.tolist(),
        "initial": [1.0, 0.0, 0.0],
    }


CV = constant_velocity(10.0, 0.1)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: make_scenario("paper", estimator="IMM"), r"estimator must be 'ekf', 'imm' or"),
        (lambda: make_scenario("paper", estimator=None), r"estimator must be 'ekf', 'imm' or"),
        (
            lambda: make_scenario("paper", estimator="imm"),
            r"estimator='imm' needs one target_behaviour with a mode set.*None",
        ),
        (
            lambda: make_scenario("evader", estimator="imm"),
            r"estimator='imm' needs one target_behaviour with a mode set.*Evasive",
        ),
        (lambda: IMMSpec([], [[1.0]]), r"estimator: IMMSpec models must be a non-empty"),
        (lambda: IMMSpec([CV, CV], [[0.9, 0.2], [0.5, 0.5]]), r"estimator: .*row-stochastic"),
        (lambda: IMMSpec([CV, CV], [[1.1, -0.1], [0.5, 0.5]]), r"estimator: .*entries in \[0, 1\]"),
        (lambda: IMMSpec([CV], [[0.5, 0.5], [0.5, 0.5]]), r"estimator: .*shape \(1, 1\)"),
        (lambda: IMMSpec([CV, CV], np.eye(2), [0.7, 0.7]), r"estimator: IMMSpec initial"),
        (
            lambda: IMMSpec([CV, constant_acceleration(1.0, 0.1)], np.eye(2)),
            r"estimator: IMMSpec models must share one state dimension",
        ),
        (
            lambda: make_scenario(
                "paper", estimator=IMMSpec([constant_acceleration(1.0, 0.1)], [[1.0]])
            ),
            r"estimator: the IMM's modes have state dimension 6, the targets' .*\[4\]",
        ),  # fmt: skip
        (
            lambda: make_scenario(
                "paper", estimator=IMMSpec([constant_velocity(10.0, 0.2)], [[1.0]])
            ),
            r"estimator: the IMM's mode 0 has time step 0.2, the scenario's dt is 0.1",
        ),  # fmt: skip
        (
            lambda: IMMSpec.from_behaviour(Evasive(5.0, 0.1)),
            r"estimator: IMMSpec.from_behaviour needs a behaviour with a mode set",
        ),
        (
            lambda: IMMSpec.from_behaviour(Maneuvering([0.0, 1.0], np.eye(2), 1.0, 0.1), [2, 0]),
            r"estimator: IMMSpec initial",
        ),
    ],
)
def test_bad_estimators_name_the_field(make, message):
    with pytest.raises(ValueError, match=message):
        make()
