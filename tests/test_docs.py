"""The manual builds with warnings as errors, and every registered environment has its
page, whose header table, media, figures, arguments and example agree with the library.

The site is built from a copy of ``docs/`` in a temporary folder (the generated pages are
written there, not into the checkout). The header tables are checked against what the
environments made from each id produce here (their spaces, the arrays ``reset`` and
``state`` return, the length of an episode), not against the generator's code. The
pages' figures (``docs/_static/envs/<Name>.json``, made by
``docs/scripts/render_env_media.py``) are checked by re-running some of their episodes
through the library and recomputing their statistics with numpy; the arguments table by
making the environment with each default shown and with values outside each range shown;
the usage example by running it (:mod:`tests.doc_blocks`).
"""

from __future__ import annotations

import ast
import dataclasses
import functools
import json
import re
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import trim_mean

pytest.importorskip("sphinx", reason="the [docs] extra (sphinx) is not installed")
pytest.importorskip("myst_parser", reason="the [docs] extra (myst-parser) is not installed")
pytest.importorskip("furo", reason="the [docs] extra (furo) is not installed")

import gymnasium  # noqa: E402
import pettingzoo  # noqa: E402

import activetrack  # noqa: E402,F401  (registers the ids)
from activetrack._registry import ALL_IDS  # noqa: E402
from tests.doc_blocks import python_blocks, run_blocks  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
MEDIA = ROOT / "docs" / "_static" / "envs"
IDS = sorted(ALL_IDS)

# The build takes about 15 s on one core (autodoc imports the train layer: torch, SB3).
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def site(docs_site: Path) -> Path:
    """The built site (``tests/conftest.py``'s ``docs_site``)."""
    return docs_site


class _Table(HTMLParser):
    """The rows (lists of cell texts) of the first table of an HTML page."""

    def __init__(self) -> None:
        super().__init__()
        self.rows: list[list[str]] = []
        self._tables = 0
        self._cell: list[str] | None = None

    def handle_starttag(self, tag: str, attrs) -> None:
        if tag == "table":
            self._tables += 1
        elif self._tables == 1 and tag == "tr":
            self.rows.append([])
        elif self._tables == 1 and tag in ("td", "th"):
            self._cell = []

    def handle_endtag(self, tag: str) -> None:
        if tag in ("td", "th") and self._cell is not None:
            self.rows[-1].append(" ".join("".join(self._cell).split()))
            self._cell = None

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell.append(data)


def _header(page: Path) -> dict[str, str]:
    parser = _Table()
    parser.feed(page.read_text(encoding="utf-8"))
    return {row[0]: row[1] for row in parser.rows if len(row) == 2 and row[0]}


def _sensor_names(sc) -> list[str]:
    """Each sensor's model name from the scenario's field as given (a name or a model)."""
    raw = sc.sensor_model if isinstance(sc.sensor_model, tuple) else (sc.sensor_model,)
    names = [m if isinstance(m, str) else m.name for m in raw]
    return names * sc.n_sensors if len(names) == 1 else names


