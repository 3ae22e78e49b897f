"""GBES's default runs on every preset (its spacing widened per problem to fit its grid
bound, GBES.adapt), and the CLI options its error names exist where it is printed."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from activetrack.baselines import GBES
from activetrack.cli import main
from activetrack.world import World
from activetrack.world.scenarios import PRESETS, make_scenario


def _first_problem(preset):
    world = World(preset, 1)
    world.reset(seeds=[0])
    return world.planning_problem(0)


@pytest.mark.parametrize("preset", sorted(set(PRESETS) - {"swarm"}))
def test_the_default_grid_fits_its_bound_on_every_preset(preset):
    problem = _first_problem(preset)
    gbes = GBES()
    result = gbes.search(problem)
    # The grid searched, counted here from the candidates themselves.
    wider = GBES(spacing=result.spacing, adapt=False)
    sizes = [len(c) for c in wider.candidates(problem)]
    assert math.prod(sizes) == result.n_combinations <= gbes.max_combinations
    strict = GBES(adapt=False)
    if math.prod(len(c) for c in strict.candidates(problem)) <= gbes.max_combinations:
        assert result.spacing == gbes.spacing  # fits: the paper's spacing, unchanged
    else:
        assert result.spacing > gbes.spacing
        with pytest.raises(ValueError, match="--gbes-spacing of activetrack simulate and eval"):
            strict.search(problem)
    # The grid optimum: no candidate combination of the searched grid is better (a random
    # sample of them, scored by the problem's own objective).
    rng = np.random.default_rng(0)
    cands = wider.candidates(problem)
    picks = np.stack([c[rng.integers(len(c), size=2000)] for c in cands], axis=1)
    assert np.all(problem.score(picks + problem.targets[0]) >= result.value * (1 - 1e-12))


def test_the_paper_keeps_the_papers_spacing():
    assert GBES().search(_first_problem("paper")).spacing == math.pi / 200


@pytest.mark.parametrize("preset", sorted(PRESETS))
def test_simulate_and_evaluate_defaults_run_on_every_preset(preset, tmp_path, monkeypatch):
    # Two steps an episode (the CLI reads the preset when it runs): what is checked is that
    # every default planner plans on the preset, which its first steps show.
    monkeypatch.setitem(PRESETS, preset, {**PRESETS[preset], "n_steps": 2})
    # 8 sensors (crowded): GBES's default grid costs about a minute a plan; a coarse one
    coarse = ["--gbes-spacing", "2.0"] if make_scenario(preset).n_sensors > 4 else []
    # 32 sensors (swarm): beyond GBES's grid (the test below), GSR and RM only
    swarm = make_scenario(preset).n_sensors > 31
    planners = ["--planner", "gsr", "--planner", "rm"] if swarm else []
    assert main(["simulate", "--scenario", preset, "--runs", "1", "--steps", "2", "--out",
                 str(tmp_path / "sim"), "--no-plot", "--no-progress", *coarse,
                 *planners]) == 0  # fmt: skip
    data = json.loads((tmp_path / "sim" / "results.json").read_text())
    assert list(data) == (["gsr", "rm"] if swarm else ["gsr", "gbes", "rm"])
    policy = "gsr" if swarm else "gbes"
    assert main(["evaluate", "--scenario", preset, "--policy", policy, "--episodes", "1",
                 "--out", str(tmp_path / "ev"), "--no-plot", "--no-progress",
                 *coarse]) == 0  # fmt: skip
    assert (tmp_path / "ev" / "results.json").exists()


def test_evaluate_takes_gbes_spacing(tmp_path):
    assert main(["evaluate", "--scenario", "paper", "--policy", "gbes", "--episodes", "1",
                 "--gbes-spacing", "0.2", "--out", str(tmp_path / "ev"), "--no-plot",
                 "--no-progress"]) == 0  # fmt: skip


def test_gbes_refuses_more_sensors_than_its_grid_has_axes():
    # swarm's 32 robots: one array axis each and one more is beyond NumPy's 32
    with pytest.raises(ValueError, match="at most 31 sensors, got 32; plan with GSR"):
        GBES().search(_first_problem("swarm"))
