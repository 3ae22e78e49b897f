"""Scenario presets and the shared closed-loop functions."""

import json

import numpy as np
import pytest

import activetrack as at


def test_paper_preset_is_section_v():
    sc = at.make_scenario("paper")
    assert sc.n_sensors == 3 and sc.n_steps == 50 and sc.dt == 0.1 and sc.q == 10.0
    np.testing.assert_allclose(sc.r, [1.0, 1.0, 1.0])  # vmax 10 m/s over 0.1 s
    np.testing.assert_allclose(sc.per_sensor("rho"), 2.0)
    np.testing.assert_allclose(sc.per_sensor("sigma_d2"), [2, 4, 4])
    np.testing.assert_allclose(sc.per_sensor("sigma_theta2"), [0.25, 0.5, 0.5])
    assert sc.x0 == (0.0, 0.0, -8.0, 6.0) and sc.x0_hat == (2.0, -2.0, 0.0, 0.0)


def test_overrides_and_errors_name_the_field():
    sc = at.make_scenario("homogeneous", n_sensors=8, rho=1.5)
    assert sc.n_sensors == 8 and np.all(sc.per_sensor("rho") == 1.5)
    assert at.make_scenario("paper", n_sensors=5).per_sensor("sigma_d2").shape == (5,)
    for kwargs, field in [
        ({"n_sensors": 0}, "n_sensors"),
        ({"dt": -0.1}, "dt"),
        ({"rho": -1.0}, "rho"),
        ({"sigma_d2": (1.0, 2.0)}, "sigma_d2"),
        ({"x0": (0.0, 0.0)}, "x0"),
        ({"P0": (1.0, -1.0, 1.0, 1.0)}, "P0"),
        ({"motion": "spiral"}, "motion"),
        ({"target_init": "random"}, "target_init"),
        ({"warp_drive": True}, "warp_drive"),
    ]:
        with pytest.raises(ValueError, match=field):
            at.make_scenario("paper", **kwargs)
    with pytest.raises(ValueError, match="scenario"):
        at.make_scenario("nope")


def test_max_cycles_is_accepted_as_n_steps():
    assert at.make_scenario("paper", max_cycles=7).n_steps == 7
    assert at.make_scenario("homogeneous", max_cycles=12, n_steps=12).n_steps == 12
    assert at.make_scenario("paper").replace(max_cycles=3).n_steps == 3
    with pytest.raises(ValueError, match="max_cycles"):
        at.make_scenario("paper", max_cycles=7, n_steps=8)
    with pytest.raises(ValueError, match="n_steps"):
        at.make_scenario("paper", max_cycles=0)


