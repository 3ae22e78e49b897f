"""Batched occluder layouts: Occluders.stack, occ[i], replaced, and the kernels on them.

References: the unbatched kernels called layout by layout on ``occ[i]`` (themselves tested
against brute force in test_occluders.py), compared bit for bit; dense sampling along
segments for ``blocked`` directly on a batch; a closed-form tolerance case (a point at a
distance from an edge between two layouts' ``eps``); the stacked layouts' own arrays for
the round trips.
"""

import pickle

import numpy as np
import pytest

from activetrack.models import occluders as oc
from tests.core.test_occluders import SQUARE, adversarial_segments, sampled_blocked

BOUNDS = (-3.0, -3.0, 3.0, 3.0)


def layouts(rng, n, rects=4):
    """Return ``n`` random layouts of ``rects`` rectangles, large enough to overlap often."""
    return [oc.random_layout(rng, rects, BOUNDS, (0.5, 2.5)) for _ in range(n)]


def same_bits(x, y):
    """Return whether float arrays ``x`` and ``y`` are equal bit for bit (shape too)."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    return x.shape == y.shape and np.array_equal(x.view(np.uint64), y.view(np.uint64))


def assert_same_layout(got, want):
    """Assert two unbatched sets hold equal arrays, tolerances and polygons."""
    assert not got.batched and got.n_layouts is None
    for name in ("edges_a", "edges_b", "edge_polygon", "starts", "bbox", "crossings"):
        assert same_bits(getattr(got, name), getattr(want, name)), name
    assert got.scale == want.scale and got.eps == want.eps
    assert isinstance(got.scale, float) and isinstance(got.eps, float)
    assert len(got.polygons) == len(want.polygons)
    for p, q in zip(got.polygons, want.polygons, strict=True):
        assert same_bits(p, q)


def assert_same_batch(got, want):
    """Assert two batched sets are equal layout by layout, with the same padding width."""
    assert got.batched and got.n_layouts == want.n_layouts
    assert got.crossings.shape == want.crossings.shape
    for i in range(want.n_layouts):
        assert_same_layout(got[i], want[i])


def edge_points(rng, occ, k):
    """Return ``k`` points on the edges of ``occ`` (some on vertices), (k, 2)."""
    j = rng.integers(occ.n_edges, size=k)
    t = np.where(rng.random(k) < 0.3, 0.0, rng.random(k))
    return occ.edges_a[j] + t[:, None] * (occ.edges_b[j] - occ.edges_a[j])


def inner_points(rng, occ, k):
    """Return ``k`` points inside polygons of ``occ`` (rectangle centres, jittered)."""
    centres = np.array([p.mean(0) for p in occ.polygons])
    return centres[rng.integers(len(centres), size=k)] + rng.uniform(-0.1, 0.1, (k, 2))


# ---------------------------------------------------------------- construction


def test_stack_getitem_round_trips_give_the_layouts_back():
    rng = np.random.default_rng(20)
    lays = layouts(rng, 7)
    # One layout far larger (its own scale and eps), one with no crossings.
    lays[3] = oc.Occluders.from_polygons([200.0 * p for p in lays[3].polygons])
    lays[5] = oc.Occluders.from_polygons([SQUARE + [3.0 * k, 0.0] for k in range(4)])
    counts = [len(occ.crossings) for occ in lays]
    assert len(set(counts)) > 2 and 0 in counts  # the padding is exercised
    occ = oc.Occluders.stack(lays)
    assert occ.batched and occ.n_layouts == 7
    assert occ.n_polygons == 4 and occ.n_edges == 16
    assert occ.edges_a.shape == (7, 16, 2) and occ.bbox.shape == (7, 4, 4)
    assert occ.crossings.shape == (7, max(counts), 2)
    assert occ.scale.shape == occ.eps.shape == (7,)
    assert not occ.edges_a.flags.writeable and not occ.crossings.flags.writeable
    for i, want in enumerate(lays):
        assert_same_layout(occ[i], want)
        assert_same_layout(occ[i - 7], want)  # negative indices
        assert np.all(np.isnan(occ.crossings[i, counts[i] :]))
        assert len(occ.polygons[i]) == 4
    assert occ[3].eps == lays[3].eps > 100 * lays[0].eps
    # Subsets: a slice, an int array, a bool mask, equal to stacking the chosen layouts.
    mask = np.array([True, False, True, False, False, True, False])
    for sel, rows in [
        (slice(1, 6, 2), [1, 3, 5]),
        (np.array([6, 0, 5]), [6, 0, 5]),
        (mask, [0, 2, 5]),
    ]:
        assert_same_batch(occ[sel], oc.Occluders.stack([lays[j] for j in rows]))
    assert occ[np.array([5])].crossings.shape == (1, 0, 2)  # padding trimmed to the subset
    with pytest.raises(IndexError, match="out of range"):
        occ[7]
    # Pickling (copies sent to worker processes) keeps the layouts and the kernels' view.
    back = pickle.loads(pickle.dumps(occ))
    assert_same_batch(back, occ)
    pts = np.stack([lay.polygons[0].mean(0) for lay in lays])[:, None]  # rectangle centres
    np.testing.assert_array_equal(oc.inside(pts, back), np.ones((7, 1), bool))
    with pytest.raises(TypeError, match="not iterable"):
        iter(occ)
    # One shared layout serves every copy: any index gives it back.
    one = lays[0]
    assert one[3] is one and one[np.array([True, False])] is one and one[1:] is one
    assert not one.batched and one.n_layouts is None


def test_replaced_swaps_the_rows_and_copies_the_rest():
    rng = np.random.default_rng(21)
    lays = layouts(rng, 6)
    occ = oc.Occluders.stack(lays)
    new = layouts(rng, 2)
    out = occ.replaced(np.array([4, 1]), new)
    want = list(lays)
    want[4], want[1] = new
    assert_same_batch(out, oc.Occluders.stack(want))
    assert_same_batch(occ, oc.Occluders.stack(lays))  # the original is unchanged
    assert out.replaced(np.array([], int), []) is out
    assert not out.edges_a.flags.writeable
    with pytest.raises(ValueError, match="rows must be distinct"):
        occ.replaced([1, 1], new)
    with pytest.raises(ValueError, match=r"rows must lie in \[0, 6\)"):
        occ.replaced([1, 6], new)
    with pytest.raises(ValueError, match="rows must be a 1-D array of ints"):
        occ.replaced([0.5, 1.0], new)
    with pytest.raises(ValueError, match="one layout per row"):
        occ.replaced([1], new)
    with pytest.raises(ValueError, match=r"layouts\[0\].*vertices"):
        occ.replaced([1], layouts(rng, 1, rects=3))
    with pytest.raises(ValueError, match="replaced needs a batched set"):
        lays[0].replaced([0], new[:1])


def test_stack_bad_input_names_the_field():
    rng = np.random.default_rng(22)
    lays = layouts(rng, 3)
    tri = oc.Occluders.from_polygons([SQUARE, SQUARE + 2, SQUARE + 4, [[0, 5], [1, 5], [0, 6]]])
    with pytest.raises(ValueError, match="at least 1"):
        oc.Occluders.stack([])
    with pytest.raises(ValueError, match=r"layouts\[2\] has 3 polygons, layouts\[0\] has 4"):
        oc.Occluders.stack([lays[0], lays[1], layouts(rng, 1, rects=3)[0]])
    with pytest.raises(ValueError, match=r"layouts\[1\] has polygons of \[4, 4, 4, 3\] vertices"):
        oc.Occluders.stack([lays[0], tri])
    with pytest.raises(TypeError, match=r"layouts\[1\] must be an Occluders, got ndarray"):
        oc.Occluders.stack([lays[0], SQUARE])
    with pytest.raises(TypeError, match="got one Occluders"):
        oc.Occluders.stack(lays[0])
    with pytest.raises(ValueError, match=r"layouts\[0\] must be one layout"):
        oc.Occluders.stack([oc.Occluders.stack(lays)])
    with pytest.raises(ValueError, match=r"layouts\[1\] has 4 polygons, layouts\[0\] has 0"):
        oc.Occluders.stack([oc.Occluders.empty(), lays[0]])


def test_batch_of_empty_layouts_is_trivial():
    occ = oc.Occluders.stack([oc.Occluders.empty()] * 3)
    assert occ.batched and occ.n_layouts == 3 and occ.n_polygons == 0 and occ.n_edges == 0
    assert_same_layout(occ[1], oc.Occluders.empty())
    p, q = np.random.default_rng(23).normal(size=(2, 3, 5, 2))
    assert not oc.inside(p, occ).any() and not oc.blocked(p, q, occ).any()
    assert oc.line_of_sight(p, q[:, :2], occ).all()
    out, proj = oc.project_move(p, p + 0.1, occ, 1.0)
    np.testing.assert_array_equal(out, p + 0.1)
    assert not proj.any()
    assert np.all(oc.ray_distances(p, np.array([[1.0, 0.0]]), occ, 7.0) == 7.0)
    with pytest.raises(ValueError, match="layout axis"):
        oc.inside(p[:2], occ)


# ---------------------------------------------------------------- kernels


def test_kernels_reject_a_wrong_layout_axis():
    rng = np.random.default_rng(24)
    occ = oc.Occluders.stack(layouts(rng, 3))
    p = rng.uniform(-3, 3, (4, 5, 2))
    dirs = np.array([[1.0, 0.0]])
    msg = r"a batched Occluders of 3 layouts needs .* layout axis, of length 3, got .*\(4, 5\)"
    with pytest.raises(ValueError, match="inside: " + msg):
        oc.inside(p, occ)
    with pytest.raises(ValueError, match="blocked: " + msg):
        oc.blocked(p, p[::-1], occ)
    with pytest.raises(ValueError, match=r"line_of_sight: .*length 3, got .*\(4, 5, 5\)"):
        oc.line_of_sight(p, p, occ)
    with pytest.raises(ValueError, match="project_move: " + msg):
        oc.project_move(p, p + 0.1, occ, 1.0)
    with pytest.raises(ValueError, match="ray_distances: " + msg):
        oc.ray_distances(p, dirs, occ, 5.0)
    with pytest.raises(ValueError, match=r"blocked: .*got points of shape \(\)"):
        oc.blocked(p[0, 0], p[1, 1], occ)  # no layout axis at all


def batch_points(rng, lays, k_random, k_edge, k_inner):
    """Return points (N, K, 2) per layout: random, on edges or vertices, inside polygons."""
    return np.stack(
        [
            np.concatenate(
                [
                    rng.uniform(-3.5, 3.5, (k_random, 2)),
                    edge_points(rng, occ, k_edge),
                    inner_points(rng, occ, k_inner),
                ]
            )
            for occ in lays
        ]
    )


@pytest.mark.kernels
@pytest.mark.parametrize("seed", [30, 31, 32])
def test_inside_blocked_line_of_sight_equal_the_layouts_kernels(seed):
    rng = np.random.default_rng(seed)
    lays = layouts(rng, 12)
    occ = oc.Occluders.stack(lays)
    pts = batch_points(rng, lays, 20, 20, 5)
    got = oc.inside(pts.reshape(12, 5, 9, 2), occ).reshape(12, -1)
    for i in range(12):
        np.testing.assert_array_equal(got[i], oc.inside(pts[i], lays[i]))
    assert got.any() and not got.all()
    # Segments: adversarial ones (through vertices, along edges, from edge points), and
    # between the points above (sensors inside, on edges).
    seg = [adversarial_segments(rng, list(lay.polygons), 40) for lay in lays]
    a = np.concatenate([np.stack([s[0] for s in seg]), pts], axis=1)
    b = np.concatenate([np.stack([s[1] for s in seg]), pts[:, ::-1]], axis=1)
    got = oc.blocked(a, b, occ)
    for i in range(12):
        np.testing.assert_array_equal(got[i], oc.blocked(a[i], b[i], lays[i]))
    assert 0.1 < got.mean() < 0.9
    # Broadcasting: one segment end shared by every copy.
    got = oc.blocked(a, b[0, 0], occ)
    for i in range(12):
        np.testing.assert_array_equal(got[i], oc.blocked(a[i], b[0, 0], lays[i]))
    # Line of sight: (N, C, M, 2) sensors against (N, C, K, 2) targets -> (N, C, K, M).
    sensors, targets = pts[:, :24].reshape(12, 3, 8, 2), pts[:, 24:].reshape(12, 3, 7, 2)
    got = oc.line_of_sight(sensors, targets, occ)
    assert got.shape == (12, 3, 7, 8)
    for i in range(12):
        np.testing.assert_array_equal(got[i], oc.line_of_sight(sensors[i], targets[i], lays[i]))
    assert got.any() and not got.all()
    # Only the pairs ``where`` holds: the same answers there, False elsewhere (a full mask,
    # and one (K, M) mask shared by every copy).
    where = rng.random(got.shape) < 0.5
    np.testing.assert_array_equal(oc.line_of_sight(sensors, targets, occ, where), got & where)
    np.testing.assert_array_equal(
        oc.line_of_sight(sensors, targets, occ, where[0, 0]), got & where[0, 0]
    )


@pytest.mark.parametrize("seed", [40, 41])
def test_project_move_equals_the_layouts_kernel_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    lays = layouts(rng, 10)
    occ = oc.Occluders.stack(lays)
    # Starts: random (some inside: they stay), on edges and vertices, inside.
    start = batch_points(rng, lays, 24, 12, 2)
    k = start.shape[1]
    r = rng.uniform(0.3, 2.0, (10, k))
    rad = 1.5 * r * np.sqrt(rng.uniform(size=(10, k)))  # within and beyond the reach
    ang = rng.uniform(0, 2 * np.pi, (10, k))
    desired = start + rad[..., None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    assert np.isnan(occ.crossings).any() and not np.isnan(occ.crossings).all()
    out, proj = oc.project_move(start, desired, occ, r)
    n_moved = 0
    for i in range(10):
        want, wproj = oc.project_move(start[i], desired[i], lays[i], r[i])
        assert same_bits(out[i], want)
        np.testing.assert_array_equal(proj[i], wproj)
        n_moved += np.sum(wproj & np.any(want != start[i], -1))
    assert proj.mean() > 0.2 and n_moved > 50  # projections onto edges and shadow rays
    # Broadcast: one reach per copy (N, 1), candidates (N, C, M, 2) against sensors (N, 1, M, 2).
    cand = desired.reshape(10, 2, k // 2, 2)
    o = start[:, None, : k // 2]
    out, proj = oc.project_move(o, cand, occ, r[:, :1, None])
    assert out.shape == (10, 2, k // 2, 2)
    for i in range(10):
        want, wproj = oc.project_move(o[i], cand[i], lays[i], r[i, 0])
        assert same_bits(out[i], want)
        np.testing.assert_array_equal(proj[i], wproj)


@pytest.mark.kernels
def test_project_move_onto_crossings_of_some_copies():
    """Closed forms: the reflex corner where two overlapping squares' edges cross (a
    crossing candidate) in copies 0 and 2; in copy 1 (disjoint squares, no crossing, NaN
    padding) the foot of the perpendicular on the square's right edge."""
    shift = np.array([-1.25, 0.75])
    occ = oc.Occluders.stack(
        [
            oc.Occluders.from_polygons([SQUARE, SQUARE + 0.5]),
            oc.Occluders.from_polygons([SQUARE, SQUARE + 3.0]),
            oc.Occluders.from_polygons([SQUARE + shift, SQUARE + 0.5 + shift]),
        ]
    )
    assert np.isnan(occ.crossings[1]).all() and not np.isnan(occ.crossings[[0, 2]]).any()
    start = np.array([[2.0, 0.3], [2.0, 0.3], [2.0, 0.3] + shift])
    out, proj = oc.project_move(start, start - [1.05, -0.3], occ, 2.0)
    assert proj.all()
    want = np.array([[1.0, 0.5], [1.0, 0.6], [1.0, 0.5] + shift])
    np.testing.assert_allclose(out, want, rtol=0, atol=1e-15)


