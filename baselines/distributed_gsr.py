"""Distributed GSR: Gauss-Seidel relaxation (Section IV-B, eq. 38) by message passing inside
each connected group of a team with limited communication (issue 37).

The step's link matrix (:mod:`activetrack.models.communication`) splits the team into
connected groups (:func:`~activetrack.models.communication.components`). Inside a group:

1. every robot announces its warm start (GSR's: where it is, or its projection onto the
   feasible set if it is inside its ``rho`` disk), computed on its own estimate;
2. a *round* visits the group's robots in index order: robot ``i`` solves its own
   single-sensor problem (eq. 38) exactly, on **its own** prediction of the targets (its
   view: a :class:`~activetrack.world.problem.PlanningProblem` whose prediction is robot
   ``i``'s), with the information of its group's other robots at their latest announced
   plans folded into its prior, keeps the new position only if it lowers its objective
   (GSR's rule) and announces it with the improvement of its objective;
3. a group stops after a round whose announced improvements add up to at most ``tol``
   times the objective at the round's start (as its lowest-indexed robot measured it), or
   after ``rounds`` rounds.

A robot knows nothing of the robots outside its group: their information is not counted
(each group plans as a team of its own; a robot alone plans alone). With one group and
every robot's estimate the central one, the rounds are GSR's sweeps, the stopping test is
GSR's, and the plan is central GSR's (tested to 1e-9).

Each robot's solve is GSR itself (:class:`~activetrack.baselines.gsr.GSR`, one sweep) on
its view with the other robots fixed at their announced plans (reach 0) and those outside
its group silenced (noise variances :data:`SILENT`: an information of 1e-40, below the
rounding of any other), so every problem GSR accepts (several targets, limited sensing,
occluders, separation) is planned the same way, batched over copies (each copy's groups
its own).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from activetrack.baselines._common import sensor_modes
from activetrack.baselines.gsr import GSR, check_parameters, warm_start
from activetrack.models.communication import components
from activetrack.validation import FloatArray
from activetrack.world.problem import PlanningProblem

#: The noise variance of a robot outside the solver's group: its information (about
#: ``1 / SILENT``) changes no sum of informations of order 1e-24 or more.
SILENT = 1e40


def _checked(views: Sequence[PlanningProblem], links: ArrayLike) -> np.ndarray:
    """Return ``links`` as bool (batch + (M, M)) after checking the views against it."""
    if not views or not all(isinstance(v, PlanningProblem) for v in views):
        raise ValueError("views must be a non-empty sequence of PlanningProblem (one per robot)")
    m, shape = views[0].n_sensors, views[0].batch_shape
    if len(views) != m:
        raise ValueError(f"views must hold one problem per robot ({m}), got {len(views)}")
    for i, v in enumerate(views):
        if v.n_sensors != m or v.batch_shape != shape:
            raise ValueError(
                f"views[{i}] must have {m} sensors and batch shape {shape} as views[0], got "
                f"{v.n_sensors} and {v.batch_shape}"
            )
        if not np.array_equal(v.sensors, views[0].sensors):
            raise ValueError(f"views[{i}] must hold the team's sensors as views[0] does")
    arr = np.asarray(links)
    if arr.dtype != np.bool_ or arr.shape != shape + (m, m):
        raise ValueError(f"links must be a bool array of shape {shape + (m, m)}, got {arr.shape}")
    return arr


def _same(a: PlanningProblem, b: PlanningProblem) -> bool:
    """Return whether two robots' views hold the same prediction of every target."""
    pa, pb = a.prediction, b.prediction
    if pa is None or pb is None:
        return np.array_equal(a.target, b.target) and np.array_equal(a.prior_cov, b.prior_cov)
    pa, pb = (pa, pb) if isinstance(pa, tuple) else ((pa,), (pb,))
    pairs = zip(pa, pb, strict=True)
    return all(np.array_equal(x.mean, y.mean) and np.array_equal(x.cov, y.cov) for x, y in pairs)


