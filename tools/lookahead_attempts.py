"""Variants of the look-ahead planner tried against GSR on ``paper`` (README, "Planning
ahead"): none is kept in the library; each is a patch of this process only.

- ``follow``: per heading, paths that turn to follow the predicted target after 3 and 6
  steps (extra options of ``horizon_paths.heading_paths``);
- ``half-speed``: the headings also at half speed (extra options);
- ``relative``: the headings also in the predicted target's frame: each step the
  target's predicted displacement plus the speed left over along the heading (extra
  options);
- ``sigma``: each sensor's information averaged over the four sigma points of the
  predicted position (its Cholesky factor times ``sqrt(2) alpha``);
- ``inflate``: the information computed at distances inflated by the prediction's
  uncertainty, ``d_eff^2 = d^2 + alpha sigma^2`` (``sigma^2`` the predicted position's
  largest variance): plans that rely on standing close count less;
- ``episode-end``: the horizon's weights cut at the episode's last step;
- ``sampled``: each team candidate scored by the mean of its model score over
  ``--samples`` sampled paths of the future estimate (the filter's linearization point)
  instead of the predicted mean path alone (:class:`SampledFutures`);
- ``exhaustive``: after the descent, every team of options (M = 3: O^3 candidates) is
  scored and the best kept (:class:`Exhaustive`): how far the descent is from the best
  plan of its own options (what led to ``Lookahead.pair_passes``).

Every variant patches ``Lookahead(**--settings)``; the default settings are those the
attempts were measured with, the planner's defaults before the terminal tail and the pair
passes (``{"tail": 0, "pair_passes": 0, "margin": 0.5}``).

Prints the ratio of the look-ahead's mean trace to GSR's over 100 seeds from ``--start``
(one batched world each, paired) with a bootstrap 95% interval. Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python tools/lookahead_attempts.py none --start 2000
    OPENBLAS_NUM_THREADS=1 .venv/bin/python tools/lookahead_attempts.py follow --start 2000
    OPENBLAS_NUM_THREADS=1 python tools/lookahead_attempts.py sigma --alpha 0.5 --start 2000
    OPENBLAS_NUM_THREADS=1 .venv/bin/python tools/lookahead_attempts.py episode-end --start 1000
    OPENBLAS_NUM_THREADS=1 python tools/lookahead_attempts.py inflate --alpha 1 --start 3000
    OPENBLAS_NUM_THREADS=1 python tools/lookahead_attempts.py sampled --samples 16 --start 2000
    OPENBLAS_NUM_THREADS=1 python tools/lookahead_attempts.py exhaustive --episodes 200 \\
        --settings '{"tail": 0, "pair_passes": 0, "margin": 0.75}'
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass

import numpy as np

from activetrack.baselines import horizon_model as hm
from activetrack.baselines import horizon_paths as hp
from activetrack.baselines import lookahead as la
from activetrack.models.objective import sensor_information
from activetrack.world import World

STATE: dict = {"cov": None, "left": None}
#: The settings the attempts were measured with (the defaults before the tail and pairs).
ATTEMPTS_BASE = {"tail": 0, "pair_passes": 0, "margin": 0.5}


def patch(attempt: str, alpha: float) -> None:
    """Install the variant ``attempt`` in this process."""
    if attempt == "follow":
        heading = hp.heading_paths

        def follow(model, start, targets, r, rho, dirs):
            base = heading(model, start, targets, r, rho, dirs)
            extra = []
            for j in (3, 6):
                out, prev = base.copy(), base[:, :, :, j - 1]
                for h in range(j, base.shape[3]):
                    goal = prev + (targets[:, h, 0] - targets[:, h - 1, 0])[:, None, None, :]
                    rr, rh = r[:, :, None], rho[:, :, None]
                    prev = model.mend(hp.toward(prev, goal, rr), prev, targets[:, h], rr, rh)
                    out[:, :, :, h] = prev
                extra.append(out)
            return np.concatenate([base, *extra], axis=2)

        hp.heading_paths = follow
    elif attempt in ("half-speed", "relative"):
        heading = hp.heading_paths

        def more(model, start, targets, r, rho, dirs):
            base = heading(model, start, targets, r, rho, dirs)
            if attempt == "half-speed":
                return np.concatenate([base, heading(model, start, targets, 0.5 * r, rho, dirs)], 2)
            out, prev = (
                np.empty_like(base),
                np.broadcast_to(start[:, :, None], base[:, :, :, 0].shape),
            )
            rr, rh = r[:, :, None], rho[:, :, None]
            for h in range(base.shape[3]):
                a, b = (h - 1, h) if h > 0 else (0, 1)
                move = (targets[:, b, 0] - targets[:, a, 0])[:, None, None, :]
                spare = np.maximum(rr[..., None] - np.linalg.norm(move, axis=-1, keepdims=True), 0)
                prev = model.mend(prev + move + spare * dirs, prev, targets[:, h], rr, rh)
                out[:, :, :, h] = prev
            return np.concatenate([base, out], axis=2)

        hp.heading_paths = more
    elif attempt == "inflate":
        plain_info = hp.PathModel.information

        def inflated(self, positions, targets):
            if not self.paper:
                return plain_info(self, positions, targets)
            rel = positions - targets[:, None, None, :, 0]
            d2 = np.maximum(np.sum(rel * rel, axis=-1, keepdims=True), 1e-300)
            var = np.linalg.eigvalsh(STATE["cov"])[:, -1][:, None, None, None, None]
            rel = rel * np.sqrt(1.0 + alpha * var / d2)
            sd2, st2 = self.sigma_d2[:, :, None, None], self.sigma_theta2[:, :, None, None]
            return [sensor_information(rel, sd2, st2)]

        hp.PathModel.information = inflated
    elif attempt == "sigma":
        plain = hp.PathModel.information

        def averaged(self, positions, targets):
            if not self.paper:
                return plain(self, positions, targets)
            chol = np.linalg.cholesky(STATE["cov"])  # (B, 2, 2)
            rel = positions - targets[:, None, None, :, 0]
            sd2, st2 = self.sigma_d2[:, :, None, None], self.sigma_theta2[:, :, None, None]
            total = 0.0
            for j in range(2):
                for sign in (1.0, -1.0):
                    d = (sign * alpha * np.sqrt(2.0)) * chol[:, :, j]
                    total = total + sensor_information(rel - d[:, None, None, None, :], sd2, st2)
            return [total / 4.0]

        hp.PathModel.information = averaged
    elif attempt == "episode-end":
        weights = hm.discount_weights

        def cut(horizon, discount):
            w = weights(horizon, discount)
            if STATE["left"] is not None:
                w = w.copy()
                w[STATE["left"] :] = 0.0
            return w

        hm.discount_weights = cut


@dataclass
class SampledFutures(la.Lookahead):
    """The look-ahead planner scoring each team candidate by its mean model score over
    ``samples`` paths of the future estimate (one target).

    Under the EKF the estimate moves at each update by ``K nu``, whose covariance is
    ``P(h|h-1) - P(h|h)`` (law of total covariance), and is then predicted by ``Phi``; the
    deterministic model keeps it on the predicted mean. Here the deviations ``e(0) = 0``,
    ``e(h+1) = Phi (e(h) + scale L(h) z(h))`` (``L L^T`` that covariance along GSR's
    rollout, ``z`` standard normals, half of them the negatives of the others, the same
    for every copy and call) move the point each sensor's information is computed about.
    """

    samples: int = 16
    scale: float = 1.0

    def _scoring(self, model, paths, means, preds, weights, objective):  # noqa: ANN001, ANN202
        ((_, P0, Phi, Q),) = preds
        B, H, n = paths.shape[0], paths.shape[3], Phi.shape[0]
        Y = model.information(paths[:, :, :1], means)[0][:, :, 0].sum(axis=1)  # GSR's rollout
        prior = hm.prior_sequence(P0, Y, Phi, Q)
        jump = prior - hm.information_update(prior, Y)
        L = np.linalg.cholesky(0.5 * (jump + jump.mT) + 1e-12 * np.eye(n))  # (B, H, n, n)
        half = np.random.default_rng(0).standard_normal((self.samples // 2, H, n))
        z = np.concatenate([half, -half])  # (S, H, n)
        e, dev = np.zeros((B, len(z), n)), np.empty((B, len(z), H, 2))
        for h in range(H):
            dev[:, :, h] = e[..., :2]
            e = (e + self.scale * np.einsum("bij,sj->bsi", L[:, h], z[:, h])) @ Phi.T
        rel = paths[:, :, :, None] - (means[:, None, :, 0] + dev)[:, None, None]
        cols = (slice(None), slice(None), None, None, None)
        info = [sensor_information(rel, model.sigma_d2[cols], model.sigma_theta2[cols])]

        def scorer(Ys: list) -> np.ndarray:  # Ys[0] (B, C, S, H, 2, 2): the samples' mean
            return hm.rollout(P0[:, None, None], Ys[0], Phi, Q, weights)[0].mean(axis=-1)

        return info, scorer  # info (B, M, O, S, H, 2, 2)


class Exhaustive(la.Lookahead):
    """The descent's plan, then the best of every team of options (three sensors)."""

    def _descend(self, info, valid, scorer, previous):  # noqa: ANN001, ANN202 (as Lookahead's)
        choice, score, gsr_score = super()._descend(info, valid, scorer, previous)
        ((Y,),) = (info,)  # one target: (B, 3, O, H, 2, 2)
        B, O, b = Y.shape[0], Y.shape[2], np.arange(Y.shape[0])
        for a in range(O):  # sensor 0 at option a, sensors 1 and 2 at every pair
            pairs = (Y[:, 1, :, None] + Y[:, 2, None]).reshape(B, O * O, *Y.shape[3:])
            team = Y[:, 0, a, None] + pairs
            ok = valid[:, 0, a, None, None] & valid[:, 1, :, None] & valid[:, 2, None]
            ok = ok.reshape(B, -1)
            s = np.where(ok, scorer([team]), np.inf)
            k = np.argmin(s, axis=1)
            better = s[b, k] < score
            choice[better] = np.stack([np.full(B, a), k // O, k % O], 1)[better]
            score = np.where(better, s[b, k], score)
        return choice, score, gsr_score


class Watched:
    """The look-ahead planner, with what the variants read set before each plan: the
    prediction's position covariance and the steps left (the copies are in step)."""

    def __init__(self, planner: la.Lookahead, n_steps: int) -> None:
        self.planner, self.n_steps, self.k = planner, n_steps, 0

    def plan_prediction(self, problem, previous=None):  # noqa: ANN001, ANN201 (as Lookahead's)
        STATE["cov"] = np.array(problem.prior_cov)
        STATE["left"] = self.n_steps - self.k
        self.k += 1
        return self.planner.plan_prediction(problem, previous=previous)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "attempt",
        choices=[
            "none", "follow", "half-speed", "relative", "sigma", "inflate", "episode-end",
            "sampled", "exhaustive",
        ],
    )  # fmt: skip
    parser.add_argument("--start", type=int, default=2000, help="first of 100 seeds")
    parser.add_argument(
        "--alpha",
        type=float,
        default=0.5,
        help="sigma: the points' scale; inflate: kappa; sampled: the deviations' scale",
    )
    parser.add_argument("--samples", type=int, default=16, help="sampled: estimate paths")
    parser.add_argument("--episodes", type=int, default=100, help="seeds from --start")
    parser.add_argument(
        "--settings", default=json.dumps(ATTEMPTS_BASE), help="Lookahead keywords (JSON)"
    )
    args = parser.parse_args()
    settings = json.loads(args.settings)
    seeds = list(range(args.start, args.start + args.episodes))
    gsr, _ = la.run_batched("paper", seeds)  # before the patch: GSR is unaffected by every variant
    patch(args.attempt, args.alpha)
    n_steps = World("paper").scenario.n_steps
    search = (
        SampledFutures(samples=args.samples, scale=args.alpha, **settings)
        if args.attempt == "sampled"
        else (Exhaustive if args.attempt == "exhaustive" else la.Lookahead)(**settings)
    )
    look, _ = la.run_batched("paper", seeds, Watched(search, n_steps))
    n = len(seeds)
    idx = np.random.default_rng(0).integers(0, n, (4000, n))
    boot = look[idx].mean(axis=1) / gsr[idx].mean(axis=1)
    lo, hi = np.percentile(boot, [2.5, 97.5])
    print(f"{args.attempt}: ratio {look.mean() / gsr.mean():.4f} [{lo:.4f}, {hi:.4f}]")


if __name__ == "__main__":
    main()
