"""The manual's index and an environment page open in a real headless browser (Debian's
Chromium, driven by Selenium) without console errors, and their screenshots show a page.

``docs/scripts/screenshots.py`` (``make docs-screenshots``) does the work; these tests run
its function. They need ``/usr/bin/chromium`` and ``/usr/bin/chromedriver`` (``apt-get
install chromium chromium-driver``) and Selenium (the ``[docs]`` extra), and are skipped
without them. The console capture is first shown to see a planted script error and a
missing image on a hand-made page, and the blank-screenshot check to see a blank page, so
"no errors, not blank" on the manual is not vacuous.
"""

from __future__ import annotations

import importlib.util
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location(
    "docs_screenshots", ROOT / "docs" / "scripts" / "screenshots.py"
)
shots_mod = importlib.util.module_from_spec(_spec)
sys.modules["docs_screenshots"] = shots_mod  # dataclasses look their module up by name
_spec.loader.exec_module(shots_mod)

needs_chromium = pytest.mark.skipif(
    not (shots_mod.CHROMIUM.is_file() and shots_mod.CHROMEDRIVER.is_file()),
    reason=f"no {shots_mod.CHROMIUM} or {shots_mod.CHROMEDRIVER} (Debian's chromium and "
    "chromium-driver packages; CI does not install them)",
)
needs_selenium = pytest.mark.skipif(
    importlib.util.find_spec("selenium") is None,
    reason="Selenium (the [docs] extra) is not installed",
)

WINDOW = (1280, 900)


class _Title(HTMLParser):
    """The text of a page's first ``<title>`` (the document's, in ``<head>``; the SVG
    icons of the body have titles of their own)."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.title, self._inside, self._seen = "", False, False

    def handle_starttag(self, tag: str, attrs) -> None:
        if tag == "title" and not self._seen:
            self._inside = self._seen = True

    def handle_endtag(self, tag: str) -> None:
        if tag == "title":
            self._inside = False

    def handle_data(self, data: str) -> None:
        if self._inside:
            self.title += data


def _title(html: Path) -> str:
    parser = _Title()
    parser.feed(html.read_text(encoding="utf-8"))
    return " ".join(parser.title.split())


def _ink(png: Path) -> tuple[tuple[int, ...], float]:
    """Decode ``png`` and return its shape and the fraction of its pixels that differ from
    its commonest colour (0 for a blank, one-colour image)."""
    import matplotlib.image

    pixels = matplotlib.image.imread(png)
    flat = pixels.reshape(-1, pixels.shape[-1])
    colours, counts = np.unique(flat, axis=0, return_counts=True)
    return pixels.shape, 1.0 - counts.max() / flat.shape[0]


@needs_chromium
@needs_selenium
def test_console_errors_and_blank_pages_are_seen(tmp_path: Path) -> None:
    """A hand-made page with a throwing script and a missing image reports both; a blank
    page gives a one-colour screenshot."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "favicon.ico").write_bytes(b"")  # Chromium asks for it; its 404 is not planted
    (site / "index.html").write_text(
        "<!doctype html><title>blank</title><body style='background:#fff'></body>"
    )
    (site / "bad.html").write_text(
        "<!doctype html><title>bad</title><body><p>text</p>"
        "<img src='missing.png'><script>throw new Error('planted failure')</script></body>"
    )
    shots = shots_mod.take_screenshots(site, tmp_path / "out", ["index.html", "bad.html"])
    blank, bad = shots
    assert blank.errors == () and blank.title == "blank"
    assert _ink(blank.png) == ((WINDOW[1], WINDOW[0], 3), 0.0)
    assert len(bad.errors) == 2, bad.errors
    assert any("missing.png" in e and "404" in e for e in bad.errors), bad.errors
    assert any("planted failure" in e for e in bad.errors), bad.errors


def test_existing_screenshots_are_kept_unless_overwrite(tmp_path: Path) -> None:
    """An existing PNG is refused before the browser starts (nor needs one), and left as it
    was; so is a page the site does not have."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "index.html").write_text("<title>x</title>")
    out = tmp_path / "out"
    out.mkdir()
    (out / "index.png").write_bytes(b"the user's file")
    with pytest.raises(FileExistsError, match="--overwrite"):
        shots_mod.take_screenshots(site, out, ["index.html"])
    assert (out / "index.png").read_bytes() == b"the user's file"
    with pytest.raises(FileNotFoundError, match="pages: 'nope.html'"):
        shots_mod.take_screenshots(site, out, ["nope.html"], overwrite=True)
    assert shots_mod.main([str(site), str(out)]) == 2  # the command's usage error


@pytest.mark.slow
@needs_chromium
@needs_selenium
def test_index_and_an_environment_page_open_without_console_errors(
    docs_site: Path, tmp_path: Path
) -> None:
    """The built manual's index and ActiveTracking-v0 page load over http in headless
    Chromium with no SEVERE console message, show their own titles, and their screenshots
    are PNGs of the window's size with text on them; no temporary file is left behind."""
    out = tmp_path / "shots"
    pages = ["index.html", "environments/ActiveTracking-v0.html"]
    shots = shots_mod.take_screenshots(docs_site, out, pages, window_size=WINDOW)
    assert [s.page for s in shots] == pages
    for shot in shots:
        assert shot.errors == (), f"{shot.page}: console errors {shot.errors}"
        assert shot.title == _title(docs_site / shot.page) != ""
        shape, ink = _ink(shot.png)
        assert shape[:2] == (WINDOW[1], WINDOW[0])
        # A page of text and navigation: well over 1% of the pixels are not background.
        assert ink > 0.01, f"{shot.png} is (nearly) one flat colour"
    assert sorted(p.name for p in out.iterdir()) == [
        "environments-ActiveTracking-v0.png",
        "index.png",
    ]
