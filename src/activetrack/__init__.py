"""activetrack: multi-robot active target tracking with range and bearing sensors.

The core (this package) holds the paper's mathematics and no RL: target motion models
(eq. 1-2), the sensors' measurement models (eq. 4-10; :class:`SensorModel`, the base of a
new one, and the built-ins :class:`RangeBearing`, :class:`RangeOnly`, :class:`BearingOnly`),
the sensors' kinematics (eq. 13-16; :class:`Kinematics`, the base of a new one, the paper's
:class:`Disk`, and robots with a state beyond the position: :class:`Unicycle`, a heading
and a turning limit, and :class:`DoubleIntegrator`, bounded acceleration and speed), the
EKF (eq. 3, 11), the covariance objective (eq. 12, 17-19;
:class:`Objective`, the base of a new one), the analytic single-sensor optimum (Section
IV-A), the planning problem and scenario presets. For decentralized teams (the paper's
motivation: limited communication): the communication model (:class:`CommunicationModel`,
the base of a new one; :class:`FullCommunication`, today's, and :class:`RangeLimited`, a
radio's range, drops, delay and line of sight; :class:`DeliveryQueue` and,
batched, :class:`DelayLine` for delayed messages) and :func:`covariance_intersection`,
fusing estimates of unknown correlation.
The layers ``activetrack.envs``, ``activetrack.baselines`` and ``activetrack.train`` build
on it, in that order.

Importing this package imports none of those layers, nor Gymnasium or PettingZoo, yet it
registers the environment ids (``activetrack/ActiveTracking-v0`` and the tasks) with both:
at once with a framework already imported, else as soon as it is imported
(:mod:`activetrack._registry`). So ``import activetrack`` then
``gymnasium.make("activetrack/ActiveTracking-v0")`` works, as does Gymnasium's
``gymnasium.register_envs(activetrack)``.
"""

import importlib.metadata as _metadata

from activetrack import _aliases, _registry
from activetrack.estimation.ekf import ExtendedKalmanFilter
from activetrack.estimation.fusion import covariance_intersection
from activetrack.estimation.imm import IMMFilter
from activetrack.kinematics.base import Kinematics
from activetrack.kinematics.disk import Disk
from activetrack.kinematics.double_integrator import DoubleIntegrator
from activetrack.kinematics.unicycle import Unicycle
from activetrack.metrics.gospa import GOSPAResult, gospa
from activetrack.models.behaviour import (
    Controlled,
    Evasive,
    FilterModel,
    Maneuvering,
    StopAndGo,
    TargetBehaviour,
)
from activetrack.models.births import BirthProcess
from activetrack.models.communication import (
    CommunicationModel,
    DelayLine,
    DeliveryQueue,
    FullCommunication,
    RangeLimited,
)
from activetrack.models.motion import (
    LinearMotionModel,
    constant_acceleration,
    constant_velocity,
    from_continuous,
    from_matrices,
)
from activetrack.models.objective import (
    LOGDET,
    TRACE,
    WORST_TRACE,
    LogDetObjective,
    Objective,
    TraceObjective,
    WorstTraceObjective,
    lemma2_rotation,
    posterior_position_covariance,
    posterior_trace,
)
from activetrack.models.sensor import BearingOnly, RangeBearing, RangeOnly, SensorModel
from activetrack.solvers.analytic import (
    BatchSolution,
    SingleSensorSolution,
    solve_single_sensor,
    solve_single_sensor_batch,
)
from activetrack.world.imm_tracking import IMMSpec
from activetrack.world.prediction import Prediction
from activetrack.world.presets import PRESETS
from activetrack.world.problem import Planner, PlanningProblem
from activetrack.world.scenarios import Scenario, make_scenario
from activetrack.world.world import World

_aliases.install()

try:
    __version__: str = _metadata.version("activetrack")
except _metadata.PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = [
    "LOGDET",
    "PRESETS",
    "TRACE",
    "WORST_TRACE",
    "BatchSolution",
    "BearingOnly",
    "CommunicationModel",
    "DelayLine",
    "DeliveryQueue",
    "FullCommunication",
    "RangeLimited",
    "covariance_intersection",
    "Disk",
    "Controlled",
    "Evasive",
    "FilterModel",
    "DoubleIntegrator",
    "SingleSensorSolution",
    "StopAndGo",
    "ExtendedKalmanFilter",
    "GOSPAResult",
    "IMMFilter",
    "IMMSpec",
    "Kinematics",
    "LinearMotionModel",
    "LogDetObjective",
    "Maneuvering",
    "Objective",
    "PlanningProblem",
    "Prediction",
    "RangeBearing",
    "RangeOnly",
    "Planner",
    "Scenario",
    "SensorModel",
    "TargetBehaviour",
    "BirthProcess",
    "TraceObjective",
    "World",
    "Unicycle",
    "WorstTraceObjective",
    "constant_acceleration",
    "constant_velocity",
    "from_continuous",
    "from_matrices",
    "gospa",
    "lemma2_rotation",
    "make_scenario",
    "posterior_position_covariance",
    "posterior_trace",
    "solve_single_sensor",
    "solve_single_sensor_batch",
]

_registry.install()
