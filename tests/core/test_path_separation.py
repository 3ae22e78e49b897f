"""The team rules along the actual paths (issue 36), against brute force.

Each step of a batched world is checked from the world's own record of the TRUE states
before and after it, without the rule's code: the command each sensor executed is
recovered from its two states (a unicycle's speed and turn rate, a double integrator's
acceleration), checked within the kinematics' limits, and integrated numerically (RK4,
200 steps) to the path it drove, which must end at the new position (the executed
motion is a command the robot can make, the state consistent). The 201 points of each
path are then checked against the rules: no point within ``d_sep`` of another sensor
where it stands when the sensor moves (sensors 0..i-1 at their new positions, i+1..M-1
at their old ones: the documented sequential rule), no two sensors closer than ``d_sep``
after the step, no point inside a building (an independent point-in-rectangle test), and
the end point outside the ``rho`` disk of every predicted target. A sensor may break the
``rho`` rule or a kinematic limit only when the world counts it ``stuck`` (held, or boxed
in), and those are counted.

The acceptance's 10,000 random steps run on each of ``crowded`` (8 disks, ``d_sep``, one
and two targets) and ``urban_unicycle`` (the urban blocks, unicycles, ``d_sep``) as many
copies times fewer steps; GSR and the look-ahead act on fewer steps (GSR's numerical
solve on unicycles is slow in this tree), so their counts are small and said here.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack import DoubleIntegrator, Unicycle
from activetrack.kinematics.disk import Disk
from activetrack.kinematics.separation import pair_distances
from activetrack.world import World
from activetrack.world.scenarios import make_scenario
from tests.core.helpers import rk4

RTOL = 1e-9
N_SAMPLES = 200  # RK4 steps of each path (201 points)
CROWDED = dict(
    n_sensors=8, d_sep=1.0, sensor_center=(8.0, 0.0), sensor_radius=5.0, x0=(0.0, 0.0, 0.0, 0.0),
    x0_hat=(0.0, 0.0, 0.0, 0.0), q=1.0, n_steps=60,
)  # fmt: skip
URBAN_UNICYCLE = dict(kinematics=Unicycle(0.0, 10.0, 8.0), d_sep=1.5)


def _wrap(a):
    return np.pi - np.mod(np.pi - a, 2.0 * np.pi)


def _limits(kins, name):
    """Return the kinematics' attribute ``name`` per sensor (M,)."""
    return np.array([getattr(k, name) for k in kins], np.float64)


