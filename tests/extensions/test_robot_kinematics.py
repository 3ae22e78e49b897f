"""The robots' kinematics with a state beyond the position, ``Unicycle`` and
``DoubleIntegrator``, against independent computations:

- the exact integration against a fine numerical integration of the ODE
  (``scipy.integrate.solve_ivp``, tolerances 1e-12);
- the reach set against a dense sampling of the command box (every sampled endpoint
  reached; membership agrees with the sampled cloud away from its edge; the reach set's
  boundary on the cloud's edge);
- the projection onto the feasible set never farther than a brute-force search over a
  dense command grid plus the ``rho`` circles (1e-6 relative), with the ``rho`` disks active
  and inactive, one and two targets, and an empty feasible set;
- the command that reaches a point reproduces it (and the command);
- bad parameters raise ValueError naming the field.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.spatial import cKDTree

from activetrack import DoubleIntegrator, Unicycle

DT = 0.1


# Longhand ----------------------------------------------------------------------------------
def unicycle_ode(state, v, w):
    """Return the state after ``DT`` of ``x' = v cos th, y' = v sin th, th' = w`` (solve_ivp)."""
    sol = solve_ivp(lambda t, s: [v * np.cos(s[2]), v * np.sin(s[2]), w], (0.0, DT), state,
                    method="DOP853", rtol=1e-12, atol=1e-12)  # fmt: skip
    return sol.y[:, -1]


def double_integrator_ode(state, a):
    """Return the state after ``DT`` of ``p'' = a`` (solve_ivp)."""
    sol = solve_ivp(lambda t, s: [s[2], s[3], a[0], a[1]], (0.0, DT), state, method="DOP853",
                    rtol=1e-12, atol=1e-12)  # fmt: skip
    return sol.y[:, -1]


def unicycle_cloud(kin, state, n=401):
    """Return the endpoints of a dense grid of commands (v, w) over the box, edges
    included, integrated longhand (the arc's closed form from its centre of rotation; the
    straight line when w = 0), (n^2, 2)."""
    v, w = np.meshgrid(np.linspace(kin.v_min, kin.v_max, n), np.linspace(-kin.w_max, kin.w_max, n))
    v, w = v.ravel(), w.ravel()
    th = state[2]
    turn = np.abs(w) > 0
    ws = np.where(turn, w, 1.0)
    x = np.where(turn, state[0] + v / ws * (np.sin(th + w * DT) - np.sin(th)),
                 state[0] + v * DT * np.cos(th))  # fmt: skip
    y = np.where(turn, state[1] - v / ws * (np.cos(th + w * DT) - np.cos(th)),
                 state[1] + v * DT * np.sin(th))  # fmt: skip
    return np.stack([x, y], -1)


def di_cloud(kin, state, n=401):
    """Return the endpoints ``p + v dt + a dt^2 / 2`` of a dense polar grid of accelerations
    with ``|a| <= a_max`` and ``|v + a dt| <= v_max`` (the circle of ``a_max`` included),
    (P, 2)."""
    r, ang = np.meshgrid(np.linspace(0.0, 1.0, n), np.linspace(-np.pi, np.pi, 4 * n))
    a = kin.a_max * np.stack([r * np.cos(ang), r * np.sin(ang)], -1).reshape(-1, 2)
    v = state[2:]
    a = a[np.hypot(*(v + a * DT).T) <= kin.v_max]
    # The speed circle's arc inside the acceleration disk (the other edge of the set).
    u = np.stack([np.cos(ang[:, 0]), np.sin(ang[:, 0])], -1)
    a2 = (kin.v_max * u - v) / DT
    a2 = a2[np.hypot(*a2.T) <= kin.a_max]
    a = np.concatenate([a, a2])
    return state[:2] + v * DT + 0.5 * a * DT * DT


def unicycle_member(kin, state, pts):
    """Return whether ``pts`` are endpoints, by inverting the arc longhand: the chord's
    angle from the heading gives w = 2 phi / dt, its length the speed v."""
    d = pts - state[:2]
    rho = np.hypot(*d.T)
    phi = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - state[2])))
    w = 2 * phi / DT
    with np.errstate(invalid="ignore", divide="ignore"):
        v = np.where(phi == 0, rho / DT, rho * w / (2 * np.sin(phi)))
    v = np.where(rho == 0, 0.0, v)
    w = np.where(rho == 0, 0.0, w)
    tol = 1e-9
    return (np.abs(w) <= kin.w_max * (1 + tol) + tol) & (v >= kin.v_min - tol) & (
        v <= kin.v_max * (1 + tol) + tol)  # fmt: skip


