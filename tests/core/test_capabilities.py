"""The fast paths decided once: a scenario's capabilities against an independent reading of
its fields, and the four sites that choose a path (the scenario, the observation layout,
the world, the planning problem) against the capabilities."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from activetrack import Disk, FilterModel, SensorModel
from activetrack.models.communication import RangeLimited
from activetrack.world import World, capabilities, observation
from activetrack.world.capabilities import Capabilities
from activetrack.world.problem import PlanningProblem
from activetrack.world.scenarios import PRESETS, make_scenario

FLAGS = (
    "one_target", "range_bearing", "known_poses", "pose_free_filter", "unlimited_sensing",
    "no_occluders", "single_update", "trace_objective", "disk_kinematics", "builtin_sensors",
    "filter_targets", "no_separation", "central_filter",
)  # fmt: skip


class OwnDisk(Disk):
    """A kinematics of its own (not the built-in Disk, though it moves as one)."""

    name = "own_disk"


class _Distance(SensorModel):
    """A sensor model of one's own (the distance; the generic path)."""

    name = "distance"
    slots = (True, False)

    def function(self, target, sensor, orientation=0.0):
        d = np.asarray(target, float) - np.asarray(sensor, float)
        return np.stack([np.hypot(d[..., 0], d[..., 1]), 0.0 * d[..., 0]], -1)


# Each preset as its description in scenarios.py / docs/tasks.md reads (True: the paper's).
PRESET_FLAGS = {
    "paper": dict.fromkeys(FLAGS, True),
    "homogeneous": dict.fromkeys(FLAGS, True),
    "two_targets": {**dict.fromkeys(FLAGS, True), "one_target": False},
    "range_only": {**dict.fromkeys(FLAGS, True), "range_bearing": False},
    "bearing_only": {**dict.fromkeys(FLAGS, True), "range_bearing": False},
    "mixed": {**dict.fromkeys(FLAGS, True), "range_bearing": False},
    "uncertain_poses": {
        **dict.fromkeys(FLAGS, True),
        "known_poses": False,
        "pose_free_filter": False,
    },  # fmt: skip
    "urban": {
        **dict.fromkeys(FLAGS, True),
        "unlimited_sensing": False,
        "no_occluders": False,
        "single_update": False,
    },  # fmt: skip
    "urban_random": {
        **dict.fromkeys(FLAGS, True),
        "unlimited_sensing": False,
        "no_occluders": False,
        "single_update": False,
    },  # fmt: skip
    "maneuvering": {**dict.fromkeys(FLAGS, True), "filter_targets": False},
    "evader": {**dict.fromkeys(FLAGS, True), "filter_targets": False},
    "pursuit": {**dict.fromkeys(FLAGS, True), "filter_targets": False},  # evader's world
    "unicycle": {**dict.fromkeys(FLAGS, True), "disk_kinematics": False},
    "fixed_wing": {**dict.fromkeys(FLAGS, True), "disk_kinematics": False},
    "crowded": {**dict.fromkeys(FLAGS, True), "no_separation": False, "single_update": False},
    "urban_unicycle": {
        **dict.fromkeys(FLAGS, True),
        "unlimited_sensing": False,
        "no_occluders": False,
        "single_update": False,
        "disk_kinematics": False,
        "no_separation": False,
    },  # fmt: skip
    # a filter per robot (issue 37): stage by stage
    "radio": {**dict.fromkeys(FLAGS, True), "central_filter": False},
    "swarm": {**dict.fromkeys(FLAGS, True), "one_target": False, "central_filter": False},
    "urban_radio": {
        **dict.fromkeys(FLAGS, True),
        "unlimited_sensing": False,
        "no_occluders": False,
        "single_update": False,
        "central_filter": False,
    },  # fmt: skip
    "patrol": {**dict.fromkeys(FLAGS, True), "one_target": False, "unlimited_sensing": False},
}