def _driven(kin, dt, old, new):
    """Return ``(path (..., M, 201, 2), valid (..., M))``: the paths sensors of one
    kinematics class drove from states ``old`` to ``new`` (..., M, S) (the command
    recovered from the states, integrated), and whether that command is within the limits
    and ends at ``new``. ``kin`` is the sensors' kinematics (M,), of one class."""
    kins = tuple(kin) if isinstance(kin, (list, tuple)) else (kin,)
    first = kins[0]
    scale = 1.0 + np.max(np.abs(old[..., :2]), axis=-1)
    if isinstance(first, Unicycle):
        w_max, v_min, v_max = (_limits(kins, a) for a in ("w_max", "v_min", "v_max"))
        chord = new[..., :2] - old[..., :2]
        length = np.hypot(chord[..., 0], chord[..., 1])
        turn = _wrap(new[..., 2] - old[..., 2])
        half = 0.5 * turn
        sinc = np.where(half == 0, 1.0, np.sin(half) / np.where(half == 0, 1.0, half))
        v, w = length / (dt * sinc), turn / dt
        ok = np.abs(w) <= w_max * (1 + RTOL) + 1e-12
        ok &= (v >= v_min * (1 - RTOL) - 1e-9) & (v <= v_max * (1 + RTOL) + 1e-9)

        def f(y):
            return np.stack([v * np.cos(y[..., 2]), v * np.sin(y[..., 2]), w + 0 * y[..., 2]], -1)

        path = rk4(f, old[..., :3], dt, N_SAMPLES)[..., :2]
    elif isinstance(first, DoubleIntegrator):
        a_max, v_max = _limits(kins, "a_max"), _limits(kins, "v_max")
        acc = (new[..., 2:4] - old[..., 2:4]) / dt
        ok = np.hypot(acc[..., 0], acc[..., 1]) <= a_max * (1 + 1e-7)
        ok &= np.hypot(new[..., 2], new[..., 3]) <= v_max * (1 + 1e-9)

        def f(y):
            return np.concatenate([y[..., 2:4], acc], -1)

        path = rk4(f, old[..., :4], dt, N_SAMPLES)[..., :2]
    else:  # the disk: a straight move within its radius
        e = new[..., :2] - old[..., :2]
        ok = np.hypot(e[..., 0], e[..., 1]) <= _limits(kins, "radius") * (1 + RTOL)
        s = np.linspace(0.0, 1.0, N_SAMPLES + 1)[:, None]
        path = old[..., None, :2] + s * e[..., None, :]
    miss = path[..., -1, :] - new[..., :2]
    ok &= np.hypot(miss[..., 0], miss[..., 1]) <= 1e-7 * scale
    # A sensor held where it is (one that cannot stop, boxed in) does not move: its path
    # is its position (a break of its kinematics unless staying is a command of it).
    # (A move back to where it started, a double integrator's parabola, is a command.)
    held = np.all(new[..., :2] == old[..., :2], axis=-1) & ~ok
    path = np.where(held[..., None, None], old[..., None, :2], path)
    return path, ok


