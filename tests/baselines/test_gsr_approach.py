"""The lost sensors' approach (issue 36): geodesic distances around occluders, against brute
force, and GSR's approach under the team rule on ``urban_unicycle`` and ``urban``.

- :class:`Roadmap` (clearance 0) against a closed form around one square and against a
  brute-force visibility graph over every rectangle corner, with its own segment-rectangle
  test (Liang-Barsky clipping) and Floyd-Warshall, including a goal inside a rectangle
  (its legs ignore that rectangle); with the default clearance, bounded by the exact
  distance and an 8-connected grid path (a real path of the free plane, so never shorter).
- GSR on ``urban_unicycle``: four unicycles facing a building with the predicted target
  behind it, every one lost. Over closed-loop steps, every plan keeps ``d_sep`` between
  every pair along the straight paths, sampled (agent order, and the same instants), ends
  outside every building and ``rho``, moves along a path no building blocks (sampled
  points, independent test), and the team's geodesic distance (brute force) falls by a
  margin each few steps until a sensor sees the target. Without the fix (the approach
  skipped under ``d_sep``) the sensors never move: the test fails.
- GSR on ``urban`` (disks): the same situation, every move within reach and clear.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from activetrack.baselines.gsr import GSR
from activetrack.kinematics.path_rule import restate
from activetrack.models.occluders import Occluders
from activetrack.models.roadmap import CLEARANCE, Roadmap
from activetrack.world import World
from activetrack.world.presets import _BLOCKS

# --- independent geometry ---------------------------------------------------------------


def rect_of(poly):
    p = np.asarray(poly, float)
    return (p[:, 0].min(), p[:, 1].min(), p[:, 0].max(), p[:, 1].max())


def hits(a, b, rect):
    """Whether the segment [a, b] has a piece of positive length in the open rectangle."""
    x0, y0, x1, y1 = rect
    d = np.asarray(b, float) - np.asarray(a, float)
    lo, hi = 0.0, 1.0
    for p, q in ((-d[0], a[0] - x0), (d[0], x1 - a[0]), (-d[1], a[1] - y0), (d[1], y1 - a[1])):
        if p == 0.0:
            if q < 0.0:
                return False
            continue
        t = q / p
        if p < 0.0:
            lo = max(lo, t)
        else:
            hi = min(hi, t)
    if hi - lo <= 1e-12:
        return False
    m = np.asarray(a, float) + 0.5 * (lo + hi) * d
    e = 1e-9
    return bool(x0 + e < m[0] < x1 - e and y0 + e < m[1] < y1 - e)


def strictly_inside(p, rect, e=1e-9):
    x0, y0, x1, y1 = rect
    return x0 + e < p[0] < x1 - e and y0 + e < p[1] < y1 - e


def brute_geodesic(point, goal, rects):
    """The shortest path from ``point`` to ``goal`` through rectangle corners (a
    visibility graph over all corners, Floyd-Warshall); legs to the goal ignore the
    rectangles that contain it."""
    own = [r for r in rects if strictly_inside(goal, r)]
    corners = [(x, y) for (x0, y0, x1, y1) in rects for x in (x0, x1) for y in (y0, y1)]
    nodes = [tuple(point)] + corners + [tuple(goal)]
    n = len(nodes)
    w = np.full((n, n), np.inf)
    np.fill_diagonal(w, 0.0)
    for i in range(n):
        for j in range(i + 1, n):
            block = [r for r in rects if not (j == n - 1 and r in own)]
            if not any(hits(nodes[i], nodes[j], r) for r in block):
                w[i, j] = w[j, i] = np.hypot(*np.subtract(nodes[i], nodes[j]))
    for k in range(n):
        w = np.minimum(w, w[:, k : k + 1] + w[k : k + 1, :])
    return w[0, -1]


def grid_path(point, goal, rects, h, grow):
    """The length of the shortest 8-connected path on an ``h`` grid through the cells
    outside every rectangle grown by ``grow + h``, from the cell of ``point`` to that of
    ``goal``, plus the two end legs: a real path that keeps ``grow`` off the rectangles."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    lo = np.minimum(np.min([r[:2] for r in rects], 0), np.minimum(point, goal)) - 3.0
    hi = np.maximum(np.max([r[2:] for r in rects], 0), np.maximum(point, goal)) + 3.0
    xs, ys = np.arange(lo[0], hi[0] + h, h), np.arange(lo[1], hi[1] + h, h)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    g = grow + h
    free = np.ones(gx.shape, bool)
    for x0, y0, x1, y1 in rects:
        free &= ~((gx > x0 - g) & (gx < x1 + g) & (gy > y0 - g) & (gy < y1 + g))
    nx, ny = free.shape
    idx = np.arange(free.size).reshape(free.shape)
    rows, cols, wts = [], [], []
    for dx, dy in ((1, 0), (0, 1), (1, 1), (1, -1)):
        ii, jj = np.nonzero(free)
        i2, j2 = ii + dx, jj + dy
        ok = (i2 < nx) & (j2 >= 0) & (j2 < ny)
        ii, jj, i2, j2 = ii[ok], jj[ok], i2[ok], j2[ok]
        ok = free[i2, j2]
        rows.append(idx[ii[ok], jj[ok]])
        cols.append(idx[i2[ok], j2[ok]])
        wts.append(np.full(int(ok.sum()), h * np.hypot(dx, dy)))
    graph = coo_matrix(
        (np.concatenate(wts), (np.concatenate(rows), np.concatenate(cols))),
        shape=(free.size, free.size),
    ).tocsr()

    def cell(p):
        i, j = int(round((p[0] - lo[0]) / h)), int(round((p[1] - lo[1]) / h))
        assert free[i, j]
        return idx[i, j], np.hypot(gx[i, j] - p[0], gy[i, j] - p[1])

    (s, ls), (t, lt) = cell(point), cell(goal)
    return dijkstra(graph, directed=False, indices=s)[t] + ls + lt


