"""The README's Python examples run as written and print what the README shows.

Every ```python block runs. A ```text block that follows it with nothing but whitespace in
between is its output: the block must print that (stdout), with each number the README
shows equal to the printed one rounded to the digits shown (an integer exactly), the text
around the numbers equal up to whitespace, and ``...`` standing for any text (rounding
noise, say). A ```python block with no such output block must print nothing.
"""

from __future__ import annotations

import pathlib
import re

import pytest

README = pathlib.Path(__file__).resolve().parents[1] / "README.md"
#: A python block and, if one follows it directly, its output block.
BLOCK = re.compile(r"```python\n(.*?)```(?:\s*```text\n(.*?)```)?", re.S)
BLOCKS = BLOCK.findall(README.read_text())
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


def assert_prints(shown: str, printed: str) -> None:
    """Assert that ``printed`` is what the output block ``shown`` describes."""
    pattern, numbers = expected_pattern(shown)
    match = re.fullmatch(pattern, printed.strip(), re.S)
    assert match, f"the README shows\n{shown}\nbut the block printed\n{printed}"
    for want, got in zip(numbers, match.groups(), strict=True):
        mantissa, _, exponent = want.lower().partition("e")
        if "." not in mantissa and not exponent:
            assert got == want, f"printed {got}, the README shows {want}"
            continue
        decimals = len(mantissa.partition(".")[2])
        half_unit = 0.5 * 10.0 ** (int(exponent or 0) - decimals)
        assert abs(float(got) - float(want)) <= half_unit * (1 + 1e-9), (
            f"printed {got}, which does not round to the README's {want}"
        )


@pytest.mark.parametrize(("code", "shown"), BLOCKS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_readme_python_block_prints_what_the_readme_shows(
    code, shown, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    exec(compile(code, str(README), "exec"), {"__name__": "__readme__"})
    printed = capsys.readouterr().out
    if shown:
        assert_prints(shown, printed)
    else:
        assert printed == "", f"the block printed\n{printed}\nbut has no output block after it"


def test_output_comparison():
    """The comparison itself, on made-up outputs."""
    assert_prints(
        "[ 1.93 -2.03] 2.0987 (4,)\nname", "[ 1.92806615 -2.02795447] 2.098699 (4,)\nname"
    )
    assert_prints("[4.0 ...] 1 True", "[ 4.00000000e+00 -1.43e-15] 1 True")
    assert_prints("1.2e-05", "1.24e-05")
    for printed in [
        "[ 1.92806615 -2.02795447] 2.0982 (4,)\nname",  # 2.0982 does not round to 2.0987
        "[ 1.92806615 -2.02795447] 2.098699 (5,)\nname",  # an integer differs
        "[ 1.92806615 -2.02795447] 2.098699 (4,)\nnames",  # the text differs
        "[ 1.92806615 -2.02795447 7.0] 2.098699 (4,)\nname",  # one number more
    ]:
        with pytest.raises(AssertionError):
            assert_prints("[ 1.93 -2.03] 2.0987 (4,)\nname", printed)
    with pytest.raises(AssertionError):
        assert_prints("1.2e-05", "1.26e-05")
    with pytest.raises(AssertionError):
        assert_prints("12 3", "123")  # separated numbers stay separate
