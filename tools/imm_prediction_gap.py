"""Why GSR planning from the IMM's predicted mixture does no better than from its
constant-velocity mode alone on ``maneuvering`` (docs/tasks.md, "Planning from the IMM's
mixture or from one mode"): how far apart the two predictions and GSR's plans from them
are, and what each plan costs on the mixture's own objective.

One batched world of ``--episodes`` copies from seed ``--start`` (exploration seeds, not the
held-out 1000..1099) runs the IMM of :data:`activetrack.world.presets.MANEUVERING`, GSR
planning from the mixture driving it; at every step GSR also plans from mode 0's problem
(:func:`activetrack.world.planning_prediction.chosen`). Prints per step and copy: the
relative gap of the predicted position covariances' traces, the predicted positions' gap
in units of the mixture's ``sqrt(tr P11)``, the plans' mean distance per sensor, the mode-0
plan's excess on the mixture's objective (its regret), and the objective each prediction
predicts for its own plan beside the realized posterior trace. ``--ratios`` adds the paired
mean trace ratios (BCa 95%) of the look-ahead from the mixture over the look-ahead from
mode 0, and of GSR's two on targets turning at 3 rad/s. Run::

    OPENBLAS_NUM_THREADS=1 .venv/bin/python tools/imm_prediction_gap.py [--ratios]
"""

from __future__ import annotations

import argparse

import numpy as np

from activetrack import IMMSpec, Maneuvering
from activetrack.baselines.evaluation import evaluate, paired_ratio_ci
from activetrack.baselines.policies import GSRPolicy, LookaheadPolicy
from activetrack.world import World
from activetrack.world.planning_prediction import chosen
from activetrack.world.presets import MANEUVERING


def gaps(start: int, episodes: int) -> None:
    """Print the predictions' and plans' gaps along GSR's (mixture) closed loop."""
    w = World("maneuvering", episodes, estimator=IMMSpec.from_behaviour(MANEUVERING))
    w.reset(seeds=list(range(start, start + episodes)))
    gsr = GSRPolicy(seed=0)
    rows: dict[str, list[np.ndarray]] = {
        k: [] for k in ("trace", "mean", "plan", "regret", "mixture", "mode0", "real")
    }
    for _ in range(w.scenario.n_steps):
        mix = w.planning_problem()
        one = chosen(mix, 0)
        plan_mix, plan_one = gsr.plan(mix), gsr.plan(one)
        tr_mix = np.trace(mix.prior_cov, axis1=-2, axis2=-1)
        rows["trace"].append(1.0 - np.trace(one.prior_cov, axis1=-2, axis2=-1) / tr_mix)
        rows["mean"].append(np.linalg.norm(mix.target - one.target, axis=-1) / np.sqrt(tr_mix))
        rows["plan"].append(np.linalg.norm(plan_mix - plan_one, axis=-1).mean(axis=-1))
        rows["regret"].append(mix.score(plan_one) / mix.score(plan_mix) - 1.0)
        rows["mixture"].append(mix.score(plan_mix))
        rows["mode0"].append(one.score(plan_one))
        w.step(plan_mix)
        rows["real"].append(w.get("trace"))
    r = {k: np.concatenate(v) for k, v in rows.items()}
    pct = np.percentile
    print(f"seeds {start}..{start + episodes - 1}, {r['trace'].size} steps of GSR (mixture)")
    print(
        f"tr P11: mode 0 below the mixture by {r['trace'].mean():.1%} on average "
        f"(95th percentile {pct(r['trace'], 95):.1%})"
    )
    print(
        f"predicted positions apart by {r['mean'].mean():.3f} sqrt(tr P11) on average "
        f"(95th percentile {pct(r['mean'], 95):.3f})"
    )
    print(
        f"GSR's plans apart by {r['plan'].mean():.3f} m per sensor on average "
        f"(95th percentile {pct(r['plan'], 95):.3f} m; reach 1 m)"
    )
    print(
        f"regret of the mode-0 plan on the mixture's objective: mean {r['regret'].mean():.2%}, "
        f"95th percentile {pct(r['regret'], 95):.2%}, max {r['regret'].max():.2%}"
    )
    print(
        f"objective of each plan, as predicted: mixture {r['mixture'].mean():.3f}, mode 0 "
        f"{r['mode0'].mean():.3f}; realized posterior trace {r['real'].mean():.3f} m^2"
    )


def ratios(start: int, episodes: int) -> None:
    """Print the look-ahead's and the 3 rad/s task's paired mixture / mode-0 ratios."""
    fast = Maneuvering((0.0, 3.0, -3.0), MANEUVERING.transition, q=10.0, dt=0.1)
    cases = {
        "look-ahead": (MANEUVERING, {}, LookaheadPolicy, {"scenario": None}),
        "GSR, turns of 3 rad/s": (fast, {"target_behaviour": fast}, GSRPolicy, {}),
    }
    for name, (behaviour, overrides, make, kw) in cases.items():
        runs = evaluate(
            {"mixture": make(**kw), "mode 0": make(prediction=0, **kw)},
            "maneuvering",
            episodes=episodes,
            seed=start,
            batched=True,
            progress=False,
            estimator=IMMSpec.from_behaviour(behaviour),
            **overrides,
        )
        a, b = runs[0].mean_trace, runs[1].mean_trace
        lo, hi = paired_ratio_ci(a, b)
        print(f"{name}: mean trace mixture / mode 0 {a.mean() / b.mean():.4f} [{lo:.4f}, {hi:.4f}]")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--start", type=int, default=0, help="first seed (default 0)")
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--ratios", action="store_true", help="also the paired ratios")
    args = parser.parse_args()
    gaps(args.start, args.episodes)
    if args.ratios:
        ratios(args.start, args.episodes)


if __name__ == "__main__":
    main()