def test_every_registered_id_has_a_page_whose_table_matches_the_environment(site: Path):
    pages = sorted(p.stem for p in (site / "environments").glob("*.html"))
    # Every id the frameworks know under our namespace (not the generator's list).
    ids = sorted(k for k in gymnasium.registry if k.startswith("activetrack/"))
    for kind in (pettingzoo.parallel_registry, pettingzoo.aec_registry):
        assert sorted(k for k in kind if str(k).startswith("activetrack/")) == ids
    assert ids == sorted(ALL_IDS)
    assert pages == sorted(["index", *(i.split("/", 1)[1] for i in ids)])
    index = (site / "environments" / "index.html").read_text(encoding="utf-8")
    for env_id in ids:
        name = env_id.split("/", 1)[1]
        page = site / "environments" / f"{name}.html"
        assert f'href="{name}.html"' in index, name
        table = _header(page)

        genv = gymnasium.make(env_id)
        penv = pettingzoo.make("parallel", env_id)
        sc = genv.unwrapped.scenario
        obs, _ = genv.reset(seed=0)
        pobs, _ = penv.reset(seed=0)
        agents = list(penv.possible_agents)
        m = sc.n_sensors
        # A two-team game (activetrack.envs.pursuit) adds its controlled targets' agents.
        targets = [f"target_{j}" for j in range(len(penv.unwrapped.world.controlled_targets))]
        assert agents == [f"sensor_{i}" for i in range(m)] + targets

        assert table["Gymnasium id"] == env_id
        assert table["Import"].startswith(f'gymnasium.make("{env_id}")')
        assert table["PettingZoo id"].startswith(f'pettingzoo.make("parallel", "{env_id}")')
        assert table["Scenario preset"] == sc.name == ALL_IDS[env_id]
        count, listed = table["Agents"].split(": ", 1)
        assert int(count) == len(agents)
        shown = listed.split(", ")
        assert shown == (agents if len(agents) <= 4 else [agents[0], "...", agents[-1]])

        # Spaces: the printed Box is the environment's, and its shape is the arrays'.
        assert table["Action space (Gymnasium)"] == repr(genv.action_space)
        assert table["Action space (per agent)"] == repr(penv.action_space(agents[0]))
        box = re.fullmatch(
            r"Box\((\S+), (\S+), (\(.*\)), (\w+)\)", table["Action space (per agent)"]
        )
        assert box is not None and ast.literal_eval(box.group(3)) == (2,)
        assert ast.literal_eval(table["Observation shape (Gymnasium)"]) == obs.shape
        assert ast.literal_eval(table["Observation shape (per agent)"]) == pobs[agents[0]].shape
        assert obs.shape == (m * pobs[agents[0]].size,)
        assert ast.literal_eval(table["State shape"]) == penv.state().shape

        # Episode length: count the steps of an episode until it truncates.
        steps, done = 0, False
        while not done:
            _, _, terminated, truncated, _ = genv.step(np.zeros(genv.action_space.shape))
            steps += 1
            done = terminated or truncated
        n_steps, dt = re.fullmatch(r"(\d+) steps of (\S+) s", table["Episode length"]).groups()
        assert int(n_steps) == steps == sc.n_steps
        assert float(dt) == sc.dt

        assert int(table["Targets"]) == sc.n_targets
        assert table["Sensor models"].split(", ") == _sensor_names(sc)
        if sc.kinematics is None:  # each sensor a disk of radius vmax_i dt (eq. 13)
            vmax = np.broadcast_to(np.asarray(sc.vmax, dtype=np.float64), (m,))
            radii = [
                float(re.fullmatch(r"Disk\((.+)\)", k).group(1))
                for k in table["Kinematics"].split(", ")
            ]
            np.testing.assert_allclose(radii, vmax * sc.dt, rtol=1e-12)
        else:  # robots: every sensor's unicycle, whose one-step reach is v_max dt
            shown = re.findall(
                r"Unicycle\(v_min=(\S+), v_max=(\S+), w_max=(\S+), dt=(\S+)\)",
                table["Kinematics"],
            )
            assert len(shown) == m
            for (v_min, v_max, w_max, dt), kin in zip(shown, sc.kinematics_models, strict=True):
                assert (float(v_min), float(v_max), float(w_max)) == (
                    kin.v_min,
                    kin.v_max,
                    kin.w_max,
                )
                assert float(dt) == sc.dt
                assert float(v_max) * float(dt) == pytest.approx(kin.radius, rel=1e-12)

        # The manual follows the table: the environment classes' docstrings.
        text = page.read_text(encoding="utf-8")
        assert "The tracking game for M cooperative sensors with a shared reward." in text
        assert "One agent choosing every sensor" in text
        genv.close()
        penv.close()


