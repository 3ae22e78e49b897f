"""Open pages of the built manual in headless Chromium, collect their console errors and
take a PNG screenshot of each (``make docs-screenshots``).

    python docs/scripts/screenshots.py SITE OUT [--overwrite] [--page PAGE ...]
        [--chromium PATH] [--chromedriver PATH]

SITE is a built site (``make docs`` writes ``docs/_build/html``); nothing is built here. The
site is served over http on an ephemeral localhost port (as a reader's browser sees it, so
a missing stylesheet or script is a failed request in the console) and each page (by default
``index.html`` and ``environments/ActiveTracking-v0.html``) is opened in Debian's Chromium
(``/usr/bin/chromium``) driven by its ``chromedriver``. Every console message of level
SEVERE (errors, failed requests, uncaught exceptions) is reported; the command exits 1 when
there is any, 2 on a usage error. Screenshots go to OUT as ``index.png``,
``environments-ActiveTracking-v0.png``...: each written to a temporary file renamed into
place; existing PNGs are kept (the command refuses) unless ``--overwrite``.

Selenium 4 drives the browser: the W3C WebDriver client maintained by the browser vendors'
project, whose ``goog:loggingPrefs`` capability reads Chromium's console log.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import os
import sys
import tempfile
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
DEFAULT_PAGES = ("index.html", "environments/ActiveTracking-v0.html")
# No network is needed or wanted: no sync, updates, QUIC or background requests; a fresh
# profile per run (--user-data-dir is added per run).
CHROMIUM_FLAGS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--hide-scrollbars",
)
INSTALL_HINT = (
    "Chromium and its driver are needed: on Debian/Ubuntu, as root, "
    "`apt-get update && apt-get install -y chromium chromium-driver` "
    f"(they install {CHROMIUM} and {CHROMEDRIVER})."
)


@dataclass(frozen=True)
class Shot:
    """One page as the browser showed it."""

    page: str  # relative to the site, e.g. "environments/ActiveTracking-v0.html"
    png: Path  # the screenshot
    title: str  # the document's title in the browser
    errors: tuple[str, ...]  # console messages of level SEVERE


def png_name(page: str) -> str:
    """Return the screenshot's file name for ``page``: ``environments/X.html`` ->
    ``environments-X.png``."""
    stem = page[: -len(".html")] if page.endswith(".html") else page
    return stem.replace("/", "-") + ".png"


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format: str, *args: object) -> None:  # noqa: A002 (stdlib's name)
        pass  # the browser's console reports failed requests; no access log on stderr


@contextmanager
def serve(site: Path) -> Iterator[str]:
    """Serve ``site`` over http on 127.0.0.1 (an ephemeral port) in a thread; yield the base
    URL (``http://127.0.0.1:PORT/``); the server is shut down on exit."""
    handler = functools.partial(_QuietHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/"
    finally:
        server.shutdown()
        server.server_close()
        thread.join()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _umask()


def _write_png(data: bytes, dest: Path, overwrite: bool) -> None:
    """Write ``data`` to a temporary file beside ``dest`` and rename it into place."""
    fd, tmp = tempfile.mkstemp(dir=dest.parent, prefix=f".{dest.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp's 0600 -> what open() would have given
        if overwrite:
            os.replace(tmp, dest)
        else:
            os.link(tmp, dest)  # fails if dest appeared meanwhile: never clobber it
            os.unlink(tmp)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def take_screenshots(
    site: Path | str,
    out: Path | str,
    pages: Sequence[str] = DEFAULT_PAGES,
    *,
    overwrite: bool = False,
    window_size: tuple[int, int] = (1280, 900),
    chromium: Path | str = CHROMIUM,
    chromedriver: Path | str = CHROMEDRIVER,
) -> list[Shot]:
    """Open each of ``pages`` (paths relative to the built site ``site``) in headless
    Chromium, served over http from localhost, and screenshot the window.

    Returns one :class:`Shot` per page, in order: its PNG in ``out`` (created if missing),
    the title the browser shows and the console's SEVERE messages (empty when the page has
    none). Raises ``FileNotFoundError`` when the site, a page, Chromium or chromedriver is
    missing, ``FileExistsError`` when a PNG exists and not ``overwrite``, ``ValueError`` for
    no page, a page outside the site, two pages with one PNG name or a window size outside
    200..8000 pixels, all checked before the browser starts; ``ModuleNotFoundError``
    without Selenium.
    """
    site, out = Path(site), Path(out)
    if not (site / "index.html").is_file():
        raise FileNotFoundError(f"site: {site} is not a built site (no index.html); run make docs")
    if not pages:
        raise ValueError("pages: at least one page is needed")
    for page in pages:
        if not (site / page).resolve().is_relative_to(site.resolve()):
            raise ValueError(f"pages: {page!r} is outside the site {site}")
        if not (site / page).is_file():
            raise FileNotFoundError(f"pages: {page!r} is not a file of the site {site}")
    if len(window_size) != 2 or not all(200 <= int(v) <= 8000 for v in window_size):
        raise ValueError(f"window_size: must be two sizes in 200..8000 pixels, got {window_size}")
    if out.exists() and not out.is_dir():
        raise NotADirectoryError(f"out: {out} exists and is not a folder")
    dests = [out / png_name(page) for page in pages]
    if len(set(dests)) != len(dests):
        raise ValueError(f"pages: {list(pages)} repeat a page (or two map to one PNG name)")
    if not overwrite:
        existing = [str(d) for d in dests if d.exists()]
        if existing:
            raise FileExistsError(
                f"out: {', '.join(existing)} already exist; pass --overwrite to replace them"
            )

    for tool in (chromium, chromedriver):
        if not Path(tool).is_file():
            raise FileNotFoundError(f"{tool} not found. {INSTALL_HINT}")

    try:  # the [docs] extra; imported once the inputs are valid
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError as exc:
        raise ModuleNotFoundError(
            "Selenium is needed: pip install -e '.[docs]' (or pip install selenium)"
        ) from exc

    out.mkdir(parents=True, exist_ok=True)
    shots: list[Shot] = []
    with tempfile.TemporaryDirectory(prefix="activetrack-chromium-") as profile, serve(site) as url:
        options = webdriver.ChromeOptions()
        options.binary_location = str(chromium)
        for flag in CHROMIUM_FLAGS:
            options.add_argument(flag)
        options.add_argument(f"--user-data-dir={profile}")
        options.add_argument(f"--window-size={int(window_size[0])},{int(window_size[1])}")
        options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
        # An explicit driver path: Selenium Manager (which would download one) is not run.
        driver = webdriver.Chrome(
            service=Service(executable_path=str(chromedriver)), options=options
        )
        try:
            driver.set_page_load_timeout(60)
            # The window's size includes the (invisible) browser frame; fix the page's
            # viewport itself, so a screenshot is exactly window_size pixels.
            width, height = (int(v) for v in window_size)
            driver.execute_cdp_cmd(
                "Emulation.setDeviceMetricsOverride",
                {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": False},
            )
            for page, dest in zip(pages, dests, strict=True):
                driver.get(url + page)  # returns once the page's load event has fired
                png = driver.get_screenshot_as_png()
                # get_log drains the buffer, so each page gets only its own messages.
                errors = tuple(
                    entry["message"]
                    for entry in driver.get_log("browser")
                    if entry.get("level") == "SEVERE"
                )
                _write_png(png, dest, overwrite)
                shots.append(Shot(page=page, png=dest, title=driver.title, errors=errors))
        finally:
            driver.quit()
    return shots


def main(argv: Sequence[str] | None = None) -> int:
    """The command line; returns the exit status (0 no console error, 1 some, 2 bad input)."""
    parser = argparse.ArgumentParser(
        description="Screenshot pages of the built manual in headless Chromium and report "
        "their console errors (builds nothing: run make docs first)."
    )
    parser.add_argument("site", type=Path, help="the built site, e.g. docs/_build/html")
    parser.add_argument("out", type=Path, help="folder for the PNGs")
    parser.add_argument(
        "--page",
        action="append",
        dest="pages",
        metavar="PAGE",
        help="a page relative to the site (repeatable); default: " + ", ".join(DEFAULT_PAGES),
    )
    parser.add_argument("--overwrite", action="store_true", help="replace existing PNGs")
    parser.add_argument(
        "--chromium", type=Path, default=CHROMIUM, help=f"the browser (default {CHROMIUM})"
    )
    parser.add_argument(
        "--chromedriver",
        type=Path,
        default=CHROMEDRIVER,
        help=f"its WebDriver, of the same version (default {CHROMEDRIVER})",
    )
    args = parser.parse_args(argv)
    try:
        shots = take_screenshots(
            args.site,
            args.out,
            args.pages or DEFAULT_PAGES,
            overwrite=args.overwrite,
            chromium=args.chromium,
            chromedriver=args.chromedriver,
        )
    except (OSError, ValueError, ImportError) as exc:
        print(f"screenshots: {exc}", file=sys.stderr)
        return 2
    failed = 0
    for shot in shots:
        print(f"{shot.page}: {shot.png} ({shot.title!r}), {len(shot.errors)} console errors")
        for message in shot.errors:
            print(f"  SEVERE {message}")
        failed += bool(shot.errors)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
