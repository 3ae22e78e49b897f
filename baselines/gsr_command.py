"""GSR's single-sensor step in command space, for any kinematics whose action is a 2-D box.

A sensor's reach set in one step is the image of its action box ``[low, high]^2`` under
:meth:`activetrack.Kinematics.apply` (every action asks for a reachable point, and every
reachable point is asked for by :meth:`~activetrack.Kinematics.command`). So sensor ``i``'s
Gauss-Seidel subproblem (eq. 38 with the other sensors' information in the base) is solved
over its commands, where the feasible set's awkward part (the reach set of a unicycle or a
double integrator) is a box:

1. **grid**: a ``GRID x GRID`` grid of the box, mapped to points by one ``apply`` call for
   every copy, the points inside a ``rho`` disk dropped, and the sensor's information there
   kept for the whole plan (the subproblem's base changes over the sweeps, its candidates
   do not); each solve evaluates the objective on them in one call and takes the best;
2. **refinement**: an adaptive pattern search about the best command (the grid's, or the
   sensor's previous solution when that is better): a ``STENCIL x STENCIL`` stencil of
   commands ``h`` apart (clipped to the box), all copies in one call; the best feasible
   point becomes the centre; ``h`` shrinks by ``STENCIL // 2 + 1`` when the centre stays
   best or the best is inside the stencil, and doubles when the best lies on the stencil's
   edge (the optimum may be farther), until ``h < STOP``.

Constraints beyond the ``rho`` disks (the team rule ``d_sep``,
:mod:`activetrack.baselines.gsr_separation`) are capsules and sweeps (:func:`keeps`); an
infeasible point is never returned (a copy with none gets ``inf``, and GSR keeps the
sensor where it was). The result is never worse than the best grid point.

The built-in kinematics (disk, unicycle, double integrator) with the built-in sensor
models and the trace objective run the same solve compiled
(:mod:`activetrack.baselines.gsr_command_kernel`); any other kinematics with a 2-D action
box runs it in NumPy, every copy in each call.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from activetrack.kinematics.separation import segment_distance
from activetrack.validation import FloatArray

#: Commands per axis of the coarse grid over the action box.
GRID = 25
#: Commands per axis of the refinement stencil (odd).
STENCIL = 5
#: The refinement stops when the stencil's spacing (in units of the box's half-width) is
#: below this.
STOP = 1e-9
#: At most this many refinement rounds per solve.
ROUNDS = 60
#: A point moved out of a disk lands this much (relative) outside it (rounding).
_EDGE = 1e-14


def supports(kinematics) -> bool:
    """Return whether every sensor's kinematics has a 2-D action box (finite bounds, low <
    high): the command-space step applies."""
    for kin in kinematics:
        lo = np.asarray(kin.action_low, np.float64)
        hi = np.asarray(kin.action_high, np.float64)
        if lo.shape != (2,) or hi.shape != (2,):
            return False
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)):
            return False
    return True


def _outside(pts: FloatArray, targets: FloatArray, rho: FloatArray) -> np.ndarray:
    """Return whether ``pts`` (S, P, 2) keep ``rho`` (S,) from every target (S, K, 2)."""
    e = pts[:, :, None, :] - targets[:, None, :, :]
    d = np.hypot(e[..., 0], e[..., 1])
    return np.all(d >= rho[:, None, None], axis=-1)


def keeps(pts: FloatArray, origin: FloatArray, caps: FloatArray, sweeps: FloatArray) -> np.ndarray:
    """Return whether ``pts`` (S, P, 2) meet the constraints (module docstring of
    :mod:`activetrack.baselines.gsr_command_kernel`): each keeps ``r`` from every capsule
    (S, J, 5), and the segment from ``origin`` (S, 2) to it (less the sweep's ``v``) keeps
    ``r`` from every sweep point (S, J2, 5) ``(cx, cy, vx, vy, r)``."""
    ok = np.ones(pts.shape[:2], bool)
    if caps.shape[1]:
        d = segment_distance(caps[:, None, :, 0:2], caps[:, None, :, 2:4], pts[:, :, None, :])
        ok &= np.all(d >= caps[:, None, :, 4], axis=-1)
    if sweeps.shape[1]:
        o = np.broadcast_to(origin[:, None, None, :], pts.shape[:2] + (sweeps.shape[1], 2))
        rel = pts[:, :, None, :] - sweeps[:, None, :, 2:4]
        d = segment_distance(o, rel, sweeps[:, None, :, 0:2])
        ok &= np.all(d >= sweeps[:, None, :, 4], axis=-1)
    return ok


def compiled_kinematics(kin) -> tuple[int, FloatArray] | None:
    """Return ``(code, params)`` of the compiled :func:`gsr_command_kernel.point` for a
    built-in kinematics with the action box [-1, 1]^2, else None."""
    from activetrack.baselines import gsr_command_kernel as ck  # noqa: PLC0415
    from activetrack.kinematics.disk import Disk  # noqa: PLC0415
    from activetrack.kinematics.double_integrator import DoubleIntegrator  # noqa: PLC0415
    from activetrack.kinematics.unicycle import Unicycle  # noqa: PLC0415

    if tuple(kin.action_low) != (-1.0, -1.0) or tuple(kin.action_high) != (1.0, 1.0):
        return None
    from activetrack.baselines.gsr_separation import RadiusDisk  # noqa: PLC0415

    if type(kin) is Disk:
        return ck.DISK, np.array([kin.radius], np.float64)
    if type(kin) is RadiusDisk:
        return ck.RADIUS_DISK, np.zeros(1)
    if type(kin) is DoubleIntegrator:
        return ck.DOUBLE_INTEGRATOR, np.array([kin.a_max, kin.v_max, kin._dt()], np.float64)
    if type(kin) is Unicycle:
        return ck.UNICYCLE, np.array([kin.v_min, kin.v_max, kin.w_max, kin._dt()], np.float64)
    return None


def warm_start(
    kinematics, states: FloatArray, current: FloatArray, targets: FloatArray, rho: FloatArray
) -> FloatArray:
    """Return GSR's warm start (B, M, 2): each sensor's current position where that is
    feasible (reachable, outside every ``rho`` disk); else the point of the command that
    :meth:`~activetrack.Kinematics.command` gives for it (clipped to the box), moved out of
    a ``rho`` disk it falls in, when that is feasible (a fixed-wing's current position is
    never reachable: this avoids a projection per sensor and step); else the kinematics'
    :meth:`~activetrack.Kinematics.project` (the nearest feasible point)."""
    s = np.array(current, np.float64)
    B = len(s)
    rows = np.arange(B)
    for i, kin in enumerate(kinematics):
        st = states[:, i, : kin.state_dim]
        ok = np.asarray(kin.reaches(s[:, i], st), bool)
        ok &= _outside(s[:, i, None], targets, rho[:, i])[:, 0]
        bad = rows[~ok]
        if bad.size == 0:
            continue
        lo = np.asarray(kin.action_low, np.float64)
        hi = np.asarray(kin.action_high, np.float64)
        u = np.clip(np.asarray(kin.command(s[bad, i], st[bad]), np.float64), lo, hi)
        one = Prepared(kinematics, states[bad], targets[bad], rho[bad], None, None)
        pts, good = one.locate(u[:, None, :], np.arange(bad.size), i)
        s[bad, i] = np.where(good[:, :1], pts[:, 0], s[bad, i])
        for b in bad[~good[:, 0]]:
            s[b, i] = kin.project(s[b, i], st[b], targets[b], rho[b, i])
    return s


class Prepared:
    """Every copy's sensor steps in command space, with the interface of
    :class:`activetrack.baselines.gsr_numeric._Prepared` (``solve(sub, i, base)``).

    Args:
        kinematics: the M sensors' kinematics.
        states: the sensors' states (B, M, S).
        targets: (B, K, 2); ``rho``: (B, M).
        entries: ``entries(pts, sub, i) -> 3 x (len(sub), P, K)``: sensor ``i``'s information
            entries at points ``pts`` (len(sub), P, 2) about every target.
        objective: the problem's objective (``of_targets``).
        constraints: None, or ``constraints(sub, i) -> (caps, sweeps)`` beyond reach and
            ``rho`` (:func:`keeps`; read at each solve: they may depend on the others).
        compiled: None, or the weights ``(w_d, w_theta)`` (B, M) of the built-in models with
            the trace objective: the sensors whose kinematics
            :func:`compiled_kinematics` knows are solved by the compiled kernel.
    """

    def __init__(
        self,
        kinematics,
        states: FloatArray,
        targets: FloatArray,
        rho: FloatArray,
        entries: Callable,
        objective,
        constraints: Callable | None = None,
        compiled: tuple[FloatArray, FloatArray] | None = None,
    ) -> None:
        self.kin = tuple(kinematics)
        self.states, self.targets, self.rho = states, targets, rho
        self.entries, self.objective, self.constraints = entries, objective, constraints
        self.weights = compiled
        self.codes = [None if compiled is None else compiled_kinematics(k) for k in self.kin]
        B, M = rho.shape
        self.grid: dict[int, tuple] = {}
        self.last = np.full((B, M, 2), np.nan)  # each copy's last refined command, per sensor

    def _constraints(self, sub: np.ndarray, i: int) -> tuple[FloatArray, FloatArray]:
        S = len(sub)
        if self.constraints is None:
            return np.zeros((S, 0, 5)), np.zeros((S, 0, 5))
        return self.constraints(sub, i)

    # Geometry --------------------------------------------------------------------------
    def _box(self, i: int) -> tuple[FloatArray, FloatArray]:
        kin = self.kin[i]
        return np.asarray(kin.action_low, np.float64), np.asarray(kin.action_high, np.float64)

    def locate(self, u: FloatArray, sub: np.ndarray, i: int, caps=None) -> tuple:
        """Return ``(points (S, P, 2), feasible (S, P))`` of commands ``u`` (S, P, 2) from
        copies ``sub``: each point moved radially out of a ``rho`` disk, and of a capsule of
        ``caps`` (S, J, 5), it falls in (as :func:`gsr_command_kernel.locate`), and whether
        it is then feasible (reachable, outside the disks and the capsules; the sweeps are
        the caller's)."""
        kin = self.kin[i]
        state = self.states[sub, i, : kin.state_dim][:, None, :]
        pts = np.array(np.asarray(kin.apply(u, state), np.float64)[..., :2])
        moved = np.zeros(pts.shape[:2], bool)
        rho = self.rho[sub, i][:, None, None]
        for k in range(self.targets.shape[1]):
            t = self.targets[sub, k][:, None, :]
            e = pts - t
            d = np.hypot(e[..., 0], e[..., 1])[..., None]
            inside = (d < rho) & (d > 0.0)
            pts = np.where(inside, t + rho * (1.0 + _EDGE) / np.where(d > 0, d, 1.0) * e, pts)
            moved |= inside[..., 0]
        for j in range(0 if caps is None else caps.shape[1]):
            a, b, r = caps[:, None, j, 0:2], caps[:, None, j, 2:4], caps[:, None, j, 4:5]
            ab = b - a
            den = np.sum(ab * ab, -1, keepdims=True)
            t = np.clip(np.sum((pts - a) * ab, -1, keepdims=True) / np.where(den > 0, den, 1.0),
                        0.0, 1.0)  # fmt: skip
            c = a + t * ab
            e = pts - c
            d = np.hypot(e[..., 0], e[..., 1])[..., None]
            inside = (d < r) & (d > 0.0)
            pts = np.where(inside, c + r * (1.0 + _EDGE) / np.where(d > 0, d, 1.0) * e, pts)
            moved |= inside[..., 0]
        ok = _outside(pts, self.targets[sub], self.rho[sub, i])
        if caps is not None and caps.shape[1]:
            ok &= keeps(pts, self.states[sub, i, :2], caps, caps[:, :0])
        if np.any(moved):
            reach = np.asarray(kin.reaches(pts, state), bool)
            ok &= ~moved | reach
        return pts, ok

    def _value(self, pts, ok, base, sub, i, ent=None):
        """Return the objective (S, P) at ``pts``, ``inf`` where not ``ok``."""
        a, b, c = self.entries(pts, sub, i) if ent is None else ent
        v = self.objective.of_targets(
            base[0][:, None, :] + a, base[1][:, None, :] + b, base[2][:, None, :] + c
        )
        return np.where(ok & np.isfinite(v), v, np.inf)

    def _evaluate(self, u, sub, i, base, caps, sweeps):
        """Return ``(values (S, P), points (S, P, 2))`` of commands ``u`` (S, P, 2)."""
        pts, ok = self.locate(u, sub, i, caps)
        if sweeps.shape[1]:
            ok &= keeps(pts, self.states[sub, i, :2], caps[:, :0], sweeps)
        return self._value(pts, ok, base, sub, i), pts

    def _grid(self, i: int) -> tuple[FloatArray, FloatArray, np.ndarray, tuple]:
        """Return sensor ``i``'s grid: commands (P, 2), points (B, P, 2) (moved out of the
        ``rho`` disks), their feasibility (B, P), and the entries there 3 x (B, P, K)
        (cached per plan)."""
        if i not in self.grid:
            lo, hi = self._box(i)
            t = np.linspace(0.0, 1.0, GRID)
            g = np.stack(np.meshgrid(t, t, indexing="ij"), -1).reshape(-1, 2)
            u = lo + (hi - lo) * g
            allrows = np.arange(len(self.rho))
            U = np.broadcast_to(u, (len(allrows),) + u.shape)
            pts, ok = self.locate(U, allrows, i)
            self.grid[i] = (u, pts, ok, self.entries(pts, allrows, i))
        return self.grid[i]

    # The solve -------------------------------------------------------------------------
    def solve(self, sub: np.ndarray, i: int, base: tuple) -> tuple[FloatArray, FloatArray]:
        """Return ``(positions (S, 2), values (S,))`` of sensor ``i`` in copies ``sub`` with
        the others' entries ``base`` (3 x (S, K)); ``inf`` where no command is feasible."""
        if self.codes[i] is not None:
            return self._solve_compiled(sub, i, base)
        caps, sweeps = self._constraints(sub, i)
        u, pts, outside, ent = self._grid(i)
        gp = pts[sub]
        ok = outside[sub]
        if caps.shape[1] or sweeps.shape[1]:
            ok = ok & keeps(gp, self.states[sub, i, :2], caps, sweeps)
        v = self._value(gp, ok, base, sub, i, tuple(e[sub] for e in ent))
        k = np.argmin(v, axis=1)
        rows = np.arange(len(sub))
        best_u = u[k]
        best_v = v[rows, k]
        best_p = gp[rows, k]
        # The previous solution of the sensor in this copy, when better (a warm start).
        prev = self.last[sub, i]
        have = np.isfinite(prev[:, 0])
        if np.any(have):
            pv, pp = self._evaluate(prev[:, None, :], sub, i, base, caps, sweeps)
            pv = pv[:, 0]
            use = have & (pv < best_v)
            best_u = np.where(use[:, None], prev, best_u)
            best_v = np.where(use, pv, best_v)
            best_p = np.where(use[:, None], pp[:, 0], best_p)
        x, fx, px = self._refine(best_u, best_v, best_p, sub, i, base, caps, sweeps)
        self.last[sub, i] = np.where(np.isfinite(fx)[:, None], x, np.nan)
        return px, fx

    def _solve_compiled(self, sub, i, base):
        """Return :meth:`solve` by :func:`gsr_command_kernel.solve_rows`."""
        from activetrack.baselines import gsr_command_kernel as ck  # noqa: PLC0415

        code, prm = self.codes[i]
        S = len(sub)
        caps, sweeps = self._constraints(sub, i)
        kin = self.kin[i]
        out_u, out_p, out_v = np.empty((S, 2)), np.empty((S, 2)), np.empty(S)
        ck.solve_rows(
            code, prm, np.ascontiguousarray(self.states[sub, i, : kin.state_dim]),
            np.ascontiguousarray(self.targets[sub]), np.ascontiguousarray(self.rho[sub, i]),
            np.ascontiguousarray(self.weights[0][sub, i]),
            np.ascontiguousarray(self.weights[1][sub, i]),
            np.ascontiguousarray(np.stack(base, -1)), np.ascontiguousarray(caps),
            np.ascontiguousarray(sweeps), np.ascontiguousarray(self.last[sub, i]),
            GRID, STENCIL // 2, STOP, ROUNDS, out_u, out_p, out_v,
        )  # fmt: skip
        self.last[sub, i] = np.where(np.isfinite(out_v)[:, None], out_u, np.nan)
        return out_p, out_v

    def _refine(self, x, fx, px, sub, i, base, caps, sweeps):
        """Return the pattern search's ``(commands, values, points)`` from ``x`` (S, 2)."""
        lo, hi = self._box(i)
        half = 0.5 * (hi - lo)
        n = STENCIL // 2
        k = np.arange(-n, n + 1, dtype=np.float64)
        offs = np.stack(np.meshgrid(k, k, indexing="ij"), -1).reshape(-1, 2)  # (Q, 2)
        edge = np.max(np.abs(offs), axis=1) == n
        h = np.full(len(sub), 2.0 / (GRID - 1))
        live = np.isfinite(fx)
        x, fx, px = x.copy(), fx.copy(), px.copy()
        for _ in range(ROUNDS):
            live &= h >= STOP
            rows = np.flatnonzero(live)
            if rows.size == 0:
                break
            cu = np.clip(x[rows, None, :] + (h[rows, None, None] * half) * offs, lo, hi)
            s = sub[rows]
            cv, cp = self._evaluate(
                cu, s, i, tuple(b[rows] for b in base), caps[rows], sweeps[rows]
            )
            j = np.argmin(cv, axis=1)
            r = np.arange(rows.size)
            better = cv[r, j] < fx[rows]
            moved = rows[better]
            x[moved], fx[moved], px[moved] = cu[r, j][better], cv[r, j][better], cp[r, j][better]
            grow = better & edge[j]
            h[rows] = np.where(grow, np.minimum(2.0 * h[rows], 2.0), h[rows] / (n + 1))
        return x, fx, px
