"""Benchmark of the analytic single-sensor solver (Section IV-A) against SLSQP.

Prints, on the same random problems (prior eigenvalues 1e-2..1e2 with a random rotation,
``||c||`` 0.5..50, ``r`` and ``rho`` 0.05..5, ``sigma_d^2`` and ``sigma_theta^2`` 1e-3..10,
the geometric cases mixed):

- the median wall time of one scalar ``solve_single_sensor`` call (and with ``check=False``),
- the time per problem of one ``solve_single_sensor_batch`` call on the whole batch,
- the time of the first calls (compiling the kernels, or loading them from numba's cache),
- the eigenvalues of f3's companion matrices of the speed-circle problems, per matrix:
  the compiled QR (:func:`activetrack.solvers.companion.monic_roots`, one call on the stack)
  beside LAPACK through NumPy (``np.linalg.eigvals`` on the same stack) and through
  SciPy's ``dgeev`` one matrix per call, in the same run,
- the median time of ``scipy.optimize.minimize(method="SLSQP")`` from 8 starts per problem
  (the constraints (23)-(24) as inequality functions), the ratio of the times,
- how often SLSQP's best feasible value is worse than the analytic one, and by how much.

Usage: ``python benchmarks/bench_solver.py [--n 10000] [--n-scalar 2000] [--n-slsqp 300]``.
Timings on a shared machine vary; the load average is printed with the results.
"""

from __future__ import annotations

import argparse
import math
import os
import time

import numpy as np
from scipy.optimize import minimize

from activetrack.solvers.analytic import solve_single_sensor, solve_single_sensor_batch


