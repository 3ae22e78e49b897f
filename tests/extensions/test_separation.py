"""The team rule of a minimum separation ``d_sep`` (issue 36), against brute force.

- The field: a distance or M radii, refused (``ValueError`` naming ``d_sep``) out of range,
  of the wrong shape, or too large for the team's start disk (with any kinematics); 0
  (the default) leaves the scenario's record and the compiled step alone.
- The world's rule, step by step on a crowded team (8 sensors around one target) with
  random actions and GSR's plans, in a batched world: no two sensors closer than their
  distance after a step, no path passing within it of a sensor where that sensor stands
  when it moves, nor of another's path at the same instant (the segments sampled), no
  sensor inside the ``rho`` disk; the collision counter equals a brute-force count of
  the wanted points' close pairs, and the reported smallest distance a brute-force
  minimum.
- The fallback: a feasible wanted point is kept; otherwise the point taken is feasible by
  sampling and no farther from the wanted point than any sampled-feasible point of the
  rule's candidate grid.
"""

from __future__ import annotations

import numpy as np
import pytest

from activetrack import Unicycle
from activetrack.kinematics import sensor_motion
from activetrack.kinematics.separation import Separation, pair_distances
from activetrack.world import World
from activetrack.world.scenarios import make_scenario

M = 8
CROWDED = dict(
    n_sensors=M, d_sep=1.0, sensor_center=(8.0, 0.0), sensor_radius=5.0, x0=(0.0, 0.0, 0.0, 0.0),
    x0_hat=(0.0, 0.0, 0.0, 0.0), q=1.0, n_steps=60,
)  # fmt: skip
RTOL = 1e-9
S = np.linspace(0.0, 1.0, 65)  # samples of a path segment


def _dist(a, b):
    return np.hypot(*(np.asarray(a) - np.asarray(b)).T)


def _check_step(old, new, pred, d, rho, stuck=False, want=None):
    """Assert the rule's guarantees on one copy's step by brute force (sampled paths);
    outside the ``rho`` disk unless a sensor was ``stuck`` (no feasible point); with the
    ``want``ed points (the disk's own moves, which a reach too short leaves inside): no
    deeper inside than the wanted point or the old position."""
    m = len(old)
    stuck = np.broadcast_to(stuck, (m,))
    for i in range(m):
        if want is not None:
            least = min(rho[i], _dist(old[i], pred), _dist(want[i], pred))
            assert _dist(new[i], pred) >= least * (1 - RTOL)
        else:
            assert stuck[i] or _dist(new[i], pred) >= rho[i] * (1 - RTOL)
        path = old[i] + S[:, None] * (new[i] - old[i])
        for j in range(m):
            if j == i:
                continue
            assert _dist(new[i], new[j]) >= d[i, j] * (1 - RTOL)
            there = new[j] if j < i else old[j]  # where j stands when i moves
            assert np.min(_dist(path, there)) >= d[i, j] * (1 - RTOL)
            # The robots move together: j's path at the same instants.
            together = old[j] + S[:, None] * (new[j] - old[j])
            assert np.min(_dist(path, together)) >= d[i, j] * (1 - RTOL)


@pytest.mark.parametrize(
    "kw, words",
    [
        (dict(d_sep=-1.0), "d_sep must lie in"),
        (dict(d_sep=float("nan")), "d_sep must be finite"),
        (dict(d_sep=(1.0, 2.0)), "d_sep must be one distance"),
        (dict(d_sep="far"), "d_sep must hold real numbers"),
        (dict(d_sep=4.0, n_sensors=8), "d_sep=4.0 does not fit the team's start"),
        (dict(d_sep=4.0, n_sensors=8, kinematics=Unicycle(0.0, 10.0, 4.0)), "does not fit"),
    ],
)
def test_d_sep_is_validated(kw, words):
    with pytest.raises(ValueError, match=words):
        make_scenario("paper", **kw)


def test_d_sep_default_and_forms():
    sc = make_scenario("paper")
    assert sc.d_sep == 0.0 and "d_sep" not in sc.to_dict() and sc.capabilities.fused_step
    radii = make_scenario("paper", d_sep=(0.1, 0.2, 0.3))
    assert radii.d_sep == (0.1, 0.2, 0.3) and not radii.capabilities.fused_step
    np.testing.assert_allclose(pair_distances(radii.d_sep, 3)[0, 2], 0.4)
    # A team of 6 repeats the paper's radii (as every per-sensor field).
    assert make_scenario(radii, n_sensors=6).d_sep == (0.1, 0.2, 0.3) * 2
    # One sensor: no pair, any d_sep fits.
    assert make_scenario("paper", n_sensors=1, d_sep=100.0).d_sep == 100.0