def _endpoints(kin, dt, state, n=41):
    """Return the end points (n^2, 2) of a grid of commands within the kinematics' limits
    from ``state`` (closed forms of the motions)."""
    u, t = (g.ravel() for g in np.meshgrid(np.linspace(0, 1, n), np.linspace(-1, 1, n)))
    if isinstance(kin, Unicycle):
        v, w = kin.v_min + u * (kin.v_max - kin.v_min), t * kin.w_max
        half = 0.5 * w * dt
        sinc = np.where(half == 0, 1.0, np.sin(half) / np.where(half == 0, 1.0, half))
        ang = state[2] + half
        return state[:2] + (v * dt * sinc)[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    if isinstance(kin, DoubleIntegrator):
        a = kin.a_max * u[:, None] * np.stack([np.cos(np.pi * t), np.sin(np.pi * t)], -1)
        vel = state[2:4] + a * dt
        ok = np.hypot(vel[:, 0], vel[:, 1]) <= kin.v_max
        return (state[:2] + state[2:4] * dt + 0.5 * a * dt * dt)[ok]
    r = kin.radius * u[:, None]
    return state[:2] + r * np.stack([np.cos(np.pi * t), np.sin(np.pi * t)], -1)


def _rectangles(world):
    """Return the occluders as axis-aligned rectangles (P, 4) (xmin, ymin, xmax, ymax)."""
    out = []
    for poly in world.scenario.occluders or ():
        v = np.asarray(poly, float)
        xs, ys = np.unique(v[:, 0]), np.unique(v[:, 1])
        assert len(v) == 4 and len(xs) == 2 and len(ys) == 2  # the test's own geometry
        out.append([xs[0], ys[0], xs[1], ys[1]])
    return np.array(out).reshape(-1, 4)


def _states(world):
    true = world.get("sensors").copy()
    motion = world.get("motion") if world._n_motion else np.zeros(true.shape[:-1] + (0,))
    return np.concatenate([true, motion], -1)


class Checker:
    """Steps a batched world and checks every copy's step by brute force."""

    def __init__(self, world):
        self.world = world
        sc = world.scenario
        self.m, self.kins, self.dt = sc.n_sensors, sc.kinematics_models, sc.dt
        self.d = pair_distances(sc.d_sep, self.m)
        self.rho = np.broadcast_to(world.params.rho, (self.m,))
        self.rects = _rectangles(world)
        self.steps = self.stuck = self.changed = self.trapped = self.collisions = 0
        self.timed = 0

    def step(self, act, absolute=False):
        w = self.world
        before, fixes = _states(w), w.get("fixes").copy()
        k = w.n_targets
        pred = w.get("x_pred").copy()[..., :2]
        pred = pred[:, None] if k == 1 else pred  # (N, K, 2)
        stuck0 = w.get("n_stuck").copy()
        self.layouts = w.occluders()  # (the step's; a reset may draw new ones)
        (w.step if absolute else w.step_actions)(act)
        after = _states(w)
        self.collisions += int(np.sum(w.get("collisions")))
        self.check(before, after, fixes, pred, w.get("n_stuck") - stuck0)
        ended = w.get("truncated") | w.get("terminated")
        if np.any(ended):
            w.reset(ended)

    def check(self, before, after, fixes, pred, n_stuck):
        n, m = before.shape[:2]
        paths = np.empty((n, m, N_SAMPLES + 1, 2))
        bad = np.zeros((n, m), bool)  # a kinematic limit broken
        for cls in {type(k) for k in self.kins}:  # the sensors of a class integrated together
            idx = [i for i, k in enumerate(self.kins) if type(k) is cls]
            kins, sd = [self.kins[i] for i in idx], self.kins[idx[0]].state_dim
            paths[:, idx], ok = _driven(kins, self.dt, before[:, idx, :sd], after[:, idx, :sd])
            bad[:, idx] = ~ok
        old, new = before[..., :2], after[..., :2]
        # Separation after the step.
        e = new[:, :, None] - new[:, None]
        dist = np.hypot(e[..., 0], e[..., 1]) + np.where(np.eye(m, dtype=bool), np.inf, 0.0)
        assert np.all(dist >= self.d * (1 - RTOL)), np.min(dist - self.d)
        # No crossing within the step: i's path against j where it stands when i moves.
        ji = np.arange(m)
        there = np.where((ji[None, :] < ji[:, None])[None, :, :, None], new[:, None], old[:, None])
        f = paths[:, :, :, None, :] - there[:, :, None, :, :]  # (N, M_i, S, M_j, 2)
        eye = np.where(np.eye(m, dtype=bool), np.inf, 0.0)
        near = np.min(np.hypot(f[..., 0], f[..., 1]), axis=2) + eye
        assert np.all(near >= self.d * (1 - RTOL)), np.min(near - self.d)
        # The robots move together: every pair keeps d_ij at every same instant of the
        # step (the paths sampled at the same 201 instants).
        g = paths[:, :, None] - paths[:, None]  # (N, M, M, S, 2)
        same = np.min(np.hypot(g[..., 0], g[..., 1]), axis=-1) + eye
        self.timed += int(np.count_nonzero(np.triu(same < self.d * (1 - RTOL), 1)))
        assert self.timed == 0, np.min(same - self.d)
        # Never inside a building, anywhere along the path (point in rectangle).
        for x0, y0, x1, y1 in self.rects:
            eps = 1e-9 * max(1.0, abs(x0), abs(x1), abs(y0), abs(y1))
            px, py = paths[..., 0], paths[..., 1]
            inside = (px > x0 + eps) & (px < x1 - eps) & (py > y0 + eps) & (py < y1 - eps)
            assert not np.any(inside)
        if self.world.scenario.random_occluders:  # each copy's own layout: its point test
            from activetrack.models.occluders import inside  # noqa: PLC0415

            assert not np.any(inside(paths, self.layouts))
        # rho, in the frame the sensor plans in (its fix plus the displacement).
        believed = fixes + (new - old)
        g = believed[:, :, None] - pred[:, None]
        in_rho = np.any(np.hypot(g[..., 0], g[..., 1]) < self.rho[None, :, None] * (1 - RTOL), -1)
        # Only a sensor the world counts stuck breaks its kinematics, or the rho rule when
        # it could have kept it (a dense grid of its commands has a point outside).
        for c, i in zip(*np.nonzero(in_rho), strict=True):
            kin = self.kins[i]
            ends = _endpoints(kin, self.dt, before[c, i, : kin.state_dim]) + (
                fixes[c, i] - old[c, i]
            )
            h = ends[:, None] - pred[c][None]
            in_rho[c, i] = np.any(np.all(np.hypot(h[..., 0], h[..., 1]) > self.rho[i], -1))
            self.trapped += not in_rho[c, i]
        assert np.all(np.count_nonzero(in_rho | bad, -1) <= n_stuck)
        self.steps += n
        self.stuck += int(np.sum(n_stuck))
        self.changed += int(np.count_nonzero(np.any(np.abs(new - old) > 0, -1)))


def _random_run(scenario, copies, steps, seed=0):
    world = World(scenario, copies)
    world.reset(seeds=range(copies))
    chk = Checker(world)
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        chk.step(rng.uniform(-1.0, 1.0, (copies, chk.m, 2)))
    return world, chk


@pytest.mark.parametrize(
    "name, kw, copies, steps",
    [
        ("paper", CROWDED, 100, 100),  # crowded, one target (the disks' closed-form rule)
        ("two_targets", CROWDED, 50, 100),  # crowded around two targets
        ("urban", URBAN_UNICYCLE, 50, 200),  # urban_unicycle: the path rule, arcs
    ],
)
def test_ten_thousand_random_steps_keep_the_team_rules(name, kw, copies, steps):
    kw = dict(kw)
    if name == "two_targets":
        kw.pop("x0"), kw.pop("x0_hat")
    world, chk = _random_run(make_scenario(name, **kw), copies, steps)
    assert chk.steps == copies * steps >= 5000
    assert chk.collisions > 0  # the rule had work to do


@pytest.mark.parametrize(
    "kw",
    [
        dict(CROWDED, pose_cov=0.05),  # disks with uncertain fixes: the TRUE positions
        dict(CROWDED, kinematics=DoubleIntegrator(20.0, 10.0)),
        dict(CROWDED, kinematics=Unicycle(5.0, 10.0, 8.0)),  # cannot stop: held when boxed
        dict(
            CROWDED,
            kinematics=Unicycle(0.0, 10.0, 8.0),
            pose_cov=0.05,
            occluders=[[(2.0, 2.0), (5.0, 2.0), (5.0, 3.0), (2.0, 3.0)]],
        ),  # fmt: skip
    ],
    ids=["pose_cov", "double_integrator", "fixed_wing", "unicycle_pose_occluder"],
)
def test_every_kinematics_with_pose_noise_and_occluders(kw):
    _random_run(make_scenario("paper", **kw), 20, 50, seed=1)


@pytest.mark.parametrize("kin", [Unicycle(0.0, 10.0, 8.0, 0.1), DoubleIntegrator(30.0, 10.0, 0.1)])
def test_sampled_paths_and_their_bounds(kin):
    """The rule's sampled path against RK4 of the command, and the bound between samples
    (and the occluder hull) against a dense sampling of the same motion."""
    from activetrack.kinematics.paths import hull_segments, path, slack  # noqa: PLC0415
    from activetrack.kinematics.separation import segment_distance  # noqa: PLC0415

    rng = np.random.default_rng(3)
    m = 200
    st = np.zeros((m, kin.state_dim))
    st[:, :2] = rng.uniform(-5, 5, (m, 2))
    if isinstance(kin, Unicycle):
        st[:, 2] = rng.uniform(-np.pi, np.pi, m)
    else:
        st[:, 2:4] = rng.uniform(-1, 1, (m, 2)) * 5.0
    ends = kin.apply(rng.uniform(-1, 1, (m, 2)), st)
    nxt = kin.advance(kin.command(ends, st), st)
    if isinstance(kin, DoubleIntegrator):
        nxt[:, :2] = ends
        nxt[:, 2:] = 2.0 * (ends - st[:, :2]) / kin.dt - st[:, 2:]
    else:
        nxt[:, :2] = ends
    dense, ok = _driven(kin, kin.dt, st, nxt)  # RK4, 200 steps
    assert np.all(ok)
    coarse = path(kin, ends, st, 8)
    np.testing.assert_allclose(coarse, dense[:, ::25], atol=1e-9)
    # Every dense point lies within the slack of the coarse polyline (at its own piece).
    a, b = coarse[:, :-1], coarse[:, 1:]
    piece = np.minimum(np.arange(N_SAMPLES + 1) // 25, 7)
    gap = segment_distance(a[:, piece], b[:, piece], dense)
    sl = slack(coarse)
    assert np.all(gap <= sl[:, None] + 1e-12) and np.max(gap / sl[:, None]) > 0.5
    # ...and inside the triangle of its piece's hull segments (its three sides' union).
    ha, hb = hull_segments(kin, ends, st, 8)  # (m, 24, 2): chords, then the two sides
    c = hb[:, 8:16]  # the control points
    tri = np.stack([a[:, piece], b[:, piece], c[:, piece]], -2)  # (m, S, 3, 2)

    def cross(o, p, q):
        return (p[..., 0] - o[..., 0]) * (q[..., 1] - o[..., 1]) - (p[..., 1] - o[..., 1]) * (
            q[..., 0] - o[..., 0]
        )

    s1 = cross(tri[..., 0, :], tri[..., 1, :], dense)
    s2 = cross(tri[..., 1, :], tri[..., 2, :], dense)
    s3 = cross(tri[..., 2, :], tri[..., 0, :], dense)
    tol = 1e-9
    inside = ((s1 >= -tol) & (s2 >= -tol) & (s3 >= -tol)) | (
        (s1 <= tol) & (s2 <= tol) & (s3 <= tol)
    )
    assert np.all(inside)


def test_random_layouts_each_copy_its_own():
    sc = make_scenario("urban_random", **URBAN_UNICYCLE)
    _, chk = _random_run(sc, 8, 20, seed=4)
    assert chk.collisions > 0


def test_urban_fixed_wing_and_double_integrator():
    for kin in (Unicycle(4.0, 10.0, 8.0), DoubleIntegrator(30.0, 10.0)):
        _random_run(make_scenario("urban", kinematics=kin, d_sep=1.5), 20, 60, seed=2)


@pytest.mark.parametrize(
    "planner, name, kw",
    [
        ("gsr", "paper", CROWDED),
        ("lookahead", "paper", CROWDED),
        ("gsr", "urban", URBAN_UNICYCLE),
        ("lookahead", "urban", URBAN_UNICYCLE),
    ],
)
def test_planned_steps_keep_the_team_rules(planner, name, kw):
    """GSR's and the look-ahead's plans, executed: 2 copies x 6 steps each (small: the
    planners on unicycles are slow in this tree)."""
    if planner == "gsr":
        from activetrack.baselines.gsr import GSR  # noqa: PLC0415

        plan = GSR().plan
    else:
        from activetrack.baselines.lookahead import LookaheadPlanner  # noqa: PLC0415

        plan = LookaheadPlanner(name).plan
    world = World(make_scenario(name, **kw), 2)
    world.reset(seeds=[5, 6])
    chk = Checker(world)
    for _ in range(6):
        pts = plan(world.planning_problem())  # (the copies planned together, as batched)
        chk.step(pts, absolute=True)
    assert chk.steps == 12


def test_the_path_rule_fixes_the_straight_occluder_check():
    """A unicycle whose chord to its wanted point is clear but whose arc cuts a
    building's corner is stopped (the old rule checked the chord only)."""
    from activetrack.models.occluders import Occluders, blocked  # noqa: PLC0415

    kin = Unicycle(0.0, 10.0, 20.0)
    # Facing east at the origin, a full left turn: the arc bulges to the left (north).
    # (dt 0.1: radius 0.5 about (0, 0.5), 2 rad; the chord runs from (0, 0) to (0.455, 0.708))
    box = [(0.45, 0.3), (0.6, 0.3), (0.6, 0.45), (0.45, 0.45)]
    sc = make_scenario("paper", n_sensors=1, kinematics=kin, occluders=[box],
                       sensor_center=(0.0, 0.0), sensor_radius=1e-9, x0=(30.0, 0.0, 0.0, 0.0),
                       x0_hat=(30.0, 0.0, 0.0, 0.0))  # fmt: skip
    world = World(sc, 2)
    world.reset(seeds=[0, 1])
    state = world.sensor_states()[0, 0].copy()
    assert abs(state[2]) < 1e-6  # facing the target, east
    bound = sc.kinematics_models[0]
    act = np.ones((2, 1, 2))
    free = bound.apply(act[0, 0], state)
    occ = Occluders.from_polygons([box])
    assert not blocked(state[:2], free, occ)  # the chord is clear...
    before = _states(world)
    world.step_actions(act)
    after = _states(world)
    path, ok = _driven(bound, sc.dt, before[0, 0], after[0, 0])
    x, y = path[..., 0], path[..., 1]
    assert ok and not np.any((x > 0.45) & (x < 0.6) & (y > 0.3) & (y < 0.45))
    full, _ = _driven(bound, sc.dt, before[0, 0], np.r_[free, state[2] + bound.w_max * sc.dt])
    x, y = full[..., 0], full[..., 1]
    assert np.any((x > 0.45) & (x < 0.6) & (y > 0.3) & (y < 0.45))  # ...the arc is not


@pytest.mark.parametrize("turn", [0.5, -1.0, 0.0])
def test_a_unicycle_facing_a_wall_stays_and_turns_as_asked(turn):
    """A unicycle that can stop, its every forward move into a wall 5 cm ahead, stays
    where it is and turns in place by its command's turn ``w dt`` (a turn moves no point
    of it); the next step it can leave along the wall."""
    kin = Unicycle(0.0, 10.0, np.pi)
    wall = [(0.05, -2.0), (1.0, -2.0), (1.0, 2.0), (0.05, 2.0)]
    sc = make_scenario("paper", n_sensors=1, kinematics=kin, occluders=[wall],
                       sensor_center=(0.0, 0.0), sensor_radius=1e-9, x0=(30.0, 0.0, 0.0, 0.0),
                       x0_hat=(30.0, 0.0, 0.0, 0.0))  # fmt: skip
    world = World(sc)
    world.reset(seeds=[0])
    before = world.sensor_states(0)[0].copy()
    assert abs(before[2]) < 1e-9  # facing the wall (and the target beyond it), east
    world.step_actions(np.array([[1.0, turn]]))  # full speed ahead: into the wall
    after = world.sensor_states(0)[0]
    np.testing.assert_array_equal(after[:2], before[:2])
    # The env's action: w = a_1 w_max, so the heading turns by a_1 w_max dt.
    assert after[2] == pytest.approx(before[2] + turn * np.pi * sc.dt, abs=1e-12)
    if turn:  # turning on, it comes to face along the wall within a quarter turn, and goes
        for _ in range(int(np.ceil(0.5 / sc.dt))):  # pi/2 at w_max = pi rad/s
            world.step_actions(np.array([[1.0, np.sign(turn)]]))
            assert world.sensor_states(0)[0, 0] < 0.05  # never into the wall
        assert np.hypot(*(world.sensor_states(0)[0, :2] - before[:2])) > 0.2


def test_d_sep_too_large_for_the_start_names_the_field_with_robots():
    for kin in (Unicycle(0.0, 10.0, 2.0), DoubleIntegrator(5.0, 10.0), Disk(1.0)):
        with pytest.raises(ValueError, match="d_sep=4.0 does not fit the team's start"):
            make_scenario("paper", n_sensors=8, d_sep=4.0, kinematics=kin)
