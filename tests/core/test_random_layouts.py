"""Random occluder layouts, one per episode and copy (``random_occluders``; the
``urban_random`` task). References: matplotlib's polygon membership on dense samples of
every move, line of sight and start disk (independent of activetrack.models.occluders), the
single-copy world (a copy of a batched world equals the world of one copy with its seed),
and the per-copy planning problems."""

import numpy as np
import pytest
from matplotlib.path import Path

from activetrack.baselines import GSR
from activetrack.world import World
from activetrack.world.scenarios import make_scenario
from tests.core.helpers import in_any as _inside
from tests.core.helpers import segments_enter as _enters

N = 24


def _paths(occ):
    return [Path(np.asarray(p)) for p in occ.polygons]


def test_each_episode_draws_its_layout_from_its_seed():
    w = World("urban_random", 3)
    w.reset(seeds=[1, 2, 1])
    a, b, c = (w.occluders(i) for i in range(3))
    assert a.n_polygons == 6 and not a.batched
    for p, q in zip(a.polygons, c.polygons, strict=True):
        np.testing.assert_array_equal(p, q)
    assert not all(np.array_equal(p, q) for p, q in zip(a.polygons, b.polygons, strict=True))
    # A new episode of copy 0 (its generator continues): a new layout.
    w.reset([0])
    assert not all(
        np.array_equal(p, q) for p, q in zip(a.polygons, w.occluders(0).polygons, strict=True)
    )
    # The fixed occluders stay in every layout, first.
    fixed = [[(30.0, 30.0), (32.0, 30.0), (32.0, 32.0)]]
    one = World("urban_random", occluders=fixed)
    one.reset(seeds=[4])
    assert one.occluders().n_polygons == 7
    np.testing.assert_array_equal(one.occluders().polygons[0], np.array(fixed[0]))


def test_layouts_keep_the_start_disk_and_the_target_clear():
    sc = make_scenario("urban_random")
    ang = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    rad = np.linspace(0, sc.sensor_radius * (1 - 1e-6), 12)
    disk = (rad[:, None, None] * np.stack([np.cos(ang), np.sin(ang)], -1)[None]).reshape(-1, 2)
    bounds = np.array(sc.occluder_bounds)
    for seed in range(40):
        occ = sc.draw_occluders(np.random.default_rng(seed))
        paths = _paths(occ)
        for center in (sc.sensor_center, sc.x0_hat[:2]):
            assert not _inside(paths, disk + np.array(center)).any()
        verts = np.concatenate(occ.polygons)
        assert np.all(verts >= bounds[:2] - 1e-9) and np.all(verts <= bounds[2:] + 1e-9)
        for poly in occ.polygons:
            sides = np.linalg.norm(poly - np.roll(poly, 1, axis=0), axis=1)
            assert np.all((sides >= 2.0 - 1e-9) & (sides <= 5.0 + 1e-9))


def test_a_copy_equals_the_world_of_one_copy_with_its_seed():
    seeds = [11, 12, 13]
    batch = World("urban_random", 3)
    batch.reset(seeds=seeds)
    singles = [World("urban_random") for _ in seeds]
    for w, s in zip(singles, seeds, strict=True):
        w.reset(seeds=[s])
    rng = np.random.default_rng(0)
    for _ in range(20):
        act = rng.uniform(-1, 1, (3, 4, 2))
        batch.step_actions(act)
        for i, w in enumerate(singles):
            w.step_actions(act[i])
            np.testing.assert_allclose(batch.get("sensors", i), w.get("sensors", 0), atol=1e-12)
            np.testing.assert_array_equal(batch.get("detected", i), w.get("detected", 0))
            # (The single filter's 2x2 algebra on Python numbers rounds differently.)
            np.testing.assert_allclose(batch.get("x_hat", i), w.get("x_hat", 0), rtol=1e-9)
            np.testing.assert_allclose(batch.observe(i), w.observe(0), atol=1e-6)


