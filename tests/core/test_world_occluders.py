"""Occluders in the world: sensors never end in or pass through one; no measurement
through one. References: dense sampling of every move and line of sight, each sample
tested with matplotlib's polygon membership (independent of activetrack.models.occluders)."""

import numpy as np
import pytest
from matplotlib.path import Path

from activetrack.models import occluders
from activetrack.world import World
from activetrack.world.scenarios import make_scenario
from tests.core.helpers import in_any as _in_any
from tests.core.helpers import segments_enter as _segments_enter


def _paths(sc):
    return [Path(np.asarray(p)) for p in sc.occluders]


def _layout(seed):
    rng = np.random.default_rng(seed)
    occ = occluders.random_layout(
        rng, int(rng.integers(1, 6)), bounds=(-10.0, -15.0, 30.0, 15.0), size_range=(1.0, 6.0),
        clear=np.array([[20.0, 0.0]]), clearance=1.5,
    )  # fmt: skip
    return [np.asarray(p) for p in occ.polygons]


def test_occluders_field_round_trip_and_defaults():
    assert make_scenario("paper").occluders == ()
    assert make_scenario("paper").occluder_set is None
    sc = make_scenario("paper", occluders=[[(5, -2), (8, -2), (8, 2), (5, 2)]])
    assert sc.occluders == (((5.0, -2.0), (8.0, -2.0), (8.0, 2.0), (5.0, 2.0)),)
    assert sc.limited_sensing and make_scenario(sc) == sc
    assert sc.to_dict()["occluders"] == sc.occluders
    with pytest.raises(ValueError, match=r"occluders\[0\]"):
        make_scenario("paper", occluders=[[(0, 0), (1, 1)]])
    with pytest.raises(ValueError, match="occluders"):
        make_scenario("paper", occluders="walls")


def test_ten_thousand_random_steps_never_enter_an_occluder():
    # 25 random layouts x 16 copies x 25 steps of random actions = 10,000 sensor-steps... x M.
    moves = 0
    for seed in range(25):
        sc = make_scenario("paper", occluders=_layout(seed))
        paths = _paths(sc)
        w = World(sc, 16)
        w.reset(seeds=list(range(100 * seed, 100 * seed + 16)))
        rng = np.random.default_rng(seed)
        assert not _in_any(paths, w.sensors.reshape(-1, 2)).any()  # starts outside
        for _ in range(25):
            before = w.sensors.copy()
            w.step_actions(rng.uniform(-1.5, 1.5, (16, 3, 2)))
            after = w.sensors
            a, b = before.reshape(-1, 2), after.reshape(-1, 2)
            assert not _in_any(paths, b).any()
            assert not _segments_enter(paths, a, b).any()
            assert np.all(np.linalg.norm(b - a, axis=-1) <= w.params.r[0] * (1 + 1e-9))
            moves += len(a)
            if w.truncated.any():
                w.reset(w.truncated)
    assert moves >= 30_000


def test_no_measurement_through_an_occluder():
    sc = make_scenario("two_targets", occluders=_layout(3) + _layout(4))
    paths = _paths(sc)
    w = World(sc, 8)
    w.reset(seeds=list(range(8)))
    rng = np.random.default_rng(1)
    for _ in range(20):
        w.step_actions(rng.uniform(-1, 1, (8, 4, 2)))
        sensors = np.broadcast_to(w.sensors[:, None], (8, 2, 4, 2)).reshape(-1, 2)
        targets = np.broadcast_to(w.get("x_true")[:, :, None, :2], (8, 2, 4, 2)).reshape(-1, 2)
        hidden = _segments_enter(paths, sensors, targets, n=2001).reshape(8, 2, 4)
        detected = w.get("detected")
        # A sampled point inside means blocked; the kernel may also see a thinner sliver.
        assert not np.any(detected & hidden)
        assert (~detected).sum() >= hidden.sum()


@pytest.mark.parametrize(
    ("value", "match"),
    [
        ([[(0, 0), (1, 0), (1, float("nan"))]], r"occluders\[0\].*finite"),
        ([[(0, 0), (2e9, 0), (2e9, 2e9)]], "occluders coordinates"),
        ([[(0, 0), (1, 1), (1, 0), (0, 1)]], r"occluders\[0\].*self-intersect"),
        ([[("a", "b"), (1, 0), (0, 1)]], r"occluders\[0\]"),
        (7, "occluders must be a sequence"),
    ],
)
def test_bad_occluders_name_the_field(value, match):
    with pytest.raises(ValueError, match=match):
        make_scenario("paper", occluders=value)


def test_problem_rejects_occluders_that_are_not_occluders():
    from activetrack.world.problem import PlanningProblem

    with pytest.raises(
        ValueError, match="occluders must be an activetrack.models.occluders.Occluders"
    ):
        PlanningProblem(np.eye(2), np.zeros(2), np.ones((3, 2)), 1.0, 0.5, 1.0, 0.1,
                        occluders=[[(0, 0), (1, 0), (0, 1)]])  # fmt: skip
