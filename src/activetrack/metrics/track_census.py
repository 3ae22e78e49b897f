"""An episode's multi-target metrics with targets that appear and leave.

:class:`TrackCensus` is fed, after every step of one episode, each slot's presence, track,
target number, true position and estimate (:attr:`activetrack.world.World.present`,
``tracked``, ``target_ids``; :mod:`activetrack.world.track_management`) and returns:

- ``gospa``: the mean over the steps of the GOSPA distance (:func:`activetrack.metrics.gospa.gospa`,
  ``alpha = 2``, cut-off ``c``, order ``p``) between the present targets' positions and
  the held tracks' position estimates;
- ``fraction_tracked``: per target, the fraction of the steps it was present during which
  its slot held a track;
- ``first_detection``: per target, the time (s) from its first step present to its first
  step tracked (its first detection: a track starts there), None if it never was;
- ``all_tracked``: whether every target that entered at least ``grace`` steps before the
  episode's last step was tracked at some step (those that entered later had no fair
  chance and are left out of it).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.metrics.gospa import gospa
from activetrack.validation import check_float, check_int


class TrackCensus:
    """The metrics of one episode (see the module docstring).

    Args:
        dt: the step (s), for the times to first detection.
        c: GOSPA's cut-off (m) > 0; p: its order >= 1.
        grace: steps before the end within which an arrival is left out of
            ``all_tracked``, >= 0.
    """

    def __init__(self, dt: float, c: float = 10.0, p: float = 2.0, grace: int = 50) -> None:
        self.dt = check_float("dt", dt, 0.0, low_open=True)
        self.c = check_float("c", c, 0.0, low_open=True)
        self.p = check_float("p", p, 1.0)
        self.grace = check_int("grace", grace, 0)
        self.distances: list[float] = []
        self.born: dict[int, int] = {}
        self.first: dict[int, int] = {}
        self.present_steps: dict[int, int] = {}
        self.tracked_steps: dict[int, int] = {}
        self.steps = 0

    def add(self, present: Any, tracked: Any, ids: Any, truths: Any, estimates: Any) -> None:
        """Record one step: ``present``, ``tracked`` (K,) bool, ``ids`` (K,) the present
        targets' numbers, ``truths`` and ``estimates`` (K, 2) positions per slot."""
        present, tracked = np.asarray(present, bool), np.asarray(tracked, bool)
        truths, estimates = np.asarray(truths, float), np.asarray(estimates, float)
        self.distances.append(gospa(truths[present], estimates[tracked], self.c, self.p).distance)
        for k in np.flatnonzero(present).tolist():
            i = int(ids[k])
            self.born.setdefault(i, self.steps)
            self.present_steps[i] = self.present_steps.get(i, 0) + 1
            if tracked[k]:
                self.tracked_steps[i] = self.tracked_steps.get(i, 0) + 1
                self.first.setdefault(i, self.steps)
        self.steps += 1

    def summary(self) -> dict[str, Any]:
        """Return ``{"gospa", "fraction_tracked", "first_detection", "all_tracked",
        "n_targets"}`` (lists per target in order of arrival)."""
        ids = sorted(self.born)
        last = self.steps - 1
        counted = [i for i in ids if last - self.born[i] >= self.grace]
        return {
            "gospa": float(np.mean(self.distances)) if self.distances else 0.0,
            "fraction_tracked": [self.tracked_steps.get(i, 0) / self.present_steps[i] for i in ids],
            "first_detection": [
                (self.first[i] - self.born[i]) * self.dt if i in self.first else None for i in ids
            ],
            "all_tracked": all(i in self.first for i in counted),
            "n_targets": len(ids),
        }


def census_of(world: Any, index: int) -> tuple[np.ndarray, ...]:
    """Return copy ``index``'s ``(present, tracked, ids, truths, estimates)`` for
    :meth:`TrackCensus.add` from a world with births (the posterior estimates)."""
    K = world.n_targets
    truths = np.array([world.get("x_true", index, k)[:2] for k in range(K)])
    estimates = np.array([world.get("x_hat", index, k)[:2] for k in range(K)])
    return (world.present[index], world.tracked[index], world.target_ids[index], truths,
            estimates)  # fmt: skip