def _run(world, policy, steps, rng):
    """Step ``world`` ``steps`` times with ``policy`` (actions in units of the reach),
    checking every copy's step by brute force; return the total collisions."""
    n = world.num_copies
    d = pair_distances(world.scenario.d_sep, M)
    r, rho = world.params.r, world.params.rho
    total = 0
    for _ in range(steps):
        old = world.get("sensors").copy()
        pred = world.get("x_pred")[:, :2].copy()
        actions = policy(world, rng)
        world.step_actions(actions)
        new = world.get("sensors")
        want, _ = sensor_motion.apply_actions(actions, old, pred, r, rho)
        for c in range(n):
            _check_step(old[c], new[c], pred[c], d, rho, want=want[c])
            e = want[c][:, None] - want[c][None]
            close = np.hypot(e[..., 0], e[..., 1]) < d
            assert world.get("collisions")[c] == np.count_nonzero(np.triu(close, 1))
            e = new[c][:, None] - new[c][None]
            dist = np.hypot(e[..., 0], e[..., 1]) + np.diag(np.full(M, np.inf))
            assert world.get("min_separation")[c] == pytest.approx(dist.min(), rel=1e-12)
        total += int(np.sum(world.get("collisions")))
        ended = world.get("truncated") | world.get("terminated")
        if np.any(ended):
            world.reset(ended)
    return total


def _random(world, rng):
    return rng.uniform(-1.0, 1.0, (world.num_copies, M, 2))


def _inward(world, rng):
    """Every sensor heads for the target: the crowd the rule must resolve."""
    e = world.get("x_pred")[:, None, :2] - world.get("sensors")
    return e / np.maximum(np.hypot(e[..., 0], e[..., 1])[..., None], 1e-12)


@pytest.mark.parametrize("policy", [_random, _inward])
def test_world_keeps_separation(policy):
    world = World("paper", 40, **CROWDED)
    world.reset(seeds=range(40))
    d = pair_distances(1.0, M)
    for c in range(40):  # the starts keep it too
        e = world.get("sensors")[c][:, None] - world.get("sensors")[c][None]
        assert np.all(np.hypot(e[..., 0], e[..., 1]) >= d)
    total = _run(world, policy, 75, np.random.default_rng(1))  # 3000 copy-steps
    assert total > 0  # the rule had work to do
    assert np.all(world.get("n_collisions") >= world.get("collisions"))


def test_world_with_gsr_plans_keeps_separation():
    from activetrack.baselines.gsr import GSR  # noqa: PLC0415 (baselines above the core)

    gsr = GSR()
    world = World("paper", 4, **CROWDED)
    world.reset(seeds=range(4))

    def plan(w, rng):
        pts = np.stack([gsr.plan(w.planning_problem(c)) for c in range(w.num_copies)])
        return sensor_motion.actions_to_reach(pts, w.get("sensors"), w.params.r)

    _run(world, plan, 50, np.random.default_rng(2))


def test_infos_report_the_separation():
    from activetrack.envs import parallel_env  # noqa: PLC0415

    env = parallel_env("paper", **CROWDED)
    env.reset(seed=3)
    _, _, _, _, infos = env.step({a: np.ones(2, np.float32) for a in env.agents})
    info = infos[env.possible_agents[0]]
    assert info["min_separation"] == pytest.approx(env.unwrapped.world.separation_info(0)[
        "min_separation"]) and info["min_separation"] >= 1.0  # fmt: skip
    assert set(info) >= {"collisions", "n_collisions", "n_stuck"}
    plain = parallel_env("paper")
    plain.reset(seed=3)
    infos = plain.step({a: np.zeros(2) for a in plain.agents})[4]
    assert "collisions" not in infos[plain.possible_agents[0]]


def test_fallback_against_brute_force():
    rng = np.random.default_rng(5)
    m = 5
    d = pair_distances(0.8, m)
    rule = Separation(d)
    r, rho = np.full(m, 1.0), np.full(m, 1.5)
    checked = 0
    for _ in range(300):
        old = rng.uniform(-3, 3, (m, 2))
        e = old[:, None] - old[None]
        tgt = rng.uniform(-3, 3, 2)
        if np.any(np.hypot(e[..., 0], e[..., 1]) + 9 * np.eye(m) < 0.8) or np.any(
            _dist(old, tgt) < 1.5
        ):
            continue
        want, _ = sensor_motion.apply_actions(rng.uniform(-1, 1, (m, 2)), old, tgt, r, rho)
        new, coll, stuck = rule.resolve(old, want, tgt, r, rho)
        _check_step(old, new, tgt, d, rho, stuck)
        for i in range(m):
            there = np.array([new[j] if j < i else old[j] for j in range(m) if j != i])
            moved = [old[j] + S[:, None] * (new[j] - old[j]) for j in range(i)]

            def feasible(p, o=old[i], ri=r[i], rhoi=rho[i], t=tgt, there=there, moved=moved):
                path = o + S[:, None] * (p - o)  # brute force: a sampled path
                return (_dist(p, o) <= ri * (1 + 1e-12) and _dist(p, t) >= rhoi
                        and all(np.min(_dist(path, q)) >= 0.8 for q in there)
                        and all(np.min(_dist(path, q)) >= 0.8 for q in moved))  # fmt: skip

            if feasible(want[i]):
                np.testing.assert_array_equal(new[i], want[i])
                continue
            checked += 1
            ang = np.linspace(0, 2 * np.pi, 64, endpoint=False)
            grid = [old[i] + f * np.array([np.cos(a), np.sin(a)]) for f in np.arange(9) / 8
                    for a in ang]  # fmt: skip
            best = min((_dist(p, want[i]) for p in grid if feasible(p)), default=None)
            if stuck[i]:  # boxed in: no deeper inside the rho disk than staying
                assert best is None
                assert _dist(new[i], tgt) >= min(_dist(old[i], tgt), rho[i])
            else:
                assert best is None or _dist(new[i], want[i]) <= best + 1e-12
    assert checked > 20