def di_member(kin, state, pts):
    """Return whether ``pts`` are reached: the acceleration ``2 (p' - p - v dt) / dt^2``
    within ``a_max`` and the new velocity within ``v_max``, written out."""
    a = 2 * (pts - state[:2] - state[2:] * DT) / DT**2
    vel = state[2:] + a * DT
    return (np.hypot(*a.T) <= kin.a_max * (1 + 1e-9)) & (np.hypot(*vel.T) <= kin.v_max * (1 + 1e-9))


def outside(pts, targets, rho, tol=1e-9):
    d = np.hypot(*(pts[:, None, :] - targets[None]).transpose(2, 0, 1))
    return np.all(d >= rho * (1 - tol), axis=1)


def rings(targets, rho, n=40_001):
    ang = np.linspace(-np.pi, np.pi, n)
    return np.concatenate([t + rho * np.stack([np.cos(ang), np.sin(ang)], -1) for t in targets])


KINEMATICS = {
    "unicycle": (Unicycle(0.0, 10.0, 4.0, dt=DT), np.array([1.0, -2.0, 0.7]), unicycle_cloud,
                 unicycle_member),
    "fixed_wing": (Unicycle(4.0, 10.0, 6.0, dt=DT), np.array([-3.0, 5.0, -2.5]), unicycle_cloud,
                   unicycle_member),
    "double_integrator": (DoubleIntegrator(60.0, 10.0, dt=DT), np.array([2.0, 1.0, 6.0, -4.0]),
                          di_cloud, di_member),
}  # fmt: skip


# (a) the exact integration -----------------------------------------------------------------
@pytest.mark.parametrize("w", [0.0, 1e-9, -1e-5, 0.3, -3.9, 4.0])
def test_unicycle_integration_matches_the_ode(w):
    kin = Unicycle(0.0, 10.0, 4.0, dt=DT)
    rng = np.random.default_rng(0)
    for _ in range(5):
        state = np.r_[rng.uniform(-50, 50, 2), rng.uniform(-np.pi, np.pi)]
        v = rng.uniform(0, 10)
        got = kin.integrate(v, w, state)
        want = unicycle_ode(state, v, w)
        np.testing.assert_allclose(got[:2], want[:2], rtol=0, atol=1e-10)
        assert abs(np.angle(np.exp(1j * (got[2] - want[2])))) < 1e-10
        assert -np.pi < got[2] <= np.pi
        # The action that asks for (v, w) advances to the same state.
        act = np.array([2 * v / 10 - 1, w / 4])
        np.testing.assert_allclose(kin.advance(act, state), got, rtol=0, atol=1e-12)


def test_double_integrator_integration_matches_the_ode():
    kin = DoubleIntegrator(60.0, 10.0, dt=DT)
    rng = np.random.default_rng(1)
    for _ in range(10):
        state = np.r_[rng.uniform(-50, 50, 2), rng.uniform(-5, 5, 2)]
        u = rng.uniform(-1, 1, 2)
        u /= max(1.0, np.hypot(*u))
        a = 60.0 * u
        want = double_integrator_ode(state, a)
        if np.hypot(*want[2:]) > 10.0:  # the speed bound restricts it: checked below
            continue
        np.testing.assert_allclose(kin.advance(u, state), want, rtol=0, atol=1e-10)
    # Every step keeps the speed bound, and the new velocity is v + a dt of the acceleration
    # the move implies (the position and velocity integrate one constant acceleration).
    state = np.array([0.0, 0.0, 9.0, 0.0])
    for _ in range(50):
        nxt = kin.advance(rng.uniform(-1, 1, 2), state)
        a = 2 * (nxt[:2] - state[:2] - state[2:] * DT) / DT**2
        assert np.hypot(*a) <= 60.0 * (1 + 1e-12)
        np.testing.assert_allclose(nxt[2:], state[2:] + a * DT, rtol=0, atol=1e-10)
        assert np.hypot(*nxt[2:]) <= 10.0 * (1 + 1e-12)
        state = nxt