def test_unknown_keyword_is_a_type_error_worded_like_python():
    with pytest.raises(TypeError, match="unexpected keyword argument 'frameskip'") as info:
        at.make_scenario("paper", frameskip=4)
    assert isinstance(info.value, ValueError)  # callers catching ValueError keep working
    assert "make_scenario() got an unexpected keyword argument 'frameskip'" in str(info.value)
    assert "n_steps" in str(info.value)  # the valid fields are listed
    with pytest.raises(ValueError, match="'frameskip'"):
        at.make_scenario("paper").replace(frameskip=4)

    # the same wording as Python's own error for a function without that keyword
    def make(n_steps=1):
        return n_steps

    with pytest.raises(TypeError) as py:
        make(frameskip=4)
    assert "got an unexpected keyword argument 'frameskip'" in str(py.value)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"dt": "0.1"}, "dt"),
        ({"reward_scale": "1.0"}, "reward_scale"),
        ({"max_trace": [1, 2]}, "max_trace"),
        ({"sensor_radius": [1, 2]}, "sensor_radius"),
        ({"n_sensors": True}, "n_sensors"),
        ({"n_sensors": 3.0}, "n_sensors"),
        ({"n_steps": np.int64(0)}, "n_steps"),
        ({"motion": ["cv"]}, "motion"),
        ({"q": 1e200}, "q"),
        ({"x0": (1e200, 0.0, 0.0, 0.0)}, "x0"),
        ({"sigma_d2": 1e-160}, "sigma_d2"),
        ({"sigma_theta2": (0.1, 1e-300, 0.1)}, "sigma_theta2"),
        ({"P0": (1e-170, 4.0, 100.0, 100.0)}, "P0"),
        ({"rho": np.nan}, "rho"),
        ({"vmax": np.inf}, "vmax"),
        ({"vmax": 1e9, "dt": 10.0}, "vmax"),
        ({"orientation": 1 + 2j}, "orientation"),
        ({"sensor_center": (1.0, [2.0])}, "sensor_center"),
        ({"sensor_center": (True, 0.0)}, "sensor_center"),
        ({"sigma_d2": None}, "sigma_d2"),
        ({"name": 3}, "name"),
        ({"motion": "ca"}, "motion='ca'"),  # x0 has 4 entries: the error says why
        # The fields beyond the paper (several targets, sensor models, uncertain poses).
        ({"n_targets": 0}, "n_targets"),
        ({"n_targets": 2.0}, "n_targets"),
        ({"n_targets": 2}, "x0"),  # the paper's single x0 is not one state per target
        ({"n_targets": 2, "x0": ((0, 0, 1, 1),), "x0_hat": ((0, 0, 1, 1),)}, "x0"),
        ({"n_targets": 2, "x0": ((0, 0, 1, 1), (0, 0, 1, np.nan))}, r"x0\[1\]"),
        ({"n_targets": 2, "motion": ("cv",)}, "motion"),
        ({"n_targets": 2, "q": (1.0, -1.0)}, "q"),
        ({"sensor_model": "sonar"}, "sensor_model"),
        ({"sensor_model": ("range", "range")}, "sensor_model"),  # 2 names for 3 sensors
        ({"sensor_model": 1}, "sensor_model"),
        ({"pose_cov": -0.1}, "pose_cov"),
        ({"pose_cov": np.nan}, "pose_cov"),
        ({"pose_cov": (0.1, 0.2)}, "pose_cov"),  # neither 1 nor 3 (M) variances
        ({"pose_cov": ((1.0, 2.0), (2.0, 1.0))}, "pose_cov"),  # not PSD
        ({"pose_cov": ((1.0, 0.1), (0.0, 1.0))}, "pose_cov"),  # not symmetric
        ({"pose_cov": 1e9}, "pose_cov"),
        ({"account_pose": 1}, "account_pose"),
        ({"objective": "det"}, "objective"),
        ({"objective": None}, "objective"),
    ],
)
def test_invalid_values_are_rejected_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        at.make_scenario("paper", **kwargs)


def test_values_are_converted_once_and_stored_converted():
    P0 = np.diag([4.0, 9.0, 1.0, 1.0])
    sc = at.make_scenario(
        "paper",
        n_sensors=np.int64(3),
        dt=np.float32(0.5),
        q=2,
        sigma_d2=[1, 2, 3],
        sigma_theta2=np.float64(0.5),
        x0=np.array([1, 2, 3, 4]),
        P0=P0,
        max_trace=10,
        n_steps=np.int32(20),
    )
    assert type(sc.n_sensors) is int and type(sc.n_steps) is int
    assert type(sc.dt) is float and sc.dt == 0.5 and type(sc.q) is float
    assert sc.sigma_d2 == (1.0, 2.0, 3.0) and all(type(v) is float for v in sc.sigma_d2)
    assert type(sc.sigma_theta2) is float and type(sc.max_trace) is float
    assert sc.x0 == (1.0, 2.0, 3.0, 4.0) and type(sc.x0) is tuple
    assert sc.P0 == tuple(tuple(row) for row in P0.tolist())
    np.testing.assert_array_equal(sc.initial_cov, P0)
    assert at.Scenario(**sc.to_dict()) == sc  # to_dict round-trips
    assert at.Scenario(**json.loads(json.dumps(sc.to_dict()))) == sc  # through JSON too
    hash(sc)


def test_equality_and_hash_compare_field_values():
    a = at.make_scenario("paper")
    b = at.make_scenario("paper", sigma_d2=[2, 4, 4], dt=np.float64(0.1), n_sensors=np.int64(3))
    assert a == b and hash(a) == hash(b)
    assert a != at.make_scenario("paper", q=11.0)
    assert a.replace() == a


