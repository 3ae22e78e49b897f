"""A receding-horizon planner: H steps of team motion scored in the deterministic model.

GSR (Section IV-B) minimizes the objective of eq. (17) for the next step only. Under the
EKF linearized at the predicted mean, the covariances a plan produces over H steps are a
deterministic function of the sensors' positions relative to the predicted target path
(:mod:`activetrack.baselines.horizon_model`), so a plan of H steps can be scored exactly
in that model: ``sum_h gamma^h tr P+_11(h)``. :class:`Lookahead` searches plans, executes
the first step and replans at the next step (receding horizon).

The search (:meth:`Lookahead.plan_prediction`), batched over copies and candidates:

1. **Options per sensor**, each a feasible path of H positions (every position within
   reach of the previous one and outside the ``rho`` disks, plus a margin, about that
   step's predicted targets; :class:`~activetrack.baselines.horizon_paths.PathModel`
   mends a move exactly as the world does, occluders included, on every task):

   - GSR's own rollout: GSR planned step after step in the model (option 0);
   - the previous call's plan shifted by one step (warm start, option 1, when given);
   - ``headings`` constant headings at full speed;
   - ``bearings`` target-relative waypoints: full speed towards the point at distance
     ``rho`` (plus margin) from the predicted target in a fixed direction.

2. **Coordinate descent over the team**: starting from the better of GSR's rollout and the
   shifted plan, each sensor in turn takes its best option given the others', for
   ``passes`` passes. Each sensor's paths and information are computed once, so a team
   candidate costs one covariance rollout; the score never increases, so the result is
   never worse in the model than GSR's rollout. With occluders, an option whose move an
   occluder stops inside a ``rho`` disk is not taken (:meth:`PathModel.outside_rho
   <activetrack.baselines.horizon_paths.PathModel.outside_rho>`).

3. **Pair passes**: then, for ``pair_passes`` passes, each pair of sensors in turn takes
   its best joint move among every pair of their options, the others fixed: joint moves
   that one sensor at a time cannot reach are rare but decide some episodes; the score
   still never increases.

Terminal cost: the episode goes on past the horizon, and where the team stands at its
end decides the steps after it (the sensors are no faster than the target in ``paper``,
so distance lost is not made up). Every candidate's last planned step's information is
held for ``tail`` more steps of the covariance rollout, each weighted ``tail_weight``
times the last step's weight: the score is the horizon's traces plus that tail's.

Minimum-distance margin: the true target is not where it is predicted; a sensor placed
on the ``rho`` circle of the predicted target ends inside the true target's ``rho`` disk
when the prediction is off. The planner keeps ``rho + margin * sigma``, with ``sigma`` the
standard deviation of the predicted position along its principal axis, in every option
(GSR's rollout included).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, fields

import numpy as np

from activetrack.baselines import horizon_model as hm
from activetrack.baselines import horizon_paths as hp
from activetrack.baselines.gsr import GSR
from activetrack.baselines.prediction_tracker import PredictionTracker
from activetrack.validation import FloatArray, check_float, check_int
from activetrack.world import World
from activetrack.world.problem import PlanningProblem


@dataclass(frozen=True)
class LookaheadResult:
    """What one :meth:`Lookahead.plan_prediction` call returns (``batch`` = problem batch).

    Attributes:
        positions: next absolute positions, ``batch + (M, 2)``.
        plan: the chosen plan, ``batch + (M, H, 2)`` (``plan[..., 0, :] == positions``).
        score: its model score (the horizon's weighted traces and the tail's), ``batch``.
        gsr_plan: GSR's rollout in the model, ``batch + (M, H, 2)``.
        gsr_score: its model score, ``batch``.
    """

    positions: FloatArray
    plan: FloatArray
    score: FloatArray
    gsr_plan: FloatArray
    gsr_score: FloatArray


#: Largest accepted :func:`_work` of a :class:`Lookahead`'s settings: about 225 times the
#: defaults' (4446), about a second per plan for the paper's three sensors (the pair pass,
#: quadratic in the options, dominates; it grows as M^2 with the team).
WORK_MAX = 1e6


def _work(search: Lookahead) -> float:
    """Return the relative cost of one plan: ``(horizon + tail) x options x (passes +
    pair_passes x options)`` with ``options = headings + bearings + 2`` (stay and the
    warm start)."""
    options = search.headings + search.bearings + 2
    return (search.horizon + search.tail) * options * (search.passes + search.pair_passes * options)


@dataclass
class Lookahead:
    """Receding-horizon planner (see the module docstring).

    Attributes:
        horizon: steps planned, H >= 1 (H = 1 is GSR's problem).
        discount: weight ``gamma^h`` of step h's trace, in (0, 1].
        headings: constant-heading options per sensor (>= 0).
        bearings: target-relative waypoint options per sensor (>= 0).
        passes: coordinate-descent passes over the sensors (>= 0).
        pair_passes: then passes over the pairs of sensors, each pair's best joint move
            among every pair of their options (>= 0).
        tail: steps past the horizon in which the last step's information is held
            (terminal cost, see the module docstring; >= 0, 0: none).
        tail_weight: weight of each tail step relative to the horizon's last, > 0.
        margin: the ``rho`` margin in standard deviations of the predicted position, >= 0.
        gsr_tol, gsr_max_sweeps: GSR's settings for its rollout.
    """

    horizon: int = 10
    discount: float = 1.0
    headings: int = 16
    bearings: int = 0
    passes: int = 1
    pair_passes: int = 1
    tail: int = 3
    tail_weight: float = 2.0
    margin: float = 0.75
    gsr_tol: float = 1e-9
    gsr_max_sweeps: int = 100
    _gsr: object = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        from activetrack.baselines.gsr import GSR

        self.horizon = check_int("horizon", self.horizon, 1, 1000)
        self.discount = check_float("discount", self.discount, 1e-6, 1.0)
        self.headings = check_int("headings", self.headings, 0, 4096)
        self.bearings = check_int("bearings", self.bearings, 0, 4096)
        self.passes = check_int("passes", self.passes, 0, 100)
        self.pair_passes = check_int("pair_passes", self.pair_passes, 0, 100)
        self.tail = check_int("tail", self.tail, 0, 1000)
        self.tail_weight = check_float("tail_weight", self.tail_weight, 1e-6, 1e6)
        self.margin = check_float("margin", self.margin, 0.0, 100.0)
        work = _work(self)
        if work > WORK_MAX:
            raise ValueError(
                f"headings, bearings, horizon, tail, passes and pair_passes: one plan would "
                f"score about {work:.3g} units ((horizon + tail) x options x (passes + "
                f"pair_passes x options), options = headings + bearings + 2), more than "
                f"WORK_MAX={WORK_MAX:g} (about a second per plan for three sensors); "
                "lower headings or bearings first"
            )
        self._gsr = GSR(tol=self.gsr_tol, max_sweeps=self.gsr_max_sweeps)

    # ------------------------------------------------------------------------------
    def plan_prediction(
        self,
        problem: PlanningProblem,
        x_pred: FloatArray | None = None,
        P_pred: FloatArray | None = None,
        Phi: FloatArray | None = None,
        Q: FloatArray | None = None,
        previous: FloatArray | None = None,
        *,
        fresh: np.ndarray | None = None,
    ) -> LookaheadResult:
        """Return the plan for ``problem`` given the full prediction.

        ``x_pred`` (batch + (n,)) and ``P_pred`` (batch + (n, n)) are the prediction
        ``x_hat(k+1|k), P(k+1|k)`` whose position parts are ``problem.target`` and
        ``problem.prior_cov``; ``Phi``, ``Q`` the motion model (eq. 2-3). All four
        ``None`` (the default): ``problem.prediction``'s. ``previous`` (batch + (M, H, 2))
        is the last plan, whose shift by one step is a warm-start option; ``fresh``
        (batch, bool) marks the copies whose ``previous`` is no plan of theirs: they get
        no warm-start option (the plan of a copy is the same alone or in any batch).
        """
        preds = _predictions(problem, x_pred, P_pred, Phi, Q)
        shape, M, H = problem.batch_shape, problem.n_sensors, self.horizon
        B = math.prod(shape)
        model = hp.PathModel(problem)
        start = problem.sensors.reshape(B, M, 2)
        r, rho = problem.r.reshape(B, M), problem.rho.reshape(B, M)
        # Every target's predicted positions, (B, H, K, 2).
        means = np.stack([hm.predicted_means(x, F, H)[..., :2] for x, _, F, _ in preds], axis=2)
        spread = np.max([_principal_std(P[:, :2, :2]) for _, P, _, _ in preds], axis=0)
        rho_eff = rho + self.margin * spread[:, None]
        weights = hm.discount_weights(H, self.discount)
        weights = np.concatenate([weights, np.full(self.tail, self.tail_weight * weights[-1])])

        gsr_paths = self._gsr_rollout(problem, model, preds, means, start, rho_eff)
        options = [gsr_paths[:, :, None]]  # (B, M, 1, H, 2)
        if previous is not None:
            prev = np.asarray(previous, dtype=np.float64).reshape(B, M, -1, 2)
            options.append(hp.shifted_paths(model, prev, start, means, r, rho_eff)[:, :, None])
        if self.headings:
            ang = 2.0 * np.pi * np.arange(self.headings) / self.headings
            dirs = np.stack([np.cos(ang), np.sin(ang)], -1)
            options.append(hp.heading_paths(model, start, means, r, rho_eff, dirs))
        if self.bearings:
            ang = 2.0 * np.pi * (np.arange(self.bearings) + 0.5) / self.bearings
            dirs = np.stack([np.cos(ang), np.sin(ang)], -1)
            options.append(hp.bearing_paths(model, start, means, r, rho_eff, dirs))
        paths = np.concatenate(options, axis=2)  # (B, M, O, H, 2)
        still = r <= 0.0  # a sensor that cannot move has one option: stay
        if np.any(still):
            paths = np.where(still[:, :, None, None, None], gsr_paths[:, :, None], paths)
        valid = model.outside_rho(paths, means, rho_eff)  # (B, M, O)
        valid[:, :, 0] = True  # GSR's rollout: its solver's candidates keep rho
        if previous is not None and fresh is not None:  # no warm start: as if not offered
            valid[np.asarray(fresh, dtype=bool).reshape(B), :, 1] = False
        info, scorer = self._scoring(model, paths, means, preds, weights, problem.objective)
        if self.tail:  # the last step's information held past the horizon (terminal cost)
            info = [np.concatenate([Y, np.repeat(Y[..., -1:, :, :], self.tail, -3)], -3)
                    for Y in info]  # fmt: skip
        choice, score, gsr_score = self._descend(info, valid, scorer, previous)
        b = np.arange(B)[:, None]
        plan = paths[b, np.arange(M)[None, :], choice]  # (B, M, H, 2)
        return LookaheadResult(
            positions=plan[:, :, 0].reshape(shape + (M, 2)),
            plan=plan.reshape(shape + (M, H, 2)),
            score=score.reshape(shape),
            gsr_plan=gsr_paths.reshape(shape + (M, H, 2)),
            gsr_score=gsr_score.reshape(shape),
        )

    # ------------------------------------------------------------------------------
    def _gsr_rollout(self, problem, model, preds, means, start, rho_eff) -> FloatArray:
        """Return GSR's rollout in the model, (B, M, H, 2): GSR at each step's prediction."""
        B, M = start.shape[:2]
        H, K = self.horizon, means.shape[2]
        shape = problem.batch_shape
        paths = np.empty((B, M, H, 2))
        covs = [P for _, P, _, _ in preds]
        sensors, states = start, model.begin(start)
        # The problem's own fields (models, pose, sensing limits, occluders) at every step.
        fixed = {f.name: getattr(problem, f.name) for f in fields(problem)}
        fixed.update(prediction=None, rho=rho_eff.reshape(shape + (M,)))
        for h in range(H):
            blocks = np.stack([P[:, :2, :2] for P in covs], axis=1)  # (B, K, 2, 2)
            multi = problem.multi_target
            # Arrays built here from a validated problem: no second validation.
            step = PlanningProblem._validated(**{
                **fixed,
                "prior_cov": (blocks if multi else blocks[:, 0]).reshape(
                    shape + ((K,) if multi else ()) + (2, 2)),
                "target": (means[:, h] if multi else means[:, h, 0]).reshape(
                    shape + ((K,) if multi else ()) + (2,)),
                "sensors": sensors.reshape(shape + (M, 2)),
                "sensor_states": None if model.n_state == 2 else
                states.reshape(shape + (M, model.n_state)),
            })  # fmt: skip
            sensors = np.asarray(self._gsr.plan(step), dtype=np.float64).reshape(B, M, 2)
            states = model.restated(sensors, states)  # (a heading, a velocity: advanced)
            paths[:, :, h] = sensors
            if h + 1 < H:
                here = model.information(sensors[:, :, None, None], means[:, h, None])
                covs = [
                    hm.predict_covariance(hm.information_update(P, Y[:, :, 0, 0].sum(1)), F, Qk)
                    for P, Y, (_, _, F, Qk) in zip(covs, here, preds, strict=True)
                ]
        return paths

    def _scoring(self, model, paths, means, preds, weights, objective) -> tuple:
        """Return ``(info, scorer)`` for :meth:`_descend`: every target's per-sensor
        information along the ``paths`` (B, M, O, H, 2), K x (B, M, O, H, 2, 2), and the
        score of team candidates' summed information (the deterministic model)."""
        return model.information(paths, means), _Scorer(preds, weights, objective)

    def _descend(self, info, valid, scorer, previous):
        """Return ``(choice (B, M), score (B,), gsr_score (B,))``: coordinate descent over
        the ``valid`` (B, M, O) options."""
        B, M, O = info[0].shape[:3]
        b = np.arange(B)
        # Starts: GSR's rollout (option 0 for every sensor) and the shifted plan (option 1).
        starts = [np.zeros((B, M), dtype=np.int64)]
        if previous is not None:
            starts.append(np.ones((B, M), dtype=np.int64))
        Ys = [
            np.stack([Ik[b[:, None], np.arange(M)[None], s].sum(axis=1) for s in starts], axis=1)
            for Ik in info
        ]  # K x (B, S, H, 2, 2)
        scores = scorer(Ys)  # (B, S)
        usable = np.stack([valid[b[:, None], np.arange(M)[None], s].all(axis=1) for s in starts], 1)
        scores = np.where(usable, scores, np.inf)
        gsr_score = scores[:, 0].copy()
        best = np.argmin(scores, axis=1)
        choice = np.stack(starts, 1)[b, best]
        score = scores[b, best]
        for _ in range(self.passes):
            changed = False
            for i in range(M):
                cand = []
                for Ik in info:
                    chosen = Ik[b[:, None], np.arange(M)[None], choice]  # (B, M, H, 2, 2)
                    others = chosen.sum(axis=1) - chosen[:, i]
                    cand.append(others[:, None] + Ik[:, i])  # (B, O, H, 2, 2)
                s = np.where(valid[:, i], scorer(cand), np.inf)
                k = np.argmin(s, axis=1)
                better = s[b, k] < score
                if np.any(better):
                    changed = True
                    choice[better, i] = k[better]
                    score = np.where(better, s[b, k], score)
            if not changed:
                break
        for _ in range(self.pair_passes if M > 1 else 0):
            changed = False
            for i, j in itertools.combinations(range(M), 2):
                better, choice, score = self._pair_step(info, valid, scorer, choice, score, i, j)
                changed = changed or better
            if not changed:
                break
        return choice, score, gsr_score

    #: Largest number of candidate rows (copies x team candidates) scored in one call.
    CHUNK_ROWS = 8192

    def _pair_step(self, info, valid, scorer, choice, score, i, j) -> tuple:
        """Return ``(changed, choice, score)`` after the best joint move of sensors i and j
        (every pair of their options, the others fixed), scored in chunks of options of i."""
        B, M, O = info[0].shape[:3]
        b = np.arange(B)
        chosen = [Ik[b[:, None], np.arange(M)[None], choice] for Ik in info]  # (B, M, H, 2, 2)
        others = [c.sum(axis=1) - c[:, i] - c[:, j] for c in chosen]
        rows = max(1, self.CHUNK_ROWS // max(1, B * O))  # options of i per call
        best_s, best_k = np.full(B, np.inf), np.zeros(B, dtype=np.int64)
        for a0 in range(0, O, rows):
            a = np.arange(a0, min(O, a0 + rows))
            cand = [
                (o[:, None, None] + Ik[:, i, a][:, :, None] + Ik[:, j][:, None]).reshape(
                    (B, a.size * O) + Ik.shape[3:]
                )
                for o, Ik in zip(others, info, strict=True)
            ]
            ok = (valid[:, i, a][:, :, None] & valid[:, j][:, None]).reshape(B, -1)
            s = np.where(ok, scorer(cand), np.inf)
            k = np.argmin(s, axis=1)
            take = s[b, k] < best_s
            best_s, best_k = np.where(take, s[b, k], best_s), np.where(take, a0 * O + k, best_k)
        better = best_s < score
        choice = choice.copy()
        choice[better, i] = (best_k // O)[better]
        choice[better, j] = (best_k % O)[better]
        return bool(np.any(better)), choice, np.where(better, best_s, score)


class _Scorer:
    """The model score of team candidates: every target's covariance rolled out (eq. 11, 3),
    the objective combining the targets at each step, weighted over the horizon."""

    def __init__(self, preds, weights, objective) -> None:
        self.preds, self.weights, self.objective = preds, weights, objective

    def __call__(self, Ys: list[FloatArray]) -> FloatArray:
        """Return the scores (B, C) of candidates' information, K x (B, C, H, 2, 2)."""
        if len(Ys) == 1:  # one target: the rollout's own weighted sum
            _, P, F, Qk = self.preds[0]
            return hm.rollout(P[:, None], Ys[0], F, Qk, self.weights, objective=self.objective)[0]
        values = np.stack(
            [
                hm.rollout(P[:, None], Y, F, Qk, self.weights, objective=self.objective)[1]
                for Y, (_, P, F, Qk) in zip(Ys, self.preds, strict=True)
            ],
            axis=-1,
        )  # (B, C, H, K)
        return hm.weighted_sum(self.objective.combine(values), self.weights)


def _predictions(problem, x_pred, P_pred, Phi, Q) -> list[tuple]:
    """Return every target's ``(x (B, n), P (B, n, n), Phi, Q)``: the arguments, or the
    problem's predictions."""
    B = math.prod(problem.batch_shape)
    given = [v is not None for v in (x_pred, P_pred, Phi, Q)]
    if any(given) and not all(given):
        raise ValueError("give all of x_pred, P_pred, Phi and Q, or none of them")
    if all(given):
        if problem.multi_target:
            raise ValueError(
                "x_pred, P_pred, Phi and Q describe one target: a multi_target problem plans "
                "from problem.prediction (one Prediction per target)"
            )
        preds = [(x_pred, P_pred, np.asarray(Phi, np.float64), np.asarray(Q, np.float64))]
    elif problem.predictions is None:
        raise ValueError(
            "problem.prediction is None: pass x_pred, P_pred, Phi and Q, or a problem "
            "that carries its prediction (World.planning_problem, "
            "PlanningProblem.from_prediction)"
        )
    else:
        preds = [(q.mean, q.cov, q.Phi, q.Q) for q in problem.predictions]
    out = []
    for x, P, F, Qk in preds:
        n = F.shape[0]
        out.append((
            np.asarray(x, dtype=np.float64).reshape(B, n),
            np.asarray(P, dtype=np.float64).reshape(B, n, n),
            F,
            Qk,
        ))  # fmt: skip
    return out


def _principal_std(P11: FloatArray) -> FloatArray:
    """Return the square root of the larger eigenvalue of 2x2 covariances (...,)."""
    a, b, c = P11[..., 0, 0], P11[..., 0, 1], P11[..., 1, 1]
    return np.sqrt(0.5 * (a + c) + np.hypot(0.5 * (a - c), b))


class LookaheadPlanner:
    """:class:`Lookahead` behind the planner interface ``plan(problem, rng) -> positions``.

    The planner reads the full prediction from ``problem.prediction`` (the world's
    problems carry it), so problems may come in any order, from any scenario. For a
    problem without one (built by hand from the position blocks only) it falls back on a
    :class:`~activetrack.baselines.prediction_tracker.PredictionTracker` per copy, which
    recovers the prediction from the episode's problems: it must then see every problem of
    an episode in order, from the first, of the scenario ``scenario``.

    Warm start: the planner keeps each copy's last plan. The next problem's option 1 is
    that plan shifted by one step where the copy continues it (its sensors stand where
    the plan's first step put them; with the tracker: the tracker continues the episode),
    none for a copy that does not (as if it were planned alone: a copy's plan does not
    depend on the batch it is planned in).

    Args:
        scenario: for the fallback only, the scenario the problems come from (name or
            Scenario); ``None``: the preset whose initial prediction matches the first
            problem.
        **settings: :class:`Lookahead`'s fields (horizon, discount, ...).
    """

    #: Largest distance (m, relative to 1 + the coordinates' scale) between a copy's
    #: sensors and its last plan's first step for the copy to continue that plan.
    CONTINUE_TOL = 1e-9

    def __init__(self, scenario: object = "paper", **settings: object) -> None:
        self.search = Lookahead(**settings)
        self.scenario = scenario
        self._trackers: list[PredictionTracker] = []
        self._previous: FloatArray | None = None
        self.last_result: LookaheadResult | None = None

    def reset(self) -> None:
        """Forget the episodes: the next problems start new ones (no warm start)."""
        for tracker in self._trackers:
            tracker.reset()
        self._previous = None

    def plan(self, problem: PlanningProblem, rng: np.random.Generator | None = None) -> FloatArray:
        """Return the next absolute positions, ``batch_shape + (M, 2)`` (``rng`` unused)."""
        shape, M = problem.batch_shape, problem.n_sensors
        B = math.prod(shape)
        if problem.prediction is not None:  # plan_prediction reads it (every target's)
            x_pred = P_pred = Phi = Q = new = None
        else:
            x_pred, P_pred, Phi, Q, new = self._track(problem)
        previous = self._previous
        if previous is not None and previous.shape[:2] != (B, M):
            previous = None
        if previous is not None:
            if new is None:
                gap = np.abs(problem.sensors.reshape(B, M, 2) - previous[:, :, 0])
                scale = 1.0 + np.abs(previous[:, :, 0]).max(axis=(1, 2))
                new = gap.max(axis=(1, 2)) > self.CONTINUE_TOL * scale
            if new.all():
                previous = None
            elif np.any(new):
                # A copy that continues no plan has no warm start: its option 1 ("stay", a
                # stand-in) is not offered, as when it is planned alone.
                start = problem.sensors.reshape(B, M, 1, 2)
                previous = np.where(new[:, None, None, None], start, previous)
        res = self.search.plan_prediction(
            problem,
            x_pred,
            P_pred,
            Phi,
            Q,
            None if previous is None else previous.reshape(shape + previous.shape[-3:]),
            fresh=None if previous is None or new is None else new,
        )
        self._previous = res.plan.reshape(B, M, -1, 2)
        self.last_result = res
        return res.positions

    def _track(self, problem: PlanningProblem) -> tuple:
        """Return ``(x_pred, P_pred, Phi, Q, new (B,))`` recovered by the copies' trackers."""
        shape = problem.batch_shape
        B = math.prod(shape)
        while len(self._trackers) < B:
            self._trackers.append(PredictionTracker(self.scenario))
        flat = [problem] if not shape else [problem[np.unravel_index(b, shape)] for b in range(B)]
        states = [tracker.observe(p) for tracker, p in zip(self._trackers, flat, strict=False)]
        x_pred = np.stack([s[0] for s in states])
        P_pred = np.stack([s[1] for s in states])
        new = np.array([s[2] for s in states])
        tracker = self._trackers[0]
        return (
            x_pred.reshape(shape + x_pred.shape[-1:]),
            P_pred.reshape(shape + P_pred.shape[-2:]),
            tracker.Phi,
            tracker.Q,
            new,
        )

    def __repr__(self) -> str:
        return f"LookaheadPlanner({self.search!r})"


def run_batched(
    scenario: str, seeds: list[int], planner: Lookahead | None = None
) -> tuple[FloatArray, FloatArray]:
    """Return ``(mean_trace, deepest)`` per seed of closed-loop episodes in one batched world.

    ``planner`` None runs GSR. ``mean_trace`` is each episode's mean posterior trace and
    ``deepest`` its deepest realized minimum-distance violation of the *true* targets,
    ``max(0, max_k max_i (rho_i - ||p_S_i(k) - p_T(k)||))`` (m; 0: never inside a disk).
    """
    from activetrack.baselines import rollout as ro

    class Warm(ro.Agent):  # each step's plan warm-starts the next (GSR: planner None)
        def start(self, seeds: list[int], batched: bool) -> None:
            self.gsr, self.previous = GSR(), None

        def decide(self, step: ro.Step) -> None:
            problem = step.planning_problem()
            if planner is None:
                step.positions = self.gsr.plan(problem)
            else:
                res = planner.plan_prediction(problem, previous=self.previous)
                step.positions, self.previous = res.positions, res.plan

    class Record(ro.Recorder):
        def step(self, step: ro.Step) -> None:
            w = step.world
            traces.append(w.trace.copy())
            # Every true target's position (N, K, 2) (each target's own state size).
            targets = np.stack([w.get("x_true", target=k)[:, :2] for k in range(w.n_targets)], 1)
            d = np.linalg.norm(w.sensors[:, None] - targets[:, :, None], axis=-1)  # (N, K, M)
            deepest[:] = np.maximum(deepest, np.max(w.params.rho - d, axis=(1, 2)))

    traces, deepest = [], np.zeros(len(seeds))
    ro.rollout(World(scenario, len(seeds)), Warm(), seeds, Record(), batched=True)
    return np.mean(traces, axis=0), deepest
