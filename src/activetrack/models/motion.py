"""Target motion models: the linear stochastic dynamics of eq. (1)-(2).

A model is the discrete-time triple (Phi, G, Qd) of eq. (2),
``x(k+1) = Phi x(k) + G w_d(k)`` with ``w_d ~ N(0, Qd)``, and the EKF propagation of
eq. (3): ``x_hat(k+1|k) = Phi x_hat(k|k)``, ``P(k+1|k) = Phi P Phi^T + G Qd G^T``.

Continuous models ``x_dot = F x + G w``, ``E[w w^T] = q I delta(t - tau)`` (the paper's
eq. (39) for constant velocity) are discretized exactly with Van Loan's method. The
state is ordered as in eq. (1): ``[x, y, x_dot, y_dot, x_ddot, y_ddot, ...]``, so the
position is always the first two entries. Lemma 1 makes the planners independent of
the model; any known (Phi, G, Qd) can be used through :func:`from_matrices`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from activetrack._jit import as_rows
from activetrack.models import _motion_kernels as lk
from activetrack.validation import FloatArray, as_finite, positive, psd


@dataclass(frozen=True, eq=False)
class LinearMotionModel:
    """Discrete linear Gaussian target model of eq. (2).

    Attributes:
        Phi: state transition matrix, shape (n, n), n even, position first.
        G: process noise Jacobian, shape (n, p).
        Qd: covariance of the discrete noise ``w_d``, shape (p, p).
        dt: the time step the model was discretized with (informational).
        name: a short label.
    """

    Phi: FloatArray
    G: FloatArray
    Qd: FloatArray
    dt: float
    name: str = "linear"
    Q: FloatArray = field(init=False, repr=False)
    noise_factor: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        q = self.G @ self.Qd @ self.G.T
        q = 0.5 * (q + q.T)
        object.__setattr__(self, "Q", q)
        # A square root of G Qd G^T that also works when it is only semidefinite.
        object.__setattr__(self, "noise_factor", psd_factor(q))

    @property
    def dim(self) -> int:
        """Return the state dimension 2N."""
        return int(self.Phi.shape[0])

    def predict(self, x: FloatArray, P: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Return ``(x_hat(k+1|k), P(k+1|k))`` of eq. (3), batched over leading axes."""
        return predict(x, P, self.Phi, self.Q)

    def sample_next(self, x: FloatArray, rng: np.random.Generator) -> FloatArray:
        """Return a draw of the true next state of eq. (2), batched over leading axes."""
        w = rng.standard_normal(np.shape(x))
        return x @ self.Phi.T + w @ self.noise_factor.T

    def __reduce__(self):  # the derived fields are recomputed, keeping pickles small
        return (LinearMotionModel, (self.Phi, self.G, self.Qd, self.dt, self.name))


def psd_factor(A: FloatArray) -> FloatArray:
    """Return ``F`` with ``F F^T = A`` for symmetric positive semidefinite ``A`` (..., n, n).

    From the eigendecomposition (eigenvalues rounded below 0 clipped), so it also works
    when ``A`` is singular, where a Cholesky factor does not exist.
    """
    w, v = np.linalg.eigh(A)
    return v * np.sqrt(np.clip(w, 0.0, None))[..., None, :]


