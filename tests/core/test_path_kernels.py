"""The compiled path checks against the NumPy expressions they replace, bit for bit:
:func:`activetrack.kinematics.paths.point_distances` (the distance from a sampled path
to points, :func:`activetrack.kinematics.separation.segment_distance` over its pieces)
and :func:`activetrack.models.occluders.path_blocked` (``np.any`` of
:func:`~activetrack.models.occluders.blocked` over a path's segments)."""

from __future__ import annotations

import numpy as np
import pytest

from activetrack.kinematics.paths import point_distances, slack
from activetrack.kinematics.separation import segment_distance
from activetrack.models.occluders import Occluders, blocked, path_blocked

pytestmark = pytest.mark.kernels


def _paths(rng, n, s):
    """Return random smooth paths (n, s, 2) and some degenerate ones (a point, a repeat)."""
    t = np.linspace(0.0, 1.0, s)[:, None]
    o = rng.uniform(-5, 5, (n, 1, 2))
    v = rng.uniform(-2, 2, (n, 1, 2))
    c = rng.uniform(-1, 1, (n, 1, 2))
    p = o + t * v + t * t * c
    p[0] = p[0, :1]  # a sensor that stays: every piece has zero length
    p[1, 3] = p[1, 2]  # one repeated sample
    return p


def test_point_distances_are_the_pieces_segment_distance_bit_for_bit():
    rng = np.random.default_rng(0)
    p = _paths(rng, 300, 33)
    q = rng.uniform(-6, 6, (300, 4, 2))
    q[2, 0] = p[2, 5]  # a point on the path
    got = point_distances(p, q)
    a, b = p[:, :-1, None, :], p[:, 1:, None, :]
    want = np.min(segment_distance(a, b, q[:, None]), axis=-2) - slack(p)[:, None]
    np.testing.assert_array_equal(got, want)
    # broadcast: one set of points for a batch of paths of copies (B, C, S, 2) / (B, 1, J, 2)
    got = point_distances(p.reshape(3, 100, 33, 2), q[:3, None])
    want = np.min(
        segment_distance(p.reshape(3, 100, 32 + 1, 1, 2)[:, :, :-1], p.reshape(3, 100, 33, 1, 2)[
            :, :, 1:], q[:3, None, None]), axis=-2,
    ) - slack(p.reshape(3, 100, 33, 2))[..., None]  # fmt: skip
    np.testing.assert_array_equal(got, want)


def _layouts():
    boxes = [[(0, 0), (2, 0), (2, 1), (0, 1)], [(3, -3), (4, -3), (4, 3), (3, 3)]]
    moved = [[(-4, -4), (-1, -4), (-1, -3), (-4, -3)], [(1, 2), (2, 2), (2, 5), (1, 5)]]
    return Occluders.from_polygons(boxes), Occluders.from_polygons(moved)


@pytest.mark.parametrize("batched", [False, True])
def test_path_blocked_is_any_blocked_segment(batched):
    rng = np.random.default_rng(1)
    one, other = _layouts()
    p = _paths(rng, 400, 17)
    a, b = p[:, :-1], p[:, 1:]
    if batched:
        occ = Occluders.stack([one, other] * 200)
        want = np.any(blocked(a, b, occ), axis=-1)
    else:
        occ = one
        want = np.any(blocked(a, b, occ), axis=-1)
    got = path_blocked(a, b, occ)
    np.testing.assert_array_equal(got, want)
    assert 0 < np.count_nonzero(got) < len(got)  # both outcomes occur
