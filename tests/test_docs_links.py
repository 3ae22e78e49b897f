"""Every internal link and anchor of the built manual resolves.

Each HTML page of the build is parsed once (the standard library's ``html.parser``): its
``id``s (and ``<a name>``s) are the anchors it offers, its ``href``/``src``/``srcset``
attributes the links it makes. A relative link must name a file of the build (a page, an
image, a ``_static`` file; a folder stands for its ``index.html``) inside the build folder,
and its ``#fragment``, when the target is a page, an anchor of that page. External links
(any scheme: http, https, mailto, data...) are not fetched.

The checker is first run on a small hand-made site whose broken links are known, then on
the manual (``tests/conftest.py``'s ``docs_site``).
"""

from __future__ import annotations

import posixpath
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

# The attributes that name another resource (and <object data>); srcset holds
# "url [descriptor], ..." and is split apart.
_LINK_ATTRS = ("href", "src", "poster")


class _Page(HTMLParser):
    """One parsed page: the anchors it offers and the (attribute value, line) it links."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.ids: set[str] = set()
        self.links: list[tuple[str, int]] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        line = self.getpos()[0]
        for name, value in attrs:
            if value is None:
                continue
            if name == "id" or (name == "name" and tag == "a"):
                self.ids.add(value)
            elif name in _LINK_ATTRS or (name == "data" and tag == "object"):
                self.links.append((value, line))
            elif name == "srcset":
                for candidate in value.split(","):
                    if candidate.strip():
                        self.links.append((candidate.split()[0], line))

    handle_startendtag = handle_starttag


def broken_links(site: Path) -> list[str]:
    """Return one line per broken internal link of the HTML pages under ``site``
    (``page:line: link (reason)``), sorted; an empty list when every link resolves."""
    site = site.resolve()
    pages: dict[str, _Page] = {}
    for path in sorted(site.rglob("*.html")):
        parser = _Page()
        parser.feed(path.read_text(encoding="utf-8"))
        parser.close()
        pages[path.relative_to(site).as_posix()] = parser

    problems: list[str] = []
    for page, parsed in pages.items():
        for link, line in parsed.links:
            reason = _check(site, pages, page, link.strip())
            if reason:
                problems.append(f"{page}:{line}: {link} ({reason})")
    return sorted(problems)


def _check(site: Path, pages: dict[str, _Page], page: str, link: str) -> str | None:
    """Return why ``link`` on ``page`` (a path relative to ``site``) is broken, or None."""
    parts = urlsplit(link)
    if parts.scheme or parts.netloc:
        return None  # external (http, https, mailto, data...) or protocol-relative: not fetched
    fragment = unquote(parts.fragment)
    if not parts.path:
        target = page  # "#anchor" or "?query" on the same page
    else:
        if parts.path.startswith("/"):
            return "absolute path: breaks when the site is not served at the root"
        joined = posixpath.normpath(posixpath.join(posixpath.dirname(page), unquote(parts.path)))
        if joined == ".." or joined.startswith("../"):
            return "outside the build"
        if (site / joined).is_dir():
            joined = posixpath.join(joined, "index.html") if joined != "." else "index.html"
        if not (site / joined).is_file():
            return "no such file in the build"
        target = joined
    if fragment and target.endswith(".html") and fragment not in pages[target].ids:
        return f"no id {fragment!r} in {target}"
    return None


def _write(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text, encoding="utf-8")
    return root


def test_checker_finds_exactly_the_planted_broken_links(tmp_path: Path) -> None:
    """On a hand-made site, every kind of broken link is reported and nothing else is."""
    site = _write(
        tmp_path,
        {
            "index.html": (
                '<html><head><link rel="stylesheet" href="_static/a.css?v=1"></head><body>\n'
                '<h1 id="top">T</h1><a name="legacy"></a>\n'
                '<a href="#top">ok</a> <a href="#legacy">ok</a> <a href="#">ok</a>\n'
                '<a href="#nowhere">bad</a>\n'
                '<a href="sub/page.html#sec-2">ok</a> <a href="sub/page.html#sec%202">bad</a>\n'
                '<a href="sub/">ok</a> <a href="sub/index.html#intro">ok</a>\n'
                '<a href="sub/missing.html">bad</a> <img src="_static/logo.png">\n'
                '<img src="_static/gone.png" srcset="_static/logo.png 1x, _static/x2.png 2x">\n'
                '<a href="https://example.org/x#y">ext</a> <a href="mailto:a@b.c">ext</a>\n'
                '<img src="data:image/png;base64,AAAA"> <a href="../escape.html">bad</a>\n'
                '<a href="/abs.html">bad</a> <svg><use href="#top"></use></svg>\n'
                '<a href="sub/page.html?q=1">ok</a> <a href="_static/a.css#whatever">ok</a>\n'
                "</body></html>"
            ),
            "sub/page.html": (
                '<p id="sec-2">x</p><a href="../index.html#top">ok</a>'
                '<a href="../index.html#gone">bad</a><a href="page.html">ok</a>'
            ),
            "sub/index.html": '<h2 id="intro">i</h2><a href=".."></a>',
            "_static/a.css": "",
            "_static/logo.png": "",
        },
    )
    (tmp_path.parent / "escape.html").write_text("", encoding="utf-8")  # exists, but outside
    assert broken_links(site) == sorted(
        [
            "index.html:4: #nowhere (no id 'nowhere' in index.html)",
            "index.html:5: sub/page.html#sec%202 (no id 'sec 2' in sub/page.html)",
            "index.html:7: sub/missing.html (no such file in the build)",
            "index.html:8: _static/gone.png (no such file in the build)",
            "index.html:8: _static/x2.png (no such file in the build)",
            "index.html:10: ../escape.html (outside the build)",
            "index.html:11: /abs.html (absolute path: breaks when the site is not served at"
            " the root)",
            "sub/page.html:1: ../index.html#gone (no id 'gone' in index.html)",
        ]
    )


@pytest.mark.slow
def test_every_internal_link_and_anchor_of_the_manual_resolves(docs_site: Path) -> None:
    """The built manual has no broken internal link or anchor, and the check saw the site's
    pages (the index, every environment page) and their links."""
    pages = {p.relative_to(docs_site).as_posix() for p in docs_site.rglob("*.html")}
    assert {"index.html", "environments/index.html"} <= pages
    assert any(p.startswith("environments/") and p != "environments/index.html" for p in pages)
    problems = broken_links(docs_site)
    assert not problems, "broken internal links:\n" + "\n".join(problems)