def test_no_sensor_enters_its_copys_occluders_and_no_measurement_crosses_them():
    w = World("urban_random", N)
    w.reset(seeds=list(range(100, 100 + N)))
    rng = np.random.default_rng(1)
    paths = [_paths(w.occluders(i)) for i in range(N)]
    for i in range(N):
        assert not _inside(paths[i], w.get("sensors", i)).any()
    hidden_misses = 0
    for _ in range(30):
        before = w.get("sensors").copy()
        w.step_actions(rng.uniform(-1.5, 1.5, (N, 4, 2)))
        after, detected = w.get("sensors"), w.get("detected")
        for i in range(N):
            assert not _inside(paths[i], after[i]).any()
            assert not _enters(paths[i], before[i], after[i]).any()
            target = np.broadcast_to(w.get("x_true", i)[:2], (4, 2))
            hidden = _enters(paths[i], after[i], target)
            assert not np.any(detected[i, 0] & hidden)
            hidden_misses += int(hidden.sum())
    assert hidden_misses > 0  # the layouts do hide the target sometimes


def test_planners_see_each_copys_own_layout():
    w = World("urban_random", 4)
    w.reset(seeds=[5, 6, 7, 8])
    rng = np.random.default_rng(2)
    for _ in range(8):
        w.step_actions(rng.uniform(-1, 1, (4, 4, 2)))
    problem = w.planning_problem()
    assert problem.occluders.batched and problem.occluders.n_layouts == 4
    planner = GSR()
    batched = planner.plan(problem)
    for i in range(4):
        # Planned moves are straight moves the world allows (checked by dense sampling).
        paths = _paths(w.occluders(i))
        assert not _enters(paths, w.get("sensors", i), batched[i]).any()
        single = w.planning_problem(i)
        assert single.occluders.n_polygons == 6
        for p, q in zip(single.occluders.polygons, w.occluders(i).polygons, strict=True):
            np.testing.assert_array_equal(p, q)
        # The expected information with copy i's line of sight: the batched score's row i.
        np.testing.assert_allclose(problem.score(batched)[i], single.score(batched[i]), rtol=1e-12)
        np.testing.assert_allclose(planner.plan(single), batched[i], atol=1e-9)


@pytest.mark.parametrize(
    ("overrides", "match"),
    [
        ({"random_occluders": -1}, r"random_occluders must be an integer in \[0, 100\]"),
        ({"random_occluders": 2.5}, "random_occluders must be an integer"),
        ({"random_occluders": True}, "random_occluders must be an integer"),
        ({"random_occluders": 101}, r"\[0, 100\]"),
        ({"occluder_bounds": (0.0, 0.0, 1.0)}, r"occluder_bounds must have shape \(4,\)"),
        ({"occluder_bounds": (5.0, 0.0, 1.0, 9.0)}, "xmin < xmax"),
        ({"occluder_bounds": (0.0, 0.0, np.nan, 9.0)}, "occluder_bounds"),
        ({"occluder_size": (3.0, 2.0)}, "lo <= hi"),
        ({"occluder_size": (0.0, 2.0)}, "occluder_size must lie in"),
        ({"occluder_size": "big"}, "occluder_size"),
        ({"occluder_size": (30.0, 40.0)}, "do not fit in occluder_bounds"),
        ({"occluder_size": (2e-5, 2.0)}, r"lo >= 2.4e-05 \(1e-06 times the occluder_bounds"),
    ],
)
def test_bad_random_layout_fields_name_the_field(overrides, match):
    with pytest.raises(ValueError, match=match):
        make_scenario("urban_random", **overrides)


@pytest.mark.parametrize("index", [3, -1, 1.0, True, "0"])
def test_occluders_of_a_copy_that_does_not_exist_names_the_index(index):
    w = World("urban_random", 3)
    w.reset(seeds=[0, 1, 2])
    with pytest.raises(ValueError, match=r"index must be None or an integer in \[0, 2\]"):
        w.occluders(index)
    assert World("paper").occluders() is None


