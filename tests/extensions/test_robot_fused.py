"""A team of robots on the fused step: the same numbers as the stage-by-stage step.

A world whose sensors move by a kinematics of their own (unicycles, double integrators)
but is otherwise the paper's case moves the team first and hands the positions to the
compiled step (``world/_fast.py``, ``team_moves``). The reference here is the generic
path, stage by stage (``World._advance``), taken by the same scenario with the fused step
switched off: every field, observation and reward must agree bit for bit, over steps of
actions and of absolute positions, single and batched, with many moves pushed out of the
target's ``rho`` disk (the sensors start 3 m from a slow target whose ``rho`` is 2 m).
"""

from __future__ import annotations

import numpy as np
import pytest

import activetrack
from activetrack.world import World
from activetrack.world.capabilities import Capabilities
from activetrack.world.scenarios import make_scenario

NEAR = dict(
    sensor_center=(0.0, 0.0), sensor_radius=3.0, x0=(0.0, 0.0, -1.0, 1.0),
    x0_hat=(0.0, 0.0, -1.0, 1.0),
)  # fmt: skip
FIELDS = ("sensors", "fixes", "projected", "motion", "x_true", "x_hat", "P", "x_pred",
          "P_pred", "trace", "score", "terminated", "truncated", "k")  # fmt: skip


def run(sc, n: int, absolute: bool, seed: int) -> list:
    """Return every step's fields, observation and reward of a world of ``n`` copies of
    ``sc`` driven by random actions (or random absolute positions near the sensors)."""
    world = World(sc, n)
    rng = np.random.default_rng(seed)
    out = []
    for episode in range(3):
        world.reset(seeds=list(range(10 * episode, 10 * episode + n)))
        while True:
            ended = np.asarray(world.get("terminated"), bool) | np.asarray(
                world.get("truncated"), bool
            )
            if ended.all():
                break
            shape = (3, 2) if n == 1 else (n, 3, 2)
            live = None if n == 1 else ~ended
            if absolute:
                result = world.step(world.get("sensors") + rng.normal(0.0, 1.5, shape), live)
            else:
                result = world.step_actions(rng.uniform(-1.2, 1.2, shape), live)
            out.append([np.array(world.get(f)) for f in FIELDS])
            out.append([world.observe(), np.array(result.reward)])
    return out


@pytest.mark.parametrize("n", [1, 5])
@pytest.mark.parametrize("absolute", [False, True])
@pytest.mark.parametrize(
    "kin",
    [activetrack.Unicycle(0.0, 10.0, np.pi), activetrack.Unicycle(3.0, 10.0, 2.0),
     activetrack.DoubleIntegrator(20.0, 10.0)],
    ids=repr,
)  # fmt: skip
def test_fused_team_equals_stage_by_stage(kin, n, absolute, monkeypatch) -> None:
    sc = make_scenario("paper", kinematics=kin, **NEAR)
    assert World(sc, n)._fused
    fused = run(sc, n, absolute, seed=1)
    monkeypatch.setattr(Capabilities, "fused_step", property(lambda self: False))
    assert not World(sc, n)._fused
    staged = run(sc, n, absolute, seed=1)
    assert len(fused) == len(staged) > 100
    for a, b in zip(fused, staged, strict=True):
        for x, y in zip(a, b, strict=True):
            assert x.dtype == y.dtype and x.shape == y.shape
            assert np.array_equal(x, y)
    projected = sum(int(np.sum(step[FIELDS.index("projected")])) for step in fused[::2])
    assert projected > 10  # the rule that pushes moves out of the rho disk was exercised


@pytest.mark.kernels
def test_unicycle_team_step_is_advance_bit_for_bit() -> None:
    """The compiled team step against the NumPy methods it replaces (``advance`` and the
    ``rho`` test), on random states and actions with the edge cases: straight moves
    (``w = 0``), clipped actions, headings at the wrap, a stop."""
    rng = np.random.default_rng(7)
    for kin in (activetrack.Unicycle(0.0, 10.0, np.pi, dt=0.1),
                activetrack.Unicycle(2.5, 7.0, 9.0, dt=0.3)):  # fmt: skip
        n, m, k = 4000, 3, 2
        actions = rng.uniform(-1.5, 1.5, (n, m, 2))
        actions[::7, :, 1] = 0.0  # straight
        actions[::11, :, 0] = -1.0  # the least speed (a stop when v_min is 0)
        states = np.concatenate(
            [rng.uniform(-20, 20, (n, m, 2)), rng.uniform(-np.pi, np.pi, (n, m, 1))], -1
        )
        states[::5, :, 2] = np.pi  # headings at the wrap
        states[1::5, :, 2] = -np.pi + 1e-15
        targets = rng.uniform(-20, 20, (n, k, 2))
        rho = rng.uniform(0.0, 15.0, (n, m))
        nxt, inside = kin.team_step(actions, states, targets, rho)
        want = kin.advance(actions, states)
        assert np.array_equal(nxt, want)  # every bit
        e = want[..., None, :2] - targets[:, None, :, :]
        brute = np.array([[any(np.hypot(*e[b, i, j]) < rho[b, i] for j in range(k))
                           for i in range(m)] for b in range(n)])  # fmt: skip
        assert np.array_equal(inside, brute) and 0 < inside.sum() < inside.size
        one, one_inside = kin.team_step(actions[3], states[3], targets[3], rho[3])
        assert np.array_equal(one, want[3]) and np.array_equal(one_inside, brute[3])