# (b) the reach set against dense sampling -------------------------------------------------
@pytest.mark.parametrize("name", list(KINEMATICS))
def test_reach_set_against_a_dense_sampling_of_commands(name):
    kin, state, cloud_of, _ = KINEMATICS[name]
    cloud = cloud_of(kin, state)
    assert np.all(kin.reaches(cloud, state))  # every sampled endpoint is reached
    # The cloud's spacing: the farthest of a point's 4 nearest (its grid neighbours),
    # which bounds the distance of any point of the set to the cloud.
    h = float(np.max(cKDTree(cloud).query(cloud, k=5)[0][:, 4]))
    tree = cKDTree(cloud)
    edge = kin.reach_boundary(state, kin.radius / 2000)
    assert len(edge) > 500 and np.all(kin.reaches(edge, state))
    # The boundary is on the cloud's edge: each point within the spacing of the cloud,
    # and a point 3 spacings away in some direction outside it.
    d_edge, _ = tree.query(edge)
    assert d_edge.max() <= h
    ang = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    ring = 3 * h * np.stack([np.cos(ang), np.sin(ang)], -1)
    probe = (edge[::10, None, :] + ring[None]).reshape(-1, 2)
    far = (tree.query(probe)[0] > h).reshape(-1, len(ang))
    assert np.all(far.any(axis=1))
    # Membership agrees with the cloud away from its edge (farther than 3 spacings).
    rng = np.random.default_rng(2)
    q = state[:2] + rng.uniform(-1.3, 1.3, (20_000, 2)) * kin.radius
    band = cKDTree(edge).query(q)[0] > 3 * h
    inside = tree.query(q)[0] <= h
    got = kin.reaches(q, state)
    assert np.array_equal(got[band], inside[band])
    assert got[band].sum() > 200 and (~got[band]).sum() > 1000


# (c) the projection against brute force ---------------------------------------------------
def brute_feasible(kin, state, cloud, member, targets, rho):
    """Return the brute-force points of F: the dense command grid's endpoints and the
    reachable points of the rho circles (longhand membership), outside every disk."""
    ring = rings(targets, rho)
    pts = np.concatenate([cloud, ring[member(kin, state, ring)]])
    return pts[outside(pts, targets, rho, tol=1e-12)]


