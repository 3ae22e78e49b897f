"""Record seeded outputs of the compiled kernels' entry points, or compare two recordings.

For refactors that must keep results bit for bit (the occluder geometry, the sensor moves,
GSR's plans): record at two commits and compare::

    PYTHONPATH=<export of commit A> python tools/record_kernel_outputs.py a.npz
    python tools/record_kernel_outputs.py b.npz
    python tools/record_kernel_outputs.py --compare a.npz b.npz

Cases: ``inside``, ``blocked``, ``project_move`` and ``ray_distances`` on 30 random layouts
(rectangles and non-convex stars, one layout and batches of five), ``apply_actions``,
``move_to``, ``project_feasible`` and ``unreachable_fallback`` on random states, GSR's
plans of 300 random three-sensor problems, batched and one by one, the single-sensor
solver on 2,000 random problems (``bench_solver.py``'s), one by one and batched, the
observations and states of every task over 30 seeded steps of random actions (one copy
and seven), and 300 random layouts (``random_layout``'s vertices and every array of ``Occluders``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(1, str(Path(__file__).resolve().parents[1]))  # tests.core (layouts)


def mixed_layout(rng: np.random.Generator, n: int) -> list[np.ndarray]:
    """Return n // 2 rotated rectangles (made here, in NumPy: the same inputs whatever the
    library's ``random_layout`` rounds) and n - n // 2 non-convex stars in [-3, 3]^2."""
    from tests.core.test_occluders import star_polygon

    polys = []
    for _ in range(n // 2):
        w, h = rng.uniform(0.5, 2.0, 2)
        c, s = np.cos(a := rng.uniform(0, np.pi)), np.sin(a)
        corners = 0.5 * np.array([[-w, -h], [w, -h], [w, h], [-w, h]])
        polys.append(rng.uniform(-2, 2, 2) + corners @ np.array([[c, s], [-s, c]]))
    stars = [star_polygon(rng, rng.uniform(-2, 2, 2), 7, 0.3, 1.2) for _ in range(n - n // 2)]
    return polys + stars


def occluder_cases(out: dict) -> None:
    """Add the occluder functions' results on random layouts to ``out``."""
    from activetrack.models import occluders as oc

    dirs = np.stack([np.cos(np.arange(16) * np.pi / 8), np.sin(np.arange(16) * np.pi / 8)], -1)
    for seed in range(30):
        rng = np.random.default_rng(seed)
        occ = oc.Occluders.from_polygons(mixed_layout(rng, 4 + seed % 3))
        pts = rng.uniform(-4, 4, (400, 2))
        q = pts + rng.uniform(-2, 2, (400, 2))
        r = rng.uniform(0.2, 3, 400)
        out[f"inside{seed}"] = oc.inside(pts, occ)
        out[f"blocked{seed}"] = oc.blocked(pts, q, occ)
        out[f"move{seed}"], out[f"projected{seed}"] = oc.project_move(pts, q, occ, r)
        out[f"rays{seed}"] = oc.ray_distances(pts, dirs, occ, 3.0)
        lays = [
            oc.Occluders.from_polygons(mixed_layout(np.random.default_rng(100 * seed + i), 4))
            for i in range(5)
        ]
        try:
            batch = oc.Occluders.stack(lays)
        except ValueError:  # layouts of different vertex counts do not stack
            continue
        P, Q = pts[:100].reshape(5, 20, 2), q[:100].reshape(5, 20, 2)
        out[f"batch_blocked{seed}"] = oc.blocked(P, Q, batch)
        out[f"batch_move{seed}"] = oc.project_move(P, Q, batch, r[:100].reshape(5, 20))[0]
        out[f"batch_rays{seed}"] = oc.ray_distances(P, dirs, batch, 3.0)


def motion_cases(out: dict) -> None:
    """Add the sensor moves' results on random states to ``out``."""
    from activetrack.kinematics import geometry
    from activetrack.kinematics import sensor_motion as sm

    rng = np.random.default_rng(5)
    for i in range(20):
        S, T = rng.uniform(-5, 5, (50, 4, 2)), rng.uniform(-5, 5, (50, 2))
        r, rho = rng.uniform(0.1, 3, 4), rng.uniform(0.5, 4, 4)
        A = rng.uniform(-2, 2, (50, 4, 2))
        A[0, 0] = [1e308, 1e308]  # overflows a plain norm
        out[f"actions{i}"], out[f"actions_inside{i}"] = sm.apply_actions(A, S, T, r, rho)
        P = S + rng.uniform(-4, 4, (50, 4, 2))
        out[f"move_to{i}"], out[f"move_to_inside{i}"] = sm.move_to(P, S, T, r, rho)
        q, c = rng.uniform(-3, 3, (200, 2)), rng.uniform(-4, 4, (200, 2))
        c[0] = 0.0
        out[f"project{i}"] = geometry.project_feasible(
            q, c, rng.uniform(0.1, 3, 200), rng.uniform(0.5, 4, 200)
        )
        out[f"fallback{i}"] = geometry.unreachable_fallback(c, 1.5)


def gsr_cases(out: dict) -> None:
    """Add GSR's plans of random three-sensor problems (batched, then one by one)."""
    from activetrack.baselines import GSR
    from activetrack.world.problem import PlanningProblem

    rng = np.random.default_rng(7)
    B = 300
    A = rng.normal(size=(B, 2, 2))
    P = A @ A.transpose(0, 2, 1) + 0.5 * np.eye(2)
    T = rng.uniform(-5, 5, (B, 2))
    S = T[:, None] + rng.uniform(-8, 8, (B, 3, 2))
    sensors = dict(
        r=np.array([1.0, 1.5, 2.0]),
        rho=np.array([1.0, 2.0, 1.5]),
        sigma_d2=np.array([2.0, 1.0, 0.5]),
        sigma_theta2=np.array([0.25, 0.1, 0.05]),
    )
    res = GSR().plan_with_info(PlanningProblem(P, T, S, **sensors))
    out["gsr_batch_positions"], out["gsr_batch_values"] = res.positions, res.value
    out["gsr_batch_sweeps"] = res.sweeps
    single = [GSR().plan_with_info(PlanningProblem(P[b], T[b], S[b], **sensors)) for b in range(B)]
    out["gsr_positions"] = np.array([x.positions for x in single])
    out["gsr_values"] = np.array([x.value for x in single])
    out["gsr_sweeps"] = np.array([x.sweeps for x in single])
    out["gsr_solves"] = np.array([x.n_solves for x in single])


def solver_cases(out: dict) -> None:
    """The single-sensor solver on 2,000 of ``bench_solver.py``'s random problems (seed 0),
    one call each (checked) and in one batch."""
    from activetrack.solvers.analytic import solve_single_sensor, solve_single_sensor_batch
    from benchmarks.bench_solver import random_problems

    prior, c, r, rho, sd2, st2 = random_problems(np.random.default_rng(0), 2000)
    batch = solve_single_sensor_batch(prior, c, r, rho, sd2, st2)
    out["solver_batch_s"], out["solver_batch_value"] = batch.s, batch.value
    out["solver_batch_case"], out["solver_batch_feasible"] = batch.case, batch.feasible
    one = [
        solve_single_sensor(
            prior[i], c[i], float(r[i]), float(rho[i]), float(sd2[i]), float(st2[i])
        )
        for i in range(len(r))
    ]
    out["solver_s"] = np.array([x.s for x in one])
    out["solver_value"] = np.array([x.value for x in one])
    out["solver_case"] = np.array([x.case for x in one])
    out["solver_feasible"] = np.array([x.feasible for x in one])


def world_cases(out: dict) -> None:
    """Add every task's observations and states along seeded random-action episodes."""
    from activetrack.world import World
    from activetrack.world.scenarios import TASKS

    for task in ["paper", "homogeneous", *TASKS]:
        for n in (1, 7):
            w = World(task, n)
            w.reset(seeds=range(n))
            rng = np.random.default_rng(5)
            for step in range(30):
                shape = (w.n_sensors, 2) if n == 1 else (n, w.n_sensors, 2)
                w.step_actions(rng.uniform(-1.2, 1.2, shape))
                ended = np.atleast_1d(w.get("terminated") | w.get("truncated"))
                if ended.any():
                    w.reset(None if n == 1 else ended)
                if step % 3 == 0:
                    out[f"{task}_{n}_{step}_obs"] = w.observe()
                    out[f"{task}_{n}_{step}_state"] = w.state()
                    for key in ("sensors", "x_hat", "P", "x_pred", "P_pred", "trace"):
                        out[f"{task}_{n}_{step}_{key}"] = np.asarray(w.get(key))


def layout_cases(out: dict) -> None:
    """Add 300 random layouts: their vertices and every array of their Occluders."""
    from activetrack.models import occluders as oc

    clear = np.array([[8.0, 0.0], [0.0, 0.0]])
    for seed in range(300):
        lay = oc.random_layout(np.random.default_rng(seed), 6, (-24, -10, 12, 20), (2, 5),
                               clear=clear, clearance=4.0)  # fmt: skip
        for name in ("edges_a", "edges_b", "bbox", "crossings", "starts", "edge_polygon"):
            out[f"layout{seed}_{name}"] = np.asarray(getattr(lay, name))
        out[f"layout{seed}_scale"] = np.array([lay.scale, lay.eps])


def compare(a: str, b: str) -> int:
    """Print how many arrays of two recordings differ (and where); return 1 if any."""
    x, y = np.load(a), np.load(b)
    if set(x) != set(y):
        print(f"different cases: {sorted(set(x) ^ set(y))}")
        return 1
    bad = [k for k in x if not np.array_equal(x[k], y[k])]
    worst = 0.0
    for k in bad:
        diff = x[k] != y[k]
        size = ""
        if x[k].dtype.kind == "f" and x[k].shape == y[k].shape:
            d = np.abs(x[k].astype(float) - y[k].astype(float))
            rel = d / np.maximum(np.abs(x[k]), np.finfo(float).tiny)
            scaled = np.max(d) / max(float(np.max(np.abs(x[k]))), np.finfo(float).tiny)
            size = (
                f", by at most {np.max(rel):.1e} relative ({np.max(d):.1e} absolute,"
                f" {scaled:.1e} of the largest entry)"
            )
            worst = max(worst, scaled)
        print(f"{k}: {int(diff.sum())} of {diff.size} entries differ{size}")
    print(f"{len(x)} arrays, {len(bad)} differ, by at most {worst:.1e} of an array's largest entry")
    return 1 if bad else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", nargs="?", help="the .npz file to write")
    parser.add_argument("--compare", nargs=2, metavar=("A", "B"), help="compare two recordings")
    args = parser.parse_args()
    if args.compare:
        return compare(*args.compare)
    if not args.out:
        parser.error("give the output file, or --compare A B")
    if Path(args.out).exists():
        parser.error(f"{args.out} exists: choose another name")
    out: dict = {}
    occluder_cases(out)
    motion_cases(out)
    gsr_cases(out)
    solver_cases(out)
    world_cases(out)
    layout_cases(out)
    tmp = Path(args.out).with_suffix(".tmp.npz")
    np.savez(tmp, **out)
    tmp.replace(args.out)
    print(f"{len(out)} arrays written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
