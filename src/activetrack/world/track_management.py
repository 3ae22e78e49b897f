"""Track management in the world: targets that appear and leave (the field ``births``).

With a :class:`~activetrack.models.births.BirthProcess` the scenario's K targets are slots
(:mod:`activetrack.models.births`): each copy keeps per slot whether a target is
``present`` and whether the team holds a track of it (``tracked``); the arrays keep their
shapes whatever is present. Data association is known (a slot's detections are its
target's), as everywhere in the world. Within the world's step, after the targets move:
departures and births (:mod:`activetrack.models.births`), then the detections (a target
not present is never detected), the EKF update of every slot, then per slot:

- **initiation** (one-point): a slot without a track that is detected this step starts
  one at the inverse of the first detecting sensor's (lowest index) measurement ``(d,
  theta)``: position ``p_S + d (cos(theta + phi), sin(theta + phi))`` with covariance
  ``R(a) diag(sigma_d^2, d^2 sigma_theta^2) R(a)^T`` (``a = theta + phi``, the
  measurement's covariance carried through the inverse to first order, plus the sensor's
  pose covariance the filter accounts for), velocity 0 with variance ``velocity_var`` per
  axis (other sensors' measurements of that step are not used);
- **deletion**: a track not detected for ``delete_after`` steps in a row is dropped (the
  team cannot tell a departed target from a missed one);
- a slot without a track shows a **search point** as its posterior, position variance
  ``search_var``, velocity 0 with ``velocity_var``: what the planners and the observation
  read there, so a team that tracks nothing goes where targets not yet detected most
  likely are. The slots without a track take the cells of highest ``q``
  (:func:`activetrack.models.search_map.search_points`); a cell farther than
  :data:`SEARCH_LEAD` times its nearest sensor's ``max_range`` from that sensor (as the
  team believes it is) is shown at that distance on the way to it: a planner counts a
  sensor's information only within its range, so a point beyond every range would pull
  no sensor, while this one draws the nearest toward the cell step by step.

The score is the objective over the tracks held plus ``search_weight`` times the search
map's expected number of targets not yet detected (:func:`score_of`); ``trace`` (what
``max_trace`` bounds) is over the tracks held. A slot is free for a birth when it has
neither a present target nor a track (:meth:`TrackManagement._arrivals`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.models import search_map
from activetrack.models.motion import predict
from activetrack.models.objective import TRACE, Objective, combined
from activetrack.validation import FloatArray

#: How far (in units of the nearest sensor's max_range) a search point is shown at most.
SEARCH_LEAD = 0.8


def lead_points(
    points: FloatArray, sensors: FloatArray, max_range: FloatArray | None
) -> FloatArray:
    """Return the search points (n, 2) as shown: each point farther than ``SEARCH_LEAD
    max_range_i`` from its nearest sensor ``i`` (of ``sensors`` (M, 2)) moved onto the
    segment from that sensor to it, at that distance (unchanged without a range)."""
    if max_range is None:
        return points
    rel = points[:, None, :] - sensors[None, :, :]
    dist = np.hypot(rel[..., 0], rel[..., 1])  # (n, M)
    near = np.argmin(dist, axis=1)
    d = dist[np.arange(len(points)), near]
    lead = SEARCH_LEAD * np.asarray(max_range, dtype=np.float64)[near]
    far = d > lead
    out = points.copy()
    out[far] = sensors[near[far]] + (lead[far] / d[far])[:, None] * rel[far, near[far]]
    return out


def initiated(
    z: FloatArray,
    sensor: FloatArray,
    orientation: float,
    sigma_d2: float,
    sigma_theta2: float,
    dim: int,
    velocity_var: float,
    pose_cov: FloatArray | None = None,
) -> tuple[FloatArray, FloatArray]:
    """Return a new track's ``(x, P)`` (dim,), (dim, dim) from one range-and-bearing
    measurement ``z = (d, theta)`` of the sensor at ``sensor`` (see the module docstring)."""
    d, theta = float(z[0]), float(z[1])
    a = theta + float(orientation)
    c, s = np.cos(a), np.sin(a)
    x = np.zeros(dim)
    x[:2] = sensor + d * np.array([c, s])
    rot = np.array([[c, -s], [s, c]])
    P = np.zeros((dim, dim))
    P[:2, :2] = rot @ np.diag([sigma_d2, d * d * sigma_theta2]) @ rot.T
    if pose_cov is not None:
        P[:2, :2] += pose_cov
    P[:2, :2] = 0.5 * (P[:2, :2] + P[:2, :2].T)
    idx = np.arange(2, dim)
    P[idx, idx] = velocity_var
    return x, P


def track_rule(
    tracked: bool, last_seen: int, seen: bool, k: int, delete_after: int
) -> tuple[bool, int, bool]:
    """Return ``(tracked, last_seen, initiate)`` after step ``k`` for one slot: a detection
    keeps or starts the track (``initiate`` when it starts one), ``delete_after`` steps
    without one since ``last_seen`` drop it."""
    if seen:
        return True, k, not tracked
    if tracked and k - last_seen >= delete_after:
        return False, last_seen, False
    return tracked, last_seen, False


def score_of(
    objective: Objective, covs: FloatArray, tracked: np.ndarray, missed: FloatArray,
    weight: float,
) -> tuple[FloatArray, FloatArray]:  # fmt: skip
    """Return ``(trace, score)``: the trace over the tracks held and the objective over
    them plus ``weight * missed``, from the posteriors ``covs`` (..., K, n, n), ``tracked``
    (..., K) and ``missed`` (...), the expected number of targets not yet detected."""
    trace = np.sum(np.where(tracked, TRACE.of_covariance(covs), 0.0), axis=-1)
    values = np.where(tracked, objective.of_covariance(covs), 0.0)
    return trace, combined(objective, values) + weight * missed


class TrackManagement:
    """The part of :class:`activetrack.world.World` that runs the births, departures and
    tracks (the module docstring); a no-op without ``births``."""

    def _init_tracks(self) -> None:
        """Set up the per-copy, per-slot masks and the search maps (births only)."""
        b = self._births = self.scenario.births
        if b is None:
            return
        N, K, g = self.num_copies, self.n_targets, b.search_cells
        self._present = np.zeros((N, K), dtype=bool)
        self._tracked = np.zeros((N, K), dtype=bool)
        self._last_seen = np.zeros((N, K), dtype=np.int64)
        self._target_ids = np.full((N, K), -1, dtype=np.int64)
        self._n_born = np.zeros(N, dtype=np.int64)
        self._search_q = np.full((N, g, g), 1.0 / (g * g))
        self._birth_rngs: list[np.random.Generator | None] = [None] * N
        self._cells = search_map.centers(b.region, g)
        self._inflow = search_map.inflow(b)
        self._spread = search_map.spread_fraction(b, self._dt)
        p = self.params
        reach = np.inf if p.max_range is None else float(np.min(p.max_range))
        x0, y0, x1, y1 = b.region
        self._spacing = min(reach, 0.5 * max(x1 - x0, y1 - y0))
        self._step_count = np.zeros(N, dtype=np.int64)

    # What the runners read ----------------------------------------------------------------
    @property
    def present(self) -> np.ndarray | None:
        """Return which slots hold a present target (N, K) bool (a copy), or None without
        births (every target present)."""
        return None if self._births is None else self._present.copy()

    @property
    def tracked(self) -> np.ndarray | None:
        """Return which slots the team holds a track of (N, K) bool (a copy), or None
        without births (every target tracked)."""
        return None if self._births is None else self._tracked.copy()

    @property
    def target_ids(self) -> np.ndarray | None:
        """Return each slot's present target's number in its copy's episode, in order of
        birth from 0 (N, K) int64, -1 where none is present; None without births."""
        return None if self._births is None else self._target_ids.copy()

    @property
    def search_maps(self) -> np.ndarray | None:
        """Return every copy's search map (N, G, G) (a copy), or None without births."""
        return None if self._births is None else self._search_q.copy()

    # Reset and step -----------------------------------------------------------------------
    def _slot(self, key: str, k: int, i: int) -> Any:
        return self._t[k][key] if self._one else self._t[k][key][i]

    def _set(self, key: str, k: int, i: int, value: Any) -> None:
        if self._one:
            self._t[k][key] = np.array(value)
        else:
            self._t[k][key][i] = value

    def _reset_tracks(self, rows: np.ndarray) -> None:
        """Start the copies ``rows`` with no target present and no track."""
        b = self._births
        if b is None:
            return
        g = b.search_cells
        for i in rows.tolist():
            self._birth_rngs[i] = self.rng(i).spawn(1)[0]  # (the stream itself does not move)
            self._present[i] = self._tracked[i] = False
            self._last_seen[i] = 0
            self._target_ids[i] = -1
            self._n_born[i] = 0
            self._step_count[i] = 0
            self._search_q[i] = 1.0 / (g * g)
            posts = [None] * self.n_targets
            self._searching(i, posts, self.get("fixes" if self._pose else "sensors", i))
            for k, (x, P) in enumerate(posts):
                self._store_slot(i, k, x, P)
            trace, score = self._score_row(i)
            if self._one:
                self._s["trace"], self._s["score"] = trace, score
            else:
                self._s["trace"][i], self._s["score"][i] = trace, score

    def _store_slot(self, i: int, k: int, x: FloatArray, P: FloatArray) -> None:
        tp = self.params.targets[k]
        xp, Pp = predict(x, P, tp.Phi, tp.Q)
        for key, v in (("x_hat", x), ("P", P), ("x_pred", xp), ("P_pred", Pp)):
            self._set(key, k, i, v)

    def _searching(self, i: int, posts: list, sensors: FloatArray) -> None:
        """Fill the entries of ``posts`` that are None (slots without a track) with search
        points' posteriors ``(x, P)`` of copy ``i`` whose sensors are at ``sensors`` (M, 2)."""
        empty = [k for k, v in enumerate(posts) if v is None]
        if not empty:
            return
        b = self._births
        pts = search_map.search_points(self._search_q[i], self._cells, len(empty), self._spacing)
        pts = lead_points(pts, np.asarray(sensors).reshape(-1, 2), self.params.max_range)
        for k, pt in zip(empty, pts, strict=True):
            n = self.params.targets[k].dim
            x = np.zeros(n)
            x[:2] = pt
            P = np.diag([b.search_var] * 2 + [b.velocity_var] * (n - 2))
            posts[k] = (x, P)

    def _score_row(self, i: int) -> tuple[float, float]:
        covs = np.stack([self._slot("P", k, i) for k in range(self.n_targets)])
        missed = float(np.sum(self._search_q[i]))
        trace, score = score_of(self.objective, covs, self._tracked[i], missed,
                                self._births.search_weight)  # fmt: skip
        return float(trace), float(score)

    def _arrivals(self, moved: list[FloatArray], sel: Any, calc: Any) -> list[FloatArray]:
        """Apply departures and births to the moved true states ``moved`` (each target's
        (..., n) over the copies ``calc``) of the copies ``sel``, in place; absent targets
        keep their state."""
        b = self._births
        for i in self._rows(sel).tolist():
            at = ... if self._one else i
            rng = self._birth_rngs[i]
            for k, x in enumerate(moved):
                if not self._present[i, k]:
                    x[at] = self._slot("x_true", k, i)
                elif not b.inside(x[at][:2]):
                    self._present[i, k] = False
                    self._target_ids[i, k] = -1
            n = b.count(rng)
            free = np.flatnonzero(~self._present[i] & ~self._tracked[i])[:n]
            if free.size:
                states = b.entry_states(rng, free.size, self.params.targets[0].dim)
                for k, xs in zip(free.tolist(), states, strict=True):
                    dim = moved[k].shape[-1]
                    moved[k][at] = xs[:dim]
                    self._present[i, k] = True
                    self._target_ids[i, k] = self._n_born[i]
                    self._n_born[i] += 1
        return moved

    def _mask_absent(self, detected: np.ndarray) -> np.ndarray:
        """Return the detections (..., K, M) with the slots without a present target off."""
        present = self._present[0] if self._one else self._present
        return detected & present[..., :, None]

    def _manage_tracks(
        self, results: list, z_all: FloatArray, sensors: FloatArray, fixes: FloatArray,
        detected: np.ndarray, sel: Any,
    ) -> None:  # fmt: skip
        """Run the track rules of one step on the copies ``sel`` (the module docstring):
        ``results`` (each slot's ``(x_true, x_post, P_post, x_pred, P_pred)`` over the step's
        copies) is rewritten in place."""
        b, p = self._births, self.params
        for k in range(len(results)):  # fresh arrays: the filter may hand back its inputs
            results[k] = [np.array(a) for a in results[k]]
        pose = p.filter_pose_cov
        for i in self._rows(sel).tolist():
            at = ... if self._one else i
            self._step_count[i] += 1
            step = int(self._step_count[i])
            self._search_q[i] = search_map.step(
                self._search_q[i], self._inflow, self._spread, self._cells, sensors[at],
                p.max_range, p.p_detect,
            )  # fmt: skip
            posts: list = [None] * len(results)
            for k, res in enumerate(results):
                seen = detected[at][k]
                tracked, last, start = track_rule(
                    bool(self._tracked[i, k]), int(self._last_seen[i, k]), bool(seen.any()),
                    step, b.delete_after,
                )  # fmt: skip
                self._tracked[i, k], self._last_seen[i, k] = tracked, last
                if start:
                    j = int(np.flatnonzero(seen)[0])
                    posts[k] = initiated(
                        z_all[at][k, j], fixes[at][j], p.orientation[j], p.sigma_d2[j],
                        p.sigma_theta2[j], res[1].shape[-1], b.velocity_var,
                        None if pose is None else pose[j],
                    )  # fmt: skip
                elif tracked:
                    posts[k] = False  # the filter's update stands
            self._searching(i, posts, fixes[at])
            for k, post in enumerate(posts):
                if post is False:
                    continue
                x, P = post
                tp = p.targets[k]
                xp, Pp = predict(x, P, tp.Phi, tp.Q)
                res = results[k]
                res[1][at], res[2][at], res[3][at], res[4][at] = x, P, xp, Pp

    def _track_score(self, sel: Any) -> tuple[Any, Any]:
        """Return ``(trace, score)`` of the copies ``sel`` after a step (:func:`score_of`)."""
        if self._one:
            return self._score_row(0)
        rows = self._rows(sel)
        pairs = [self._score_row(i) for i in rows.tolist()]
        trace = np.array([t for t, _ in pairs])
        score = np.array([s for _, s in pairs])
        if isinstance(sel, (int, np.integer)):
            return trace[0], score[0]
        return trace, score
