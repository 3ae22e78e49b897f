"""Which of the paper's special cases a scenario is in: the fast paths, decided once.

The paper's problem (one target, range-and-bearing sensors at known positions, the trace
objective, the EKF of eq. 11) has exact and compiled shortcuts: the analytic solve of
Section IV-A, the paper's observation layout, and a whole world step in one compiled call.
:class:`Capabilities` holds the facts those shortcuts rest on, as named booleans, and
derives from them which shortcut applies; the scenario (:attr:`Scenario.capabilities
<activetrack.world.scenarios.Scenario.capabilities>`), the world, the observation layout
and the planning problem all read it here instead of testing the scenario's fields again.

A planning problem built by hand has no scenario; :attr:`PlanningProblem.is_paper
<activetrack.world.problem.PlanningProblem.is_paper>` applies the same rule,
:func:`paper_problem`, to its own arrays.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from activetrack.kinematics.team import all_disks


def paper_problem(
    one_target: bool,
    range_bearing: bool,
    pose_free_filter: bool,
    unlimited_sensing: bool,
    trace_objective: bool,
    disk_kinematics: bool = True,
) -> bool:
    """Return whether a planning problem is the paper's (Section IV-A's exact solve and the
    planners' paper arithmetic apply): one target, every sensor range-and-bearing, no pose
    noise in the filter, every sensor always measures, the trace objective, every sensor
    moves by a built-in disk."""
    return (
        one_target and range_bearing and pose_free_filter and unlimited_sensing and trace_objective
        and disk_kinematics
    )  # fmt: skip


@dataclass(frozen=True)
class Capabilities:
    """The facts of a scenario the fast paths rest on (each True is the paper's case).

    Attributes:
        one_target: K = 1. With ``unlimited_sensing`` and ``single_update``, the world's
            advance updates one target in one call (:attr:`per_target_update`).
        range_bearing: every sensor measures distance and bearing (eq. 4): the paper's
            observation layout and the planners' paper arithmetic.
        known_poses: the world draws no position fixes (every ``pose_cov`` is zero): the
            sensors are where the team believes; needed by the fused step and the paper's
            layout.
        pose_free_filter: the filter's noise has no pose term (known poses, or
            ``account_pose=False``): the planning problem carries no ``pose_cov``.
        unlimited_sensing: every sensor measures every target at every step (no
            ``max_range``, every ``p_detect`` 1, no occluders): no detection flags.
        no_occluders: no fixed or random occluders: no moves mended around them, no
            range-finder rays in the observation (implied by ``unlimited_sensing``).
        single_update: the EKF of eq. (11) (``filter_iterations == 1``), not the
            iterated one: the fused step's kernel.
        trace_objective: the score is the trace (eq. 17): the reward needs no second
            evaluation of the objective.
        disk_kinematics: every sensor moves by a built-in
            :class:`activetrack.kinematics.disk.Disk` (``vmax dt``): the compiled moves; else
            the world moves by each kinematics (:class:`activetrack.kinematics.team.TeamMotion`).
        builtin_sensors: every sensor's model is a built-in (:attr:`activetrack.SensorModel.code`):
            the compiled measurement and filter kernels; else the generic NumPy path
            (:mod:`activetrack.estimation.generic`) for the world and the planners.
        filter_targets: no ``target_behaviour``: every true target moves by its filter's
            own model (eq. 2), in the compiled step; else the world moves each by its
            behaviour (:mod:`activetrack.world.behaviours`), stage by stage.
        no_separation: ``d_sep`` is 0: no team rule; else the world's moves go through
            :class:`activetrack.kinematics.separation.Separation`, stage by stage.
        central_filter: no ``communication`` model: one central filter; else a filter per
            robot too (:mod:`activetrack.world.team_filters`), stage by stage.
    """

    one_target: bool
    range_bearing: bool
    known_poses: bool
    pose_free_filter: bool
    unlimited_sensing: bool
    no_occluders: bool
    single_update: bool
    trace_objective: bool
    disk_kinematics: bool = True
    builtin_sensors: bool = True
    filter_targets: bool = True
    no_separation: bool = True
    central_filter: bool = True

    @classmethod
    def of(cls, sc: Any) -> Capabilities:
        """Return the capabilities of scenario ``sc`` (an :class:`activetrack.Scenario`)."""
        known = sc.pose_covariances is None
        return cls(
            one_target=sc.n_targets == 1,
            range_bearing=sc.sensor_model == "range_bearing",  # (one name when all agree)
            known_poses=known,
            pose_free_filter=known or not sc.account_pose,
            unlimited_sensing=not sc.limited_sensing,
            no_occluders=not sc.has_occluders,
            single_update=sc.filter_iterations == 1,
            trace_objective=sc.objective == "trace",
            disk_kinematics=sc.kinematics is None or all_disks(sc.kinematics_models),
            builtin_sensors=all(m.builtin for m in sc.sensor_objects),
            filter_targets=sc.target_behaviour is None,
            no_separation=not any(np.atleast_1d(sc.d_sep)),
            central_filter=sc.communication is None,
        )

    @property
    def paper_problem(self) -> bool:
        """Whether the world's planning problem is the paper's (:func:`paper_problem`)."""
        return paper_problem(
            self.one_target,
            self.range_bearing,
            self.pose_free_filter,
            self.unlimited_sensing,
            self.trace_objective,
            self.disk_kinematics,
        )

    @property
    def paper_model(self) -> bool:
        """Whether the whole measurement setup is the paper's: its planning problem, known
        poses and the EKF of eq. (11) (``Scenario.is_paper_model``)."""
        return self.paper_problem and self.known_poses and self.single_update

    @property
    def paper_observation(self) -> bool:
        """Whether the observation has the paper's layout (``D = 5 + 6M``; else the
        extended one): one target, range-and-bearing sensors at known positions, every
        sensor always measures."""
        return (
            self.one_target and self.range_bearing and self.known_poses and self.unlimited_sensing
        )

    @property
    def per_target_update(self) -> bool:
        """Whether the world's advance moves, measures and filters the one target in one
        call (:func:`activetrack.world.tracking.advance_target`), not stage by stage."""
        return (
            self.one_target and self.unlimited_sensing and self.single_update
            and self.filter_targets and self.central_filter
        )  # fmt: skip

    @property
    def fused_step(self) -> bool:
        """Whether a whole world step (move, advance, score, predict; with one copy also
        the observation) is one compiled call (:mod:`activetrack.world._loop_kernels`):
        :attr:`per_target_update` with known poses and built-in sensor models, no team
        rule. A team that does not move by disks moves first, by its kinematics
        (:func:`activetrack.world._fast.team_moves`), and the compiled call takes those
        positions as they are: the same numbers as the stage-by-stage step."""
        return (
            self.per_target_update and self.known_poses and self.builtin_sensors
            and self.no_separation
        )  # fmt: skip