@pytest.mark.kernels
def test_one_copy_team_move_is_the_general_rule_bit_for_bit() -> None:
    """A single copy's team move (:meth:`activetrack.Unicycle.team_step_one`, taken when no
    move ends inside a ``rho`` disk) against the NumPy ``advance`` and against the general
    rule on the same copy batched (one row), moves into a disk included."""
    from activetrack.kinematics.team import TeamMotion

    rng = np.random.default_rng(8)
    kin = activetrack.Unicycle(0.0, 10.0, np.pi, dt=0.1)
    team = TeamMotion((kin,) * 3)
    kinds = set()
    for trial in range(300):
        x = rng.uniform(-1.2, 1.2, (3, 2))
        states = np.concatenate([rng.uniform(-3, 3, (3, 2)), rng.uniform(-4, 4, (3, 1))], -1)
        where = rng.uniform(-3, 3, (2,) if trial % 2 else (2, 2))
        rho = rng.uniform(0.0, 2.0, 3)
        pos, projected, nxt = team.move(False, x, states, where, rho)
        ref = team.move(False, x[None], states[None], where[None], rho[None])
        for got, want in zip((pos, projected, nxt), ref, strict=True):
            assert got.shape == want.shape[1:] and np.array_equal(got, want[0])
        if not projected.any():
            assert np.array_equal(nxt, kin.advance(x, states))
        kinds.add(bool(projected.any()))
    assert kinds == {False, True}  # both the compiled step alone and the projection


@pytest.mark.kernels
@pytest.mark.parametrize(
    "kin",
    [activetrack.Unicycle(0.0, 10.0, np.pi), activetrack.Unicycle(3.0, 10.0, 2.0)],
    ids=repr,
)
def test_batched_unicycle_step_is_the_team_move_then_the_step(kin) -> None:
    """The batched unicycle step in one compiled call (``_fast.advance_arcs``:
    ``advance_unicycle_rows``, the copies with a move into a ``rho`` disk projected and
    then ``advance_listed_rows``) against the path it replaces, from the same state: the
    team's move (``TeamMotion.move``, NumPy's arithmetic) then the compiled step of given
    positions (``advance_rows``); every output and the next headings, bit for bit, over
    steps with and without such moves."""
    from activetrack.world import _fast

    sc = make_scenario("paper", kinematics=kin, **NEAR)
    world = World(sc, 40)
    assert world._arcs is not None
    world.reset(seeds=list(range(40)))
    rng = np.random.default_rng(3)
    pending = []
    for _ in range(12):
        actions = rng.uniform(-1.3, 1.3, (40, 3, 2))
        noise = rng.standard_normal((40, world._n_noise))
        got = _fast.advance_arcs(world, actions, noise, slice(None))
        heading = world._motion_next
        arcs, world._arcs = world._arcs, None  # the path before: team_moves, advance_rows
        try:
            want = _fast.advance_fused(world, actions, False, noise, slice(None))
        finally:
            world._arcs = arcs
        assert np.array_equal(heading, world._motion_next)
        flat = lambda r: [r[0], r[1], *r[2]]  # noqa: E731
        for x, y in zip(flat(got), flat(want), strict=True):
            assert x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y)
        pending.append(int(got[1].any(-1).sum()))
        world.step_actions(actions)
    # both kinds of copies were stepped, in the same calls
    assert any(0 < count < 40 for count in pending) and sum(pending) > 5


