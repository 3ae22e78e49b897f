"""A target moved by an agent (:class:`activetrack.Controlled`) and the world's
``set_target_actions``: against closed forms (a straight move of ``speed a dt``, an evader
moving ``speed dt`` away) and against the ``evader`` task's world (the fallback)."""

import numpy as np
import pytest

from activetrack import Controlled, Evasive, make_scenario
from activetrack.world import World

SPEED, DT = 10.0, 0.1


def _worlds(n, seeds):
    a, b = World(make_scenario("pursuit"), n), World(make_scenario("evader"), n)
    a.reset(seeds=seeds)
    b.reset(seeds=seeds)
    return a, b


def test_act_moves_at_the_action_s_velocity_scaled_onto_the_unit_disk():
    b = Controlled(SPEED, DT)
    x = np.array([1.0, 2.0, -3.0, 4.0])
    # Inside the disk: velocity speed * a; (3, 4) is scaled to (0.6, 0.8).
    np.testing.assert_allclose(b.act(x, [0.5, -0.25]), [1.5, 1.75, 5.0, -2.5], rtol=1e-15)
    np.testing.assert_allclose(b.act(x, [3.0, 4.0]), [1.6, 2.8, 6.0, 8.0], rtol=1e-15)
    # Without an action and without a fallback: it coasts, its speed clipped to 10 m/s.
    nxt, mode = b.step(np.array([0.0, 0.0, 30.0, 40.0]), np.random.default_rng(0))
    np.testing.assert_allclose(nxt, [0.6, 0.8, 6.0, 8.0], rtol=1e-15)
    assert mode == 0


def test_world_moves_the_controlled_target_by_its_actions_in_every_copy():
    world, _ = _worlds(3, [3, 4, 5])
    start = world.get("x_true", target=0)[:, :2].copy()
    rng = np.random.default_rng(7)
    total = np.zeros((3, 2))
    for _ in range(20):
        a = rng.uniform(-1.5, 1.5, (3, 1, 2))
        world.set_target_actions(a)
        world.step_actions(rng.uniform(-1, 1, (3, 4, 2)))
        n = np.linalg.norm(a[:, 0], axis=1, keepdims=True)
        total += SPEED * DT * a[:, 0] / np.maximum(n, 1.0)  # the closed form of each step
    np.testing.assert_allclose(world.get("x_true", target=0)[:, :2], start + total, atol=1e-12)


def test_an_action_holds_one_step_and_copies_without_one_follow_the_evader():
    world, evader = _worlds(2, [3, 4])
    moves = np.random.default_rng(1).uniform(-1, 1, (6, 2, 4, 2))
    # Step 0: copy 1 alone gets an action; copy 0 is the evader task's bit for bit.
    world.set_target_actions(np.array([[[0.0, 1.0]], [[1.0, 0.0]]]), copies=[1])
    x1 = world.get("x_true", target=0)[1].copy()
    world.step_actions(moves[0])
    evader.step_actions(moves[0])
    np.testing.assert_array_equal(world.get("x_true", 0), evader.get("x_true", 0))
    np.testing.assert_allclose(world.get("x_true", 1), [x1[0] + 1.0, x1[1], 10.0, 0.0])
    # Step 1: no action: copy 1 flees the nearest sensor, moving exactly speed dt away.
    x, s = world.get("x_true", 1)[:2].copy(), world.get("sensors", 1).copy()
    world.step_actions(moves[1])
    d0 = np.min(np.linalg.norm(s - x, axis=1))
    nearest = s[np.argmin(np.linalg.norm(s - x, axis=1))]
    assert np.linalg.norm(world.get("x_true", 1)[:2] - nearest) == pytest.approx(
        d0 + SPEED * DT, rel=1e-12
    )


def test_a_reset_drops_the_actions_set_before_it():
    world, evader = _worlds(1, [9])
    world.set_target_actions([[1.0, 0.0]])
    world.reset(seeds=[9])
    m = np.zeros((4, 2))
    world.step_actions(m)
    evader.step_actions(m)
    np.testing.assert_array_equal(world.get("x_true", 0), evader.get("x_true", 0))


def test_bad_parameters_and_actions_name_their_field():
    with pytest.raises(ValueError, match="speed"):
        Controlled(-1.0, DT)
    with pytest.raises(ValueError, match="dt"):
        Controlled(SPEED, 0.0)
    with pytest.raises(ValueError, match="fallback"):
        Controlled(SPEED, DT, fallback="evasive")
    with pytest.raises(ValueError, match="fallback's dt"):
        Controlled(SPEED, DT, fallback=Evasive(SPEED, 0.2))
    with pytest.raises(ValueError, match="target_behaviour.*dt"):
        make_scenario("evader", target_behaviour=Controlled(SPEED, 0.05))
    world = World(make_scenario("pursuit"), 2)
    world.reset(seeds=[1, 2])
    with pytest.raises(ValueError, match=r"target_actions must have shape \(2, 1, 2\)"):
        world.set_target_actions([[1.0, 0.0]])
    with pytest.raises(ValueError, match="target_actions"):
        world.set_target_actions([[[np.nan, 0.0]], [[0.0, 0.0]]])
    plain = World(make_scenario("evader"), 1)
    plain.reset(seeds=[1])
    with pytest.raises(ValueError, match="target_actions: no target"):
        plain.set_target_actions([[1.0, 0.0]])
    with pytest.raises(ValueError, match="action must have shape"):
        Controlled(SPEED, DT).act(np.zeros(4), [1.0, 0.0, 0.0])