@pytest.mark.kernels
def test_ray_distances_equal_the_layouts_kernel_bit_for_bit():
    rng = np.random.default_rng(50)
    lays = layouts(rng, 9)
    occ = oc.Occluders.stack(lays)
    o = batch_points(rng, lays, 8, 6, 1).reshape(9, 3, 5, 2)
    ang = np.arange(16) * np.pi / 8 + 0.05
    dirs = np.stack([np.cos(ang), np.sin(ang)], -1)
    got = oc.ray_distances(o, dirs, occ, 4.0)
    assert got.shape == (9, 3, 5, 16)
    for i in range(9):
        assert same_bits(got[i], oc.ray_distances(o[i], dirs, lays[i], 4.0))
    assert np.mean(got < 4.0) > 0.3


def test_each_layout_keeps_its_own_tolerance():
    """A point 1e-8 inside an edge: inside for a layout of scale 6 (eps 6e-10), on the
    boundary for one of scale 1001 (eps 1.001e-7); the same square in both."""
    small = oc.Occluders.from_polygons([SQUARE, SQUARE + 5.0])
    large = oc.Occluders.from_polygons([SQUARE, SQUARE + 1000.0])
    occ = oc.Occluders.stack([small, large, small])
    np.testing.assert_allclose(occ.eps, [6e-10, 1.001e-7, 6e-10], rtol=1e-15, atol=0)
    p = np.array([0.5, 1e-8])
    np.testing.assert_array_equal(oc.inside(np.stack([p, p, p])[:, None], occ)[:, 0], [1, 0, 1])
    # A segment ending there: blocked where the point is inside only.
    a = np.array([0.5, -1.0])
    np.testing.assert_array_equal(oc.blocked(a, np.stack([p, p, p]), occ), [1, 0, 1])


def test_blocked_on_a_batch_matches_dense_sampling():
    """Directly on the batched path: each copy's segments against its own polygons."""
    rng = np.random.default_rng(60)
    lays = layouts(rng, 8)
    occ = oc.Occluders.stack(lays)
    seg = [adversarial_segments(rng, list(lay.polygons), 8) for lay in lays]
    a = np.stack([np.concatenate([s[0], rng.uniform(-3.5, 3.5, (4, 2))]) for s in seg])
    b = np.stack([np.concatenate([s[1], rng.uniform(-3.5, 3.5, (4, 2))]) for s in seg])
    got = oc.blocked(a, b, occ)
    for i, lay in enumerate(lays):
        np.testing.assert_array_equal(got[i], sampled_blocked(a[i], b[i], list(lay.polygons)))
    assert 0.1 < got.mean() < 0.9