CASES = {  # target offsets from the sensor (in radii), rho (in radii)
    "rho_inactive": ([[5.0, 5.0]], 1.0),
    "one_disk": ([[0.7, 0.2]], 0.35),
    "two_disks": ([[0.8, 0.1], [0.45, -0.4]], 0.3),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("name", list(KINEMATICS))
def test_projection_is_never_farther_than_a_brute_force_search(name, case):
    kin, state, cloud_of, member = KINEMATICS[name]
    offsets, rho_r = CASES[case]
    r = kin.radius
    # Targets placed relative to the reach set's middle (the coasting point or the chord
    # at half speed), so the disks cut it.
    mid = kin.apply(np.zeros(2), state)
    targets = mid + r * np.asarray(offsets) - r * np.array([0.3, 0.0])
    rho = rho_r * r
    cloud = cloud_of(kin, state, 501)
    feas = brute_feasible(kin, state, cloud, member, targets, rho)
    assert len(feas) > 100
    rng = np.random.default_rng(3)
    wanted = np.concatenate([
        state[:2] + rng.uniform(-1.5, 1.5, (40, 2)) * r,  # anywhere, in and out of reach
        targets[0] + rng.uniform(-1, 1, (25, 2)) * rho,  # inside the first disk
        cloud[rng.integers(len(cloud), size=15)],  # reachable points
        cloud[~outside(cloud, targets, rho, tol=0.0)][::997][:15],  # reachable, in a disk
    ])  # fmt: skip
    branches = set()
    for q in wanted:
        got = kin.project(q, state, targets, rho)
        assert member(kin, state, got[None])[0] and outside(got[None], targets, rho)[0]
        d_got = float(np.hypot(*(got - q)))
        d_best = float(np.min(np.hypot(*(feas - q).T)))
        assert d_got <= d_best * (1 + 1e-6) + 1e-12 * r, (q, got, d_got, d_best)
        in_r = member(kin, state, q[None])[0]
        free = outside(q[None], targets, rho)[0]
        branches.add((bool(in_r), bool(free)))
    # Wanted points of every kind: feasible, reachable inside a disk, beyond reach.
    assert (True, True) in branches and (False, True) in branches
    if case != "rho_inactive":
        assert (True, False) in branches


def test_a_unicycle_that_can_stop_projects_as_the_full_search():
    """The arc at ``v_min = 0`` is the position for every parameter (so ``project`` takes
    it once): the same points, bit for bit, as the search that refines every sample."""

    class Searched(Unicycle):  # every piece searched (the unshortened rule)
        def point_pieces(self):
            return ()

    kin, full = Unicycle(0.0, 10.0, np.pi, dt=0.1), Searched(0.0, 10.0, np.pi, dt=0.1)
    state = np.array([1.0, -2.0, 0.4])
    t = np.linspace(0.0, 1.0, 1001)
    assert np.all(kin.piece(np.array(1), t, state) == state[:2])
    assert kin.point_pieces() == (1,) and Unicycle(1.0, 10.0, 1.0, dt=0.1).point_pieces() == ()
    rng = np.random.default_rng(5)
    corner = 0  # answers at the position that the nearest reachable point does not give
    for _ in range(250):  # a disk reaching almost to the sensor, wanted points about it
        targets = state[:2] + rng.uniform(-1.0, 1.0, (int(rng.integers(1, 3)), 2))
        rho = float(np.hypot(*(targets[0] - state[:2])) * rng.uniform(0.9, 1.0))
        q = state[:2] + rng.uniform(-0.3, 0.3, 2)
        got = kin.project(q, state, targets, rho)
        assert np.array_equal(got, full.project(q, state, targets, rho))
        clipped = kin.clip(q, state)[None]
        corner += bool(
            np.all(got == state[:2]) and not kin.feasible(clipped, state, targets, rho)[0]
        )
    assert corner >= 3


@pytest.mark.parametrize("name", list(KINEMATICS))
def test_projection_of_an_empty_feasible_set_violates_least(name):
    kin, state, cloud_of, _ = KINEMATICS[name]
    cloud = cloud_of(kin, state, 301)
    targets = kin.apply(np.zeros(2), state)[None]
    rho = 3.0 * kin.radius  # the disk covers the whole reach set
    assert not np.any(outside(cloud, targets, rho))
    got = kin.project(state[:2], state, targets, rho)
    assert kin.reaches(got, state)
    best = np.max(np.hypot(*(cloud - targets[0]).T))
    assert np.hypot(*(got - targets[0])) >= best - 2 * kin.radius / 300


# (d) commands ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", list(KINEMATICS))
def test_the_command_that_reaches_a_point_reproduces_it(name):
    kin, state, cloud_of, member = KINEMATICS[name]
    rng = np.random.default_rng(4)
    act = rng.uniform(-1, 1, (400, 2))
    pts = kin.apply(act, state)
    assert np.all(member(kin, state, pts))
    cmd = kin.command(pts, state)
    np.testing.assert_allclose(kin.apply(cmd, state), pts, rtol=0, atol=1e-12)
    np.testing.assert_allclose(kin.advance(cmd, state), kin.advance(act, state), rtol=0,
                               atol=1e-9)  # fmt: skip
    if isinstance(kin, Unicycle):  # the command itself (v, w) comes back
        np.testing.assert_allclose(cmd, act, rtol=0, atol=1e-9)
    # Batched states broadcast like single ones.
    states = np.tile(state, (400, 1))
    np.testing.assert_allclose(kin.apply(act, states), pts, rtol=0, atol=1e-14)


def test_unicycle_that_can_stop_stays_with_a_zero_command():
    kin = Unicycle(0.0, 5.0, 2.0, dt=DT)
    state = np.array([1.0, 1.0, 0.4])
    assert kin.reaches(state[:2], state)
    np.testing.assert_array_equal(kin.command(state[:2], state), [-1.0, 0.0])
    # Turning in place: v = 0 changes the heading only.
    np.testing.assert_allclose(kin.advance([-1.0, 1.0], state), [1.0, 1.0, 0.6], atol=1e-15)
    assert not Unicycle(1.0, 5.0, 2.0, dt=DT).reaches(state[:2], state)


# (e) parameters -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("make", "field"),
    [
        (lambda: Unicycle(-1.0, 5.0, 1.0), "v_min"),
        (lambda: Unicycle(0.0, -5.0, 1.0), "v_max"),
        (lambda: Unicycle(3.0, 2.0, 1.0), "v_min"),
        (lambda: Unicycle(0.0, 5.0, float("nan")), "w_max"),
        (lambda: Unicycle(0.0, 5.0, -1.0), "w_max"),
        (lambda: Unicycle(0.0, 5.0, 100.0, dt=0.1), "w_max"),
        (lambda: Unicycle(0.0, "5", 1.0), "v_max"),
        (lambda: DoubleIntegrator(0.0, 5.0), "a_max"),
        (lambda: DoubleIntegrator(-2.0, 5.0), "a_max"),
        (lambda: DoubleIntegrator(2.0, float("inf")), "v_max"),
        (lambda: DoubleIntegrator(2.0, 0.0), "v_max"),
    ],
)
def test_bad_parameters_name_the_field(make, field):
    with pytest.raises(ValueError, match=field):
        make()


def test_a_scenario_binds_its_dt_and_refuses_a_turn_beyond_a_circle():
    import activetrack

    sc = activetrack.make_scenario("paper", kinematics=Unicycle(0.0, 10.0, 3.0))
    assert sc.kinematics.dt == sc.dt and sc.r[0] == pytest.approx(10.0 * sc.dt)
    with pytest.raises(ValueError, match="w_max"):
        activetrack.make_scenario("paper", kinematics=Unicycle(0.0, 10.0, 70.0))
    with pytest.raises(ValueError, match="dt"):
        _ = Unicycle(0.0, 1.0, 1.0).radius
