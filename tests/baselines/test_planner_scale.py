"""Every planner answers across the accepted scale range of a hand-built problem
(``activetrack.world.problem.SCALE_RANGE``: the noise variances and the prior's eigenvalues);
outside it the problem is refused with a ValueError naming the field."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from activetrack.baselines import GBES, GSR, LookaheadPlanner, RandomMotion
from activetrack.world.problem import SCALE_RANGE, PlanningProblem, Prediction

DT = 0.1
PHI = np.block([[np.eye(2), DT * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
Q = np.block([[DT**3 / 3 * np.eye(2), DT**2 / 2 * np.eye(2)],
              [DT**2 / 2 * np.eye(2), DT * np.eye(2)]])  # fmt: skip
LO, HI = (int(round(np.log10(v))) for v in SCALE_RANGE)
EXPONENT = st.floats(LO, HI)


def _problem(e_prior, e_sd2, e_st2, seed):
    """Return a 3-sensor problem carrying a CV prediction: prior eigenvalues 10**e_prior
    (rotated at random; a condition number float64 keeps positive definite, the smaller
    eigenvalue 0.01 decades inside the range: the rotation's rounding moves it by about
    eps times the condition number, relative), noise variances 10**e_sd2, 10**e_st2 (one
    per sensor)."""
    rng = np.random.default_rng(seed)
    lam = 10.0 ** np.asarray(e_prior, np.float64)
    phi = rng.uniform(0.0, np.pi)
    rot = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    prior = rot @ np.diag(lam) @ rot.T
    cov = np.zeros((4, 4))
    cov[:2, :2] = 0.5 * (prior + prior.T)
    cov[2:, 2:] = lam.max() * np.eye(2)
    pred = Prediction(mean=np.array([0.0, 0.0, 1.0, 0.0]), cov=cov, Phi=PHI, Q=Q)
    ang, dist = rng.uniform(0, 2 * np.pi, 3), rng.uniform(1.0, 4.0, 3)
    sensors = dist[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    return PlanningProblem.from_prediction(
        pred, sensors, 1.0, 2.0, 10.0 ** np.asarray(e_sd2), 10.0 ** np.asarray(e_st2)
    )


PLANNERS = {
    "GSR": lambda: GSR(),
    "GSR(restarts=True)": lambda: GSR(restarts=True),
    "GBES": lambda: GBES(),
    "RM": lambda: RandomMotion(),
    "lookahead": lambda: LookaheadPlanner(horizon=3, headings=8),
}


def _check_answers(problem):
    for name, make in PLANNERS.items():
        with warnings.catch_warnings():  # intermediate infinities (1/0) the planners handle
            warnings.simplefilter("ignore", RuntimeWarning)
            x = make().plan(problem, np.random.default_rng(0))
        assert x.shape == (3, 2) and np.all(np.isfinite(x)), name
        # Feasibility against the constraints computed here (eq. 15-16), not the problem's.
        step = np.linalg.norm(x - problem.sensors, axis=-1)
        dist = np.linalg.norm(x - problem.target, axis=-1)
        assert np.all(step <= 1.0 * (1 + 1e-9)), (name, step)
        assert np.all(dist >= 2.0 * (1 - 1e-9)), (name, dist)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    e_prior=st.tuples(EXPONENT, st.floats(0.0, 12.0)).map(
        lambda t: (max(LO + 0.01, t[0] - t[1]), t[0])
    ),
    e_sd2=st.lists(EXPONENT, min_size=3, max_size=3),
    e_st2=st.lists(EXPONENT, min_size=3, max_size=3),
    seed=st.integers(0, 2**32 - 1),
)
@example(e_prior=(LO + 0.01, LO + 0.01), e_sd2=[LO] * 3, e_st2=[LO] * 3, seed=0)
@example(e_prior=(HI, HI), e_sd2=[HI] * 3, e_st2=[HI] * 3, seed=0)
@example(e_prior=(HI - 12, HI), e_sd2=[LO, HI, 0], e_st2=[HI, LO, 0], seed=1)
@example(e_prior=(LO + 0.01, LO + 12), e_sd2=[HI, LO, 0], e_st2=[LO, HI, 0], seed=4)
@example(e_prior=(HI, HI), e_sd2=[LO] * 3, e_st2=[LO] * 3, seed=2)
@example(e_prior=(LO + 0.01, LO + 0.01), e_sd2=[HI] * 3, e_st2=[HI] * 3, seed=3)
@example(  # one sensor's bearing information 1e70 times the prior's: singular in float64
    e_prior=(24.373051256327827, 29.24511040544448),
    e_sd2=[47.44818373184103, 10.515916542603584, 46.769798268681825],
    e_st2=[-45.60123079436029, 38.269265284270034, 5.937718754487655],
    seed=2348432197,
)
def test_every_planner_answers_feasible_finite_positions_across_the_scale_range(
    e_prior, e_sd2, e_st2, seed
):
    _check_answers(_problem(e_prior, e_sd2, e_st2, seed))


@pytest.mark.parametrize("factor", [1e-3, 1e-150])
@pytest.mark.parametrize("field", ["sigma_d2", "sigma_theta2", "prior_cov"])
def test_outside_the_scale_range_a_value_error_names_the_field(field, factor):
    lo, hi = SCALE_RANGE
    for value in (lo * factor, hi / factor):
        e = np.log10(value)
        kw = {"e_prior": (0.0, 0.0), "e_sd2": [0.0] * 3, "e_st2": [0.0] * 3, "seed": 0}
        kw[{"sigma_d2": "e_sd2", "sigma_theta2": "e_st2", "prior_cov": "e_prior"}[field]] = (
            [0.0, 0.0, e] if field != "prior_cov" else (e, e)
        )
        with pytest.raises(ValueError, match=rf"^{field}.*\[1e-50, 1e\+50\]"):
            _problem(**kw)
    # A hand-built problem without a prediction is checked the same way.
    base = _problem((0.0, 0.0), [0.0] * 3, [0.0] * 3, 0)
    args = dict(prior_cov=base.prior_cov, target=base.target, sensors=base.sensors, r=1.0,
                rho=2.0, sigma_d2=1.0, sigma_theta2=1.0)  # fmt: skip
    args[field] = np.eye(2) * lo * factor if field == "prior_cov" else lo * factor
    with pytest.raises(ValueError, match=rf"^{field}"):
        PlanningProblem(**args)
