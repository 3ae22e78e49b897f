"""A filter per robot: decentralized tracking over a communication model (issue 37).

The scenario field ``communication`` (:mod:`activetrack.models.communication`) chooses who
hears whom each step. ``None`` (the default) is today's world: one central filter, no
per-robot filters, no extra random draws, the compiled paths bit for bit. With a model
(:class:`~activetrack.FullCommunication` included) every robot ``i`` also keeps its own
estimate of every target, on an extra robot axis: ``x`` (N, M, n) and ``P`` (N, M, n, n)
per target, and the world still runs its central filter (the global state for centralized
critics, the planners, the ``rho`` disks and ``max_trace``).

The links of a step come from the sensors' true positions after the move
(:meth:`~activetrack.CommunicationModel.links_from_draws`, with the episode's occluders for
line of sight); a model's drop draws come from a generator per copy spawned at reset from
the copy's stream (:meth:`numpy.random.Generator.spawn` does not advance it, so every other
draw of the copy is what it was). Two ways to use the links (the field ``team_fusion``):

``"measurements"`` (measurement sharing, the default). Robot ``i`` updates with every
measurement it has of the step: its own and those of the robots ``j`` with
``links[i, j]`` (and, with limited sensing, that detected the target), in one EKF update
(:func:`activetrack.world.tracking.filter_update`, the central filter's code). With
:class:`~activetrack.FullCommunication` every row of the links is True and every robot's
update is the central one on the same numbers: every robot's estimate equals the central
filter's bit for bit. With a delay ``d`` (whole steps) the neighbours' measurements of step
``s`` arrive at step ``s + d``. The rule (a short history, re-run): each robot keeps a
*settled* estimate, the filter of every measurement it has of steps up to ``t - d``
(complete: by step ``t`` everything sent at ``t - d`` has arrived); at step ``t`` it
settles step ``t - d`` (predict, update with its own and the delivered measurements of
that step) and then re-runs steps ``t - d + 1 .. t`` from it with its own measurements
alone (kept ``d`` steps). So an out-of-sequence measurement is always processed in time
order, before the later ones, and the result is exactly the filter that had received
everything in time. Its measurements of ``t - d + 1 .. t`` are used once, in the re-run,
and again (with the neighbours') when settled: never twice in one estimate.

``"covariance_intersection"`` (estimate sharing, the documented second option). Robot
``i`` updates its estimate with its own measurement alone, then fuses it with the
estimates it receives (each neighbour's own-updated estimate of the step it sent, predicted
``d`` steps by the motion model) by covariance intersection (Julier & Uhlmann 1997:
``P^{-1} = sum_j w_j P_j^{-1}``, consistent under any correlation for weights on the
simplex; :mod:`activetrack.estimation.fusion`). The weights are the *fast* CI's
(Niehsen 2002), ``w_j`` proportional to ``1 / tr P_j``, closed form and batched: any
weights on the simplex keep CI consistent, so they affect how small the fused covariance
is, never its consistency (:func:`ci_fuse`).

The reward and the metrics of robot ``i`` use its own estimate (:meth:`TeamTracking.
robot_scores`); the team's metrics (:meth:`TeamTracking.team_metrics`) are the mean and
the worst (largest) robot score and the *disagreement*: the root mean square distance of
the robots' position estimates from their mean, averaged over targets (metres; 0 when
every robot agrees).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from activetrack.models.communication import CommunicationModel, RangeLimited
from activetrack.models.motion import predict
from activetrack.models.objective import combined
from activetrack.validation import FloatArray

#: The values of the scenario field ``team_fusion``.
FUSIONS = ("measurements", "covariance_intersection")
#: Robots and targets the team filters are sized for (the ``swarm`` task: 32 and 8).
MAX_ROBOTS, MAX_TARGETS = 64, 16


def converted(value: object, sc: Any) -> CommunicationModel | None:
    """Return the scenario field ``communication`` checked: None, a
    :class:`~activetrack.CommunicationModel`, or a record ``{"name": "RangeLimited",
    "range": ..., "drop": ..., "delay": ..., "line_of_sight": ...}`` /
    ``{"name": "FullCommunication"}`` (what :func:`record` writes); its delay must be
    shorter than the episode (``sc`` the scenario, its other fields converted). Else a
    ValueError naming the field."""
    from activetrack.models.communication import FullCommunication  # noqa: PLC0415

    if value is None:
        return None
    if isinstance(value, dict):
        rest = dict(value)
        name = rest.pop("name", None)
        try:
            if name == "FullCommunication" and not rest:
                value = FullCommunication()
            elif name == "RangeLimited":
                value = RangeLimited(**rest)
            else:
                raise ValueError(
                    f"a record's name must be 'FullCommunication' or 'RangeLimited', got {name!r}"
                )
        except TypeError as exc:
            raise ValueError(f"communication: {exc}") from None
        except ValueError as exc:
            raise ValueError(f"communication: {exc}") from None
    if not isinstance(value, CommunicationModel):
        raise ValueError(
            "communication must be None (one central filter), an activetrack."
            f"CommunicationModel or its record, got {value!r}"
        )
    try:
        value.check(sc.n_steps)
    except ValueError as exc:
        raise ValueError(f"communication: {exc}") from None
    if sc.estimator != "ekf":
        raise ValueError(
            f"communication needs estimator='ekf' (one EKF per robot), got {sc.estimator!r}"
        )
    if sc.n_sensors > MAX_ROBOTS or sc.n_targets > MAX_TARGETS:
        raise ValueError(
            f"communication: a filter per robot is sized for at most {MAX_ROBOTS} robots "
            f"and {MAX_TARGETS} targets, got n_sensors={sc.n_sensors}, n_targets={sc.n_targets}"
        )
    return value


def check_fields(sc: Any, put: Any) -> None:
    """Check and convert the scenario's fields ``communication``, ``team_fusion`` and
    ``team_observation`` (``put(name, value)`` stores one), or raise a ValueError naming
    the field."""
    put("communication", converted(sc.communication, sc))
    if not isinstance(sc.team_fusion, str) or sc.team_fusion not in FUSIONS:
        raise ValueError(f"team_fusion must be one of {list(FUSIONS)}, got {sc.team_fusion!r}")
    if not isinstance(sc.team_observation, (bool, np.bool_)):
        raise ValueError(f"team_observation must be True or False, got {sc.team_observation!r}")
    put("team_observation", bool(sc.team_observation))
    if sc.team_observation and sc.communication is None:
        raise ValueError("team_observation needs a communication model (the field communication)")


def record(value: CommunicationModel | None) -> dict | None:
    """Return a JSON record of a communication model (None stays None)."""
    if value is None:
        return None
    if isinstance(value, RangeLimited):
        return {"name": "RangeLimited", "range": value.range, "drop": value.drop,
                "delay": value.delay, "line_of_sight": value.line_of_sight}  # fmt: skip
    return {"name": value.name}


def ci_fuse(x: FloatArray, P: FloatArray, links: np.ndarray) -> tuple[FloatArray, FloatArray]:
    """Return every robot's covariance-intersection fusion of the estimates it receives.

    ``x`` (..., R, n) and ``P`` (..., R, n, n) SPD the robots' estimates of one target,
    ``links`` (..., R, R) bool, ``[i, j]`` robot ``i`` receives ``j`` (the diagonal True).
    Robot ``i``'s fusion: ``Y_i = sum_j w_ij P_j^{-1}``, ``P_i = Y_i^{-1}``, ``x_i = P_i
    sum_j w_ij P_j^{-1} x_j``, with the fast CI weights ``w_ij`` proportional to
    ``links[i, j] / tr P_j`` and summing to 1 over ``j``. Returns ``(x_fused, P_fused)``
    of the shapes of ``x`` and ``P`` (a robot that receives no one keeps its estimate).
    """
    n = x.shape[-1]
    Y = np.linalg.inv(P)
    Y = 0.5 * (Y + np.swapaxes(Y, -1, -2))
    a = 1.0 / np.trace(P, axis1=-2, axis2=-1)  # (..., R)
    W = links * a[..., None, :]
    W = W / W.sum(axis=-1, keepdims=True)
    lead = Y.shape[:-2]
    Yf = (W @ Y.reshape(lead + (n * n,))).reshape(lead + (n, n))
    yf = W @ np.einsum("...ij,...j->...i", Y, x)
    Pf = np.linalg.inv(Yf)
    Pf = 0.5 * (Pf + np.swapaxes(Pf, -1, -2))
    alone = links.sum(axis=-1) == 1  # keep those exactly (no inverse of an inverse)
    xf = np.where(alone[..., None], x, np.einsum("...ij,...j->...i", Pf, yf))
    return xf, np.where(alone[..., None, None], P, Pf)


def _masks(links: FloatArray, detected: np.ndarray | None, k: int, own: bool) -> np.ndarray:
    """Return which sensors' measurements of target ``k`` each robot uses, (N, R, M)."""
    n, m = links.shape[0], links.shape[-1]
    base = np.broadcast_to(np.eye(m, dtype=bool), (n, m, m)) if own else links
    return base if detected is None else base & detected[:, None, k, :]


