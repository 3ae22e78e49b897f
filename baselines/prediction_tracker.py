"""The filter's full prediction, recovered from the sequence of planning problems.

The world's planning problems carry the full prediction (``problem.prediction``, an
:class:`activetrack.world.problem.Prediction`); this module is the fallback for problems built
from the position part of the prediction ``x_hat(k+1|k), P(k+1|k)`` (eq. 3) only. A
planner that looks several steps ahead also needs the velocity and the full covariance.
Both follow from the problems of one episode and the scenario (initial estimate, motion
model, sensor noise):

- the covariance does not depend on the measurements (the EKF of eq. 11 is linearized at
  the predicted mean, the problem's ``target``): replaying the filter's update at the
  executed positions (the next problem's ``sensors``) and its prediction gives the
  filter's ``P(k+1|k)`` exactly (the same functions on the same inputs);
- the update moves the mean by ``P[:, :2] g`` for some ``g`` in R^2 (eq. 11: the gain's
  columns span ``P[:, :2]``), and the next problem's ``target`` is the position part of
  ``Phi (x + P[:, :2] g)`` (eq. 3): two equations for ``g``.

:class:`PredictionTracker` does this for one episode at a time and checks every step
against the problem's ``prior_cov``; a problem that continues no episode it knows must be
the first of a new one (the scenario's initial prediction), else it raises.
"""

from __future__ import annotations

import numpy as np

from activetrack.estimation import ekf
from activetrack.models.motion import predict
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem
from activetrack.world.scenarios import PRESETS, Scenario, make_scenario
from activetrack.world.tracking import LoopParams

#: Relative tolerance of the check of a recovered covariance against the problem's.
RTOL = 1e-8


class PredictionTracker:
    """Recovers ``(x_hat(k+1|k), P(k+1|k))`` of one episode from its planning problems.

    Args:
        scenario: the scenario the problems come from (a preset name or a Scenario);
            ``None``: the preset whose initial prediction matches the first problem.
    """

    def __init__(self, scenario: str | Scenario | None = "paper") -> None:
        self._candidates = (
            [make_scenario(name) for name in PRESETS]
            if scenario is None
            else [make_scenario(scenario)]
        )
        self.scenario: Scenario | None = None
        if len(self._candidates) == 1:
            self.scenario = self._candidates[0]
            self.params = LoopParams.from_scenario(self.scenario)
        self.reset()

    @property
    def Phi(self) -> FloatArray:
        """Return the motion model's transition matrix (eq. 2)."""
        return self.params.Phi

    @property
    def Q(self) -> FloatArray:
        """Return the motion model's process noise covariance (eq. 3)."""
        return self.params.Q

    def reset(self) -> None:
        """Forget the episode: the next problem must be the first of one."""
        self._last: tuple[FloatArray, FloatArray, FloatArray] | None = None

    def observe(self, problem: PlanningProblem) -> tuple[FloatArray, FloatArray, bool]:
        """Return ``(x_pred (n,), P_pred (n, n), new_episode)`` for a single problem.

        Raises:
            ValueError: the problem neither continues the episode nor starts one.
        """
        if problem.batch_shape:
            raise ValueError("PredictionTracker.observe takes a single problem")
        nxt = self._continue(problem) if self._last is not None else None
        new = nxt is None
        if new:
            nxt = self._first(problem)
        x, P = nxt
        self._last = (x, P, problem.target.copy())
        return x, P, new

    def _continue(self, problem: PlanningProblem) -> tuple[FloatArray, FloatArray] | None:
        """Return the prediction that follows the last one, or None if it does not fit."""
        x, P, _ = self._last
        p = self.params
        sensors = problem.sensors
        if sensors.shape[0] != p.r.shape[0]:
            return None
        z = np.zeros_like(sensors)  # the covariance does not depend on the measurements
        P_post = ekf.update(x, P, z, sensors, p.sigma_d2, p.sigma_theta2, p.orientation)[1]
        x_next, P_next = predict(x, P_post, p.Phi, p.Q)
        if not _close(P_next[:2, :2], problem.prior_cov):
            return None
        # target = (Phi x_post)[:2] with x_post = x + P[:, :2] g.
        A = p.Phi[:2] @ P[:, :2]
        g = np.linalg.solve(A, problem.target - x_next[:2])
        return x_next + p.Phi @ (P[:, :2] @ g), P_next

    def _first(self, problem: PlanningProblem) -> tuple[FloatArray, FloatArray]:
        """Return the initial prediction of the scenario that fits ``problem``, or raise."""
        for sc in self._candidates:
            if problem.n_sensors != sc.n_sensors:
                continue
            p = LoopParams.from_scenario(sc)
            x, P = predict(np.asarray(sc.x0_hat, dtype=np.float64), sc.initial_cov, p.Phi, p.Q)
            if _close(P[:2, :2], problem.prior_cov) and np.allclose(
                x[:2], problem.target, rtol=RTOL, atol=1e-12
            ):
                self.scenario, self.params = sc, p
                return x, P
        names = [sc.name for sc in self._candidates]
        raise ValueError(
            "the planning problem neither continues the episode nor starts one of scenario "
            f"{names}: pass the scenario the problems come from, and every problem of an "
            "episode in order"
        )


def _close(a: FloatArray, b: FloatArray) -> bool:
    """Return whether two covariances agree to :data:`RTOL` of their scale."""
    scale = max(float(np.max(np.abs(b))), 1e-300)
    return bool(np.max(np.abs(a - b)) <= RTOL * scale)