class DistributedGSR:
    """GSR by message passing inside each connected group (see the module's text).

    Args:
        tol: a group stops after a round whose improvements add up to at most ``tol`` times
            its objective, in [0, 1) (GSR's).
        rounds: at most this many rounds per step (>= 1); GSR's ``max_sweeps`` (100) by
            default, so that with full communication the plan is GSR's.
        connection: which links join robots into a group: ``"strong"`` (each reaches the
            other along received links: the announced plans reach every member) or
            ``"weak"``.
        shortcut: with every link up and every robot's view the same, run the rounds as
            GSR's own sweeps (:class:`~activetrack.baselines.gsr.GSR`, bit for bit);
            ``False`` always passes the messages robot by robot.
    """

    def __init__(
        self,
        tol: float = 1e-9,
        rounds: int = 100,
        connection: str = "strong",
        shortcut: bool = True,
    ) -> None:
        check_parameters(tol, 1)
        if isinstance(rounds, bool) or not isinstance(rounds, (int, np.integer)) or rounds < 1:
            raise ValueError(f"rounds must be an integer >= 1, got {rounds!r}")
        self.tol, self.rounds = float(tol), int(rounds)
        if connection not in ("weak", "strong"):
            raise ValueError(f"connection must be one of ['weak', 'strong'], got {connection!r}")
        self.connection = connection
        self.shortcut = bool(shortcut)
        self._solver = GSR(tol=self.tol, max_sweeps=1)
        #: The rounds each copy's groups ran in the latest :meth:`plan` (batch + (M,), by robot).
        self.last_rounds: np.ndarray | None = None

    def plan(self, problem: PlanningProblem, rng: np.random.Generator | None = None) -> FloatArray:
        """Return the team's next absolute positions for a world's planning problem,
        batch + (M, 2): a decentralized team's
        (:class:`~activetrack.world.team_problem.TeamProblem`) by its robots' own
        predictions and links, a central team's as one group sharing its estimate (no
        ``rng``: deterministic)."""
        team = getattr(problem, "team", None)
        if team is None:
            m = problem.n_sensors
            return self.plan_views([problem] * m, np.ones(problem.batch_shape + (m, m), bool))
        return self.plan_views(team.views(problem), team.links)

    def plan_views(self, views: Sequence[PlanningProblem], links: ArrayLike) -> FloatArray:
        """Return the team's next absolute positions, batch + (M, 2).

        ``views[i]`` is the step's planning problem as robot ``i`` sees it (its own
        prediction of every target; the team's sensors, reaches and rules); ``links`` the
        step's link matrix, bool batch + (M, M) (row: receiver).
        """
        link = _checked(views, links)
        m, shape = views[0].n_sensors, views[0].batch_shape
        if self.shortcut and link.all() and all(_same(v, views[0]) for v in views[1:]):
            # One group sharing one estimate: its rounds are GSR's sweeps, message for
            # message; GSR's own kernel runs them (its plan bit for bit).
            self.last_rounds = None
            return GSR(tol=self.tol, max_sweeps=self.rounds).plan(views[0])
        _, labels = components(link, self.connection)
        same = labels[..., :, None] == labels[..., None, :]  # (..., M, M): i's group
        plans = self._warm_starts(views)
        running = np.ones(shape + (m,), bool)  # by robot: its group has not stopped
        first = np.argmax(same, axis=-1)  # each robot's group's lowest member
        rounds = np.zeros(shape + (m,), np.int64)
        for _ in range(self.rounds):
            if not running.any():
                break
            # Each group's objective at the round's start, as its lowest robot measures it.
            start = np.zeros(shape + (m,))
            for i in np.unique(first):
                start[..., i] = self._view(views, i, same, running, plans).score(plans)
            gain = np.zeros(shape + (m,))
            for i in range(m):
                view = self._view(views, i, same, running, plans)
                before = view.score(plans)
                moved = plans.copy()
                moved[..., i, :] = self._solver.plan(view)[..., i, :]
                after = view.score(moved)
                keep = running[..., i] & (after < before)  # GSR's rule: only if it lowers
                plans[..., i, :] = np.where(keep[..., None], moved[..., i, :], plans[..., i, :])
                gain[..., i] = np.where(keep, before - after, 0.0)
            rounds += running
            # A group's improvement and its objective at the round's start (its lowest robot's).
            total = np.einsum("...ij,...j->...i", same.astype(float), gain)
            f0 = np.take_along_axis(start, first, axis=-1)
            running &= ~(total <= self.tol * f0)
        self.last_rounds = rounds
        return plans

    def _view(
        self,
        views: Sequence[PlanningProblem],
        i: int,
        same: np.ndarray,
        running: np.ndarray,
        plans: FloatArray,
    ) -> PlanningProblem:
        """Return robot ``i``'s problem: its view with the others fixed at their announced
        ``plans``, itself free from where it is (only where its group still runs), and the
        robots outside its group silenced."""
        v = views[i]
        sensors = plans.copy()
        sensors[..., i, :] = v.sensors[..., i, :]
        shape, m = v.batch_shape, v.n_sensors
        r = np.zeros(shape + (m,))
        r[..., i] = np.where(running[..., i], np.broadcast_to(v.r, shape + (m,))[..., i], 0.0)
        out = same[..., i, :]
        sd2 = np.where(out, np.broadcast_to(v.sigma_d2, shape + (m,)), SILENT)
        st2 = np.where(out, np.broadcast_to(v.sigma_theta2, shape + (m,)), SILENT)
        return dataclasses.replace(v, sensors=sensors, r=r, sigma_d2=sd2, sigma_theta2=st2)

    def _warm_starts(self, views: Sequence[PlanningProblem]) -> FloatArray:
        """Return every robot's announced warm start (GSR's, on its own view), batch + (M, 2)."""
        plans = np.array(views[0].sensors, np.float64)
        for i, v in enumerate(views):
            free, fixed_rel = sensor_modes(v)
            anchor = v.targets[..., 0, :]
            s, _ = warm_start(v.sensors - anchor[..., None, :], v.r, v.rho, free, fixed_rel)
            plans[..., i, :] = s[..., i, :] + anchor
        return plans