def _reference_rectangles(rng, n, bounds, sizes, clear, clearance):
    """The draws of random_layout in NumPy: sides, angle, centre; redrawn while a clear
    point is inside (matplotlib) or nearer than ``clearance`` (distance to each side)."""
    out = []
    for _ in range(n):
        while True:
            w, h = rng.uniform(sizes[0], sizes[1], 2)
            ang = rng.uniform(0.0, np.pi)
            rot = np.array([[np.cos(ang), np.sin(ang)], [-np.sin(ang), np.cos(ang)]])
            half = 0.5 * np.abs(rot) @ [w, h]
            lo, hi = bounds[:2] + half, bounds[2:] - half
            if np.any(lo > hi):
                continue
            corners = 0.5 * np.array([[-w, -h], [w, -h], [w, h], [-w, h]])
            poly = rng.uniform(lo, hi) + corners @ rot
            a, b = poly, np.roll(poly, -1, axis=0)
            f = b - a
            t = np.clip(np.einsum("kej,ej->ke", clear[:, None] - a, f) / np.sum(f * f, -1), 0, 1)
            d = np.linalg.norm(clear[:, None] - (a + t[..., None] * f), axis=-1)
            if Path(poly).contains_points(clear).any() or (d < clearance).any():
                continue
            out.append(poly)
            break
    return np.array(out)


@pytest.mark.kernels
def test_compiled_rectangles_are_the_numpy_draws():
    """The compiled rectangles (occluder_kernels.rectangles_into) consume the generator as
    the NumPy draws do (same rectangles to rounding, the same state afterwards), over
    layouts where the clearance rejects many draws; a batch of layouts equals the layouts
    drawn one at a time."""
    from activetrack.models import occluders as oc

    bounds, sizes = np.array([-6.0, -5.0, 7.0, 4.0]), np.array([1.0, 3.5])
    clear = np.array([[0.0, 0.0], [2.0, 1.0], [-3.0, -2.0]])
    for seed in range(60):
        got = oc.random_layout(np.random.default_rng(seed), 5, bounds, sizes, clear=clear,
                               clearance=1.5)  # fmt: skip
        ref_rng = np.random.default_rng(seed)
        want = _reference_rectangles(ref_rng, 5, bounds, sizes, clear, 1.5)
        np.testing.assert_allclose(np.array(got.polygons), want, rtol=0, atol=1e-13)
        rng = np.random.default_rng(seed)
        oc.random_layout(rng, 5, bounds, sizes, clear=clear, clearance=1.5)
        assert rng.random() == ref_rng.random()  # as many draws
    sc = make_scenario("urban_random")
    batch = sc.draw_occluder_batch([np.random.default_rng(s) for s in range(6)])
    single = oc.Occluders.stack([sc.draw_occluders(np.random.default_rng(s)) for s in range(6)])
    for name in ("edges_a", "edges_b", "bbox", "crossings", "scale", "eps", "starts"):
        np.testing.assert_array_equal(getattr(batch, name), getattr(single, name))
    for i in range(6):
        for p, q in zip(batch[i].polygons, single[i].polygons, strict=True):
            np.testing.assert_array_equal(p, q)
    # A batch in place of a list of layouts, in replaced.
    base = oc.Occluders.stack([batch[0]] * 4)
    np.testing.assert_array_equal(
        base.replaced([3, 1], batch[[2, 5]]).edges_a,
        base.replaced([3, 1], [batch[2], batch[5]]).edges_a,
    )


def test_draw_occluders_without_random_rectangles():
    """An open plane draws no polygon; a fixed layout draws itself (no generator used)."""
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    assert make_scenario("paper").draw_occluders(rng).n_polygons == 0
    urban = make_scenario("urban")
    drawn = urban.draw_occluders(rng)
    assert drawn.n_polygons == len(urban.occluders) and not drawn.batched
    for p, q in zip(drawn.polygons, urban.occluders, strict=True):
        np.testing.assert_array_equal(p, np.asarray(q, float))
    assert rng.bit_generator.state == state
    assert make_scenario("paper").draw_occluder_batch([rng, rng]).n_layouts == 2


def test_draw_occluders_refuses_what_is_not_a_generator():
    sc = make_scenario("urban_random")
    for bad in (0, None, np.random.RandomState(0)):
        with pytest.raises(TypeError, match=r"rngs\[0\] must be a numpy.random.Generator"):
            sc.draw_occluders(bad)
    with pytest.raises(TypeError, match=r"rngs\[1\]"):
        sc.draw_occluder_batch([np.random.default_rng(0), 3])
