"""The communication model (issue 37) against independent computations: pairwise loops,
an independent segment-rectangle clipping for line of sight, binomial bands for the drops,
breadth-first search for the groups, a brute-force schedule for the delivery queue."""

import math
import pickle
from collections import deque

import numpy as np
import pytest
from scipy import stats

import activetrack
from activetrack.models.communication import (
    CommunicationModel,
    DelayLine,
    DeliveryQueue,
    FullCommunication,
    RangeLimited,
    components,
    measurement_mask,
    measurement_senders,
)
from activetrack.models.occluders import Occluders

RECTS = [(4.0, 6.0, 12.0, 9.0), (14.0, 2.0, 17.0, 16.0)]  # (xmin, ymin, xmax, ymax)


def rect_polygon(r):
    x0, y0, x1, y1 = r
    return [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]


def segment_in_open_rect(a, b, r):
    """Return whether a sub-segment of positive length of [a, b] lies in the open rectangle
    ``r``: Liang-Barsky clipping of the parameter interval, written out here."""
    x0, y0, x1, y1 = r
    lo, hi = 0.0, 1.0
    d = np.asarray(b, float) - np.asarray(a, float)
    for p, q in ((-d[0], a[0] - x0), (d[0], x1 - a[0]), (-d[1], a[1] - y0), (d[1], y1 - a[1])):
        if p == 0.0:
            if q <= 0.0:
                return False
        else:
            t = q / p
            if p < 0.0:
                lo = max(lo, t)
            else:
                hi = min(hi, t)
    return hi - lo > 1e-9


def outside_points(rng, n, rects):
    """Return ``n`` random points in [0, 20]^2 outside every rectangle (with a margin)."""
    out = []
    while len(out) < n:
        p = rng.uniform(0.0, 20.0, 2)
        if all(not (x0 - 0.1 < p[0] < x1 + 0.1 and y0 - 0.1 < p[1] < y1 + 0.1)
               for x0, y0, x1, y1 in rects):  # fmt: skip
            out.append(p)
    return np.array(out)


def brute_links(p, rng_range, rects=None):
    m = len(p)
    out = np.zeros((m, m), bool)
    for i in range(m):
        for j in range(m):
            d = math.sqrt((p[i, 0] - p[j, 0]) ** 2 + (p[i, 1] - p[j, 1]) ** 2)
            ok = i == j or d <= rng_range
            if ok and rects and i != j:
                ok = not any(segment_in_open_rect(p[i], p[j], r) for r in rects)
            out[i, j] = ok
    return out


@pytest.mark.parametrize("radius", [0.0, 3.0, 7.5, 30.0, math.inf])
def test_range_links_match_a_pairwise_loop_batched(radius):
    rng = np.random.default_rng(3)
    p = rng.uniform(0.0, 20.0, (4, 9, 2))
    got = RangeLimited(radius).links(p, np.random.default_rng(0))
    assert got.shape == (4, 9, 9) and got.dtype == bool
    for b in range(4):
        np.testing.assert_array_equal(got[b], brute_links(p[b], radius))


def test_line_of_sight_links_match_an_independent_clipping_test():
    rng = np.random.default_rng(5)
    occ = Occluders.from_polygons([rect_polygon(r) for r in RECTS])
    model = RangeLimited(12.0, line_of_sight=True)
    n_blocked = 0
    for _ in range(10):
        p = outside_points(rng, 8, RECTS)
        got = model.links(p, np.random.default_rng(0), occ)
        want = brute_links(p, 12.0, RECTS)
        np.testing.assert_array_equal(got, want)
        n_blocked += int(np.sum(brute_links(p, 12.0) & ~want))
    assert n_blocked > 20  # the occluders did cut links: the comparison is not vacuous
    # Without line_of_sight the occluders are ignored.
    np.testing.assert_array_equal(RangeLimited(12.0).links(p, np.random.default_rng(0), occ),
                                  brute_links(p, 12.0))  # fmt: skip


