"""The robot tasks (issue 36): ``unicycle``, ``fixed_wing``, ``crowded`` and
``urban_unicycle``, made from their ids.

Each episode of random actions is checked step by step against geometry computed here,
not by the kinematics' code: a unicycle's step is an arc, so from the headings before
and after it (read from the agents' observations) and the chord it drove, its turn rate
``w = dtheta / dt`` and its speed ``v = chord / (dt sinc(dtheta / 2))`` follow, and must
lie in the robot's documented ranges (a fixed-wing robot never slows below ``v_min``);
the chord must point along the mean of the two headings. Every two sensors keep
``d_sep`` (brute-force pair distances) and none ends inside an occluder (a point-in-
polygon test by ray crossing). Bad kinematics parameters given as the environment's
keywords are refused, naming the field.
"""

from __future__ import annotations

import gymnasium
import numpy as np
import pettingzoo
import pytest

import activetrack  # noqa: F401  (registers the ids)
from activetrack import Disk, Unicycle

#: Each robot task's id, preset and its robots as docs/tasks.md gives them:
#: (v_min, v_max, w_max) of a unicycle, or None for the paper's disk; and d_sep.
ROBOTS = {
    "activetrack/Unicycle-v0": ("unicycle", (0.0, 10.0, np.pi), 0.0),
    "activetrack/FixedWing-v0": ("fixed_wing", (4.0, 10.0, 2.0 * np.pi / 3.0), 0.0),
    "activetrack/Crowded-v0": ("crowded", None, 2.0),
    "activetrack/UrbanUnicycle-v0": ("urban_unicycle", (0.0, 10.0, np.pi), 1.5),
}
IDS = sorted(ROBOTS)
#: Rounding allowance of the geometry (positions of tens of meters, float64).
TOL = 1e-9