def test_api_reference_documents_every_public_name(site: Path):
    import activetrack.baselines
    import activetrack.envs
    import activetrack.train

    html = (site / "api.html").read_text(encoding="utf-8")
    for mod in (activetrack, activetrack.envs, activetrack.baselines, activetrack.train):
        for name in mod.__all__:
            obj = getattr(mod, name)
            documented = {f'id="{mod.__name__}.{name}"'}
            where = getattr(obj, "__module__", None)
            if where and hasattr(obj, "__qualname__"):
                documented.add(f'id="{mod.__name__}.{obj.__qualname__}"')
            assert any(d in html for d in documented), f"{mod.__name__}.{name}"


def _name(env_id: str) -> str:
    return env_id.split("/", 1)[1]


@functools.cache
def _page(env_id: str) -> str:
    """The Markdown of ``env_id``'s page, from the generator (no Sphinx build)."""
    sys.path.insert(0, str(ROOT / "docs" / "_ext"))
    try:
        import env_pages
    finally:
        sys.path.remove(str(ROOT / "docs" / "_ext"))
    return env_pages.page(env_id)


def _section(text: str, heading: str) -> str:
    """The text of the ``## heading`` section of a page."""
    match = re.search(rf"^## {re.escape(heading)}\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert match is not None, heading
    return match.group(1)


def _table(text: str) -> list[list[str]]:
    """The rows (cells, unescaped) of the Markdown table in ``text``, header excluded."""
    rows = [line for line in text.splitlines() if line.startswith("|")][2:]
    return [[c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", r)[1:-1]] for r in rows]


def test_every_id_has_a_small_gif_of_several_frames_that_its_page_shows(site: Path):
    from PIL import Image

    total = 0
    for env_id in IDS:
        name = _name(env_id)
        gif = MEDIA / f"{name}.gif"
        with Image.open(gif) as im:
            assert im.format == "GIF"
            assert im.n_frames >= 10, (name, im.n_frames)
            im.seek(im.n_frames - 1)  # every frame decodes
            im.convert("RGB")
        size = gif.stat().st_size
        assert size < 400 * 1024, (name, size)
        total += size
        # The built page shows it (Sphinx copies it beside the pages), so does the index.
        html = (site / "environments" / f"{name}.html").read_text(encoding="utf-8")
        assert f'src="../_images/{name}.gif"' in html, name
        assert (site / "_images" / f"{name}.gif").read_bytes() == gif.read_bytes()
        index = (site / "environments" / "index.html").read_text(encoding="utf-8")
        assert f'src="../_images/{name}.gif"' in index, name
    assert total < 3 * 1024 * 1024, total


def _figures(env_id: str) -> dict:
    return json.loads((MEDIA / f"{_name(env_id)}.json").read_text(encoding="utf-8"))


@pytest.mark.parametrize("env_id", IDS)
def test_stored_figures_are_the_library_s_and_their_statistics(env_id: str):
    from activetrack.baselines.evaluation import run_episode
    from activetrack.baselines.policy_specs import resolve_policy
    from activetrack.envs import parallel_env
    from activetrack.world.scenarios import make_scenario

    data = _figures(env_id)
    sc = make_scenario(ALL_IDS[env_id])
    assert data["env_id"] == env_id and data["scenario"] == ALL_IDS[env_id]
    episodes = data["episodes"]["policies"]
    seeds = list(range(1000, 1100))
    assert set(episodes) == {"gsr", "rm"}
    # A few episodes re-run through the library give the stored per-episode figures
    # (mean trace, RMSE, return, NEES; the CPU time is the machine's). GSR's first episode
    # is re-run by the page's usage example (test_usage_example_runs_...). The tolerance is
    # rounding's: BLAS builds differ in the last bits (OpenBLAS picks its kernels by CPU),
    # and GSR's iterative solves carry that over 50 steps to about 2e-9 (fixed_wing, AMD
    # EPYC against the recording machine); any change of the model moves these far more.
    env = parallel_env(ALL_IDS[env_id])
    try:
        for policy, rerun in (("gsr", seeds[1:3]), ("rm", seeds[:1])):
            for seed in rerun:
                j = episodes[policy]["seeds"].index(seed)
                got = run_episode(env, resolve_policy(policy), seed)
                stored = [episodes[policy][k][j] for k in ("mean_trace", "rmse", "return", "nees")]
                np.testing.assert_allclose(got[:4], stored, rtol=1e-7, err_msg=f"{policy} {seed}")
    finally:
        env.close()
    # The summaries are the statistics of the stored episodes, recomputed here.
    summary = {r["policy"]: r for r in data["results"]}
    gsr_mean = np.mean(episodes["gsr"]["mean_trace"])
    gsr_iqm = trim_mean(episodes["gsr"]["mean_trace"], 0.25)
    for policy, ep in episodes.items():
        r = summary[policy]
        assert ep["seeds"] == seeds and r["episodes"] == 100
        assert r["seed_range"] == {"first": 1000, "last": 1099}
        trace = np.asarray(ep["mean_trace"])
        assert np.all(trace > 0)
        np.testing.assert_allclose(r["mean_trace"], np.mean(trace), rtol=1e-12)
        np.testing.assert_allclose(r["median_trace"], np.median(trace), rtol=1e-12)
        np.testing.assert_allclose(r["rmse"], np.mean(ep["rmse"]), rtol=1e-12)
        np.testing.assert_allclose(r["mean_return"], np.mean(ep["return"]), rtol=1e-12)
        np.testing.assert_allclose(r["nees"], np.mean(ep["nees"]), rtol=1e-12)
        np.testing.assert_allclose(
            r["cpu_ms_per_decision"], np.mean(ep["cpu_ms_per_decision"]), rtol=1e-12
        )
        np.testing.assert_allclose(r["ratio_to_gsr"], np.mean(trace) / gsr_mean, rtol=1e-12)
        # The protocol's statistics: the IQM is scipy's 25%-trimmed mean (100 episodes: the
        # middle 50), its ratio to GSR's the ratio of the two trimmed means.
        np.testing.assert_allclose(r["iqm_trace"], trim_mean(trace, 0.25), rtol=1e-12)
        np.testing.assert_allclose(
            r["iqm_ratio_to_gsr"], trim_mean(trace, 0.25) / gsr_iqm, rtol=1e-12
        )
        for key in ("iqm_trace", "median_trace", "ratio_to_gsr", "iqm_ratio_to_gsr"):
            lo, hi = r[f"{key}_ci95"]
            assert lo <= r[key] <= hi, key
            assert (lo == hi) == (policy == "gsr" and "ratio" in key), key
        if "no_detection" in r:  # limited sensing: the mean fraction, the longest gap
            np.testing.assert_allclose(r["no_detection"], np.mean(ep["no_detection"]), rtol=1e-12)
            assert r["longest_gap"] == max(ep["longest_gap"])
            # The track-loss rate: the episodes' mean rate, each a fraction; never above
            # the fraction of steps without a detection (a loss is an unmeasured step).
            loss = np.asarray(ep["track_loss"])
            np.testing.assert_allclose(r["track_loss_rate"], np.mean(loss), rtol=1e-12)
            assert np.all((0 <= loss) & (loss <= np.asarray(ep["no_detection"]) + 1e-12))
            lo, hi = r["track_loss_rate_ci95"]
            assert lo <= r["track_loss_rate"] <= hi
        # The bootstrap interval of the mean: around it, and within the episodes' range.
        lo, hi = r["mean_trace_ci95"]
        assert trace.min() <= lo < np.mean(trace) < hi <= trace.max()
        # With the trace objective the reward is -reward_scale times the step's trace:
        # the return is -reward_scale n_steps times the episode's mean trace.
        assert sc.objective == "trace" and sc.max_trace is None
        if sc.births is None:
            np.testing.assert_allclose(
                ep["return"], -sc.reward_scale * sc.n_steps * trace, rtol=1e-9
            )
        else:  # plus the search term, search_weight times a non-negative expected count
            assert np.all(np.asarray(ep["return"]) <= -sc.reward_scale * sc.n_steps * trace)
    # The page shows these figures: each row's IQM, median and mean trace (4 digits), and
    # the track-loss rate where sensing is limited (3 decimals).
    section = _section(_page(env_id), "The expert and random motion")
    head = next(line for line in section.splitlines() if line.startswith("|"))
    columns = [c.strip() for c in head.split("|")[1:-1]]
    rows = {row[0].strip("`"): dict(zip(columns, row, strict=True)) for row in _table(section)}
    assert set(rows) == {"gsr", "rm"}
    shown_statistics = {
        "IQM trace (m²) [95% CI]": lambda t: trim_mean(t, 0.25),
        "median [95% CI]": np.median,
        "mean [95% CI]": np.mean,
    }
    for policy, ep in episodes.items():
        for column, statistic in shown_statistics.items():
            shown = re.match(r"(\S+) \[(\S+), (\S+)\]", rows[policy][column]).groups()
            assert float(shown[0]) == pytest.approx(statistic(ep["mean_trace"]), rel=5e-4)
        if "no_detection" in summary[policy]:
            shown = rows[policy]["track loss [95% CI]"].split()[0]
            assert float(shown) == pytest.approx(np.mean(ep["track_loss"]), abs=5e-4)


def _out_of_range(accepted: str) -> list[object]:
    """Values just outside the range the page shows (``[lo, hi]``, ``0 or [lo, hi]``, ``an
    integer in [lo, hi]``), or none if it shows no range."""
    match = re.search(r"(an integer in )?(0 or )?\[([^,\]]+), ([^\]]+)\]$", accepted)
    if match is None:
        return []
    integer, _, lo, hi = match.groups()
    if integer:
        return [int(lo) - 1, int(hi) + 1]
    lo, hi = float(lo), float(hi)
    below = lo / 10 if lo > 0 else (-1.0 if lo == 0 else lo * 10)
    return [below, hi * 10]


@pytest.mark.parametrize("env_id", IDS)
def test_arguments_on_the_page_are_accepted_and_their_ranges_enforced(env_id: str):
    from activetrack.world.scenarios import Scenario, make_scenario

    rows = _table(_section(_page(env_id), "Arguments"))
    preset = make_scenario(ALL_IDS[env_id])

    def default(name: str, shown: str) -> object:
        """The default the page shows: a literal, or an object (a behaviour, a model) shown
        by its repr, which must be the preset's own."""
        try:
            return ast.literal_eval(shown)
        except (ValueError, SyntaxError):
            value = getattr(preset, name)
            assert shown == repr(value), (name, shown)
            return value

    defaults = {row[0].strip("`"): default(row[0].strip("`"), row[2].strip("`")) for row in rows}
    fields = {f.name for f in dataclasses.fields(Scenario) if f.init}
    assert set(defaults) == fields | {"scenario", "render_mode", "max_cycles"}
    # Every argument with its default, alone and all together: the id's environment.
    for name, value in defaults.items():
        gymnasium.make(env_id, **{name: value}).close()
    env = gymnasium.make(env_id, **defaults)
    assert env.unwrapped.scenario == make_scenario(ALL_IDS[env_id])
    env.close()
    # Outside the range shown: refused, naming the argument.
    tried = 0
    for name, _, _, accepted in rows:
        name = name.strip("`")
        if not isinstance(defaults[name], (int, float, type(None))):
            continue  # a vector, a name or an object: checked by the core's tests
        for value in _out_of_range(accepted):
            with pytest.raises(ValueError, match=name):
                gymnasium.make(env_id, **{name: value})
            tried += 1
    assert tried >= 30, tried


@pytest.mark.parametrize("env_id", IDS)
def test_usage_example_runs_and_prints_what_the_page_shows(env_id, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    text = _page(env_id)
    assert len(python_blocks(text)) == 1
    assert run_blocks(f"environments/{_name(env_id)}.md", text, capsys) == 1
    # The example's episode is the figures' first: its printed mean trace is theirs.
    gsr = _figures(env_id)["episodes"]["policies"]["gsr"]
    shown = python_blocks(text)[0][1].split()[-1]
    assert float(shown) == pytest.approx(gsr["mean_trace"][0], rel=5e-4)
