"""The manual builds with warnings as errors, and every registered environment has its
page, whose header table agrees with the environment itself.

The site is built from a copy of ``docs/`` in a temporary folder (the generated pages are
written there, not into the checkout). The header tables are checked against what the
environments made from each id produce here (their spaces, the arrays ``reset`` and
``state`` return, the length of an episode), not against the generator's code.
"""

from __future__ import annotations

import ast
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("sphinx", reason="the [docs] extra (sphinx) is not installed")
pytest.importorskip("myst_parser", reason="the [docs] extra (myst-parser) is not installed")
pytest.importorskip("furo", reason="the [docs] extra (furo) is not installed")

import gymnasium  # noqa: E402
import pettingzoo  # noqa: E402

import activetrack  # noqa: E402,F401  (registers the ids)
from activetrack._registry import ALL_IDS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

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
        assert agents == [f"sensor_{i}" for i in range(m)]

        assert table["Gymnasium id"] == env_id
        assert table["Import"].startswith(f'gymnasium.make("{env_id}")')
        assert table["PettingZoo id"].startswith(f'pettingzoo.make("parallel", "{env_id}")')
        assert table["Scenario preset"] == sc.name == ALL_IDS[env_id]
        count, listed = table["Agents"].split(": ", 1)
        assert int(count) == m
        shown = listed.split(", ")
        assert shown == (agents if m <= 4 else [agents[0], "...", agents[-1]])

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
        # The scenarios give no kinematics: each sensor is a disk of radius vmax_i dt (eq. 13).
        assert sc.kinematics is None
        vmax = np.broadcast_to(np.asarray(sc.vmax, dtype=np.float64), (m,))
        radii = [
            float(re.fullmatch(r"Disk\((.+)\)", k).group(1))
            for k in table["Kinematics"].split(", ")
        ]
        np.testing.assert_allclose(radii, vmax * sc.dt, rtol=1e-12)

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
