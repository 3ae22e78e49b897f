"""Motion models: exact discretization against closed forms, sampling against moments."""

import numpy as np
import pytest

import activetrack as at
from activetrack.models.motion import make_model


@pytest.mark.parametrize("dt", [0.05, 0.1, 1.0])
@pytest.mark.parametrize("q", [0.5, 10.0])
def test_constant_velocity_matches_closed_form(q, dt):
    I2 = np.eye(2)
    Phi = np.block([[I2, dt * I2], [0 * I2, I2]])
    Qd = q * np.block([[dt**3 / 3 * I2, dt**2 / 2 * I2], [dt**2 / 2 * I2, dt * I2]])
    model = at.constant_velocity(q, dt)
    np.testing.assert_allclose(model.Phi, Phi, atol=1e-14)
    np.testing.assert_allclose(model.Q, Qd, rtol=1e-12, atol=1e-15)


def test_constant_acceleration_matches_closed_form():
    q, dt = 3.0, 0.2
    I2 = np.eye(2)
    phi1 = np.array([[1, dt, dt**2 / 2], [0, 1, dt], [0, 0, 1]])
    q1 = q * np.array(
        [
            [dt**5 / 20, dt**4 / 8, dt**3 / 6],
            [dt**4 / 8, dt**3 / 3, dt**2 / 2],
            [dt**3 / 6, dt**2 / 2, dt],
        ]
    )
    model = at.constant_acceleration(q, dt)
    np.testing.assert_allclose(model.Phi, np.kron(phi1, I2), atol=1e-14)
    np.testing.assert_allclose(model.Q, np.kron(q1, I2), rtol=1e-12, atol=1e-15)


def test_sampled_process_noise_has_model_covariance():
    model = at.constant_velocity(10.0, 0.1)
    rng = np.random.default_rng(1)
    x = np.zeros((200_000, 4))
    w = model.sample_next(x, rng)
    cov = np.cov(w.T)
    np.testing.assert_allclose(cov, model.Q, atol=4 * np.sqrt(2.0 / 200_000) * np.max(model.Q))


def test_generic_model_predicts_like_textbook():
    rng = np.random.default_rng(2)
    Phi = rng.standard_normal((4, 4))
    G = rng.standard_normal((4, 2))
    A = rng.standard_normal((2, 2))
    Qd = A @ A.T
    model = at.from_matrices(Phi, G, Qd, dt=0.3)
    x = rng.standard_normal(4)
    B = rng.standard_normal((4, 4))
    P = B @ B.T + np.eye(4)
    xp, Pp = model.predict(x, P)
    np.testing.assert_allclose(xp, Phi @ x)
    np.testing.assert_allclose(Pp, Phi @ P @ Phi.T + G @ Qd @ G.T, rtol=1e-12)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"Phi": np.eye(3), "G": np.eye(3), "Qd": np.eye(3)}, "Phi"),
        ({"Phi": np.eye(4), "G": np.eye(3), "Qd": np.eye(3)}, "G"),
        ({"Phi": np.eye(4), "G": np.eye(4), "Qd": -np.eye(4)}, "Qd"),
        ({"Phi": np.eye(4), "G": np.eye(4), "Qd": np.array([[1, 2], [0, 1]])}, "Qd"),
        ({"Phi": np.full((4, 4), np.nan), "G": np.eye(4), "Qd": np.eye(4)}, "Phi"),
    ],
)
def test_generic_model_rejects_bad_input(kwargs, field):
    with pytest.raises(ValueError, match=field):
        at.from_matrices(**kwargs)


def test_named_model_errors():
    with pytest.raises(ValueError, match="motion"):
        make_model("zigzag", 1.0, 0.1)
    with pytest.raises(ValueError, match="dt"):
        at.constant_velocity(1.0, 0.0)
    with pytest.raises(ValueError, match="q"):
        at.constant_velocity(-1.0, 0.1)