def test_line_of_sight_with_one_layout_per_copy():
    rng = np.random.default_rng(6)
    layouts = [[RECTS[0]], [(8.0, 1.0, 11.0, 19.0)]]
    occ = Occluders.stack([Occluders.from_polygons([rect_polygon(r) for r in lay])
                           for lay in layouts])  # fmt: skip
    # Leading axes (layout, copy of the layout, robots): the first is the layout axis.
    p = np.stack([[outside_points(rng, 7, lay) for _ in range(3)] for lay in layouts])
    model = RangeLimited(25.0, line_of_sight=True)
    got = model.links(p, np.random.default_rng(0), occ)
    assert got.shape == (2, 3, 7, 7)
    for b, lay in enumerate(layouts):
        for c in range(3):
            np.testing.assert_array_equal(got[b, c], brute_links(p[b, c], 25.0, lay))
    # One layout shared by every copy.
    shared = Occluders.from_polygons([rect_polygon(r) for r in RECTS])
    p = np.stack([outside_points(rng, 6, RECTS) for _ in range(4)])
    got = model.links(p, np.random.default_rng(0), shared)
    for b in range(4):
        np.testing.assert_array_equal(got[b], brute_links(p[b], 25.0, RECTS))


def drop_band(n, p, alpha=1e-6):
    """Return the two-sided (1 - alpha) binomial interval of a count of n trials of p."""
    return stats.binom.interval(1.0 - alpha, n, p)


def test_drop_frequency_within_its_binomial_band_and_a_ten_percent_error_fails_it():
    drop, m, steps = 0.2, 10, 400
    p = np.random.default_rng(1).uniform(0, 1, (m, 2))  # all within range 5
    n = steps * m * (m - 1)  # packets (ordered pairs i != j)

    def lost(model, seed):
        rng = np.random.default_rng(seed)
        links = np.stack([model.links(p, rng) for _ in range(steps)])
        off = ~np.eye(m, dtype=bool)
        return int(np.sum(~links[:, off])), links

    lo, hi = drop_band(n, drop)
    k, links = lost(RangeLimited(5.0, drop=drop), 11)
    assert lo <= k <= hi
    # A model dropping 10% more often (0.22) falls outside the band for 0.2.
    k_bad, _ = lost(RangeLimited(5.0, drop=1.1 * drop), 11)
    assert not lo <= k_bad <= hi
    # Each direction independently: both packets of a pair lost with probability drop^2.
    iu = np.triu_indices(m, 1)
    both = int(np.sum(~links[:, iu[0], iu[1]] & ~links[:, iu[1], iu[0]]))
    lo2, hi2 = drop_band(steps * len(iu[0]), drop**2)
    assert lo2 <= both <= hi2
    # Out of range, nothing arrives whatever the draws.
    far = RangeLimited(0.5, drop=drop).links(np.array([[0.0, 0.0], [1.0, 0.0]]),
                                             np.random.default_rng(0))  # fmt: skip
    np.testing.assert_array_equal(far, np.eye(2, dtype=bool))


def test_seeded_reproducibility_and_the_documented_draws():
    p = np.random.default_rng(2).uniform(0, 10, (3, 6, 2))
    model = RangeLimited(8.0, drop=0.5, delay=2)
    a = model.links(p, np.random.default_rng(42))
    b = model.links(p, np.random.default_rng(42))
    c = model.links(p, np.random.default_rng(43))
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)
    # Exactly one rng.standard_normal((..., M * M)): a twin stream advanced by that is left
    # in the same state, and its draws give the links (drop 0.5: lost iff the normal < 0).
    r1, r2 = np.random.default_rng(7), np.random.default_rng(7)
    got = model.links(p, r1)
    u = r2.standard_normal((3, 36))
    assert r1.bit_generator.state == r2.bit_generator.state
    want = np.stack([brute_links(q, 8.0) for q in p]) & ~(u.reshape(3, 6, 6) < 0.0)
    want[:, np.arange(6), np.arange(6)] = True
    np.testing.assert_array_equal(got, want)
    # The same from the draws given (the world's noise block), and the draws checked.
    assert model.n_draws(6) == 36 and FullCommunication().n_draws(6) == 0
    np.testing.assert_array_equal(model.links_from_draws(p, u), want)
    with pytest.raises(ValueError, match="draws"):
        model.links_from_draws(p, u[:, :35])
    with pytest.raises(ValueError, match="draws"):
        model.links_from_draws(p, None)
    with pytest.raises(ValueError, match="draws"):
        RangeLimited(8.0).links_from_draws(p, u)
    np.testing.assert_array_equal(RangeLimited(8.0).links_from_draws(p, None),
                                  np.stack([brute_links(q, 8.0) for q in p]))  # fmt: skip
    # drop = 1 loses every packet, drop = 0 none.
    none = RangeLimited(100.0, drop=1.0).links(p, np.random.default_rng(0))
    np.testing.assert_array_equal(none, np.broadcast_to(np.eye(6, dtype=bool), (3, 6, 6)))


