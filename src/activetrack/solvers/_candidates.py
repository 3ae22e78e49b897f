"""The numerical single-sensor solver's candidates: where its starts are sampled.

On each boundary circle of the feasible set a uniform grid of angles plus, around the
direction to each target, angles at multiples ``WELL_OFFSETS`` of the target's angular
well width; with several targets a square grid of the reach disk and a log-polar grid of
``POLAR_RINGS`` rings of ``POLAR_ANGLES`` angles around each target (finer closer in).
:func:`_tables` gives the candidates' neighbours (a local minimum has no lower neighbour)
and groups. Used by :class:`activetrack.solvers.numeric.Prepared`.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np

from activetrack.solvers._refine import _TINY, _circle_points
from activetrack.validation import FloatArray

if TYPE_CHECKING:
    from activetrack.solvers.numeric import _Problem

#: Multipliers of a target's angular well width at which extra angles are placed.
WELL_OFFSETS = np.array(
    [0.0, 0.125, -0.125, 0.25, -0.25, 0.5, -0.5, 1.0, -1.0, 2.0, -2.0, 4.0, -4.0]
)


#: Rings and angles of the log-polar grid around each target (interior, K >= 2).
POLAR_RINGS = 8


POLAR_ANGLES = 12


def _arc_candidates(p: _Problem, n_boundary: int) -> list[tuple[FloatArray, ...]]:
    """Return two groups of circle candidates ``(origins, radii, angles, points)``.

    Shapes (B, n, 2), (B, n), (B, n, M), (B, n, M, 2): the reach circle (n = 1) with
    ``n_boundary`` uniform angles plus the well angles around each target's direction,
    sorted; the ``rho`` circles (n = K) with ``n_boundary`` uniform angles (a circle's own
    target is at constant distance, so it has no well).
    """
    b = len(p.r)
    dist = np.hypot(p.t[..., 0], p.t[..., 1])  # reach circle's centre -> targets (B, K)
    phi = np.arctan2(p.t[..., 1], p.t[..., 0])
    width = np.maximum(np.abs(dist - p.r[:, None]), p.rho[:, None])
    # Wider wells are resolved by the uniform grid (spacing 2 pi / n_boundary).
    sigma = np.minimum(width / np.maximum(p.r[:, None], _TINY), 0.25)
    well = (phi[..., None] + sigma[..., None] * WELL_OFFSETS).reshape(b, -1)
    uniform = np.linspace(-np.pi, np.pi, n_boundary, endpoint=False)
    th0 = np.concatenate([np.broadcast_to(uniform, (b, n_boundary)), well], axis=-1)
    th0 = np.sort(np.mod(th0 + np.pi, 2.0 * np.pi) - np.pi, axis=-1)[:, None]
    th1 = np.broadcast_to(uniform, (b, p.origins.shape[1] - 1, n_boundary))
    groups = []
    for sl, th in ((slice(0, 1), th0), (slice(1, None), th1)):
        o, rad = p.origins[:, sl], p.radii[:, sl]
        pts = _circle_points(o[:, :, None, :], np.broadcast_to(rad[..., None], th.shape), th)
        groups.append((o, rad, th, pts))
    return groups


@functools.lru_cache(maxsize=8)
def _unit_grid(n: int) -> tuple[FloatArray, np.ndarray]:
    """Return the ``n x n`` square grid over [-1, 1]^2 (n n, 2) and the indices in the unit disk."""
    u = np.linspace(-1.0, 1.0, n)
    grid = np.stack(np.meshgrid(u, u, indexing="ij"), -1).reshape(-1, 2)
    inside = np.flatnonzero(np.hypot(grid[:, 0], grid[:, 1]) <= 1.0)
    grid.flags.writeable = inside.flags.writeable = False
    return grid, inside


def _interior_candidates(p: _Problem, n_interior: int) -> tuple[FloatArray, np.ndarray, FloatArray]:
    """Return the square grid over the reach disk (B, n n, 2), the indices inside the disk,
    and the spacing (B,)."""
    grid, inside = _unit_grid(n_interior)
    pts = p.r[:, None, None] * grid
    return pts, inside, p.r * (2.0 / max(n_interior - 1, 1))


def _polar_candidates(p: _Problem) -> tuple[FloatArray, FloatArray]:
    """Return log-polar grids around each target (B, K, R, A, 2) and their ring steps (B, K, R).

    Near a target ``f`` varies on the scale of the distance to it (the bearing information
    grows as its inverse square), so an interior optimum there (possible with K >= 2: the
    other targets pull elsewhere) needs a grid that is finer closer in: ``POLAR_RINGS``
    rings from ``1.3 rho`` (at least ``1e-3 r``) out to ``r`` in geometric progression,
    ``POLAR_ANGLES`` angles each.
    """
    inner = 1.3 * np.maximum(p.rho, 1e-3 * p.r)
    outer = np.maximum(p.r, 2.0 * inner)
    frac = np.arange(POLAR_RINGS) / (POLAR_RINGS - 1)
    radii = inner[:, None] * (outer / inner)[:, None] ** frac  # (B, R)
    ang = np.linspace(-np.pi, np.pi, POLAR_ANGLES, endpoint=False)
    unit = np.stack([np.cos(ang), np.sin(ang)], -1)  # (A, 2)
    pts = p.t[:, :, None, None, :] + radii[:, None, :, None, None] * unit
    step = np.broadcast_to(radii[:, None, :] * (2.0 * np.pi / POLAR_ANGLES), pts.shape[:3])
    return pts, step


def _cyclic(n_rings: int, n: int) -> np.ndarray:
    """Return the neighbours (n_rings n, 4) of points on rings of ``n`` cyclic angles:
    the previous and next angle, and the same angle on the previous and next ring (-1
    where there is none)."""
    ring, ang = np.divmod(np.arange(n_rings * n), n)
    return np.stack(
        [
            ring * n + (ang - 1) % n,
            ring * n + (ang + 1) % n,
            np.where(ring > 0, (ring - 1) * n + ang, -1),
            np.where(ring < n_rings - 1, (ring + 1) * n + ang, -1),
        ],
        -1,
    )


def _grid_neighbours(n: int, inside: np.ndarray) -> np.ndarray:
    """Return the 4 neighbours (len(inside), 4) of the square grid points ``inside`` (flat
    indices of an ``n x n`` grid), as positions in ``inside`` (-1 outside the disk)."""
    where = np.full(n * n, -1)
    where[inside] = np.arange(len(inside))
    i, j = np.divmod(inside, n)
    out = []
    for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        ii, jj = i + di, j + dj
        ok = (ii >= 0) & (ii < n) & (jj >= 0) & (jj < n)
        out.append(np.where(ok, where[np.where(ok, ii * n + jj, 0)], -1))
    return np.stack(out, -1)


@functools.lru_cache(maxsize=64)
def _tables(
    nv: int, n0: int, n1: int, nc: int, k: int, n_interior: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Return the candidates' neighbours (C, 4), the start groups (G, n) and how many of
    the groups are circles, for the layout of :class:`Prepared` (``C`` stands for none).

    Neighbours: the previous and next angle on each circle (cyclic); the 4 grid neighbours
    inside the disk; on the polar grids the previous and next angle (cyclic) and the same
    angle on the previous and next ring of the same target. Groups: the reach circle, each
    of the ``nc`` circles about the targets (``rho``, then the sensing ranges), and
    (``n_interior > 0``) the square grid and the K polar grids.
    """
    # Circles: only the neighbouring angles (no rings across circles).
    nbr = [
        np.full((nv, 4), -1),
        np.concatenate([nv + _cyclic(1, n0)[:, :2], np.full((n0, 2), -1)], 1),
        np.concatenate([nv + n0 + _cyclic(nc, n1)[:, :2], np.full((nc * n1, 2), -1)], 1),
    ]
    groups = [nv + np.arange(n0)] + [nv + n0 + c * n1 + np.arange(n1) for c in range(nc)]
    arc_groups = len(groups)
    if n_interior:
        inside = _unit_grid(n_interior)[1]
        start, ng = nv + n0 + nc * n1, len(inside)
        g_nbr = _grid_neighbours(n_interior, inside)
        p_nbr = _cyclic(k * POLAR_RINGS, POLAR_ANGLES)
        # Polar rings of different targets are not neighbours.
        ring = np.arange(k * POLAR_RINGS * POLAR_ANGLES) // POLAR_ANGLES % POLAR_RINGS
        p_nbr[:, 2] = np.where(ring > 0, p_nbr[:, 2], -1)
        p_nbr[:, 3] = np.where(ring < POLAR_RINGS - 1, p_nbr[:, 3], -1)
        nbr.append(np.where(g_nbr >= 0, start + g_nbr, -1))
        nbr.append(np.where(p_nbr >= 0, start + ng + p_nbr, -1))
        groups += [start + np.arange(ng), start + ng + np.arange(k * POLAR_RINGS * POLAR_ANGLES)]
    nbr = np.concatenate(nbr, axis=0)
    c = len(nbr)
    table = np.full((len(groups), max(len(g) for g in groups)), c)
    for i, g in enumerate(groups):
        table[i, : len(g)] = g
    neighbours = np.where(nbr >= 0, nbr, c)
    neighbours.flags.writeable = table.flags.writeable = False
    return neighbours, table, arc_groups