def _wrap(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def _inside(point, polygon) -> bool:
    """Whether ``point`` lies inside ``polygon`` (even-odd ray crossing) farther than
    :data:`TOL` times its size from its edges (a move the occluder stopped ends on one)."""
    x, y = point
    inside = False
    n = len(polygon)
    gap = np.inf
    for i in range(n):
        (x1, y1), (x2, y2) = polygon[i], polygon[(i + 1) % n]
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
        d = np.array([x2 - x1, y2 - y1])
        t = np.clip(np.dot([x - x1, y - y1], d) / np.dot(d, d), 0.0, 1.0)
        gap = min(gap, np.hypot(x - x1 - t * d[0], y - y1 - t * d[1]))
    return inside and gap > TOL * (1.0 + np.max(np.abs(polygon)))


@pytest.mark.parametrize("env_id", IDS)
def test_the_task_has_its_documented_robots(env_id):
    preset, robots, d_sep = ROBOTS[env_id]
    env = pettingzoo.make("parallel", env_id)
    sc = env.unwrapped.scenario
    assert sc.name == preset and sc.d_sep == d_sep
    models = sc.kinematics_models
    if robots is None:
        assert all(type(k) is Disk for k in models) and sc.kinematics is None
    else:
        assert all(k == Unicycle(*robots, dt=sc.dt) for k in models)
        # The action: speed and turn rate scaled onto their ranges; the heading observed.
        assert env.action_space(env.possible_agents[0]).shape == (2,)
    env.close()


def _episode(env_id, seed, steps=50):
    """Yield (positions before, after, headings before, after, infos) of a random episode
    (headings None for the disk)."""
    env = pettingzoo.make("parallel", env_id)
    world = env.unwrapped.world
    unicycle = env.unwrapped.scenario.kinematics is not None
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(seed)

    def headings(obs):
        return np.array([np.arctan2(obs[a][-1], obs[a][-2]) for a in env.possible_agents])

    before, head = world.get("sensors", 0).copy(), headings(obs) if unicycle else None
    for _ in range(steps):
        if not env.agents:
            break
        actions = {a: rng.uniform(-1, 1, 2).astype(np.float32) for a in env.agents}
        obs, _, _, _, infos = env.step(actions)
        after = world.get("sensors", 0).copy()
        new_head = headings(obs) if unicycle else None
        yield before, after, head, new_head, infos, env
        before, head = after, new_head
    env.close()


@pytest.mark.parametrize("env_id", [i for i in IDS if ROBOTS[i][1] is not None])
def test_every_step_of_a_unicycle_is_an_arc_within_its_limits(env_id):
    _, (v_min, v_max, w_max), _ = ROBOTS[env_id]
    dt, steps = 0.1, 0
    # (observations are float32: headings to about 1e-7 rad)
    for seed in (0, 1):
        for p0, p1, h0, h1, _, _ in _episode(env_id, seed):
            dtheta = _wrap(h1 - h0)
            assert np.all(np.abs(dtheta) <= w_max * dt + 1e-6)
            chord = np.hypot(*(p1 - p0).T)
            half = 0.5 * dtheta
            sinc = np.where(half == 0.0, 1.0, np.sin(half) / np.where(half == 0.0, 1.0, half))
            v = chord / (dt * sinc)
            assert np.all(v <= v_max * (1 + 1e-6)), v
            assert np.all(v >= v_min * (1 - 1e-6)), v
            moved = chord > 1e-6
            direction = np.arctan2(*(p1 - p0)[:, ::-1].T)
            assert np.all(np.abs(_wrap(direction - (h0 + half)))[moved] < 1e-5)
            steps += 1
    assert steps == 100


@pytest.mark.parametrize("env_id", [i for i in IDS if ROBOTS[i][2] > 0])
def test_the_team_keeps_d_sep_and_stays_out_of_the_occluders(env_id):
    d_sep, steps = ROBOTS[env_id][2], 0
    for seed in (0, 1, 2):
        for _, p1, _, _, infos, env in _episode(env_id, seed):
            e = p1[:, None, :] - p1[None, :, :]
            dist = np.hypot(e[..., 0], e[..., 1])[np.triu_indices(len(p1), 1)]
            assert dist.min() >= d_sep * (1 - TOL), dist.min()
            assert infos["sensor_0"]["min_separation"] == pytest.approx(dist.min(), rel=1e-12)
            for poly in env.unwrapped.scenario.occluders:
                assert not any(_inside(p, poly) for p in p1)
            steps += 1
    assert steps == 150


#: Bad kinematics parameters given as keywords, and the field each error names.
BAD = [
    ({"kinematics": "unicycle"}, "kinematics"),
    ({"kinematics": (Unicycle(0.0, 10.0, 1.0),) * 2}, "kinematics"),
    ({"dt": 3.0}, "w_max"),  # (w_max dt = 3 pi: more than a full turn a step)
    ({"d_sep": -1.0}, "d_sep"),
    ({"d_sep": float("nan")}, "d_sep"),
    ({"d_sep": 50.0}, "d_sep"),  # (the start disk cannot hold it)
]


@pytest.mark.parametrize("env_id", IDS)
@pytest.mark.parametrize(("kwargs", "field"), BAD, ids=[f"{f}-{i}" for i, (_, f) in enumerate(BAD)])
def test_bad_kinematics_keywords_are_refused_naming_the_field(env_id, kwargs, field):
    if "dt" in kwargs and ROBOTS[env_id][1] is None:
        kwargs, field = {"vmax": -10.0}, "vmax"  # (a disk has no turn rate: its speed)
    with pytest.raises(ValueError, match=field):
        gymnasium.make(env_id, **kwargs)
    with pytest.raises(ValueError, match=field):
        pettingzoo.make("parallel", env_id, **kwargs)


@pytest.mark.parametrize(
    ("args", "field"),
    [((-1.0, 10.0, 1.0), "v_min"), ((5.0, 1.0, 1.0), "v_min"), ((0.0, 10.0, np.nan), "w_max"),
     ((0.0, 10.0, np.inf), "w_max"), ((0.0, np.nan, 1.0), "v_max"), ((0.0, -10.0, 1.0), "v_max")],
)  # fmt: skip
def test_bad_unicycle_parameters_are_refused_naming_the_field(args, field):
    with pytest.raises(ValueError, match=field):
        Unicycle(*args)
