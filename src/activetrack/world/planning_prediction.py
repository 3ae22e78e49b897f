"""Which prediction a planner plans from: the filter's, or one mode's of an IMM alone.

The world's planning problem carries the filter's prediction (eq. 3): with an IMM
(the scenario field ``estimator``) the moments of its predicted mixture
``sum_j c_j N(x_j(k+1|k), P_j(k+1|k))``, and the mixture mode by mode
(:class:`activetrack.world.prediction.ModePredictions`). A policy's ``prediction``
(:class:`activetrack.baselines.policies.PlannerPolicy`) says which one its planner plans
from; the problem is then :func:`chosen`'s, whatever the planner (GSR, GBES, RM, the
look-ahead, which extrapolates it with the problem's motion model ``Phi``, ``Q``):

- ``"mixture"`` (the default): the problem as the world gives it, the predicted mixture's
  moments (with the EKF, the EKF's prediction): the planners plan against the
  uncertainty the filter actually has;
- ``j`` (an int): mode j's mode-matched prediction ``x_j(k+1|k), P_j(k+1|k)`` alone (the
  IMM's mixing, then eq. 3 with mode j's model), what a planner unaware of the other
  modes would plan from; with :meth:`activetrack.IMMSpec.from_behaviour` of
  :data:`activetrack.world.presets.MANEUVERING` mode 0 is the constant-velocity one. A
  filter without modes (the EKF) is its own single mode: ``0`` is its prediction.

The world itself (its score, rewards, the ``rho`` it keeps from the predicted target) is
unchanged by the choice: only what the planner is shown.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from activetrack.world.problem import PlanningProblem

#: The prediction every planner plans from by default: the filter's (the IMM's mixture).
MIXTURE = "mixture"


def checked(value: object) -> str | int:
    """Return the option ``prediction`` checked: ``"mixture"`` or a mode index (an int
    >= 0; its upper bound, the number of modes, is the problem's: :func:`chosen`), else a
    ValueError naming the field."""
    if isinstance(value, str) and value == MIXTURE:
        return MIXTURE
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        if value >= 0:
            return int(value)
    raise ValueError(
        f"prediction must be {MIXTURE!r} or a mode index, an int >= 0 ({MIXTURE!r}: the "
        f"filter's prediction; j: mode j's alone), got {value!r}"
    )


def chosen(problem: PlanningProblem, prediction: Any) -> PlanningProblem:
    """Return ``problem`` as a planner planning from ``prediction`` (:func:`checked`) sees
    it: the problem itself for ``"mixture"``, else the problem at mode ``prediction``'s
    prediction of every target (its ``target`` and ``prior_cov`` that prediction's position
    blocks; the other fields unchanged). Raises ValueError naming ``prediction`` when the
    problem carries no prediction or the filter has no such mode."""
    prediction = checked(prediction)
    if prediction == MIXTURE:
        return problem
    preds = problem.predictions
    if preds is None:
        raise ValueError(
            f"prediction={prediction} needs a problem that carries the filter's prediction "
            "(World.planning_problem's, or PlanningProblem.from_prediction)"
        )
    out = []
    for k, q in enumerate(preds):
        r = 1 if q.modes is None else q.modes.n_modes
        if prediction >= r:
            whose = f" of target {k}" if problem.multi_target else ""
            raise ValueError(
                f"prediction must be {MIXTURE!r} or a mode index in [0, {r - 1}] (the "
                f"filter{whose} has {r} mode{'s' if r > 1 else ''}), got {prediction}"
            )
        if q.modes is None:  # a single model's filter: its prediction is the mode's
            out.append(q)
            continue
        j = prediction
        out.append(q.with_state(q.modes.means[..., j, :], q.modes.covs[..., j, :, :]))
    return dataclasses.replace(
        problem,
        prior_cov=None,
        target=None,
        prediction=tuple(out) if problem.multi_target else out[0],
    )
