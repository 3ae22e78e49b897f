"""Random K-target / mixed-model / uncertain-pose problems and an independent boundary
tabulation by dense sampling, shared by the multi-target planner tests."""

from __future__ import annotations

import numpy as np

from activetrack.models.objective import TRACE
from activetrack.world.problem import PlanningProblem


def multi_problem(
    rng: np.random.Generator,
    m: int,
    k: int,
    objective=TRACE,
    *,
    models: bool = True,
    pose: bool = True,
    multi_target: bool = True,
    spread: float = 1.2,
    distance: tuple[float, float] = (1.0, 3.0),
    r: float = 1.0,
    rho: float = 1.2,
) -> PlanningProblem:
    """Return a random problem: K targets in a square of half-side ``spread``, sensors at
    ``distance`` from the origin, random SPD priors, model codes and pose covariances."""
    targets = rng.uniform(-spread, spread, (k, 2))
    a = rng.normal(size=(k, 2, 2))
    prior = a @ a.transpose(0, 2, 1) + 0.3 * np.eye(2)
    ang = rng.uniform(0.0, 2.0 * np.pi, m)
    dist = rng.uniform(*distance, m)
    sensors = dist[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    pose_cov = None
    if pose:
        e = 0.3 * rng.normal(size=(m, 2, 2))
        pose_cov = e @ e.transpose(0, 2, 1)
    if not multi_target:
        assert k == 1
        targets, prior = targets[0], prior[0]
    return PlanningProblem(
        prior,
        targets,
        sensors,
        r,
        rho,
        rng.uniform(0.5, 2.0, m),
        rng.uniform(0.05, 0.5, m),
        objective=objective,
        models=rng.integers(0, 3, m).astype(np.int8) if models else None,
        pose_cov=pose_cov,
        multi_target=multi_target,
    )


def dense_boundary(sensor, r, targets, rho, n=200_000, slack=1e-12):
    """Return ``[(centre, radius, angles, feasible)]``: every circle of the feasible set's
    boundary (the reach circle, then each distinct target's ``rho`` circle) sampled at ``n``
    angles ``2 pi j / n`` with the points that satisfy eq. (15)-(16) for all targets."""
    sensor = np.asarray(sensor, float)
    targets = np.asarray(targets, float)
    theta = 2.0 * np.pi * np.arange(n) / n
    e = np.stack([np.cos(theta), np.sin(theta)], -1)
    out = []
    circles = [(sensor, r, None)]
    for k, t in enumerate(targets):
        if not any(np.array_equal(t, targets[j]) for j in range(k)):
            circles.append((t, rho, k))
    for centre, radius, k in circles:
        pts = centre + radius * e
        gap = np.linalg.norm(pts[:, None, :] - targets[None], axis=-1) - rho  # (n, K)
        if k is not None:
            gap[:, k] = 0.0  # on its own circle
        ok = np.all(gap >= -slack, axis=1)
        ok &= np.linalg.norm(pts - sensor, axis=-1) <= r + slack
        out.append((centre, radius, theta, ok))
    return out