SQUARE = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]
LAYOUT = [
    [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]],
    [[6.0, -2.0], [8.0, -2.0], [8.0, 6.0], [6.0, 6.0]][::-1],  # clockwise
    [[-3.0, 5.0], [5.0, 5.0], [5.0, 6.5], [-3.0, 6.5]],
]


def test_roadmap_around_one_square_closed_form():
    rm = Roadmap(Occluders.from_polygons([np.array(SQUARE)]), clearance=0.0)
    # Opposite sides: straight to a corner, along an edge, straight on.
    d = rm.distances(np.array([[[-3.0, 0.0]]]), np.array([[3.0, 0.0]]))[0, 0]
    assert d == pytest.approx(2.0 * np.hypot(2.0, 1.0) + 2.0, rel=1e-12)
    # Round one corner: (-2, -3) sees (1, -1) (the segment passes below the square), which
    # sees (3, 1).
    d = rm.distances(np.array([[[-2.0, -3.0]]]), np.array([[3.0, 1.0]]))[0, 0]
    assert d == pytest.approx(np.hypot(3.0, 2.0) + np.hypot(2.0, 2.0), rel=1e-12)
    # Visible: the straight line.
    d = rm.distances(np.array([[[-3.0, 2.0]]]), np.array([[3.0, 2.0]]))
    assert d[0, 0] == pytest.approx(6.0, rel=1e-12)


def test_roadmap_against_brute_force_visibility_graph():
    rects = [rect_of(p) for p in LAYOUT]
    rm = Roadmap(Occluders.from_polygons([np.array(p) for p in LAYOUT]), clearance=0.0)
    rng = np.random.default_rng(5)
    pts = rng.uniform([-6.0, -5.0], [11.0, 10.0], (60, 2))
    pts = pts[[not any(strictly_inside(p, r) for r in rects) for p in pts]]
    # Goals outside the rectangles, and one inside the first (a target in a tunnel).
    for goal in ([2.0, 8.5], [10.0, 2.0], [7.0, -4.0], [2.0, 1.5]):
        got = rm.distances(pts[None], np.array([goal]))[0]
        want = [brute_geodesic(p, goal, rects) for p in pts]
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10)
    # Inside a rectangle: no path.
    assert np.isinf(rm.distances(np.array([[[7.0, 0.0]]]), np.array([[-5.0, 0.0]]))[0, 0])


def test_roadmap_with_clearance_between_exact_and_a_grid_path():
    rects = [rect_of(p) for p in LAYOUT]
    occ = Occluders.from_polygons([np.array(p) for p in LAYOUT])
    rm = Roadmap(occ)  # the default clearance
    pairs = (([-2.0, 1.0], [10.0, 3.0]), ([2.0, -1.5], [2.0, 8.0]), ([9.5, 7.0], [1.0, 4.0]))
    for point, goal in pairs:
        got = rm.distances(np.array([[point]]), np.array([goal]))[0, 0]
        exact = brute_geodesic(point, goal, rects)
        grid = grid_path(point, goal, rects, 0.05, CLEARANCE)
        # Never shorter than the exact geodesic, never longer than a real path that keeps
        # the clearance off the walls (the roadmap turns round the grown corners).
        assert exact - 1e-9 <= got <= grid + 1e-9


# --- GSR's approach ----------------------------------------------------------------------

BLOCK3 = rect_of(_BLOCKS[2])  # (-9, 2, -5, 5.5)


SOUTH = [[-7.0, 0.5], [-8.8, 0.6], [-5.3, 0.7], [-7.2, -1.5]]


def lost_problem(scenario, sensors=SOUTH, heading=np.pi / 2):
    """The world's planning problem with the predicted target north of block 3 and the
    four sensors south of it, out of its sight (facing north: the wall)."""
    world = World(scenario, 1)
    world.reset(seeds=[1000])
    p = world.planning_problem(0)
    sensors = np.array(sensors, float)
    target = np.array([-7.0, 8.0])
    kw = {"target": target, "sensors": sensors, "prediction": None}
    if p.sensor_states is not None:
        st = np.array(p.sensor_states, float)
        st[:, :2], st[:, 2] = sensors, heading
        kw["sensor_states"] = st
    return dataclasses.replace(p, **kw)