@pytest.mark.parametrize("model", [FullCommunication(), RangeLimited(3.0),
                                   RangeLimited(3.0, line_of_sight=True)])  # fmt: skip
def test_models_without_drops_consume_no_randomness(model):
    rng = np.random.default_rng(9)
    before = rng.bit_generator.state
    occ = Occluders.from_polygons([rect_polygon(RECTS[0])])
    links = model.links(outside_points(np.random.default_rng(1), 5, RECTS[:1]), rng, occ)
    assert rng.bit_generator.state == before
    if isinstance(model, FullCommunication):
        assert links.all() and links.shape == (5, 5)


def test_validation_names_the_field():
    for kw, field in [({"range": -1.0}, "range"), ({"range": math.nan}, "range"),
                      ({"range": "10"}, "range"), ({"range": 1.0, "drop": -0.01}, "drop"),
                      ({"range": 1.0, "drop": 1.5}, "drop"),
                      ({"range": 1.0, "drop": math.nan}, "drop"),
                      ({"range": 1.0, "delay": -1}, "delay"),
                      ({"range": 1.0, "delay": 1.5}, "delay"),
                      ({"range": 1.0, "line_of_sight": "yes"}, "line_of_sight")]:  # fmt: skip
        with pytest.raises(ValueError, match=field):
            RangeLimited(**kw)
    with pytest.raises(TypeError, match="unexpected keyword"):
        RangeLimited(1.0, dropout=0.1)
    RangeLimited(0.0, drop=1.0, delay=0)  # the closed ends are allowed
    RangeLimited(math.inf, drop=0.0)
    model = RangeLimited(1.0, delay=5)
    model.check(6)
    with pytest.raises(ValueError, match="delay"):
        model.check(5)
    with pytest.raises(ValueError, match="n_steps"):
        model.check(0)
    FullCommunication().check(1)
    with pytest.raises(ValueError, match="positions"):
        model.links(np.array([[0.0, np.nan]]), np.random.default_rng(0))
    with pytest.raises(ValueError, match="positions"):
        model.links(np.zeros((3, 3)), np.random.default_rng(0))
    with pytest.raises(ValueError, match="rng"):
        model.links(np.zeros((3, 2)), 0)


def test_compared_by_value_and_pickled_and_exported():
    assert RangeLimited(10, drop=0.2) == RangeLimited(10.0, drop=0.2)
    assert RangeLimited(10, drop=0.2) != RangeLimited(10, drop=0.3)
    assert RangeLimited(10) != FullCommunication() and FullCommunication() == FullCommunication()
    m = RangeLimited(4.0, drop=0.1, delay=2, line_of_sight=True)
    assert pickle.loads(pickle.dumps(m)) == m and "delay=2" in repr(m)
    for name in [
        "CommunicationModel",
        "FullCommunication",
        "RangeLimited",
        "DeliveryQueue",
        "DelayLine",
    ]:
        assert name in activetrack.__all__ and hasattr(activetrack, name)
    assert issubclass(RangeLimited, CommunicationModel)


def bfs_groups(links, strong):
    """Return canonical labels by breadth-first search: weak (links either way) or strong
    (mutual reachability along received links), groups numbered by lowest member."""
    m = len(links)

    def reach(adj, s):
        seen, todo = {s}, deque([s])
        while todo:
            u = todo.popleft()
            for v in range(m):
                if adj[u][v] and v not in seen:
                    seen.add(v)
                    todo.append(v)
        return seen

    if strong:
        fwd = [reach(links, s) for s in range(m)]
        same = [[j in fwd[i] and i in fwd[j] for j in range(m)] for i in range(m)]
    else:
        sym = links | links.T
        r = [reach(sym, s) for s in range(m)]
        same = [[j in r[i] for j in range(m)] for i in range(m)]
    labels, next_label = [-1] * m, 0
    for i in range(m):
        if labels[i] < 0:
            for j in range(m):
                if same[i][j]:
                    labels[j] = next_label
            next_label += 1
    return next_label, labels


