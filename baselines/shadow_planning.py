"""Planning from one filter's prediction while another filter keeps the score.

The question of issue 38's IMM item: does a planner do better when it plans from the
prediction of the filter that knows the target turns (the IMM's mixture, eq. 3 per mode
then mixed) than from a single-model filter's (the constant-velocity EKF of eqs. 3-6)?
Scoring each team with its own filter cannot say: the single-model EKF understates its
error on a turning target (its mean NEES is above its band), so its smaller trace is not
less uncertainty. Here both teams are scored by the same honest filter.

:func:`shadowed_run` steps two worlds of the same scenario and seeds in lockstep: the
*planning* world (for example with the EKF) moves its sensors as that team would: the
planner plans from its problem and the world keeps them out of the ``rho`` disk about its
own predicted target. The *scoring* world (for example with the IMM) is built with
``rho = 0`` and moved to the planning world's realized sensor positions (within reach by
construction), so it only observes. Each copy's target draws from its own generator and
the measurement noise comes from the copy's stream whatever the filter, so both worlds
hold the same targets and sensors and their filters process the same measurements; every
step checks it (true states, sensor positions and each copy's generator state). With
``plan_estimator=None`` the planner plans from the scoring world itself (one world, its
own ``rho``). The scoring world's posterior traces and errors are the result.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from activetrack.world import World


@dataclass(frozen=True)
class ShadowedRun:
    """Per-episode results of :func:`shadowed_run`, each (episodes,), of the scoring world.

    ``mean_trace``: the mean over steps of ``tr P(k|k)_11`` (m^2); ``rmse``: the root mean
    square position error over steps (m); ``plan_trace``: the planning world's mean trace
    (its filter's own account; equal to ``mean_trace`` without a planning world).
    """

    mean_trace: np.ndarray
    rmse: np.ndarray
    plan_trace: np.ndarray


def shadowed_run(
    planner: Any,
    scenario: str,
    seeds: list[int],
    score_estimator: Any,
    plan_estimator: Any = None,
    **overrides: Any,
) -> ShadowedRun:
    """Return the scoring world's per-episode results when ``planner`` (an object with
    ``plan(problem) -> positions``) plans from the planning world's problem.

    Both worlds are ``World(scenario, len(seeds), estimator=..., **overrides)`` reset with
    ``seeds`` (the scoring one with ``rho=0`` beside a planning world);
    ``plan_estimator=None`` plans from the scoring world. Raises ValueError if the two
    worlds ever part (the lockstep's premise).
    """
    n = len(seeds)
    if plan_estimator is None:
        score = plan = World(scenario, n, estimator=score_estimator, **overrides)
    else:
        plan = World(scenario, n, estimator=plan_estimator, **overrides)
        score = World(scenario, n, estimator=score_estimator, **{**overrides, "rho": 0.0})
    for world in {id(score): score, id(plan): plan}.values():
        world.reset(seeds=list(seeds))
    traces, errors, plan_traces = [], [], []
    for _ in range(score.scenario.n_steps):
        plan.step(planner.plan(plan.planning_problem()))
        if score is not plan:
            score.step(plan.get("sensors"))
            _check_lockstep(plan, score)
        traces.append(np.array(score.get("trace"), dtype=float))
        errors.append(np.array(score.position_error(), dtype=float))
        plan_traces.append(np.array(plan.get("trace"), dtype=float))
    return ShadowedRun(
        mean_trace=np.mean(traces, axis=0),
        rmse=np.sqrt(np.mean(np.square(errors), axis=0)),
        plan_trace=np.mean(plan_traces, axis=0),
    )


def _check_lockstep(plan: World, score: World) -> None:
    """Raise ValueError unless the two worlds hold the same targets and sensors and every
    copy's generator has made the same draws."""
    same = np.array_equal(plan.get("x_true"), score.get("x_true")) and np.array_equal(
        plan.get("sensors"), score.get("sensors")
    )
    same = same and all(
        plan.rng(i).bit_generator.state == score.rng(i).bit_generator.state
        for i in range(plan.num_copies)
    )
    if not same:
        raise ValueError(
            "the two worlds parted (targets, sensors or random draws): they are not in lockstep"
        )