@pytest.mark.kernels
def test_compiled_headings_are_the_unicycle_features() -> None:
    """``headings_into`` against :meth:`activetrack.Unicycle.features` (NumPy's cosine and
    sine) rounded to float32, headings at the wrap and at zero included; the entries
    around the columns it writes untouched."""
    from activetrack.world._observation_kernels import headings_into

    rng = np.random.default_rng(11)
    motion = rng.uniform(-np.pi, np.pi, (200, 3, 1))
    motion[:4, 0, 0] = (np.pi, -np.pi, 0.0, -0.0)
    out = np.full((200, 3, 7), 5.0, np.float32)
    headings_into(motion, out, 4)
    states = np.concatenate([rng.uniform(-9, 9, (200, 3, 2)), motion], -1)
    want = activetrack.Unicycle(0.0, 1.0, 1.0, dt=0.1).features(states).astype(np.float32)
    assert np.array_equal(out[..., 4:6], want)
    assert (out[..., :4] == 5.0).all() and (out[..., 6] == 5.0).all()


@pytest.mark.parametrize("scenario", ["unicycle", "fixed_wing", "paper", "double"])
def test_batched_observation_is_the_generic_one(scenario) -> None:
    """A batched fused world's observation in one call (``_fast.observe_batch``) against the
    readers' general path (``observation.encode``, then the team's NumPy features), bit for
    bit, after a few steps: unicycles (compiled headings), a double integrator (NumPy
    features), the paper's disks (none)."""
    kin = {"double": activetrack.DoubleIntegrator(20.0, 10.0)}
    sc = make_scenario("paper", kinematics=kin["double"]) if scenario in kin else scenario
    world = World(make_scenario(sc), 7)
    assert world._fused
    world.reset(seeds=list(range(7)))
    rng = np.random.default_rng(5)
    for _ in range(4):
        world.step_actions(rng.uniform(-1, 1, (7, world.n_sensors, 2)))
        fast = world.observe()
        world._fused = False  # the readers' general path
        try:
            general = world.observe()
        finally:
            world._fused = True
        assert fast.dtype == general.dtype and np.array_equal(fast, general)


@pytest.mark.kernels
def test_unicycle_rows_rho_test_is_hypot_at_the_boundary() -> None:
    """The one-call step's test of a move into the ``rho`` disk (a squared-distance
    prefilter, then ``hypot``) against NumPy's ``hypot(...) < rho (1 - TOL)`` where it is
    hardest: ``rho`` within a few ulps of sensor 0's new distance to the target (the
    others at random distances), and far inside and outside."""
    from activetrack.kinematics.base import TOL
    from activetrack.world import _loop_kernels as lk

    kin = activetrack.Unicycle(0.0, 10.0, np.pi, dt=0.1)
    rng = np.random.default_rng(12)
    b, m, n = 600, 3, 4
    actions = rng.uniform(-1, 1, (b, m, 2))
    sensors = rng.uniform(-50, 50, (b, m, 2))
    motion = rng.uniform(-np.pi, np.pi, (b, m, 1))
    x_pred = np.zeros((b, n))
    x_pred[:, :2] = rng.uniform(-50, 50, (b, 2))
    ends = kin.advance(actions, np.concatenate([sensors, motion], -1))[..., :2]
    dist = np.hypot(*np.moveaxis(ends - x_pred[:, None, :2], -1, 0))  # (b, m)
    rho = dist[:, 0] / (1.0 - TOL) * (1.0 + rng.integers(-4, 5, b) * 2.0**-52)
    rho[::7] *= rng.uniform(0.2, 5.0, len(rho[::7]))  # far from the boundary too
    table, mats = World(make_scenario("paper", kinematics=kin), 2)._fused_args
    flags = np.empty((b, m), bool)
    for row in range(b):  # one copy a call: each its own rho
        out = (np.empty((1, m, 2)), flags[row : row + 1], np.empty((1, n)), np.empty((1, n)),
               np.empty((1, n, n)), np.empty((1, n)), np.empty((1, n, n)), np.empty(1))  # fmt: skip
        lk.advance_unicycle_rows(
            actions[row : row + 1], sensors[row : row + 1], motion[row : row + 1],
            np.zeros((1, n)), x_pred[row : row + 1], np.eye(n)[None].copy(), np.zeros((1, 10)),
            table, mats, kin.v_min, kin.v_max, kin.w_max, kin.dt,
            np.full(m, rho[row] * (1.0 - TOL)), *out, np.empty((1, m, 1)), np.empty(1, bool),
        )  # fmt: skip
    want = dist < (rho * (1.0 - TOL))[:, None]
    assert np.array_equal(flags, want)
    near = np.ones(b, bool)
    near[::7] = False
    assert 0 < want[near, 0].sum() < near.sum()  # both sides, within ulps of the boundary