@pytest.mark.parametrize("connection", ["weak", "strong"])
def test_components_match_breadth_first_search(connection):
    rng = np.random.default_rng(8)
    links = rng.random((5, 3, 12, 12)) < 0.08
    n, labels = components(links, connection=connection)
    assert n.shape == (5, 3) and labels.shape == (5, 3, 12)
    counts = set()
    for idx in np.ndindex(5, 3):
        want_n, want = bfs_groups(links[idx], connection == "strong")
        assert n[idx] == want_n
        np.testing.assert_array_equal(labels[idx], want)
        counts.add(want_n)
    assert len(counts) > 2  # varied cases
    with pytest.raises(ValueError, match="connection"):
        components(links, connection="both")
    with pytest.raises(ValueError, match="links"):
        components(np.ones((3, 4), bool))


def test_measurement_senders_own_always_and_the_rows():
    rng = np.random.default_rng(4)
    links = rng.random((7, 7)) < 0.4
    got = measurement_senders(links)
    for i in range(7):
        want = [j for j in range(7) if links[i, j] or j == i]
        assert got[i].tolist() == want
    mask = measurement_mask(links[None])
    assert mask.shape == (1, 7, 7) and mask[0, np.arange(7), np.arange(7)].all()
    full = FullCommunication().links(np.zeros((4, 2)), np.random.default_rng(0))
    assert [s.tolist() for s in measurement_senders(full)] == [list(range(4))] * 4


def test_delivery_queue_releases_after_the_delay_in_send_order():
    rng = np.random.default_rng(12)
    m, steps = 5, 30
    queue = DeliveryQueue(m, delay=3)
    sent = []  # (due, send_step, sender, receiver, payload): the brute-force schedule
    for t in range(steps):
        links = rng.random((m, m)) < 0.5
        # A varying per-send delay too: later sends can come due before earlier ones.
        d = 3 if t % 4 else int(rng.integers(0, 6))
        payloads = [f"z{t}.{j}" for j in range(m)]
        queue.send(t, links, payloads, delay=d)
        sent += [(t + d, t, j, i, payloads[j]) for i in range(m) for j in range(m)
                 if links[i, j] and i != j]  # fmt: skip
        got = queue.deliver(t)
        for i in range(m):
            want = sorted((s, j, z) for due, s, j, r, z in sent if r == i and due == t)
            assert got[i] == want
    assert len(queue) == sum(due >= steps for due, *_ in sent)
    # Nothing sent at the last steps is lost: delivering later releases it, once.
    late = queue.deliver(steps + 10)
    assert sum(map(len, late)) == sum(due >= steps for due, *_ in sent) and len(queue) == 0
    with pytest.raises(ValueError, match="links"):
        queue.send(0, np.ones((4, 4), bool), ["a"] * 4)
    with pytest.raises(ValueError, match="payloads"):
        queue.send(0, np.ones((m, m), bool), ["a"])
    with pytest.raises(ValueError, match="delay"):
        DeliveryQueue(3, delay=-1)