def test_several_targets_sensor_models_and_poses_are_stored_converted():
    sc = at.make_scenario(
        "paper",
        n_targets=2,
        motion=("cv", "ca"),
        q=(1.0, np.float32(2.0)),
        x0=((0, 0, 1, 1), np.arange(6)),
        x0_hat=((0, 0, 1, 1), (0, 0, 0, 0, 0, 0)),
        P0=((4, 4, 25, 25), np.full(6, 4.0)),
        sensor_model=["range", "bearing", "range_bearing"],
        pose_cov=np.array([0.1, 0.0, 0.2]),
    )
    assert sc.q == (1.0, 2.0) and all(type(v) is float for v in sc.q)
    assert sc.x0[1] == (0.0, 1.0, 2.0, 3.0, 4.0, 5.0) and type(sc.x0[1][1]) is float
    assert [m.dim for m in sc.target_models] == [4, 6]
    assert sc.sensor_model == ("range", "bearing", "range_bearing")
    assert sc.sensor_models.tolist() == [1, 2, 0]
    assert sc.pose_cov == (0.1, 0.0, 0.2)
    np.testing.assert_array_equal(sc.pose_covariances[2], 0.2 * np.eye(2))
    json.dumps(sc.to_dict())  # JSON-friendly, the new fields included
    assert at.make_scenario("paper", sensor_model=("range",) * 3).sensor_model == "range"


def test_occluders_beyond_the_vertex_limit_are_refused_naming_the_field():
    from activetrack.models.occluders import MAX_VERTICES

    tri = ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0))
    many = tuple(tuple((x + 3.0 * k, y + 30.0) for x, y in tri) for k in range(20_000))
    with pytest.raises(ValueError, match=rf"^occluders must have at most {MAX_VERTICES}"):
        at.make_scenario("urban", occluders=many)
    ang = np.linspace(0, 2 * np.pi, 8000, endpoint=False)
    circle = tuple(zip(30 + np.cos(ang), 30 + np.sin(ang), strict=True))
    with pytest.raises(ValueError, match=rf"^occluders must have at most {MAX_VERTICES}"):
        at.make_scenario("urban", occluders=(circle,))
    # Fixed and random together: 4 vertices a random rectangle.
    fixed = (circle[: MAX_VERTICES - 396],)
    at.make_scenario("paper", occluders=fixed, random_occluders=99)  # 4092 vertices
    with pytest.raises(ValueError, match=r"^occluders and random_occluders must have at most"):
        at.make_scenario("paper", occluders=fixed, random_occluders=100)


_TEAM = ("sigma_d2", "sigma_theta2", "vmax", "rho", "orientation", "sensor_model", "pose_cov",
         "max_range", "p_detect")  # fmt: skip


def _sensor_entries(sc, key):
    """Return field ``key`` of ``sc`` as a list of one entry per sensor, read from the
    stored field itself (one value for every sensor, or a tuple of M; pose_cov as 2x2)."""
    v = getattr(sc, key)
    m = sc.n_sensors
    if key == "pose_cov":
        arr = np.asarray(v, np.float64)
        if arr.ndim == 0:
            return [arr * np.eye(2)] * m
        if arr.ndim == 1:
            return [x * np.eye(2) for x in arr]
        return [arr] * m if arr.ndim == 2 else list(arr)
    if isinstance(v, tuple):
        return list(v)
    return [v] * m


@pytest.mark.parametrize("preset", sorted(at.world.scenarios.PRESETS))
@pytest.mark.parametrize("m", [1, 2, 5, 6, 9])
def test_a_new_team_size_repeats_the_presets_team_on_every_preset(preset, m):
    base = at.make_scenario(preset)
    sc = at.make_scenario(preset, n_sensors=m)
    L = base.n_sensors
    for key in _TEAM:
        want = _sensor_entries(base, key)
        got = _sensor_entries(sc, key)
        assert len(got) == m, key
        for i in range(m):  # sensor i is the preset's sensor i mod L
            np.testing.assert_array_equal(np.asarray(got[i]), np.asarray(want[i % L]), key)
    # What the world reads agrees: the models and covariances per sensor.
    codes = base.sensor_models
    np.testing.assert_array_equal(sc.sensor_models, codes[np.arange(m) % L])
    np.testing.assert_array_equal(sc.per_sensor("sigma_d2"),
                                  base.per_sensor("sigma_d2")[np.arange(m) % L])  # fmt: skip


def test_a_mixed_team_of_six_stays_mixed():
    sc = at.make_scenario("mixed", n_sensors=6)
    assert sc.sensor_model == ("range_bearing", "range", "bearing", "range") * 1 + (
        "range_bearing", "range")  # fmt: skip
    assert at.make_scenario("uncertain_poses", n_sensors=6).pose_cov == (
        0.25, 0.5, 1.0, 2.0, 0.25, 0.5)  # fmt: skip