# Which paths each preset takes, as docs/architecture.md and the presets describe them.
PRESET_PATHS = {  # (paper_model, paper_problem, paper_observation, fused_step)
    "paper": (True, True, True, True),
    "homogeneous": (True, True, True, True),
    "two_targets": (False, False, False, False),
    "range_only": (False, False, False, True),
    "bearing_only": (False, False, False, True),
    "mixed": (False, False, False, True),
    "uncertain_poses": (False, False, False, False),
    "urban": (False, False, False, False),
    "urban_random": (False, False, False, False),
    # the paper's measurement setup; the targets' behaviours: stage by stage
    "maneuvering": (True, True, True, False),
    "evader": (True, True, True, False),
    "pursuit": (True, True, True, False),
    # unicycles: the team moves first, by its kinematics, then the one compiled step
    "unicycle": (False, False, True, True),
    "fixed_wing": (False, False, True, True),
    # the paper's sensors and disks; the iterated EKF and the team rule d_sep: stage by stage
    "crowded": (False, True, True, False),
    "urban_unicycle": (False, False, False, False),
    # the paper's measurement setup, a filter per robot: stage by stage
    "radio": (True, True, True, False),
    "swarm": (False, False, False, False),
    "urban_radio": (False, False, False, False),
    "patrol": (False, False, False, False),
}


def test_every_preset_is_described() -> None:
    assert set(PRESET_FLAGS) == set(PRESETS) == set(PRESET_PATHS)


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_preset_capabilities(name: str) -> None:
    caps = make_scenario(name).capabilities
    assert dataclasses.asdict(caps) == PRESET_FLAGS[name]
    paths = (caps.paper_model, caps.paper_problem, caps.paper_observation, caps.fused_step)
    assert paths == PRESET_PATHS[name]


def expected(fields: dict) -> dict[str, bool]:
    """Return the flags and paths of a scenario made from ``fields`` (the overrides of the
    paper's preset), read from the fields themselves, not from the Scenario."""
    pose = np.asarray(fields.get("pose_cov", 0.0), dtype=np.float64)
    models = fields.get("sensor_model", "range_bearing")
    models = (models,) if isinstance(models, str) else models
    known = not np.any(pose)
    occluded = bool(fields.get("occluders")) or fields.get("random_occluders", 0) > 0
    p_detect = np.asarray(fields.get("p_detect", 1.0))
    f = {
        "one_target": fields.get("n_targets", 1) == 1,
        "range_bearing": all(m == "range_bearing" for m in models),
        "known_poses": known,
        "pose_free_filter": known or not fields.get("account_pose", True),
        "unlimited_sensing": fields.get("max_range") is None
        and bool(np.all(p_detect == 1.0))
        and not occluded,
        "no_occluders": not occluded,
        "single_update": fields.get("filter_iterations", 1) == 1,
        "trace_objective": fields.get("objective", "trace") == "trace",
        "disk_kinematics": all(type(k) is Disk for k in fields.get("kinematics", ())),
        "builtin_sensors": all(isinstance(m, str) for m in models),
        "filter_targets": fields.get("target_behaviour") is None,
        "no_separation": not np.any(fields.get("d_sep", 0.0)),
        "central_filter": fields.get("communication") is None,
    }
    return {
        **f,
        # The paper's measurement setup: every flag but how the true targets move and
        # whether the robots also keep filters of their own (the maneuvering and radio
        # presets); its planning problem: those the planners see.
        "paper_model": all(
            v for k, v in f.items() if k not in ("central_filter", "filter_targets")
        ),
        "paper_problem": all(
            f[k]
            for k in (
                "one_target",
                "range_bearing",
                "pose_free_filter",
                "unlimited_sensing",
                "trace_objective",
                "disk_kinematics",
            )
        ),  # fmt: skip
        "paper_observation": all(
            f[k] for k in ("one_target", "range_bearing", "known_poses", "unlimited_sensing")
        ),
        "fused_step": all(
            f[k]
            for k in (
                "one_target",
                "known_poses",
                "unlimited_sensing",
                "single_update",
                "builtin_sensors",
                "filter_targets",
                "no_separation",
                "central_filter",
            )
        ),  # fmt: skip
    }