def predict(
    x: FloatArray, P: FloatArray, Phi: FloatArray, Q: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Return the propagated mean and symmetric covariance of eq. (3) (batched;
    :func:`activetrack.models._motion_kernels.predict_into`, exactly symmetric for a symmetric
    ``P``).

    ``x`` (..., n) and ``P`` (..., n, n) keep their own batch shapes; the values are not
    checked, the sizes are (ValueError: the kernel indexes unchecked).
    """
    x, P = np.asarray(x, np.float64), np.asarray(P, np.float64)
    Phi, Q = matrix(Phi), matrix(Q)
    n = Phi.shape[0]
    if Phi.shape != (n, n) or Q.shape != (n, n) or x.shape[-1:] != (n,) or P.shape[-2:] != (n, n):
        raise ValueError(
            f"predict needs x (..., {n}) and P (..., {n}, {n}) for Phi and Q of shape"
            f" ({n}, {n}); got x {x.shape}, P {P.shape}, Phi {Phi.shape}, Q {Q.shape}"
        )
    batch = P.shape[:-2]
    x_out, P_out = np.empty(x.shape), np.empty(P.shape)
    if x.shape[:-1] == batch:  # (the common case) the mean's rows beside the covariances'
        lk.predict_rows(
            as_rows(x, batch, (n,)), as_rows(P, batch, (n, n)), Phi, Q, x_out.reshape(-1, n),
            P_out.reshape(-1, n, n),
        )  # fmt: skip
        return x_out, P_out
    # A mean and covariances of other batch shapes: each with a stand-in for the other.
    xr, Pr = as_rows(x, x.shape[:-1], (n,)), as_rows(P, batch, (n, n))
    lk.predict_rows(xr, np.zeros((xr.shape[0], n, n)), Phi, Q, x_out.reshape(-1, n),
                    np.empty((xr.shape[0], n, n)))  # fmt: skip
    lk.predict_rows(np.zeros((Pr.shape[0], n)), Pr, Phi, Q, np.empty((Pr.shape[0], n)),
                    P_out.reshape(-1, n, n))  # fmt: skip
    return x_out, P_out


def matrix(a: FloatArray) -> FloatArray:
    """Return ``a`` as a C-contiguous float64 matrix (the kernels' one signature)."""
    if type(a) is np.ndarray and a.dtype == np.float64 and a.flags.c_contiguous:
        return a
    return np.ascontiguousarray(a, np.float64)


def van_loan(
    F: FloatArray, L: FloatArray, Qc: FloatArray, dt: float
) -> tuple[FloatArray, FloatArray]:
    """Return ``(Phi, Qd)`` of ``x_dot = F x + L w``, ``E[w w^T] = Qc delta``, over ``dt``.

    Van Loan (1978): with ``M = [[-F, L Qc L^T], [0, F^T]] dt``, ``expm(M) = [[., B12], [0, B22]]``
    gives ``Phi = B22^T`` and ``Qd = Phi B12``, the exact covariance of
    ``int_0^dt e^{F s} L Qc L^T e^{F^T s} ds``.
    """
    n = F.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -F
    M[:n, n:] = L @ Qc @ L.T
    M[n:, n:] = F.T
    E = scipy.linalg.expm(M * dt)
    Phi = E[n:, n:].T
    Qd = Phi @ E[:n, n:]
    return Phi, 0.5 * (Qd + Qd.T)


def _integrator_chain(order: int) -> tuple[FloatArray, FloatArray]:
    """Return (F, L) of an ``order``-fold integrator in 2D with noise on the highest derivative."""
    n = 2 * order
    F = np.zeros((n, n))
    for k in range(order - 1):
        F[2 * k : 2 * k + 2, 2 * k + 2 : 2 * k + 4] = np.eye(2)
    L = np.zeros((n, 2))
    L[-2:, :] = np.eye(2)
    return F, L


def from_continuous(F, L, q: float, dt: float, name: str = "continuous") -> LinearMotionModel:
    """Return the exact discretization of ``x_dot = F x + L w``, ``E[w w^T] = q I delta``."""
    F = as_finite("F", F)
    L = as_finite("L", L)
    q = float(positive("q", q, allow_zero=True))
    dt = float(positive("dt", dt))
    if F.ndim != 2 or F.shape[0] != F.shape[1] or F.shape[0] % 2:
        raise ValueError(f"F must be square with even size (position first), got {F.shape}")
    if L.ndim != 2 or L.shape[0] != F.shape[0]:
        raise ValueError(f"L must have shape ({F.shape[0]}, p), got {L.shape}")
    Phi, Qd = van_loan(F, L, q * np.eye(L.shape[1]), dt)
    return LinearMotionModel(Phi, np.eye(F.shape[0]), Qd, dt, name)


def constant_velocity(q: float, dt: float) -> LinearMotionModel:
    """Return the paper's zero-acceleration model of eq. (39), discretized exactly.

    State ``[x, y, x_dot, y_dot]``; white acceleration noise of intensity ``q``.
    """
    F, L = _integrator_chain(2)
    return from_continuous(F, L, q, dt, name="constant_velocity")


def constant_acceleration(q: float, dt: float) -> LinearMotionModel:
    """Return the constant-acceleration (white jerk) model, discretized exactly.

    State ``[x, y, x_dot, y_dot, x_ddot, y_ddot]``; white jerk noise of intensity ``q``.
    """
    F, L = _integrator_chain(3)
    return from_continuous(F, L, q, dt, name="constant_acceleration")


def from_matrices(Phi, G, Qd, dt: float = 1.0, name: str = "generic") -> LinearMotionModel:
    """Return a model from any known ``(Phi, G, Qd)`` of eq. (2), validated."""
    Phi = as_finite("Phi", Phi)
    if Phi.ndim != 2 or Phi.shape[0] != Phi.shape[1] or Phi.shape[0] % 2 or Phi.shape[0] < 2:
        raise ValueError(
            f"Phi must be square with even size >= 2 (position first), got {Phi.shape}"
        )
    n = Phi.shape[0]
    G = as_finite("G", G)
    if G.ndim != 2 or G.shape[0] != n:
        raise ValueError(f"G must have shape ({n}, p), got {G.shape}")
    Qd = psd("Qd", Qd)
    if Qd.shape[0] != G.shape[1]:
        raise ValueError(f"Qd must have shape ({G.shape[1]}, {G.shape[1]}), got {Qd.shape}")
    return LinearMotionModel(Phi, G, Qd, float(positive("dt", dt)), name)


MODELS = {"cv": constant_velocity, "ca": constant_acceleration}


def make_model(kind: str, q: float, dt: float) -> LinearMotionModel:
    """Return the named model (``"cv"`` or ``"ca"``) with noise intensity ``q`` and step ``dt``."""
    if kind not in MODELS:
        raise ValueError(f"motion must be one of {sorted(MODELS)}, got {kind!r}")
    return MODELS[kind](q, dt)