def test_measurement_sharing_is_how_each_robots_filter_updates():
    # The per-robot filters' rule (to be wired into the world): robot r's EKF update uses
    # the measurements of row r of measurement_mask, as the EKF's ``mask`` over sensors,
    # all robots at once along a leading robot axis (the world's
    # ``detected`` mask combines with it by ``&``). Checked against the update of only
    # those sensors' measurements (sliced: an independent path of the EKF), and, with
    # full communication, against today's central update.
    from activetrack.estimation import ekf

    rng = np.random.default_rng(13)
    m = 7
    x = np.array([1.0, 2.0, 0.3, -0.2])
    A = rng.standard_normal((4, 4))
    P = A @ A.T + np.eye(4)
    sensors = rng.uniform(-10, 10, (m, 2))
    sd2, st2 = rng.uniform(0.5, 2.0, m), rng.uniform(0.01, 0.05, m)
    z = np.stack([np.hypot(*(x[:2] - sensors).T), np.arctan2(*(x[:2] - sensors).T[::-1])], -1)
    z = z + rng.standard_normal((m, 2)) * 0.1

    def per_robot(mask):
        rep = (m,) + (1,) * 2
        return ekf.update(np.tile(x, (m, 1)), np.tile(P, (m, 1, 1)), np.tile(z, rep),
                          np.tile(sensors, rep), np.tile(sd2, (m, 1)), np.tile(st2, (m, 1)),
                          0.0, mask)  # fmt: skip

    links = RangeLimited(9.0, drop=0.3).links(sensors, rng)
    heard = links.sum(axis=1)
    assert (heard < m).any() and (heard > 1).any()  # partial sharing: not vacuous
    xs, Ps = per_robot(measurement_mask(links))
    for r, s in enumerate(measurement_senders(links)):
        xr, Pr = ekf.update(x, P, z[s], sensors[s], sd2[s], st2[s])
        np.testing.assert_allclose(xs[r], xr, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(Ps[r], Pr, rtol=1e-12, atol=1e-14)
    full = FullCommunication().links(sensors, rng)
    xs, Ps = per_robot(measurement_mask(full))
    xc, Pc = ekf.update(x, P, z, sensors, sd2, st2)
    for r in range(m):  # bit for bit: the masked kernel with every sensor is today's
        np.testing.assert_array_equal(xs[r], xc)
        np.testing.assert_array_equal(Ps[r], Pc)


@pytest.mark.parametrize("delay", [0, 1, 3])
def test_delay_line_returns_each_copys_own_pushes_delay_steps_late(delay):
    # Against a per-copy Python history since the copy's last reset; copies step in random
    # subsets (a world's live copies) and reset at random times.
    rng = np.random.default_rng(20 + delay)
    n, m = 4, 3
    line = DelayLine(n, delay)
    history = [[] for _ in range(n)]
    n_valid = 0
    for _ in range(60):
        if rng.random() < 0.1:
            gone = rng.random(n) < 0.5
            line.reset(gone)
            for i in np.flatnonzero(gone):
                history[i] = []
        rows = np.flatnonzero(rng.random(n) < 0.7)
        links = rng.random((n, m, m)) < 0.5
        z = rng.standard_normal((n, m, 2))
        (got_links, got_z), valid = line.push((links, z), rows)
        for i in range(n):
            if i not in rows:
                assert not valid[i]
                continue
            h = history[i]
            h.append((links[i].copy(), z[i].copy()))
            ok = len(h) > delay
            assert valid[i] == ok
            if ok:
                np.testing.assert_array_equal(got_links[i], h[-1 - delay][0])
                np.testing.assert_array_equal(got_z[i], h[-1 - delay][1])
                n_valid += 1
    assert n_valid > 60  # not vacuous
    with pytest.raises(ValueError, match="arrays"):
        line.push((np.zeros((n + 1, 2)),))
    with pytest.raises(ValueError, match="delay"):
        DelayLine(2, -1)


def test_a_users_model_subclasses_the_base():
    # A fixed ring topology that loses each packet with the user's own rule: the base
    # validates, draws n_draws normals per step and sets the diagonal.
    class Ring(CommunicationModel):
        def n_draws(self, n_robots):
            return n_robots

        def _links(self, positions, draws, occluders):
            m = positions.shape[-2]
            ring = np.zeros(positions.shape[:-2] + (m, m), bool)
            i = np.arange(m)
            ring[..., i, (i + 1) % m] = draws > 0.0  # robot i hears i + 1 if its draw > 0
            return ring

    with pytest.raises(TypeError):
        CommunicationModel()
    p = np.zeros((2, 5, 2))
    r1, r2 = np.random.default_rng(3), np.random.default_rng(3)
    got = Ring().links(p, r1)
    u = r2.standard_normal((2, 5))
    assert r1.bit_generator.state == r2.bit_generator.state
    for b in range(2):
        want = np.eye(5, dtype=bool)
        for i in range(5):
            want[i, (i + 1) % 5] |= u[b, i] > 0.0
        np.testing.assert_array_equal(got[b], want)
    assert Ring() == Ring() and Ring().name == "Ring" and Ring().delay == 0