def random_problems(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    """Return ``(prior, c, r, rho, sd2, st2)`` arrays for ``n`` feasible problems."""
    lam = 10.0 ** rng.uniform(-2, 2, (n, 2))
    phi = rng.uniform(0, math.pi, n)
    cs, sn = np.cos(phi), np.sin(phi)
    R = np.stack([np.stack([cs, -sn], -1), np.stack([sn, cs], -1)], -2)
    prior = np.einsum("bij,bj,bkj->bik", R, lam, R)
    nc = 10 ** rng.uniform(math.log10(0.5), math.log10(50), n)
    ang = rng.uniform(-math.pi, math.pi, n)
    c = nc[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    r = 10 ** rng.uniform(math.log10(0.05), math.log10(5), n)
    rho = 10 ** rng.uniform(math.log10(0.05), math.log10(5), n)
    # Half the problems with rho comparable to ||c||, so that cases II, III, 4 appear too.
    mix = rng.random(n) < 0.5
    rho[mix] = np.minimum(5.0, nc[mix] * rng.uniform(0.3, 1.2, mix.sum()))
    rho = np.minimum(rho, 0.999 * (nc + r))  # feasible, and not the single tangent point
    sd2 = 10 ** rng.uniform(-3, 1, n)
    st2 = 10 ** rng.uniform(-3, 1, n)
    return prior, c, r, rho, sd2, st2


def objective(prior: np.ndarray, sd2: float, st2: float):
    """Return f0 of eq. (22) in the original frame, as a function of s (for SLSQP)."""
    p11, p12, p22 = prior[0, 0], prior[0, 1], prior[1, 1]

    def f(s: np.ndarray) -> float:
        x, y = s
        d = x * x + y * y
        a = 1.0 / (sd2 * d)
        b = 1.0 / (st2 * d * d)
        m11 = p11 + a * x * x + b * y * y
        m22 = p22 + a * y * y + b * x * x
        m12 = p12 + (a - b) * x * y
        return (m11 + m22) / (m11 * m22 - m12 * m12)

    return f


def slsqp(prior, c, r, rho, sd2, st2, n_starts: int = 8) -> float:
    """Return the best feasible SLSQP value from ``n_starts`` starts inside the speed disk.

    The constraints (23)-(24) are inequality functions scaled to O(1)
    (``1 - ||s - c||^2 / r^2 >= 0``, ``||s||^2 / rho^2 - 1 >= 0``) and ``ftol = 1e-12``,
    which SLSQP needs to meet them to ~1e-9; a result violating either by more than 1e-9
    (relative) is discarded. ``inf`` if no start gives a feasible point.
    """
    f = objective(prior, sd2, st2)
    cons = [
        {"type": "ineq", "fun": lambda s: 1.0 - ((s[0] - c[0]) ** 2 + (s[1] - c[1]) ** 2) / r**2}
    ]
    if rho > 0:
        cons.append({"type": "ineq", "fun": lambda s: (s[0] ** 2 + s[1] ** 2) / rho**2 - 1.0})
    best = math.inf
    for k in range(n_starts):
        t = 2 * math.pi * k / n_starts
        x0 = c + 0.5 * r * np.array([math.cos(t), math.sin(t)])
        if not np.any(x0):
            x0 = x0 + 1e-3
        try:
            res = minimize(
                f,
                x0,
                method="SLSQP",
                constraints=cons,
                options={"maxiter": 200, "ftol": 1e-12},
            )
        except (ValueError, ZeroDivisionError, FloatingPointError):
            continue
        s = res.x
        ok = (
            np.all(np.isfinite(s))
            and np.hypot(*(s - c)) <= r * (1 + 1e-9)
            and np.hypot(*s) >= rho * (1 - 1e-9)
        )
        if ok:
            best = min(best, float(f(s)))
    return best


def companion_peers(prior, c, r, sd2, st2) -> None:
    """Print the compiled QR's time per companion matrix beside LAPACK's, same matrices."""
    from scipy.linalg import lapack

    from activetrack.solvers._coefficients import sylvester_gammas
    from activetrack.solvers._steps import circle_polynomial, eig_frame, normalize
    from activetrack.solvers.companion import monic, monic_roots

    qs = []
    for i in range(prior.shape[0]):
        cph, sph, l1, l2 = eig_frame(prior[i, 0, 0], prior[i, 0, 1], prior[i, 1, 1])
        _, L1, L2, A, Bn, C1, C2, _ = normalize(
            l1, l2, 1 / sd2[i], 1 / st2[i], c[i, 0], c[i, 1], cph, sph, r[i], 0.0
        )
        hk = circle_polynomial(L1, L2, A, Bn, C1, C2, abs(C1) > abs(C2))
        qs.append(monic(np.array(sylvester_gammas(*hk))))
    q = np.array(qs)
    comp = np.zeros((len(q), 10, 10))
    comp[:, np.arange(1, 10), np.arange(9)] = 1.0
    comp[:, 0, :] = -q[:, ::-1]
    monic_roots(q[:2])
    t0 = time.perf_counter()
    monic_roots(q)
    ours = (time.perf_counter() - t0) / len(q)
    t0 = time.perf_counter()
    np.linalg.eigvals(comp)
    numpy_stack = (time.perf_counter() - t0) / len(q)
    mats = [np.asfortranarray(m) for m in comp[:2000]]  # dgeev overwrites its input
    t0 = time.perf_counter()
    for m in mats:
        lapack.dgeev(m, 0, 0, 40, 1)
    dgeev = (time.perf_counter() - t0) / len(mats)
    print(
        f"companion eigenvalues ({len(q)} speed-circle polynomials), per matrix: compiled QR "
        f"{ours * 1e6:.1f} us, LAPACK via np.linalg.eigvals on the stack "
        f"{numpy_stack * 1e6:.1f} us ({numpy_stack / ours:.2f}x), scipy dgeev per call "
        f"{dgeev * 1e6:.1f} us ({dgeev / ours:.2f}x)"
    )


def main() -> None:
    """Run the benchmark and print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10_000, help="batch size")
    ap.add_argument("--n-scalar", type=int, default=2_000, help="problems timed one by one")
    ap.add_argument("--n-slsqp", type=int, default=300, help="problems given to SLSQP")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    rng = np.random.default_rng(args.seed)
    prior, c, r, rho, sd2, st2 = random_problems(rng, args.n)
    print(f"load average: {os.getloadavg()}, cpus: {os.cpu_count()}")

    # Warm up: the first calls compile the kernels (or load them from numba's cache).
    t0 = time.perf_counter()
    solve_single_sensor_batch(prior[:10], c[:10], r[:10], rho[:10], sd2[:10], st2[:10])
    solve_single_sensor(prior[0], c[0], r[0], rho[0], sd2[0], st2[0])
    print(f"first calls (compile, or load from the cache): {time.perf_counter() - t0:.2f} s")

    # Batched: time of one call on the whole batch, per problem (best and median of 5).
    reps = []
    for _ in range(5):
        t0 = time.perf_counter()
        batch = solve_single_sensor_batch(prior, c, r, rho, sd2, st2)
        reps.append((time.perf_counter() - t0) / args.n)
    cases = np.bincount(batch.case, minlength=5)[1:]
    print(f"problems: {args.n}, cases I/II/III/4: {cases.tolist()}")
    print(
        f"batched solve (B={args.n}): median {np.median(reps) * 1e6:.1f} us/problem, "
        f"best {min(reps) * 1e6:.1f} us/problem"
    )
    circle_rows = (batch.case == 1) | (batch.case == 3)
    if circle_rows.any() and (~circle_rows).any():
        for name, sel in (("I/III", circle_rows), ("II/4", ~circle_rows)):
            sub = [a[sel] for a in (prior, c, r, rho, sd2, st2)]
            t0 = time.perf_counter()
            solve_single_sensor_batch(*sub)
            dt = (time.perf_counter() - t0) / sel.sum()
            print(f"  batched, cases {name} only ({sel.sum()}): {dt * 1e6:.1f} us/problem")

    if circle_rows.any():
        companion_peers(*(a[circle_rows] for a in (prior, c, r, sd2, st2)))

    # Scalar: median over single calls.
    m = min(args.n_scalar, args.n)
    times, times_u, values = [], [], []
    for i in range(m):
        # A caller's arguments: the (2, 2) and (2,) rows and four floats, made before the
        # clock starts (indexing the stacks is not the solver's time).
        call = (prior[i], c[i], float(r[i]), float(rho[i]), float(sd2[i]), float(st2[i]))
        t0 = time.perf_counter()
        sol = solve_single_sensor(*call)
        times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        solve_single_sensor(*call, check=False)
        times_u.append(time.perf_counter() - t0)
        values.append(sol.value)
    values = np.array(values)
    agree = np.max(np.abs(values - batch.value[:m]) / values)
    print(
        f"scalar solve: median {np.median(times) * 1e6:.1f} us "
        f"(check=False: {np.median(times_u) * 1e6:.1f} us), over {m} problems; "
        f"max |scalar - batch| / value = {agree:.1e}"
    )

    # SLSQP from 8 starts on the first n_slsqp problems.
    k = min(args.n_slsqp, args.n)
    t_sl, v_sl = [], []
    for i in range(k):
        t0 = time.perf_counter()
        v_sl.append(slsqp(prior[i], c[i], r[i], rho[i], sd2[i], st2[i]))
        t_sl.append(time.perf_counter() - t0)
    v_sl = np.array(v_sl)
    v_an = batch.value[:k]
    rel = (v_sl - v_an) / v_an  # > 0: SLSQP worse
    t_med = float(np.median(t_sl))
    print(f"SLSQP (8 starts): median {t_med * 1e3:.2f} ms per problem over {k} problems")
    print(
        f"  time ratio SLSQP / scalar analytic: {t_med / np.median(times):.0f}x, "
        f"SLSQP / batched analytic: {t_med / np.median(reps):.0f}x"
    )
    failed = ~np.isfinite(v_sl)
    fin = ~failed
    print(f"  no feasible SLSQP result (all 8 starts violate a constraint): {failed.sum()}/{k}")
    print(
        f"  SLSQP worse than analytic (of the {fin.sum()} with a feasible result) by "
        f"> 1e-9 rel: {np.mean(rel[fin] > 1e-9) * 100:.1f}%, "
        f"> 1e-6: {np.mean(rel[fin] > 1e-6) * 100:.1f}%, "
        f"> 1e-3: {np.mean(rel[fin] > 1e-3) * 100:.1f}%; worst {np.max(rel[fin]):.2e}"
    )
    print(
        f"  SLSQP better than analytic by > 1e-9 rel: {np.mean(rel[fin] < -1e-9) * 100:.1f}% "
        f"(most negative rel diff {np.min(rel[fin]):.1e})"
    )


if __name__ == "__main__":
    main()
