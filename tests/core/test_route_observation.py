"""Route readings (``route_observation``): each agent's way to the target around the
occluders, against closed forms (the straight line; the way round one square) and against
the world's own positions and predictions.
"""

import numpy as np
import pytest

from activetrack.models.occluders import Occluders
from activetrack.models.roadmap import CLEARANCE, route_readings
from activetrack.world import World
from activetrack.world.scenarios import make_scenario


def test_open_plane_reads_the_straight_line():
    rng = np.random.default_rng(0)
    p, g = rng.normal(size=(5, 3, 2)), rng.normal(size=(5, 2, 2))
    out = route_readings(p, g, None).reshape(5, 3, 2, 3)
    d = g[:, None] - p[:, :, None]
    np.testing.assert_allclose(out[..., :2], d / np.linalg.norm(d, axis=-1, keepdims=True))
    np.testing.assert_array_equal(out[..., 2], 1.0)


def test_round_one_square_closed_form():
    # A 2 m square between the sensor and the goal: the route turns round a corner of the
    # square grown by the clearance c (its nodes), runs along the grown side, and on.
    occ = Occluders.from_polygons([np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])])
    c = CLEARANCE
    p, g = np.array([[-3.0, 0.0]]), np.array([[3.0, 0.0]])
    corner = np.array([-1.0 - c, 1.0 + c])  # or its mirror image below
    leg = corner - p[0]
    geodesic = 2 * np.linalg.norm(leg) + 2 * (1.0 + c)
    out = route_readings(p, g, occ)
    np.testing.assert_allclose(out[0, 0], leg[0] / np.linalg.norm(leg), rtol=1e-12)
    np.testing.assert_allclose(abs(out[0, 1]), leg[1] / np.linalg.norm(leg), rtol=1e-12)
    np.testing.assert_allclose(out[0, 2], 6.0 / geodesic, rtol=1e-12)
    # In sight: the straight line, ratio 1.
    out = route_readings(np.array([[-3.0, 2.0]]), np.array([[3.0, 2.0]]), occ)
    np.testing.assert_allclose(out, [[1.0, 0.0, 1.0]])
    # Batched layouts (one per copy) read as each alone.
    far = Occluders.from_polygons([np.array([[9.0, 9.0], [10.0, 9.0], [10.0, 10.0], [9.0, 10.0]])])
    both = Occluders.stack([occ, far])
    pp, gg = np.array([[[-3.0, 0.0]], [[-3.0, 0.0]]]), np.array([[[3.0, 0.0]], [[3.0, 0.0]]])
    out = route_readings(pp, gg, both)
    np.testing.assert_allclose(out[0], route_readings(pp[0], gg[0], occ))
    np.testing.assert_allclose(out[1], [[1.0, 0.0, 1.0]])


@pytest.mark.parametrize("batched", [False, True])
def test_the_world_observes_each_agents_route_after_its_rays(batched):
    sc = make_scenario("urban_unicycle")
    w = World(sc, 2 if batched else 1)
    w.reset(seeds=[3, 4] if batched else [3])
    rng = np.random.default_rng(1)
    for _ in range(8):
        w.step_actions(rng.uniform(-1.0, 1.0, (w.num_copies, 4, 2)) if batched else
                       rng.uniform(-1.0, 1.0, (4, 2)))  # fmt: skip
    obs = w.observe() if batched else w.observe(0)[None]
    lay = w.layout
    start = lay.obs_dim - lay.motion - lay.route
    sensors = np.reshape(w.get("sensors"), (-1, 4, 2))
    goal = np.reshape(w.get("x_pred"), (-1, 4))[:, :2]
    want = route_readings(sensors, goal[:, None], w.occluders())
    np.testing.assert_allclose(obs[..., start : start + 3], want, rtol=1e-6, atol=1e-7)
    # Where the way is clear the reading is the straight line to the prediction.
    d = goal[:, None] - sensors
    clear = want[..., 2] == 1.0
    assert clear.any()
    np.testing.assert_allclose(
        want[clear][:, :2], (d / np.linalg.norm(d, axis=-1, keepdims=True))[clear], rtol=1e-12
    )
    # Every agent's route in the global state, after the rays, before the headings.
    state = w.state() if batched else w.state(0)[None]
    r = start - lay.target_dim - lay.sensor_dim * 4  # the rays of one agent
    base = lay.target_dim + lay.sensor_dim * 4 + 4 * r
    np.testing.assert_allclose(
        state[:, base : base + 12], want.reshape(-1, 12), rtol=1e-6, atol=1e-7
    )


def test_route_observation_is_validated_and_off_by_default():
    assert make_scenario("urban").route_observation is False
    with pytest.raises(ValueError, match="route_observation must be True or False"):
        make_scenario("urban", route_observation="yes")
    # On an open plane the route is the straight line; the observation grows by 3 K.
    w = World(make_scenario("two_targets", route_observation=True))
    w.reset(seeds=[0])
    assert w.observe(0).shape[-1] == World("two_targets").layout.obs_dim + 6
