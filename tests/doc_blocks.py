"""Running the Python blocks of a Markdown page (the README, the manual's pages) and
checking that each prints what the page shows.

Every ```python block runs. A ```text block that follows it with nothing but whitespace in
between is its output: the block must print that (stdout), with each number the page shows
equal to the printed one rounded to the digits shown (an integer exactly), the text around
the numbers equal up to whitespace, and ``...`` standing for any text (rounding noise, say).
A ```python block with no such output block must print nothing. The blocks of one page run
in order in one namespace (a tutorial builds on its earlier blocks), in a temporary folder.
"""

from __future__ import annotations

import re
from pathlib import Path

#: A python block and, if one follows it directly, its output block.
BLOCK = re.compile(r"```python\n(.*?)```(?:\s*```text\n(.*?)```)?", re.S)

NUMBER = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?"
_TOKEN = re.compile(rf"(\.\.\.)|({NUMBER})|(\s+)|(.)", re.S)


def expected_pattern(shown: str) -> tuple[str, list[str]]:
    """Return a regular expression matching any output that ``shown`` (an output block)
    describes, with one group per number, and the numbers as shown."""
    items: list[tuple[str, bool]] = []  # (regex, whether it is a word or a number)
    numbers: list[str] = []
    spaced: list[bool] = []  # whether whitespace precedes the item in ``shown``
    space = False
    for ellipsis, number, blank, char in (m.groups() for m in _TOKEN.finditer(shown.strip())):
        if blank:
            space = True
            continue
        if ellipsis:
            items.append((".*?", False))
        elif number:
            items.append((f"({NUMBER})", True))
            numbers.append(number)
        else:
            items.append((re.escape(char), char.isalnum()))
        spaced.append(space)
        space = False
    # Whitespace is free (numpy pads arrays by their widest entry) but never created or
    # removed between two words or numbers: "12 3" is not "123", "final trace" not "finaltrace".
    parts = [items[0][0]] if items else []
    for (regex, word), (_, word_before), gap in zip(items[1:], items[:-1], spaced[1:], strict=True):
        if word and word_before:
            parts.append((r"\s+" if gap else "") + regex)
        else:
            parts.append(r"\s*" + regex)
    return "".join(parts), numbers


def assert_prints(shown: str, printed: str, where: str = "the page") -> None:
    """Assert that ``printed`` is what the output block ``shown`` describes."""
    pattern, numbers = expected_pattern(shown)
    match = re.fullmatch(pattern, printed.strip(), re.S)
    assert match, f"{where} shows\n{shown}\nbut the block printed\n{printed}"
    for want, got in zip(numbers, match.groups(), strict=True):
        mantissa, _, exponent = want.lower().partition("e")
        if "." not in mantissa and not exponent:
            assert got == want, f"printed {got}, the page shows {want}"
            continue
        decimals = len(mantissa.partition(".")[2])
        half_unit = 0.5 * 10.0 ** (int(exponent or 0) - decimals)
        assert abs(float(got) - float(want)) <= half_unit * (1 + 1e-9), (
            f"printed {got}, which does not round to the page's {want}"
        )


def python_blocks(text: str) -> list[tuple[str, str]]:
    """Return the page's ``(code, shown output or "")`` pairs, in order."""
    return BLOCK.findall(text)


def run_blocks(path: Path | str, text: str, capsys, namespace: dict | None = None) -> int:
    """Run the Python blocks of ``text`` (a page read from ``path``) in order in one
    namespace and check each one's output against the page; return how many ran.

    ``capsys`` is pytest's fixture; the caller chooses the working folder.
    """
    namespace = {"__name__": "__doc_page__"} if namespace is None else namespace
    blocks = python_blocks(text)
    for i, (code, shown) in enumerate(blocks):
        capsys.readouterr()
        exec(compile(code, f"{path} (python block {i})", "exec"), namespace)
        printed = capsys.readouterr().out
        if shown:
            assert_prints(shown, printed, where=f"{path}, python block {i}")
        else:
            assert printed == "", (
                f"{path}, python block {i} printed\n{printed}\nbut has no output block after it"
            )
    return len(blocks)
