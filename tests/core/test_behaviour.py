"""Target behaviours against independent computations: the coordinated turn against a
numerical ODE integration (mean and covariance), the maneuvering target's Markov chain
against its transition matrix (a chi-square band on the transition counts), the evader's
speed and distance against geometry, the filter's model against the motion model and the
world's step bit for bit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from scipy.integrate import solve_ivp

from activetrack import (
    Evasive,
    FilterModel,
    IMMFilter,
    Maneuvering,
    StopAndGo,
    TargetBehaviour,
    constant_velocity,
)
from activetrack.models.behaviour import coordinated_turn


def ct_field(omega):
    F = np.zeros((4, 4))
    F[0, 2] = F[1, 3] = 1.0
    F[2, 3], F[3, 2] = -omega, omega
    return F


@pytest.mark.parametrize("omega", [0.0, 0.35, -1.2, 1e-7, 3.0])
def test_coordinated_turn_against_ode_integration(omega):
    dt, q = 0.7, 0.4
    model = coordinated_turn(omega, q, dt)
    F = ct_field(omega)
    x0 = np.array([1.0, -2.0, 3.0, 0.5])
    # The mean: the noise-free ODE d/dt [p, v] = [v, omega J v].
    sol = solve_ivp(lambda t, x: F @ x, (0, dt), x0, rtol=1e-12, atol=1e-12, method="DOP853")
    np.testing.assert_allclose(model.Phi @ x0, sol.y[:, -1], rtol=1e-10, atol=1e-10)
    # The speed is kept by a turn (a rotation of the velocity).
    assert np.hypot(*(model.Phi @ x0)[2:]) == pytest.approx(np.hypot(*x0[2:]), rel=1e-12)
    # The covariance: the Lyapunov ODE dP/dt = F P + P F^T + q L L^T from P(0) = 0.
    LLt = np.diag([0.0, 0.0, q, q])

    def lyap(t, p):
        P = p.reshape(4, 4)
        return (F @ P + P @ F.T + LLt).ravel()

    sol = solve_ivp(lyap, (0, dt), np.zeros(16), rtol=1e-12, atol=1e-14, method="DOP853")
    np.testing.assert_allclose(model.Q, sol.y[:, -1].reshape(4, 4), rtol=1e-9, atol=1e-12)


def test_zero_rate_is_constant_velocity():
    a, b = coordinated_turn(0.0, 0.3, 0.5), constant_velocity(0.3, 0.5)
    np.testing.assert_allclose(a.Phi, b.Phi, atol=1e-15)
    np.testing.assert_allclose(a.Q, b.Q, rtol=1e-12, atol=1e-15)


def transition_chi2(counts, Pi):
    """Return Pearson's statistic of the transition counts against ``Pi`` and its degrees
    of freedom: given the n_i visits of mode i, the counts from i are multinomial(n_i,
    Pi[i]) (the strong Markov property), so the sum over rows is chi-square with
    sum_i (nonzero entries of row i - 1) degrees of freedom."""
    n_i = counts.sum(axis=1, keepdims=True)
    expected = n_i * Pi
    keep = Pi > 0
    stat = float(np.sum((counts[keep] - expected[keep]) ** 2 / expected[keep]))
    assert np.all(counts[~keep] == 0)  # an impossible transition never happens
    return stat, int(np.sum(keep.sum(axis=1) - 1))


def test_markov_chain_transition_frequencies_match_the_matrix():
    Pi = np.array([[0.90, 0.05, 0.05], [0.10, 0.80, 0.10], [0.15, 0.0, 0.85]])
    b = Maneuvering([0.0, 0.3, -0.3], Pi, q=0.1, dt=1.0, initial=[0.2, 0.3, 0.5])
    rng = np.random.default_rng(0)
    x, mode = np.array([0.0, 0.0, 1.0, 0.0]), b.initial_mode(rng)
    steps = 60_000
    counts = np.zeros((3, 3))
    for _ in range(steps):
        x_next, m_next = b.step(x, rng, mode=mode)
        counts[mode, m_next] += 1
        x = x_next * np.array([0, 0, 1, 1])  # keep the position small (it is not tested)
        mode = m_next
    stat, df = transition_chi2(counts, Pi)
    hi = stats.chi2.ppf(0.999, df)
    assert stat < hi, (stat, hi)
    # The band is tight: a matrix 10% off (one off-diagonal entry of each row scaled by
    # 1.1, the diagonal compensating) is rejected by the same counts.
    wrong = Pi.copy()
    for i, j in [(0, 1), (1, 0), (2, 0)]:
        wrong[i, i] -= 0.1 * wrong[i, j]
        wrong[i, j] *= 1.1
    assert transition_chi2(counts, wrong)[0] > hi


def test_initial_mode_frequencies():
    b = Maneuvering([0.0, 0.2], [[0.5, 0.5], [0.5, 0.5]], q=0.1, dt=1.0, initial=[0.3, 0.7])
    rng = np.random.default_rng(1)
    n = 20_000
    k = sum(b.initial_mode(rng) for _ in range(n))
    # binomial(n, 0.7): within 4 standard deviations
    assert abs(k - 0.7 * n) < 4 * np.sqrt(n * 0.21)


def test_maneuvering_moves_with_the_mode_it_switches_to():
    # A deterministic chain (always to mode 1) and no noise: the step is mode 1's turn.
    b = Maneuvering([0.0, 0.5], [[0.0, 1.0], [0.0, 1.0]], q=0.0, dt=0.4)
    x = np.array([1.0, 2.0, 3.0, -1.0])
    x1, m1 = b.step(x, np.random.default_rng(0), mode=0)
    F = ct_field(0.5)
    sol = solve_ivp(lambda t, y: F @ y, (0, 0.4), x, rtol=1e-12, atol=1e-12, method="DOP853")
    assert m1 == 1
    np.testing.assert_allclose(x1, sol.y[:, -1], rtol=1e-10, atol=1e-10)


def test_evader_keeps_its_speed_limit_and_flees_the_nearest_sensor():
    rng = np.random.default_rng(2)
    for _ in range(200):
        speed, dt = rng.uniform(0.1, 3.0), rng.uniform(0.1, 1.0)
        b = Evasive(speed, dt)
        sensors = rng.uniform(-10, 10, (rng.integers(1, 5), 2))
        x = np.concatenate([rng.uniform(-10, 10, 2), rng.normal(0, 5, 2)])
        d0 = np.linalg.norm(sensors - x[:2], axis=1)
        x1, mode = b.step(x, rng, sensors)
        near = int(np.argmin(d0))
        assert mode == 1
        assert np.hypot(*x1[2:]) <= speed * (1 + 1e-12)
        assert np.linalg.norm(x1[:2] - x[:2]) <= speed * dt * (1 + 1e-12)
        # straight away: the distance to the nearest sensor grows by exactly speed * dt
        d1 = np.linalg.norm(x1[:2] - sensors[near])
        assert d1 == pytest.approx(d0[near] + speed * dt, rel=1e-12)


def test_evader_against_a_fixed_sensor_over_an_episode():
    b = Evasive(1.5, 0.5, detection_range=7.9)
    sensor = np.array([[0.0, 0.0]])
    x, rng = np.array([3.0, 4.0, 5.0, 0.0]), np.random.default_rng(0)
    d = [5.0]
    modes = []
    for _ in range(10):
        x, m = b.step(x, rng, sensor)
        d.append(float(np.hypot(*x[:2])))
        modes.append(m)
        assert np.hypot(*x[2:]) <= 1.5 * (1 + 1e-12)
    # Flees (0.75 a step: 5, 5.75, 6.5, 7.25) until beyond 7.9, then coasts at its last
    # velocity (still away).
    assert modes[:4] == [1, 1, 1, 1] and modes[4:] == [0] * 6
    np.testing.assert_allclose(np.diff(d), 0.75, rtol=1e-12)


def test_evader_coasts_clipped_outside_its_detection_range():
    b = Evasive(2.0, 0.5, detection_range=1.0)
    x, _ = b.step(np.array([10.0, 0.0, 3.0, 4.0]), np.random.default_rng(0), [[0.0, 0.0]])
    np.testing.assert_allclose(x, [10.0 + 0.5 * 1.2, 0.8, 1.2, 1.6], rtol=1e-12)


def test_filter_model_equals_the_motion_model_and_the_worlds_step_bit_for_bit():
    from activetrack.world.tracking import TargetParams, move_target

    model = constant_velocity(0.3, 0.5)
    b = FilterModel(model)
    for seed in range(100):
        x = np.random.default_rng(seed + 500).normal(0, 10, 4)
        got, mode = b.step(x, np.random.default_rng(seed))
        want = model.sample_next(x, np.random.default_rng(seed))
        assert mode == 0 and np.array_equal(got, want)
        w = np.random.default_rng(seed).standard_normal(4)
        world = move_target(TargetParams(model.Phi, model.Q, model.noise_factor), x, w)
        assert np.array_equal(b.move(x, w), world)
        # and the two agree to rounding (the world sums in index order, NumPy's matmul not)
        np.testing.assert_allclose(world, want, rtol=1e-13, atol=1e-13)


def test_behaviours_compare_by_value_and_subclass_the_base():
    a = Maneuvering([0.0, 0.1], [[0.9, 0.1], [0.2, 0.8]], q=0.1, dt=1.0)
    b = Maneuvering([0.0, 0.1], [[0.9, 0.1], [0.2, 0.8]], q=0.1, dt=1.0)
    assert a == b and a != Maneuvering([0.0, 0.2], [[0.9, 0.1], [0.2, 0.8]], q=0.1, dt=1.0)
    assert all(isinstance(v, TargetBehaviour) for v in (a, Evasive(1.0, 1.0)))
    assert FilterModel(constant_velocity(0.1, 1.0)) == FilterModel(constant_velocity(0.1, 1.0))


@pytest.mark.parametrize(
    "kwargs,field",
    [
        ({"turn_rates": []}, "turn_rates"),
        ({"turn_rates": [0.0, np.nan]}, "turn_rates"),
        ({"transition": [[0.9, 0.2], [0.5, 0.5]]}, "transition"),
        ({"transition": [[1.1, -0.1], [0.5, 0.5]]}, "transition"),
        ({"transition": [[0.9, 0.1]]}, "transition"),
        ({"transition": [[np.nan, 0.1], [0.5, 0.5]]}, "transition"),
        ({"q": -0.1}, "q"),
        ({"q": np.nan}, "q"),
        ({"dt": 0.0}, "dt"),
        ({"initial": [0.5, 0.6]}, "initial"),
    ],
)
def test_maneuvering_rejects_bad_parameters_naming_the_field(kwargs, field):
    args = {"turn_rates": [0.0, 0.2], "transition": [[0.9, 0.1], [0.5, 0.5]], "q": 0.1, "dt": 1.0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=rf"^{field} "):
        Maneuvering(**args)


@pytest.mark.parametrize(
    "kwargs,field",
    [({"speed": -1.0}, "speed"), ({"speed": np.nan}, "speed"), ({"dt": -1.0}, "dt"),
     ({"detection_range": -2.0}, "detection_range"), ({"idle": "cv"}, "idle")],
)  # fmt: skip
def test_evasive_rejects_bad_parameters_naming_the_field(kwargs, field):
    args = {"speed": 1.0, "dt": 1.0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=rf"^{field} "):
        Evasive(**args)


def test_steps_reject_bad_inputs():
    with pytest.raises(ValueError, match="^sensors "):
        Evasive(1.0, 1.0).step(np.zeros(4), np.random.default_rng(0))
    with pytest.raises(ValueError, match="^x "):
        Evasive(1.0, 1.0).step([0.0, np.nan, 0, 0], np.random.default_rng(0), [[1.0, 1.0]])
    b = Maneuvering([0.0], [[1.0]], q=0.1, dt=1.0)
    with pytest.raises(ValueError, match="^mode "):
        b.step(np.zeros(4), np.random.default_rng(0), mode=3)
    with pytest.raises(ValueError, match="^model "):
        FilterModel("cv")


def test_stop_and_go_chain_stops_and_move_offs():
    b = StopAndGo(speed=2.0, p_stop=0.1, p_go=0.25, q=0.0, dt=0.5)
    rng = np.random.default_rng(3)
    x, mode = np.array([0.0, 0.0, 2.0, 0.0]), 0
    counts = np.zeros((2, 2))
    headings = []
    for _ in range(40_000):
        x_next, m_next = b.step(x, rng, mode=mode)
        counts[mode, m_next] += 1
        if m_next == 1:  # stopped: where it was, at rest
            assert np.array_equal(x_next[:2], x[:2]) and np.all(x_next[2:] == 0.0)
        elif mode == 1:  # moved off at its speed (q = 0: no noise) and moved on
            assert np.hypot(*x_next[2:]) == pytest.approx(2.0, rel=1e-12)
            np.testing.assert_allclose(x_next[:2], x[:2] + 0.5 * x_next[2:], rtol=1e-12)
            headings.append(np.arctan2(x_next[3], x_next[2]))
        x, mode = x_next * np.array([0, 0, 1, 1]), m_next
    stat, df = transition_chi2(counts, b.transition)
    hi = stats.chi2.ppf(0.999, df)
    assert stat < hi
    wrong = StopAndGo(2.0, 0.11, 0.275, 0.0, 0.5).transition  # both rates 10% off
    assert transition_chi2(counts, wrong)[0] > hi
    # Uniform headings: the mean resultant length of n uniform angles is about 1/sqrt(n)
    # (Rayleigh); 4/sqrt(n) bounds it with probability 1 - exp(-16).
    h = np.array(headings)
    assert np.hypot(np.cos(h).mean(), np.sin(h).mean()) < 4 / np.sqrt(h.size)


def test_stop_and_go_modes_run_in_an_imm():
    # The two modes as linear models (the stopped one with a singular covariance) keep
    # the IMM's covariance symmetric positive definite and find the stops.
    b = StopAndGo(3.0, 0.1, 0.2, 0.05, 1.0)
    f = IMMFilter([b.moving_model, b.stopped_model], b.transition, np.zeros(4), np.eye(4))
    rng = np.random.default_rng(0)
    x, m = np.array([0.0, 0.0, 3.0, 0.0]), 0
    offsets = np.array([[10.0, 0.0], [0.0, 10.0]])
    right = 0
    for _ in range(60):
        x, m = b.step(x, rng, mode=m)
        s = x[:2] + offsets
        rel = x[:2] - s
        z = np.stack([np.hypot(rel[:, 0], rel[:, 1]), np.arctan2(rel[:, 1], rel[:, 0])], 1)
        f.predict()
        f.update(z + rng.normal(0, [0.3, 0.01], (2, 2)), s, 0.09, 1e-4)
        assert np.array_equal(f.P, f.P.T) and np.linalg.eigvalsh(f.P)[0] > 0
        right += int(np.argmax(f.mu) == m)
    assert right >= 50  # the mode is told apart most of the time (not a tuned threshold:
    # a filter guessing by the stationary probabilities would be right 2/3 of the time)


@pytest.mark.parametrize(
    "kwargs,field",
    [({"speed": 0.0}, "speed"), ({"p_stop": 1.5}, "p_stop"), ({"p_go": -0.1}, "p_go"),
     ({"p_go": np.nan}, "p_go"), ({"q": -1.0}, "q"), ({"dt": np.inf}, "dt")],
)  # fmt: skip
def test_stop_and_go_rejects_bad_parameters_naming_the_field(kwargs, field):
    args = {"speed": 1.0, "p_stop": 0.1, "p_go": 0.2, "q": 0.1, "dt": 1.0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=rf"^{field} "):
        StopAndGo(**args)
