"""Occluder kernels: inside, blocked, project_move, ray_distances, random_layout, validation.

References: matplotlib's ``Path.contains_points`` and a winding number written out here
(membership), dense sampling along segments (line of sight, motion), dense polar sampling
of the reach disk (nearest reachable point), closed forms of hand-built cases, and
point-to-segment distances written out here.
"""

import numpy as np
import pytest
from matplotlib.path import Path

from activetrack.models import _polygons
from activetrack.models import occluders as oc

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
# An L: the notch x > 1, y > 1 is outside; (1, 1) is its reflex vertex.
ELL = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]])


# ---------------------------------------------------------------- independent references


def winding(points, poly):
    """Return the winding number of ``poly`` around each point (sum of subtended angles)."""
    total = np.zeros(len(points))
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        u, v = a - points, b - points
        total += np.arctan2(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0], np.sum(u * v, -1))
    return np.rint(total / (2 * np.pi)).astype(int)


def boundary_distance(points, polys):
    """Return the distance from each point (M, 2) to the nearest polygon edge."""
    best = np.full(len(points), np.inf)
    for poly in polys:
        for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
            d = b - a
            t = np.clip(((points - a) @ d) / (d @ d), 0.0, 1.0)
            best = np.minimum(best, np.linalg.norm(points - a - t[:, None] * d, axis=-1))
    return best


def strictly_inside(points, polys, margin=1e-9):
    """Return whether points (M, 2) lie in some polygon, farther than ``margin`` from edges."""
    hit = np.zeros(len(points), bool)
    for poly in polys:
        inner = Path(poly).contains_points(points)
        if margin > 0 and np.any(inner):
            inner[inner] = boundary_distance(points[inner], [poly]) > margin
        hit |= inner
    return hit


def sampled_blocked(a, b, polys, n=20_000):
    """Return whether any of ``n + 1`` points along each segment is strictly inside."""
    t = np.linspace(0.0, 1.0, n + 1)
    out = np.zeros(len(a), bool)
    for i in range(len(a)):
        pts = a[i] + t[:, None] * (b[i] - a[i])
        out[i] = np.any(strictly_inside(pts, polys))
    return out