def sees(p, t, rects, max_range):
    return np.hypot(*np.subtract(p, t)) <= max_range and not any(hits(p, t, r) for r in rects)


def path_keeps(old, plan, d):
    t = np.linspace(0.0, 1.0, 201)[:, None]
    for a in range(len(plan)):
        for b in range(a + 1, len(plan)):
            pa = old[a] + t * (plan[a] - old[a])
            pb = old[b] + t * (plan[b] - old[b])
            if (
                np.min(np.hypot(*(pa - old[b]).T)) < d
                or np.min(np.hypot(*(pb - plan[a]).T)) < d
                or np.min(np.hypot(*(pa - pb).T)) < d
            ):
                return False
    return True


def path_clear(points, rects):
    return not any(strictly_inside(q, r, 0.0) for q in points for r in rects)


@pytest.mark.parametrize("scenario", ["urban_unicycle", "urban"])
def test_lost_sensors_go_around_the_building_keeping_the_rule(scenario):
    rects = [rect_of(b) for b in _BLOCKS]
    p = lost_problem(scenario)
    target = np.asarray(p.target)
    max_range = float(np.min(p.max_range))
    d_sep = p.d_sep
    assert not any(sees(s, target, rects, max_range) for s in p.sensors)  # all lost
    start = min(brute_geodesic(s, target, rects) for s in p.sensors)
    gsr, team = GSR(), p.kinematics
    best = start
    for step in range(20):
        old = np.array(p.sensors)
        plan = np.asarray(gsr.plan(p))
        if d_sep is not None:
            assert path_keeps(old, plan, d_sep), step
        for i in range(len(plan)):
            assert not any(strictly_inside(plan[i], r, 0.0) for r in rects), (step, i)
            assert np.hypot(*(plan[i] - target)) >= p.rho[i] * (1 - 1e-12)
            assert np.hypot(*(plan[i] - old[i])) <= p.r[i] * (1 + 1e-9)
        if team is None:  # disks: the straight move
            t = np.linspace(0.0, 1.0, 101)[:, None]
            moves = [old[i] + t * (plan[i] - old[i]) for i in range(len(plan))]
            states = None
        else:
            from activetrack.kinematics.paths import path

            st = np.asarray(p.sensor_states)
            moves = [path(team[i], plan[i], st[i], 100) for i in range(len(plan))]
            states = np.stack([restate(team[i], plan[i], st[i]) for i in range(len(plan))])
        for m in moves:
            assert path_clear(m, rects)
        if any(sees(s, target, rects, max_range) for s in plan):
            break
        now = min(brute_geodesic(s, target, rects) for s in plan)
        best = min(best, now)
        kw = {"sensors": plan} if states is None else {"sensors": plan, "sensor_states": states}
        p = dataclasses.replace(p, **kw)
    else:
        pytest.fail(f"no sensor regained sight in 20 steps; geodesic {start:.2f} -> {best:.2f}")
    # It got there by closing in: around the block (the target is 6 m and more away, round
    # the corner), at least a step's reach nearer than where it started.
    assert best <= start - float(np.max(p.r))


def test_a_unicycle_near_the_wall_gets_round_the_block():
    # Sensor 0 stands 0.3 m from block 3's south wall facing it: it gets round only by
    # turning along the wall with small moves (the fine commands) whose paths stay clear.
    rects = [rect_of(b) for b in _BLOCKS]
    p = lost_problem("urban_unicycle", [[-7.0, 1.7], [-7.0, -12.0], [-4.0, -12.0], [-10.0, -12.0]])
    target, team, gsr = np.asarray(p.target), p.kinematics, GSR()
    start = brute_geodesic(p.sensors[0], target, rects)
    for _ in range(12):
        plan = np.asarray(gsr.plan(p))
        st = np.asarray(p.sensor_states)
        states = np.stack([restate(team[i], plan[i], st[i]) for i in range(len(plan))])
        p = dataclasses.replace(p, sensors=plan, sensor_states=states)
    # 12 steps of 1 m: a quarter turn (5 steps at pi / 10 a step) leaves 7 m of travel;
    # the corner is 2.3 m away, so the geodesic falls by at least 3 m.
    assert brute_geodesic(p.sensors[0], target, rects) <= start - 3.0


def test_roadmap_validates_its_input():
    occ = Occluders.from_polygons([np.array(SQUARE)])
    for bad in (-0.1, np.inf, np.nan):
        with pytest.raises(ValueError, match="clearance"):
            Roadmap(occ, clearance=bad)
    with pytest.raises(ValueError, match="one layout"):
        Roadmap(Occluders.stack([occ, occ]))
