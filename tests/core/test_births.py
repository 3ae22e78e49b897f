"""Targets that appear and leave: the birth process, departures, the track rules and the
search map, each against an independent computation (issue 38)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import activetrack as at
from activetrack.models import search_map
from activetrack.world import World
from activetrack.world.track_management import initiated, lead_points, track_rule

REGION = (-20.0, -20.0, 20.0, 20.0)


def _counts(rate: float, steps: int, seed: int) -> np.ndarray:
    b = at.BirthProcess(rate, REGION)
    rng = np.random.default_rng(seed)
    return np.array([b.count(rng) for _ in range(steps)])


def test_birth_counts_are_poisson():
    # The total over T steps is Poisson(rate T): a two-sided 99.9% band of that law for
    # the sum, and the variance-to-mean ratio within its chi-square band (a Poisson law
    # has ratio 1; a 10% error in the rate leaves the first band).
    rate, T = 0.3, 20000
    c = _counts(rate, T, 1)
    lo, hi = stats.poisson.ppf([0.0005, 0.9995], rate * T)
    assert lo <= c.sum() <= hi
    assert not (0.9 * rate * T >= lo and 0.9 * rate * T <= hi)  # the band can see 10%
    disp = c.var(ddof=1) * (T - 1) / c.mean()
    assert stats.chi2.ppf(0.0005, T - 1) <= disp <= stats.chi2.ppf(0.9995, T - 1)


def test_entry_states_lie_on_the_edge_heading_inward_uniform_by_length():
    b = at.BirthProcess(1.0, (0.0, 0.0, 30.0, 10.0), speed=(1.0, 2.0))
    x = b.entry_states(np.random.default_rng(2), 4000, 4)
    p, v = x[:, :2], x[:, 2:]
    on_x = np.isclose(p[:, 0], 0.0) | np.isclose(p[:, 0], 30.0)
    on_y = np.isclose(p[:, 1], 0.0) | np.isclose(p[:, 1], 10.0)
    assert np.all(on_x | on_y)
    speed = np.hypot(v[:, 0], v[:, 1])
    assert np.all((speed >= 1.0) & (speed <= 2.0))
    # one step later (1 s) every arrival is inside: the velocity points in
    assert np.all(b.inside(p + 1e-3 * v))
    # and its ray crosses the central half [7.5, 22.5] x [2.5, 7.5] (sampled along it)
    t = np.linspace(0.0, 40.0, 4001)
    ray = p[:, None, :] + t[None, :, None] * (v / speed[:, None])[:, None, :]
    hits = (np.abs(ray[..., 0] - 15.0) <= 7.5 + 1e-6) & (np.abs(ray[..., 1] - 5.0) <= 2.5 + 1e-6)
    assert np.all(hits.any(axis=1))
    # uniform by length: the long sides hold 60 of the 80 m of the perimeter
    long_sides = np.isclose(p[:, 1], 0.0) | np.isclose(p[:, 1], 10.0)
    n, k = len(p), int(long_sides.sum())
    lo, hi = stats.binom.ppf([0.0005, 0.9995], n, 0.75)
    assert lo <= k <= hi


def test_spawn_areas_hold_every_arrival_in_proportion_to_area():
    areas = ((0.0, 0.0, 2.0, 2.0), (10.0, 10.0, 16.0, 12.0))  # areas 4 and 12
    b = at.BirthProcess(1.0, REGION, spawn_areas=areas)
    x = b.entry_states(np.random.default_rng(3), 4000, 4)
    first = (x[:, 0] <= 2.0) & (x[:, 1] <= 2.0) & (x[:, 0] >= 0) & (x[:, 1] >= 0)
    second = (x[:, 0] >= 10.0) & (x[:, 0] <= 16.0) & (x[:, 1] >= 10.0) & (x[:, 1] <= 12.0)
    assert np.all(first | second)
    lo, hi = stats.binom.ppf([0.0005, 0.9995], len(x), 0.25)
    assert lo <= first.sum() <= hi


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"rate": -0.1}, "births.rate"),
        ({"rate": np.nan}, "births.rate"),
        ({"region": (0, 0, -1, 1)}, "births.region"),
        ({"speed": (3.0, 1.0)}, "births.speed"),
        ({"delete_after": 0}, "births.delete_after"),
        ({"velocity_var": -1.0}, "births.velocity_var"),
        ({"search_cells": 0}, "births.search_cells"),
        ({"search_weight": -1.0}, "births.search_weight"),
        ({"search_var": 0.0}, "births.search_var"),
        ({"spawn_areas": ((30.0, 0.0, 40.0, 1.0),)}, "births.spawn_areas[0]"),
    ],
)
def test_bad_parameters_name_the_field(kwargs, field):
    args = {"rate": 0.1, "region": REGION, **kwargs}
    with pytest.raises(ValueError, match=field.replace("[", r"\[").replace("]", r"\]")):
        at.BirthProcess(args.pop("rate"), args.pop("region"), **args)


def test_births_need_limited_sensing_and_range_bearing():
    b = at.BirthProcess(0.1, REGION)
    with pytest.raises(ValueError, match="births needs limited sensing"):
        at.make_scenario("two_targets", births=b)
    with pytest.raises(ValueError, match="births needs range_bearing"):
        at.make_scenario("range_only", births=b, max_range=10.0)
    with pytest.raises(ValueError, match="births must be None or an activetrack.BirthProcess"):
        at.make_scenario("patrol", births=0.3)


def test_track_rule_on_a_hand_made_sequence():
    # detections at steps 1, 2, then none until 6; delete_after 3: the track starts at 1,
    # holds through 4 (4 - 2 = 2 < 3), is dropped at 5 (5 - 2 = 3), starts again at 6.
    seen = {1: True, 2: True, 3: False, 4: False, 5: False, 6: True, 7: False}
    tracked, last, log = False, 0, []
    for k in range(1, 8):
        tracked, last, start = track_rule(tracked, last, seen[k], k, 3)
        log.append((tracked, start))
    assert log == [(True, True), (True, False), (True, False), (True, False), (False, False),
                   (True, True), (True, False)]  # fmt: skip


def test_initiation_is_the_measurements_inverse_with_its_first_order_covariance():
    sensor, d, theta, phi = np.array([1.0, 2.0]), 10.0, 0.4, 0.3
    x, P = initiated(np.array([d, theta]), sensor, phi, 2.0, 0.01, 4, 9.0)
    np.testing.assert_allclose(x[:2], sensor + d * np.array([np.cos(0.7), np.sin(0.7)]))
    assert np.all(x[2:] == 0.0)
    # Monte Carlo: the inverse of noisy measurements has that covariance to first order.
    rng = np.random.default_rng(4)
    dd = d + np.sqrt(2.0) * rng.standard_normal(200000)
    tt = theta + 0.1 * rng.standard_normal(200000)
    pts = sensor + dd[:, None] * np.stack([np.cos(tt + phi), np.sin(tt + phi)], -1)
    np.testing.assert_allclose(np.cov(pts.T), P[:2, :2], rtol=0.03, atol=0.02)
    np.testing.assert_allclose(np.diag(P)[2:], 9.0)


def test_search_map_spreads_keeps_mass_and_is_searched():
    b = at.BirthProcess(0.0, (0.0, 0.0, 4.0, 4.0), speed=(0.0, 1.0), search_cells=4)
    cells = search_map.centers(b.region, 4)
    q = np.zeros((4, 4))
    q[1, 2] = 0.8
    a = search_map.spread_fraction(b, 0.5)  # 1 m/s * 0.5 s / 1 m
    far = np.array([[100.0, 100.0]])
    out = search_map.step(q, np.zeros((4, 4)), a, cells, far, np.array([1.0]), np.array([1.0]))
    assert a == 0.5
    assert out[1, 2] == pytest.approx(0.4)
    for nb in ((0, 2), (2, 2), (1, 1), (1, 3)):
        assert out[nb] == pytest.approx(0.1)
    assert out.sum() == pytest.approx(0.8)
    # a sensor at the cell's centre with p_detect 0.9 leaves a tenth
    at_cell = cells[1, 2][None]
    out2 = search_map.step(q, np.zeros((4, 4)), 0.0, cells, at_cell, np.array([0.5]),
                           np.array([0.9]))  # fmt: skip
    assert out2[1, 2] == pytest.approx(0.08)
    # edge inflow: the rate spread over the perimeter by length
    b2 = at.BirthProcess(0.2, (0.0, 0.0, 4.0, 4.0), search_cells=4)
    inflow = search_map.inflow(b2)
    assert inflow.sum() == pytest.approx(0.2)
    assert inflow[0, 0] == pytest.approx(0.2 * 2 / 16)  # a corner cell: two unit sides
    assert inflow[1, 1] == 0.0


def _run(world: World, steps: int, seed: int):
    world.reset(seeds=[seed])
    log = []
    for _ in range(steps):
        world.step(world.get("sensors", 0))
        truths = [world.get("x_true", 0, k).copy() for k in range(world.n_targets)]
        log.append((world.present[0].copy(), world.tracked[0].copy(), truths))
    return log


def test_departures_free_the_slot_once_outside_the_region():
    world = World("patrol", 1, n_steps=400)
    log = _run(world, 400, 5)
    region = world.scenario.births
    seen_departure = False
    for (p0, t0, _), (p1, _, x1) in zip(log, log[1:], strict=False):
        for k in range(world.n_targets):
            if p0[k] and not p1[k]:  # departed: outside the region now
                assert not region.inside(x1[k][:2])
                seen_departure = True
            if p1[k]:  # present: inside
                assert region.inside(x1[k][:2])
            if p1[k] and not p0[k]:  # born: only into a slot free of target and track
                assert not t0[k]
    assert seen_departure


def test_a_world_without_births_has_no_masks():
    world = World("two_targets", 1)
    assert world.present is None and world.tracked is None and world.target_ids is None


def test_absent_targets_are_never_detected_and_tracks_follow_the_rule():
    world = World("patrol", 1, n_steps=300)
    world.reset(seeds=[7])
    b = world.scenario.births
    last = np.zeros(world.n_targets, dtype=int)
    tracked = np.zeros(world.n_targets, dtype=bool)
    for k in range(1, 301):
        world.step(world.get("sensors", 0))
        det = world.get("detected", 0).any(axis=-1)
        present = world.present[0]
        assert not np.any(det & ~present)
        for s in range(world.n_targets):  # the rule, recomputed by hand
            if det[s]:
                tracked[s], last[s] = True, k
            elif tracked[s] and k - last[s] >= b.delete_after:
                tracked[s] = False
        np.testing.assert_array_equal(world.tracked[0], tracked)


def test_search_points_beyond_reach_are_shown_on_the_way_from_the_nearest_sensor():
    sensors = np.array([[0.0, 0.0], [100.0, 0.0]])
    pts = np.array([[30.0, 40.0], [5.0, 0.0], [100.0, -8.0]])
    out = lead_points(pts, sensors, np.array([10.0, 20.0]))
    # the first: 50 m from sensor 0 (its nearest), shown 8 m along the way (0.8 x 10)
    np.testing.assert_allclose(out[0], [4.8, 6.4])
    np.testing.assert_allclose(out[1], [5.0, 0.0])  # within 8 m: unchanged
    np.testing.assert_allclose(out[2], [100.0, -8.0])  # within 16 m of sensor 1
    np.testing.assert_array_equal(lead_points(pts, sensors, None), pts)


def test_errors_and_nees_are_over_the_tracks_held_of_present_targets():
    world = World("patrol", 2, n_steps=200)
    world.reset(seeds=[11, 12])
    checked = 0
    for _ in range(200):
        world.step(world.get("sensors"))
        for i in range(2):
            held = world.present[i] & world.tracked[i]
            errs, nees = [], []
            for k in np.flatnonzero(held).tolist():
                e = world.get("x_true", i, k)[:2] - world.get("x_hat", i, k)[:2]
                errs.append(float(e @ e))
                nees.append(float(e @ np.linalg.solve(world.get("P", i, k)[:2, :2], e)))
            want = np.sqrt(np.mean(errs)) if errs else 0.0
            assert world.position_error(i) == pytest.approx(want, rel=1e-12)
            if nees:
                assert world.position_nees(i) == pytest.approx(np.mean(nees), rel=1e-9)
                checked += 1
            else:
                assert np.isnan(world.position_nees(i))
    assert checked > 50


def test_the_observation_ends_with_the_track_flags_inside_its_bounds():
    world = World("patrol", 1, n_steps=120)
    world.reset(seeds=[3])
    low, high = world.layout.bounds(world.length_scale)
    K, M = world.n_targets, world.n_sensors
    seen_both = set()
    for _ in range(120):
        world.step(world.get("sensors", 0))
        obs = world.observe(0)
        flags = world.tracked[0].astype(np.float32)
        assert obs.shape == (M, world.layout.obs_dim)
        for i in range(M):
            np.testing.assert_array_equal(obs[i, -K:], flags)
        assert np.all((obs >= low) & (obs <= high))
        state = world.state(0)
        np.testing.assert_array_equal(state[-1 - M * K : -1], np.tile(flags, M))
        seen_both |= set(flags.tolist())
    assert seen_both == {0.0, 1.0}