def random_fields(rng: np.random.Generator) -> dict:
    """Return random overrides of the paper's preset touching every flag."""
    fields: dict = {"n_sensors": 3}
    if rng.random() < 0.3:
        fields.update(
            n_targets=2,
            x0=((-10.0, -10.0, 4.0, 4.0), (-10.0, 10.0, 4.0, -4.0)),
            x0_hat=((-10.0, -10.0, 4.0, 4.0), (-10.0, 10.0, 4.0, -4.0)),
        )
    choice = int(rng.integers(5))
    if choice == 1:
        fields["sensor_model"] = ("range_bearing", "range", "bearing")[int(rng.integers(1, 3))]
    elif choice == 2:  # a mixed team, possibly all range-and-bearing given per sensor
        fields["sensor_model"] = tuple(
            ("range_bearing", "range", "bearing")[int(i)] for i in rng.integers(0, 3, 3)
        )
    elif choice == 3:  # a model of one's own among built-ins
        fields["sensor_model"] = ("range_bearing", _Distance(), "bearing")
    if rng.random() < 0.3:
        fields["pose_cov"] = (0.0, 0.5, 0.0) if rng.random() < 0.5 else 0.25
        fields["account_pose"] = bool(rng.random() < 0.5)
    if rng.random() < 0.25:
        fields["max_range"] = 30.0
    if rng.random() < 0.25:
        fields["p_detect"] = (1.0, 0.9, 1.0) if rng.random() < 0.5 else 1.0
    occ = int(rng.integers(4))
    if occ == 1:
        fields["occluders"] = PRESETS["urban"]["occluders"]
    elif occ == 2:
        fields.update(
            random_occluders=2, occluder_bounds=(-24.0, -10.0, 12.0, 20.0),
            occluder_size=(2.0, 5.0),
        )  # fmt: skip
    if rng.random() < 0.25:
        fields["filter_iterations"] = 3
    if rng.random() < 0.3:
        fields["objective"] = ("trace", "worst_trace", "logdet")[int(rng.integers(3))]
    if rng.random() < 0.3:  # the built-in disks given, or one of them a kinematics of its own
        own = rng.random() < 0.6
        fields["kinematics"] = (Disk(1.0), OwnDisk(1.0) if own else Disk(0.5), Disk(1.0))
    if rng.random() < 0.2:  # true targets that follow a behaviour (here their own model)
        fields["target_behaviour"] = FilterModel(make_scenario("paper").model)
    if rng.random() < 0.2:  # a filter per robot
        fields["communication"] = RangeLimited(10.0, drop=0.2)
    return fields


def sites(sc, world: World) -> dict[str, bool]:
    """Return the path each of the four sites took for scenario ``sc``."""
    problem = world.planning_problem(0)
    # A hand-built problem (no scenario) from the same arrays decides by the same rule.
    fields = {f.name: getattr(problem, f.name) for f in dataclasses.fields(PlanningProblem)}
    by_hand = PlanningProblem(**fields)
    assert by_hand.is_paper == problem.is_paper
    return {
        "paper_model": sc.is_paper_model,
        "paper_problem": problem.is_paper,
        "paper_observation": not observation.layout_of(sc).extended,
        "fused_step": world._fused,
    }


def test_random_scenarios_agree_with_fields_and_sites() -> None:
    rng = np.random.default_rng(20261129)
    seen = {k: set() for k in ("paper_model", "paper_problem", "paper_observation", "fused_step")}
    for _ in range(120):
        fields = random_fields(rng)
        sc = make_scenario("paper", **fields)
        want = expected(fields)
        caps = sc.capabilities
        assert dataclasses.asdict(caps) == {k: want[k] for k in FLAGS}, fields
        for path in seen:
            assert getattr(caps, path) == want[path], (path, fields)
            seen[path].add(want[path])
        assert sites(sc, World(sc)) == {path: want[path] for path in seen}, fields
    assert all(v == {True, False} for v in seen.values()), seen  # both sides of each path


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_sites_follow_the_capabilities(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each site reads the capabilities: flipping a derived path flips its decision."""
    sc = make_scenario(name)
    want = dict(zip(("paper_model", "paper_problem", "paper_observation", "fused_step"),
                    PRESET_PATHS[name], strict=True))  # fmt: skip
    assert sites(sc, World(sc)) == want
    for path in ("paper_model", "paper_observation", "fused_step"):
        monkeypatch.setattr(Capabilities, path, property(lambda self, v=not want[path]: v))
    # The planning problem's rule is the module's function (a hand-built problem uses it too).
    monkeypatch.setattr(capabilities, "paper_problem", lambda *a, v=not want["paper_problem"]: v)
    assert sites(sc, World(sc)) == {k: not v for k, v in want.items()}