def star_polygon(rng, center, n, r_lo, r_hi):
    """Return a random star-shaped (generally non-convex) simple polygon."""
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    gaps = lambda a: np.diff(np.append(a, a[0] + 2 * np.pi))  # noqa: E731
    while np.min(gaps(ang)) < 0.05 or np.max(gaps(ang)) > 0.9 * np.pi:  # star-shaped
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    rad = rng.uniform(r_lo, r_hi, n)
    poly = center + rad[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    return poly if rng.random() < 0.5 else poly[::-1]  # either orientation


def mixed_layout(rng, n=4):
    """Return polygons: rotated rectangles and non-convex stars in [-3, 3]^2 (may overlap)."""
    polys = list(oc.random_layout(rng, n // 2, (-3, -3, 3, 3), (0.5, 2.0)).polygons)
    polys += [star_polygon(rng, rng.uniform(-2, 2, 2), 7, 0.3, 1.2) for _ in range(n - n // 2)]
    return [np.array(p) for p in polys]


# ---------------------------------------------------------------- construction


def test_from_polygons_stores_float64_edges_in_order():
    occ = oc.Occluders.from_polygons([SQUARE.astype(int), ELL])
    assert occ.n_polygons == 2 and occ.n_edges == 10
    assert occ.edges_a.dtype == np.float64
    np.testing.assert_array_equal(occ.edges_a[:4], SQUARE)
    np.testing.assert_array_equal(occ.edges_b[:4], np.roll(SQUARE, -1, axis=0))
    np.testing.assert_array_equal(occ.edge_polygon, [0] * 4 + [1] * 6)
    assert not occ.edges_a.flags.writeable
    with pytest.raises(AttributeError):
        occ.eps = 1.0  # frozen


@pytest.mark.parametrize(
    "bad, match",
    [
        ([[0, 0], [1, 0]], r"polygons\[0\].*n >= 3"),
        ([[0, 0], [1, 0], [np.nan, 1]], r"polygons\[0\].*finite"),
        ([[0, 0], [1, 0], [2, 0]], r"polygons\[0\].*(area|self-intersect)"),
        ([[0, 0], [1, 0], [1, 0], [0, 1]], r"polygons\[0\].*repeated"),
        ([[0, 0], [1, 1], [1, 0], [0, 1]], r"polygons\[0\].*self-intersect"),  # bow tie
        ([[0, 0], [2, 0], [1, 0], [1, 1]], r"polygons\[0\].*self-intersect"),  # fold-back
        ([[0, 0], [2, 0], [2, 2], [1, 0], [0, 2]], r"polygons\[0\].*self-intersect"),  # touch
        ([["a", "b"], [1, 0], [0, 1]], r"polygons\[0\].*real"),
    ],
)
def test_bad_polygons_raise_naming_the_field(bad, match):
    with pytest.raises(ValueError, match=match):
        oc.Occluders.from_polygons([bad])


def test_one_array_instead_of_a_sequence_of_polygons_raises():
    with pytest.raises(ValueError, match="polygons must be a sequence"):
        oc.Occluders.from_polygons(SQUARE)


def test_bad_second_polygon_is_named():
    with pytest.raises(ValueError, match=r"polygons\[1\]"):
        oc.Occluders.from_polygons([SQUARE, [[0, 0], [1, 1]]])


@pytest.mark.kernels
def test_empty_set_is_trivial():
    occ = oc.Occluders.empty()
    rng = np.random.default_rng(0)
    p, q = rng.normal(size=(2, 5, 3, 2))
    assert not oc.inside(p, occ).any() and oc.inside(p, occ).shape == (5, 3)
    assert not oc.blocked(p, q, occ).any()
    q[0] = p[0] + [[0.3, 0.4], [3.0, 4.0], [0.0, 0.0]]
    out, proj = oc.project_move(p, q, occ, np.ones((5, 3)))
    far = np.linalg.norm(q - p, axis=-1) > 1.0
    assert far.any() and (~far).any()
    np.testing.assert_array_equal(out[~far], q[~far])
    np.testing.assert_array_equal(proj, far)
    np.testing.assert_allclose(out[0, 1], p[0, 1] + [0.6, 0.8], rtol=0, atol=1e-15)
    d = (q - p)[far]
    radial = p[far] + d / np.linalg.norm(d, axis=-1)[:, None]
    np.testing.assert_allclose(out[far], radial, rtol=0, atol=1e-15)
    d = oc.ray_distances(p, np.array([[1.0, 0.0]]), occ, 7.0)
    np.testing.assert_array_equal(d, np.full((5, 3, 1), 7.0))


@pytest.mark.kernels
def test_crossings_of_overlapping_squares():
    occ = oc.Occluders.from_polygons([SQUARE, SQUARE + [0.5, 0.5]])
    got = sorted(map(tuple, occ.crossings))
    assert got == [(0.5, 1.0), (1.0, 0.5)]


# ---------------------------------------------------------------- inside


@pytest.mark.kernels
def test_inside_matches_matplotlib_and_winding_numbers():
    rng = np.random.default_rng(1)
    for _ in range(10):
        polys = mixed_layout(rng)
        occ = oc.Occluders.from_polygons(polys)
        pts = rng.uniform(-3.5, 3.5, (4000, 2))
        got = oc.inside(pts.reshape(40, 100, 2), occ).reshape(-1)
        mpl = np.zeros(len(pts), bool)
        wind = np.zeros(len(pts), bool)
        for poly in polys:
            mpl |= Path(poly).contains_points(pts)
            wind |= winding(pts, poly) != 0
        far = boundary_distance(pts, polys) > 1e-9
        assert far.sum() > 3900
        np.testing.assert_array_equal(got[far], mpl[far])
        np.testing.assert_array_equal(got[far], wind[far])
        assert got.mean() > 0.05  # the test exercises insides


@pytest.mark.kernels
def test_boundary_points_are_not_inside():
    rng = np.random.default_rng(2)
    polys = mixed_layout(rng, 6)
    occ = oc.Occluders.from_polygons(polys)
    pts = []
    for poly in polys:
        for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
            t = rng.uniform(0, 1, 20)
            pts.append(a + t[:, None] * (b - a))
        pts.append(poly)  # the vertices
    pts = np.concatenate(pts)
    # A boundary point is inside only if it is in another polygon's interior.
    for i, poly in enumerate(polys):
        others = [p for j, p in enumerate(polys) if j != i]
        on = boundary_distance(pts, [poly]) < 1e-12
        want = strictly_inside(pts[on], others, margin=1e-9)
        unsure = boundary_distance(pts[on], others) < 1e-9
        got = oc.inside(pts[on], occ)
        np.testing.assert_array_equal(got[~unsure], want[~unsure])


# ---------------------------------------------------------------- blocked


@pytest.mark.kernels
@pytest.mark.parametrize(
    "polys, a, b, want",
    [
        ([SQUARE], (0, 0), (1, 0), False),  # along an edge
        ([SQUARE], (-1, 0), (2, 0), False),  # along an edge, beyond both vertices
        ([SQUARE], (0, 0), (1, 1), True),  # diagonal, vertex to vertex
        ([SQUARE], (-1, -1), (2, 2), True),
        ([SQUARE], (-1, 1), (1, -1), False),  # grazes the vertex (0, 0)
        ([SQUARE], (0.5, 0), (0.5, -1), False),  # starts on an edge, goes out
        ([SQUARE], (0.5, 0), (0.5, 1e-6), True),  # starts on an edge, goes in a little
        ([SQUARE], (0.5, 0.5), (0.5, 0.5), True),  # a point strictly inside
        ([SQUARE], (0.5, 0.0), (0.5, 0.0), False),  # a point on an edge
        ([SQUARE], (0.5, 2.0), (0.5, 0.5), True),  # ends inside
        ([SQUARE], (0.5, 2.0), (0.5, 1.0), False),  # ends on an edge
        ([SQUARE], (2.0, 0.0), (0.0, 2.0), False),  # touches the vertex (1, 1)
        ([ELL], (2, 1), (1, 2), False),  # across the notch, reflex vertex ends
        ([ELL], (2, 1), (1, 1), False),  # along the notch's edge
        ([ELL], (3, 1), (0, 1), True),  # along the edge, then through the interior
        ([ELL], (1, 3), (1, 0), True),  # likewise, vertical
        ([ELL], (3, 3), (1, 1), False),  # into the reflex vertex from the notch
        ([ELL], (3, 3), (0.5, 0.5), True),  # through the reflex vertex into the interior
        ([ELL], (3, 0), (-1, 0), False),  # along the bottom edge
        ([SQUARE, SQUARE + [0.5, 0]], (1, -1), (1, 2), True),  # an edge inside the other
        ([SQUARE, SQUARE + [0.5, 0]], (-1, 0), (3, 0), False),  # along both bottoms
        ([SQUARE, SQUARE + [1, 0]], (1, -1), (1, 2), False),  # the seam of abutting ones
    ],
)
def test_blocked_hand_cases(polys, a, b, want):
    occ = oc.Occluders.from_polygons(polys)
    a, b = np.array(a, float), np.array(b, float)
    assert bool(oc.blocked(a, b, occ)) is want
    assert bool(oc.blocked(b, a, occ)) is want  # symmetric


def test_blocked_matches_dense_sampling_on_random_segments():
    rng = np.random.default_rng(3)
    n_blocked = 0
    for _ in range(6):
        polys = mixed_layout(rng)
        occ = oc.Occluders.from_polygons(polys)
        a, b = rng.uniform(-3.5, 3.5, (2, 60, 2))
        got = oc.blocked(a.reshape(6, 10, 2), b.reshape(6, 10, 2), occ).reshape(-1)
        np.testing.assert_array_equal(got, sampled_blocked(a, b, polys))
        n_blocked += got.sum()
    assert 50 < n_blocked < 330


@pytest.mark.kernels
def test_line_of_sight_matches_dense_sampling():
    """Every sensor (copies, M, 2) against every target (copies, K, 2): (copies, K, M)."""
    rng = np.random.default_rng(11)
    polys = mixed_layout(rng)
    occ = oc.Occluders.from_polygons(polys)
    sensors = rng.uniform(-3.5, 3.5, (4, 3, 2))
    targets = rng.uniform(-3.5, 3.5, (4, 2, 2))
    got = oc.line_of_sight(sensors, targets, occ)
    assert got.shape == (4, 2, 3)
    for c in range(4):
        for k in range(2):
            want = ~sampled_blocked(sensors[c], np.repeat(targets[c, k][None], 3, 0), polys)
            np.testing.assert_array_equal(got[c, k], want)
    assert 0 < got.sum() < got.size
    # No target or no sensor: empty answers of the right shape.
    assert oc.line_of_sight(sensors, targets[:, :0], occ).shape == (4, 0, 3)
    assert oc.line_of_sight(sensors[:, :0], targets, occ).shape == (4, 2, 0)
    # One copy without a leading axis, targets broadcast against a batch of sensors.
    np.testing.assert_array_equal(oc.line_of_sight(sensors[1], targets[1], occ), got[1])
    np.testing.assert_array_equal(oc.line_of_sight(sensors, targets[1], occ)[1], got[1])


def adversarial_segments(rng, polys, n):
    """Return segments through vertices, along edges, and from points on edges."""
    verts = np.concatenate(polys)
    ea = verts
    eb = np.concatenate([np.roll(p, -1, axis=0) for p in polys])
    out_a, out_b = [], []
    for _ in range(n):
        kind = rng.integers(3)
        if kind == 0:  # through a vertex, in a random direction
            v = verts[rng.integers(len(verts))]
            u = rng.normal(size=2)
            u /= np.linalg.norm(u)
            a, b = v - rng.uniform(0, 2) * u, v + rng.uniform(0, 2) * u
        elif kind == 1:  # on an edge's line, a random sub or super segment
            j = rng.integers(len(ea))
            t0, t1 = rng.uniform(-0.5, 1.5, 2)
            a, b = ea[j] + t0 * (eb[j] - ea[j]), ea[j] + t1 * (eb[j] - ea[j])
        else:  # from a point on an edge to a random point
            j = rng.integers(len(ea))
            a = ea[j] + rng.uniform() * (eb[j] - ea[j])
            b = a + rng.normal(size=2)
        out_a.append(a)
        out_b.append(b)
    return np.array(out_a), np.array(out_b)


@pytest.mark.kernels
def test_blocked_matches_dense_sampling_on_adversarial_segments():
    rng = np.random.default_rng(4)
    n_blocked = 0
    for _ in range(5):
        polys = mixed_layout(rng)
        occ = oc.Occluders.from_polygons(polys)
        a, b = adversarial_segments(rng, polys, 60)
        got = oc.blocked(a, b, occ)
        np.testing.assert_array_equal(got, sampled_blocked(a, b, polys))
        n_blocked += got.sum()
    assert 30 < n_blocked < 270


# ---------------------------------------------------------------- project_move


def reach_sample(o, r, polys, n_ang, n_rad):
    """Return dense polar samples of the reach disk and which are reachable (ray sampling).

    A sample is reachable when no sample at a smaller radius on its ray is strictly
    inside (the dense-sampling segment test, shared along each ray). ``certain`` further
    drops the rays passing within ``10`` radial steps of a vertex ahead of the start, where
    the ray could cut a polygon's corner between two samples.
    """
    ang = np.linspace(0, 2 * np.pi, n_ang, endpoint=False)
    u = np.stack([np.cos(ang), np.sin(ang)], -1)
    rad = np.linspace(0, r, n_rad + 1)
    pts = o + rad[None, :, None] * u[:, None, :]
    bad = strictly_inside(pts.reshape(-1, 2), polys, margin=0.0).reshape(pts.shape[:2])
    reach = np.cumsum(bad, axis=1) == 0
    h = r / n_rad
    rel = np.concatenate(polys) - o
    along = rel @ u.T  # (V, n_ang)
    perp = np.abs(rel[:, None, 0] * u[None, :, 1] - rel[:, None, 1] * u[None, :, 0])
    near = np.any((along > -h) & (along < r + h) & (perp < 10 * h), axis=0)
    return pts, reach, reach & ~near[:, None]


def check_nearest(o, q, r, polys, got, n_ang=1000, n_rad=1000):
    """Assert ``got`` is reachable (dense sampling of its segment, reach), that no certainly
    reachable sample is nearer to ``q`` by 1e-9 and no loosely reachable one by the grid
    spacing."""
    seg = o + np.linspace(0, 1, 20_001)[:, None] * (got - o)
    assert not np.any(strictly_inside(seg, polys))
    assert np.linalg.norm(got - o) <= r * (1 + 1e-9)
    pts, loose, certain = reach_sample(o, r, polys, n_ang, n_rad)
    mine = np.linalg.norm(got - q)
    dist = np.linalg.norm(pts - q, axis=-1)
    assert np.min(dist[certain]) >= mine - 1e-9
    spacing = r * max(2 * np.pi / n_ang, 1 / n_rad)
    assert mine <= np.min(dist[loose]) + spacing


def strata(o, r, out, polys):
    """Return the kind of each answer (M,): 0 on an edge only, 1 off every edge (a shadow
    ray), 2 on the reach circle and an edge, 3 on the reach circle only."""
    on_edge = boundary_distance(out, polys) < 1e-9
    on_circle = np.abs(np.linalg.norm(out - o, axis=-1) - r) < 1e-9 * r
    return np.where(on_circle, np.where(on_edge, 2, 3), np.where(on_edge, 0, 1))


def pick(kinds, mask, per_kind):
    """Return up to ``per_kind`` indices of each kind among ``mask`` (first ones)."""
    return [i for k in range(4) for i in np.flatnonzero(mask & (kinds == k))[:per_kind]]


@pytest.mark.kernels
def test_project_move_hand_cases():
    occ = oc.Occluders.from_polygons([SQUARE])
    # Onto the facing edge.
    out, proj = oc.project_move([-1.0, 0.5], [0.5, 0.5], occ, 2.0)
    np.testing.assert_allclose(out, [0.0, 0.5], atol=1e-15)
    assert proj
    # Behind the square: the foot of the perpendicular on the shadow ray through (0, 1).
    o, q = np.array([-2.0, 0.5]), np.array([1.5, 0.6])
    g = np.array([2.0, 0.5])
    want = o + (q - o) @ g / (g @ g) * g
    out, proj = oc.project_move(o, q, occ, 4.0)
    np.testing.assert_allclose(out, want, atol=1e-14)
    # Start inside: stays.
    out, proj = oc.project_move([0.5, 0.5], [2.0, 0.5], occ, 2.0)
    np.testing.assert_array_equal(out, [0.5, 0.5])
    assert proj
    # Start on an edge, moving along it or away from it: unchanged.
    out, proj = oc.project_move([0.5, 0.0], [0.9, 0.0], occ, 1.0)
    assert not proj and out.tolist() == [0.9, 0.0]
    # Beyond the reach, the wall x in [0, 0.1] in the way: where the reach circle meets
    # the wall's face x = 0 (the radial projection lies beyond the wall).
    wall = oc.Occluders.from_polygons([[[0.0, -1.0], [0.1, -1.0], [0.1, 5.0], [0.0, 5.0]]])
    out, proj = oc.project_move([-1.0, 0.0], [1.0, 0.8], wall, 1.2)
    np.testing.assert_allclose(out, [0.0, np.sqrt(1.2**2 - 1.0)], rtol=0, atol=1e-15)
    # Beyond the reach behind the square: where the reach circle meets the shadow ray
    # through (0, 1) (the segment to it grazes that vertex).
    o, g = np.array([-1.0, 0.5]), np.array([1.0, 0.5])
    out, proj = oc.project_move(o, [2.0, 0.9], occ, 1.6)
    np.testing.assert_allclose(out, o + 1.6 * g / np.linalg.norm(g), rtol=0, atol=1e-15)
    # Hidden in a wall behind the square: where the shadow ray through (0, 1) first meets
    # the wall x = 2 (the foot on the ray lies beyond, inside the wall).
    both = oc.Occluders.from_polygons([SQUARE, [[2.0, -5.0], [2.2, -5.0], [2.2, 5.0], [2.0, 5.0]]])
    out, proj = oc.project_move(o, [2.15, 1.8], both, 10.0)
    np.testing.assert_allclose(out, [2.0, 2.0], rtol=0, atol=1e-15)
    # Inside two overlapping squares: the reflex corner of their union, where the edges
    # cross (the feet on both edges lie inside the other square).
    two = oc.Occluders.from_polygons([SQUARE, SQUARE + 0.5])
    out, proj = oc.project_move([2.0, 0.3], [0.95, 0.6], two, 2.0)
    np.testing.assert_allclose(out, [1.0, 0.5], rtol=0, atol=1e-15)


def test_project_move_broadcasts_like_single_calls():
    occ = oc.Occluders.from_polygons([SQUARE, ELL + [2.0, 0.0]])
    rng = np.random.default_rng(13)
    start = rng.uniform(-1, 4, (3, 1, 2))
    start = start[~oc.inside(start, occ)[:, 0]]
    desired = rng.uniform(-1, 4, (1, 5, 2))
    r = 2.5
    out, proj = oc.project_move(start, desired, occ, r)
    assert out.shape == (len(start), 5, 2) and proj.shape == (len(start), 5)
    for i in range(len(start)):
        for j in range(5):
            one, p = oc.project_move(start[i, 0], desired[0, j], occ, r)
            np.testing.assert_array_equal(out[i, j], one)
            assert proj[i, j] == p


def test_project_move_unblocked_is_bit_for_bit():
    rng = np.random.default_rng(5)
    occ = oc.Occluders.from_polygons(mixed_layout(rng))
    o = rng.uniform(-3, 3, (2000, 2))
    o = o[~oc.inside(o, occ)]
    q = o + rng.uniform(-0.3, 0.3, o.shape) * np.pi
    out, proj = oc.project_move(o, q, occ, np.full(len(o), 1.5))
    free = ~oc.blocked(o, q, occ)
    assert free.sum() > 100 and (~free).sum() > 10
    np.testing.assert_array_equal(proj, ~free)
    assert np.array_equal(out[free].view(np.uint64), q[free].view(np.uint64))


def random_steps(rng, polys, n, r_lo=0.2, r_hi=2.0, beyond=1.0):
    """Return ``n`` (start, desired, r): starts outside, desired uniform in the disk of
    radius ``beyond * r`` (the reach disk for ``beyond = 1``)."""
    occ = oc.Occluders.from_polygons(polys)
    o = rng.uniform(-3.5, 3.5, (4 * n, 2))
    o = o[~strictly_inside(o, polys, margin=0.0) & ~oc.inside(o, occ)][:n]
    r = rng.uniform(r_lo, r_hi, n)
    rad = beyond * r * np.sqrt(rng.uniform(size=n))
    ang = rng.uniform(0, 2 * np.pi, n)
    return o, o + rad[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1), r


@pytest.mark.kernels
@pytest.mark.parametrize("beyond", [1.0, 1.5])
def test_project_move_is_the_nearest_reachable_point_by_brute_force(beyond):
    """Desired points in the reach disk, and beyond it (the reach circle's candidates)."""
    rng = np.random.default_rng(6)
    seen = np.zeros(4, int)
    for _ in range(4):
        polys = mixed_layout(rng)
        occ = oc.Occluders.from_polygons(polys)
        o, q, r = random_steps(rng, polys, 200, beyond=beyond)
        out, proj = oc.project_move(o, q, occ, r)
        radial = o + r[:, None] * (q - o) / np.linalg.norm(q - o, axis=-1)[:, None]
        not_radial = ~np.all(np.isclose(out, radial, rtol=0, atol=1e-12), -1)
        kinds = strata(o, r, out, polys)
        for i in pick(kinds, proj & not_radial, 1):
            check_nearest(o[i], q[i], r[i], polys, out[i])
            seen[kinds[i]] += 1
    # Shadow-ray and edge answers always; beyond the reach also corners of the reach circle
    # with an edge or a shadow ray, within it never (module docstring).
    assert seen[0] and seen[1]
    assert bool(seen[2] and seen[3]) is (beyond > 1)


@pytest.mark.kernels
def test_project_move_behind_corners_by_brute_force():
    """Desired points hidden behind a square from a start near it: shadow-ray answers."""
    rng = np.random.default_rng(7)
    occ = oc.Occluders.from_polygons([SQUARE])
    for _ in range(6):
        o = np.array([-0.6, 0.5]) + rng.uniform(-0.3, 0.3, 2)
        q = np.array([1.3, 0.5]) + rng.uniform(-0.3, 0.3, 2)
        r = np.linalg.norm(q - o) * rng.uniform(1.0, 1.3)
        out, proj = oc.project_move(o, q, occ, r)
        assert proj
        check_nearest(o, q, r, [SQUARE], out)


def test_ten_thousand_random_steps_never_enter_and_are_nearest():
    """The issue's acceptance at the kernel level: 10,000 random steps on random layouts."""
    rng = np.random.default_rng(8)
    n_proj = 0
    seen = np.zeros(4, int)
    for _ in range(50):
        polys = mixed_layout(rng, 5)
        occ = oc.Occluders.from_polygons(polys)
        o, q, r = random_steps(rng, polys, 200)
        assert len(o) == 200
        out, proj = oc.project_move(o, q, occ, r)
        n_proj += proj.sum()
        assert np.all(np.linalg.norm(out - o, axis=-1) <= r * (1 + 1e-9))
        t = np.linspace(0, 1, 501)
        seg = o[:, None, :] + t[None, :, None] * (out - o)[:, None, :]
        inside = strictly_inside(seg.reshape(-1, 2), polys).reshape(seg.shape[:2])
        assert not inside.any()
        # The nearest-point check, coarser, on a projected step of each kind per layout.
        kinds = strata(o, r, out, polys)
        for i in pick(kinds, proj, 1):
            check_nearest(o[i], q[i], r[i], polys, out[i], n_ang=400, n_rad=400)
            seen[kinds[i]] += 1
    assert n_proj > 500
    assert seen[0] > 20 and seen[1] > 20 and seen[2] == seen[3] == 0


# ---------------------------------------------------------------- ray_distances


@pytest.mark.kernels
def test_ray_distances_match_sampling_along_rays():
    rng = np.random.default_rng(9)
    polys = mixed_layout(rng)
    occ = oc.Occluders.from_polygons(polys)
    o = rng.uniform(-3, 3, (12, 2))
    o = o[~oc.inside(o, occ)]
    ang = np.arange(8) * 2 * np.pi / 8 + 0.1
    dirs = np.stack([np.cos(ang), np.sin(ang)], -1)
    got = oc.ray_distances(o, dirs, occ, 4.0)
    s = np.linspace(0, 4.0, 20_001)
    for i in range(len(o)):
        pts = o[i] + s[None, :, None] * dirs[:, None, :]
        d = boundary_distance(pts.reshape(-1, 2), polys).reshape(pts.shape[:2])
        first = np.where(np.any(d < 1e-4, axis=1), s[np.argmax(d < 1e-4, axis=1)], 4.0)
        # No edge before the first sample within 1e-4 of one (less a sampling step).
        assert np.all(got[i] >= first - 2 * (s[1] - s[0]))
        close = got[i] < 4.0
        tip = o[i] + got[i][:, None] * dirs
        assert np.all(boundary_distance(tip[close], polys) < 1e-9)


@pytest.mark.kernels
def test_ray_distances_equal_the_closed_form_over_every_edge():
    """The kernel skips back faces of polygons it is clearly outside of; the first hit over
    every edge of every polygon (both orientations, non-convex, overlapping, axis-aligned
    boxes whose sides are their bounding boxes'), by the closed form, is the same, for
    origins far off, just outside edges (from 1e-13 to 1e-3 off: those within ``eps`` see
    through the polygon), on vertices and on edges."""
    rng = np.random.default_rng(31)
    polys = mixed_layout(rng, 6)
    polys += [np.array([[3.0, 3.0], [4.0, 3.0], [4.0, 4.5], [3.0, 4.5]]), SQUARE - 4.0]
    polys = [p if k % 2 else p[::-1] for k, p in enumerate(polys)]  # both orientations
    occ = oc.Occluders.from_polygons(polys)
    a = np.concatenate(polys)
    f = np.concatenate([np.roll(p, -1, axis=0) for p in polys]) - a  # (E, 2)
    t = rng.uniform(0, 1, 300)
    k = rng.integers(0, len(a), 300)
    normal = np.stack([f[k, 1], -f[k, 0]], -1) / np.linalg.norm(f[k], axis=-1)[:, None]
    off = 10.0 ** rng.uniform(-13, -3, 300) * rng.choice([-1.0, 1.0], 300)
    o = np.concatenate([
        rng.uniform(-5, 5, (300, 2)),
        a[k] + t[:, None] * f[k] + off[:, None] * normal,  # near an edge, either side
        a[k[:50]],  # on vertices
        a[k[:50]] + 0.5 * f[k[:50]],  # on edges
    ])  # fmt: skip
    o = o[~oc.inside(o, occ)]
    ang = np.arange(16) * 2 * np.pi / 16 + rng.uniform(0, 0.4)
    g = np.stack([np.cos(ang), np.sin(ang)], -1)
    got = oc.ray_distances(o, g, occ, 4.0)
    w = a - o[:, None, None, :]  # (B, 1, E, 2)
    den = g[:, None, 0] * f[:, 1] - g[:, None, 1] * f[:, 0]  # (R, E)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (w[..., 0] * f[:, 1] - w[..., 1] * f[:, 0]) / den
        u = (w[..., 0] * g[:, None, 1] - w[..., 1] * g[:, None, 0]) / den
    hit = (den != 0) & (u >= 0) & (u <= 1) & (s > occ.eps)
    want = np.minimum(np.min(np.where(hit, s, np.inf), axis=-1), 4.0)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    assert (want < 4.0).mean() > 0.3


# ---------------------------------------------------------------- random_layout


@pytest.mark.kernels
def test_random_layout_is_seeded_inside_bounds_and_keeps_points_clear():
    clear = np.array([[0.0, 0.0], [2.0, 1.0]])
    a = oc.random_layout(
        np.random.default_rng(10), 6, (-4, -3, 4, 3), (0.5, 1.5), clear=clear, clearance=0.7
    )
    b = oc.random_layout(
        np.random.default_rng(10), 6, (-4, -3, 4, 3), (0.5, 1.5), clear=clear, clearance=0.7
    )
    c = oc.random_layout(
        np.random.default_rng(11), 6, (-4, -3, 4, 3), (0.5, 1.5), clear=clear, clearance=0.7
    )
    assert a.n_polygons == 6
    for p, q in zip(a.polygons, b.polygons, strict=True):
        np.testing.assert_array_equal(p, q)
    assert not np.array_equal(a.edges_a, c.edges_a)
    for p in a.polygons:
        assert np.all(p >= [-4 - 1e-12, -3 - 1e-12]) and np.all(p <= [4 + 1e-12, 3 + 1e-12])
        side = np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=-1)
        assert np.all((side >= 0.5 - 1e-12) & (side <= 1.5 + 1e-12))
        assert not np.any(Path(p).contains_points(clear))
    assert np.all(boundary_distance(clear, list(a.polygons)) >= 0.7)


def test_random_layout_bad_input():
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="bounds"):
        oc.random_layout(rng, 2, (0, 0, -1, 1), (0.1, 0.2))
    with pytest.raises(ValueError, match="size_range"):
        oc.random_layout(rng, 2, (0, 0, 1, 1), (0.2, 0.1))
    with pytest.raises(ValueError, match="n must"):
        oc.random_layout(rng, -1, (0, 0, 1, 1), (0.1, 0.2))
    with pytest.raises(ValueError, match="clearance"):
        oc.random_layout(rng, 1, (0, 0, 1, 1), (0.1, 0.2), clearance=-1.0)
    with pytest.raises(ValueError, match="max_tries"):
        oc.random_layout(rng, 1, (0, 0, 1, 1), (0.5, 0.6), clear=[[0.5, 0.5]], clearance=1.0)
    # Sides below 1e-6 of the bounds' scale would be degenerate at the boundary tolerance.
    with pytest.raises(ValueError, match=r"size_range .* lo >= 0\.0001 "):
        oc.random_layout(rng, 1, (0, 0, 100, 1), (1e-5, 1.0))


@pytest.mark.kernels
def test_rays_written_into_float32_views_equal_the_float64_readings_cast():
    """What the observation does (its rays written in place): the same values as the float64
    readings rounded once to float32, for a view that reshapes in place and for one that
    does not (written back); the rest of the array untouched."""
    from activetrack.world.observation import RAY_DIRECTIONS, RAY_MAX, ray_readings

    rng = np.random.default_rng(12)
    polys = mixed_layout(rng)
    occ = oc.Occluders.from_polygons(polys)
    pts = rng.uniform(-3.5, 3.5, (3, 4, 2))
    pts = np.where(oc.inside(pts, occ)[..., None], pts + 7.0, pts)  # range finders outside
    want = (oc.ray_distances(pts, RAY_DIRECTIONS, occ, RAY_MAX) / RAY_MAX).astype(np.float32)
    # The readings themselves, by the closed form of ray-segment intersections.
    o, g = pts[..., None, None, :], RAY_DIRECTIONS[:, None, :]  # (3, 4, 1, 1, 2), (R, 1, 2)
    a = np.concatenate(polys)
    f = np.concatenate([np.roll(p, -1, axis=0) for p in polys]) - a  # (E, 2)
    den = g[..., 0] * f[:, 1] - g[..., 1] * f[:, 0]  # (R, E)
    w = a - o
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (w[..., 0] * f[:, 1] - w[..., 1] * f[:, 0]) / den
        u = (w[..., 0] * g[..., 1] - w[..., 1] * g[..., 0]) / den
    hit = (u >= 0) & (u <= 1) & (s > 1e-9)
    closed = np.minimum(np.min(np.where(hit, s, np.inf), axis=-1), RAY_MAX) / RAY_MAX
    np.testing.assert_allclose(want, closed, rtol=1e-6)
    full = np.zeros((3, 4, 20), np.float32)
    ray_readings(pts, occ, out=full[..., 4:])
    np.testing.assert_array_equal(full[..., 4:], want)
    assert not full[..., :4].any()
    swapped = np.zeros((4, 3, 20), np.float32)
    ray_readings(pts, occ, out=swapped.transpose(1, 0, 2)[..., 4:])
    np.testing.assert_array_equal(swapped.transpose(1, 0, 2)[..., 4:], want)
    assert not swapped[..., :4].any() and 0 < want.min() and want.max() <= 1
    assert (want < 1).any()  # some rays hit an edge
    for bad in (np.zeros((3, 4, 15), np.float32), np.zeros((3, 4, 16), np.int64)):
        with pytest.raises(ValueError, match="out must be a float32 or float64 array"):
            ray_readings(pts, occ, out=bad)


# ---------------------------------------------------------------- bounded input (issue 35)


def _star(n, rng):
    """Return a simple star-shaped polygon of n vertices (radii in [1, 2] at sorted angles)."""
    ang = np.sort(rng.uniform(0, 2 * np.pi, n))
    ang = np.unique(ang)
    rad = rng.uniform(1.0, 2.0, len(ang))
    return np.stack([rad * np.cos(ang), rad * np.sin(ang)], -1)


def _first_bad_pair_brute_force(p, eps):
    """Return the first pair (i, j), i < j, in row order, of edges that meet other than
    consecutive edges at their shared vertex (segment tests written out, one pair at a
    time), or None."""
    n = len(p)
    q = np.roll(p, -1, axis=0)
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue  # consecutive: the fold-back test, not exercised by these cases
            # Orientation tests of the closed segments with the module's tolerance rule.
            if _polygons._segments_meet(p[i], q[i], p[j], q[j], eps):
                return i, j
    return None


@pytest.mark.parametrize("n", [12, 40])
def test_chunked_simplicity_check_names_the_brute_force_first_bad_pair(monkeypatch, n):
    # Chunks of a few pairs: every chunk boundary falls inside the pair table.
    monkeypatch.setattr(_polygons, "_PAIRS_PER_CHUNK", 7)
    rng = np.random.default_rng(n)
    for _ in range(20):
        p = _star(n, rng)
        k, m = sorted(rng.choice(len(p), 2, replace=False))
        p[[k, m]] = p[[m, k]]  # usually a self-intersection, possibly several
        eps = oc.TOL * max(1.0, float(np.max(np.abs(p))))
        ref = _first_bad_pair_brute_force(p, eps)
        if ref is None:
            _polygons._check_simple("polygons[0]", p, eps)  # accepted, as the brute force says
            continue
        with pytest.raises(ValueError, match=rf"edges {ref[0]} and {ref[1]} meet$"):
            _polygons._check_simple("polygons[0]", p, eps)


def test_a_polygon_at_the_vertex_limit_is_accepted_one_beyond_is_refused():
    rng = np.random.default_rng(0)
    p = _star(oc.MAX_VERTICES + 50, rng)[: oc.MAX_VERTICES]  # a star minus a sliver: simple
    assert len(p) == oc.MAX_VERTICES
    occ = oc.Occluders.from_polygons([p])
    assert occ.n_edges == oc.MAX_VERTICES
    # A point at the centre is inside (winding number, written out here), far out is not.
    assert bool(oc.inside(np.zeros(2), occ)) == (winding(np.zeros((1, 2)), p)[0] != 0)
    assert not oc.inside(np.array([5.0, 5.0]), occ)
    big = np.concatenate([p, [[0.0, 0.0]]])
    with pytest.raises(ValueError, match=rf"^polygons must have at most {oc.MAX_VERTICES}"):
        oc.Occluders.from_polygons([big])


def test_many_polygons_are_refused_before_any_pair_is_built():
    # 20,000 triangles: 60,000 edges, whose pair table would need 26.8 GiB.
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    many = [tri + [3.0 * k, 0.0] for k in range(20_000)]
    with pytest.raises(ValueError, match=rf"^polygons must have at most {oc.MAX_VERTICES}"):
        oc.Occluders.from_polygons(many)