class TeamTracking:
    """The per-robot filters of :class:`activetrack.world.World` (module docstring).

    State, with a leading copies axis N even for one copy: per target ``x_hat``, ``P``
    (posterior) and ``x_pred``, ``P_pred`` (prediction) (N, M, n) / (N, M, n, n); the
    settled prediction and the history of the last ``delay`` steps with a delay;
    ``links`` (N, M, M) of the last step (the identity after a reset).
    """

    def _init_team(self) -> None:
        sc = self.scenario
        self._comm = sc.communication
        #: Whether agents observe decentralized (activetrack.world.team_observation).
        self._team_obs = sc.team_observation
        if self._comm is None:
            return
        if self._team_obs:
            from activetrack.world import team_observation  # noqa: PLC0415 (its own option)

            self._team_constants = team_observation.constants(self)
        n_c, m = self.num_copies, self.n_sensors
        self._team_delay = self._comm.delay
        self._fusion = sc.team_fusion
        self._comm_rngs: list[np.random.Generator | None] = [None] * n_c
        self._robot_filters: list[dict[str, FloatArray]] = []
        for tp, x0, P0 in zip(self.params.targets, self._x0_hats, self._P0s, strict=True):
            xp, Pp = predict(x0, P0, tp.Phi, tp.Q)
            d = {"x_hat": x0, "P": P0, "x_pred": xp, "P_pred": Pp, "s_pred": xp, "s_Ppred": Pp}
            self._robot_filters.append(
                {key: np.broadcast_to(v, (n_c, m, *np.shape(v))).copy() for key, v in d.items()}
            )
        self._team_k = np.zeros(n_c, np.int64)
        self._links = np.broadcast_to(np.eye(m, dtype=bool), (n_c, m, m)).copy()
        self._team_scores = np.zeros((n_c, m))
        h = self._team_delay + 1  # ring of the last delay + 1 steps' data, slot t % h
        kk = self.n_targets
        self._hist = {
            "z": np.zeros((h, n_c, kk, m, 2)),
            "fixes": np.zeros((h, n_c, m, 2)),
            "detected": np.ones((h, n_c, kk, m), bool),
            "links": np.ones((h, n_c, m, m), bool),
            "sent": [np.zeros((h, n_c, m, t.dim)) for t in self.params.targets],
            "sent_P": [np.zeros((h, n_c, m, t.dim, t.dim)) for t in self.params.targets],
        }

    def _reset_team(self, rows: np.ndarray) -> None:
        """Start the copies ``rows``' robot filters at the prior; spawn their link streams."""
        if self._comm is None:
            return
        for k, t in enumerate(self._robot_filters):
            x0, P0 = self._x0_hats[k], self._P0s[k]
            xp, Pp = predict(x0, P0, self.params.targets[k].Phi, self.params.targets[k].Q)
            for key, v in zip(t, (x0, P0, xp, Pp, xp, Pp), strict=True):
                t[key][rows] = v
        self._team_k[rows] = 0
        self._links[rows] = np.eye(self.n_sensors, dtype=bool)
        self._team_scores[rows] = (
            float(self._s["score"]) if self._one else self._s["score"][rows, None]
        )
        for i in rows.tolist():
            self._comm_rngs[i] = self.rng(i).spawn(1)[0]

    def _draw_links(self, sensors: FloatArray, rows: np.ndarray) -> np.ndarray:
        """Return the step's link matrices (N, M, M): drawn for the copies ``rows`` (their
        spawned streams advance), the identity for the others."""
        m = self.n_sensors
        n = self._comm.n_draws(m)
        draws = None
        if n:
            draws = np.zeros((self.num_copies, n))
            for i in rows.tolist():
                draws[i] = self._comm_rngs[i].standard_normal(n)
        occ = self._occ if self._comm_uses_occluders() else None
        return self._comm.links_from_draws(sensors, draws, occ)

    def _comm_uses_occluders(self) -> bool:
        return bool(getattr(self._comm, "line_of_sight", False)) and self._occ is not None

    def _team_step(self, z: FloatArray, fixes: FloatArray, detected: Any, sensors: FloatArray,
                   sel: Any) -> None:  # fmt: skip
        """Advance every robot's filters by the step's measurements ``z`` (..., K, M, 2) at
        ``fixes`` (..., M, 2), ``detected`` (..., K, M) or None, the sensors' true
        positions ``sensors`` (..., M, 2); only the copies ``sel`` keep the result."""
        if self._comm is None:
            return
        if self._one:
            z, fixes, sensors = z[None], fixes[None], sensors[None]
            detected = None if detected is None else detected[None]
        rows = self._rows(sel)
        go = np.zeros(self.num_copies, bool)
        go[rows] = True
        links = self._draw_links(sensors, rows)
        h, d = self._team_delay + 1, self._team_delay
        t = self._team_k + 1  # each copy's step index
        slot = t % h
        ix = np.arange(self.num_copies)
        hist = self._hist
        for key, v in (("z", z), ("fixes", fixes), ("links", links)):
            hist[key][slot[go], ix[go]] = v[go]
        if detected is not None:
            hist["detected"][slot[go], ix[go]] = detected[go]
        p = self.params
        new = []
        for k, (tm, tp) in enumerate(zip(self._robot_filters, p.targets, strict=True)):
            if self._fusion == "measurements":
                out = self._shared_measurements(k, tm, tp, t, d, h, ix)
            else:
                out = self._shared_estimates(k, tm, tp, z, fixes, detected, links, t, d, h, ix, go)
            new.append(out)
        for tm, out in zip(self._robot_filters, new, strict=True):
            for key, v in out.items():
                tm[key][go] = v[go]
        self._links[go] = links[go]
        self._team_k[go] = t[go]
        scores = self._robot_scores_now()
        self._team_scores[go] = scores[go]

    def _data(self, s: np.ndarray, ix: np.ndarray, k: int):
        """Return step ``s``'s (per copy) ``(z (N, M, 2), fixes, detected (N, K, M), links)``."""
        hist, h = self._hist, self._team_delay + 1
        sl = s % h
        return (hist["z"][sl, ix, k], hist["fixes"][sl, ix], hist["detected"][sl, ix],
                hist["links"][sl, ix])  # fmt: skip

    def _update(self, x: FloatArray, P: FloatArray, z: FloatArray, fixes: FloatArray,
                mask: np.ndarray) -> tuple[FloatArray, FloatArray]:  # fmt: skip
        """Return every robot's EKF update (the central filter's code, robots as a batch
        axis): ``x`` (N, R, n), ``z`` (N, M, 2), ``fixes`` (N, M, 2), ``mask`` (N, R, M)."""
        from activetrack.world.tracking import filter_update  # noqa: PLC0415 (no cycle)

        r = x.shape[1]
        zz = np.broadcast_to(z[:, None], (z.shape[0], r) + z.shape[1:])
        ff = np.broadcast_to(fixes[:, None], (fixes.shape[0], r) + fixes.shape[1:])
        return filter_update(self.params, x, P, zz, ff, mask)

    def _shared_measurements(self, k, tm, tp, t, d, h, ix) -> dict[str, FloatArray]:
        """One step of measurement sharing for target ``k`` (module docstring's rule)."""
        limited = self._limited
        # Settle step t - d where it exists (t > d): own + delivered measurements.
        settle = t - d >= 1
        sx, sP = tm["s_pred"], tm["s_Ppred"]
        z, f, det, lk = self._data(np.maximum(t - d, 1), ix, k)
        mask = _masks(lk, det if limited else None, k, own=False)
        ux, uP = self._update(sx, sP, z, f, mask)
        nx, nP = predict(ux, uP, tp.Phi, tp.Q)
        c1, c2 = settle[:, None, None], settle[:, None, None, None]
        s_pred, s_Ppred = np.where(c1, nx, sx), np.where(c2, nP, sP)
        if d == 0:
            return {"x_hat": ux, "P": uP, "x_pred": nx, "P_pred": nP, "s_pred": nx, "s_Ppred": nP}
        x, P = s_pred, s_Ppred  # re-run steps t - d + 1 .. t with the robot's own
        post_x, post_P = x, P
        for r in range(d):
            s = t - d + 1 + r
            act = s >= 1
            z, f, det, lk = self._data(np.maximum(s, 1), ix, k)
            ux, uP = self._update(x, P, z, f, _masks(lk, det if limited else None, k, own=True))
            a1, a2 = act[:, None, None], act[:, None, None, None]
            post_x, post_P = np.where(a1, ux, post_x), np.where(a2, uP, post_P)
            if r < d - 1:
                px, pP = predict(ux, uP, tp.Phi, tp.Q)
                x, P = np.where(a1, px, x), np.where(a2, pP, P)
        xp, Pp = predict(post_x, post_P, tp.Phi, tp.Q)
        return {"x_hat": post_x, "P": post_P, "x_pred": xp, "P_pred": Pp, "s_pred": s_pred,
                "s_Ppred": s_Ppred}  # fmt: skip

    def _shared_estimates(self, k, tm, tp, z, fixes, detected, links, t, d, h, ix, go):
        """One step of estimate sharing (covariance intersection) for target ``k``."""
        own = _masks(links, detected, k, own=True)
        lx, lP = self._update(tm["x_pred"], tm["P_pred"], z[:, k], fixes, own)
        hist = self._hist
        slot = t % h
        hist["sent"][k][slot[go], ix[go]] = lx[go]
        hist["sent_P"][k][slot[go], ix[go]] = lP[go]
        if d == 0:
            rx, rP, rl = lx, lP, links
        else:  # what was sent at t - d (none before), predicted d steps
            old = np.maximum(t - d, 1) % h
            rx, rP = hist["sent"][k][old, ix], hist["sent_P"][k][old, ix]
            for _ in range(d):
                rx, rP = predict(rx, rP, tp.Phi, tp.Q)
            eye = np.eye(self.n_sensors, dtype=bool)
            rl = np.where((t - d >= 1)[:, None, None], hist["links"][old, ix], eye)
            rl = rl & ~eye  # the received ones; the robot's own is this step's
        if d == 0:
            fx, fP = ci_fuse(rx, rP, rl)
        else:
            # Each robot fuses [its own, the R received]: (N, R, 1 + R) estimates.
            shape = lx.shape[:2]
            allx = np.concatenate(
                [lx[:, :, None], np.broadcast_to(rx[:, None], shape + rx.shape[1:])], 2
            )
            allP = np.concatenate(
                [lP[:, :, None], np.broadcast_to(rP[:, None], shape + rP.shape[1:])], 2
            )
            lk = np.concatenate([np.ones(rl.shape[:2] + (1,), bool), rl], 2)  # (N, R, 1 + R)
            fx, fP = _ci_rows(allx, allP, lk)
        xp, Pp = predict(fx, fP, tp.Phi, tp.Q)
        return {"x_hat": fx, "P": fP, "x_pred": xp, "P_pred": Pp}

    def _robot_scores_now(self) -> FloatArray:
        """Return each robot's score (N, M): the objective over its own posteriors."""
        if self._plain:
            return sum(t["P"][..., 0, 0] + t["P"][..., 1, 1] for t in self._robot_filters)
        vals = np.stack([self.objective.of_covariance(t["P"]) for t in self._robot_filters], -1)
        return combined(self.objective, vals)

    # Readers -------------------------------------------------------------------------
    def observation_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Return float32 ``(low, high)`` of one agent's observation: the layout's
        (:meth:`activetrack.world.observation.Layout.bounds`), or with ``team_observation``
        the decentralized one's (:func:`activetrack.world.team_observation.bounds`)."""
        if not self._team_obs:
            return self.layout.bounds(self.length_scale)
        from activetrack.world import team_observation  # noqa: PLC0415 (its own option)

        return team_observation.bounds(self)

    def team_info(self, index: int) -> dict[str, list[float] | float]:
        """Return copy ``index``'s per-robot and team figures for an environment's infos:
        ``robot_score`` (M,) and :meth:`team_metrics` (empty without communication)."""
        if self._comm is None:
            return {}
        return {"robot_score": self._team_scores[index].tolist(), **self.team_metrics(index)}

    @property
    def decentralized(self) -> bool:
        """Whether the world keeps a filter per robot (a ``communication`` model is set)."""
        return self._comm is not None

    def _need_team(self) -> None:
        if self._comm is None:
            raise RuntimeError(
                "this world has one central filter: set the scenario field communication "
                "for a filter per robot"
            )

    def team_get(self, name: str, index: int | None = None, target: int = 0) -> FloatArray:
        """Return every robot's ``x_hat``, ``P``, ``x_pred`` or ``P_pred`` of target
        ``target``: (N, M, ...) for all copies, (M, ...) for copy ``index``."""
        self._need_team()
        if name not in ("x_hat", "P", "x_pred", "P_pred"):
            raise ValueError(
                f"name must be one of ['x_hat', 'P', 'x_pred', 'P_pred'], got {name!r}"
            )
        v = self._robot_filters[target][name]
        return v if index is None else v[index]

    def links(self, index: int | None = None) -> np.ndarray:
        """Return the last step's link matrices (N, M, M) (or copy ``index``'s (M, M))."""
        self._need_team()
        return self._links if index is None else self._links[index]

    def robot_scores(self, index: int | None = None) -> FloatArray:
        """Return each robot's score on its own estimate (N, M) (copy ``index``: (M,)); the
        robot's reward is ``-reward_scale`` times it."""
        self._need_team()
        return self._team_scores if index is None else self._team_scores[index]

    def team_metrics(self, index: int | None = None) -> dict[str, Any]:
        """Return the team's metrics (module docstring): ``robot_score_mean``,
        ``robot_score_worst`` and ``disagreement`` (m), each (N,) or a float for copy
        ``index``."""
        self._need_team()
        s = self._team_scores
        spread = []
        for t in self._robot_filters:
            pos = t["x_hat"][..., :2]
            # (the mean square distance from the mean is half the mean square distance
            # between pairs: exactly 0 when every robot agrees)
            d = pos[..., :, None, :] - pos[..., None, :, :]
            spread.append(np.sqrt(0.5 * (d * d).sum(-1).mean(axis=(-2, -1))))
        out = {
            "robot_score_mean": s.mean(-1),
            "robot_score_worst": s.max(-1),
            "disagreement": np.mean(spread, axis=0),
        }
        if index is not None:
            out = {key: float(v[index]) for key, v in out.items()}
        return out


def _ci_rows(x: FloatArray, P: FloatArray, links: np.ndarray):
    """Return :func:`ci_fuse` of robot ``i``'s own list of estimates: ``x`` (N, R, L, n),
    ``P`` (N, R, L, n, n), ``links`` (N, R, L) which of them it uses (the first, its own,
    always)."""
    Y = np.linalg.inv(P)
    Y = 0.5 * (Y + np.swapaxes(Y, -1, -2))
    a = 1.0 / np.trace(P, axis1=-2, axis2=-1)
    W = links * a
    W = W / W.sum(axis=-1, keepdims=True)
    Yf = np.einsum("...l,...lij->...ij", W, Y)
    yf = np.einsum("...l,...lij,...lj->...i", W, Y, x)
    Pf = np.linalg.inv(Yf)
    Pf = 0.5 * (Pf + np.swapaxes(Pf, -1, -2))
    alone = links.sum(axis=-1) == 1
    xf = np.where(alone[..., None], x[..., 0, :], np.einsum("...ij,...j->...i", Pf, yf))
    return xf, np.where(alone[..., None, None], P[..., 0, :, :], Pf)
