"""Every Python block of the README and of the manual's pages runs as written and prints
what the page shows (the rules are in :mod:`tests.doc_blocks`).

The pages are found, not listed: the README and every Markdown page under ``docs/`` that
Sphinx builds (the generated environment pages are checked by ``tests/test_docs.py``).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.doc_blocks import assert_prints, python_blocks, run_blocks

ROOT = Path(__file__).resolve().parents[1]
#: Pages Sphinx does not build (``docs/conf.py``'s ``exclude_patterns``) or generates.
NOT_PAGES: set[str] = set()
PAGES = [
    p.relative_to(ROOT).as_posix()
    for p in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    if not {"_build", "environments"} & set(p.relative_to(ROOT).parts)
    and p.relative_to(ROOT).as_posix() not in NOT_PAGES
]
WITH_CODE = [p for p in PAGES if python_blocks((ROOT / p).read_text(encoding="utf-8"))]

#: The README is read in five minutes; the manual holds the rest.
README_MAX_LINES = 200

#: A word that looks like a commit: 7 to 40 hex digits, at least one digit and one letter,
#: not part of a longer word, file name or number (``regression_x.json``, ``1.2345678e5``,
#: ``12345678e5`` are not commits; ``1000000`` and ``deadbeef`` have no letter or digit).
COMMIT = re.compile(
    r"(?<![\w.])(?![0-9]+e[0-9]+(?!\w))(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}(?!\w)",
    re.IGNORECASE,
)


def commits_named(text: str) -> list[str]:
    """Return the commit-like words of ``text``, in order."""
    return COMMIT.findall(text)


def test_the_pages_are_found():
    assert "README.md" in WITH_CODE and "docs/index.md" in PAGES


@pytest.mark.parametrize("page", WITH_CODE)
def test_python_blocks_print_what_the_page_shows(page, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert run_blocks(page, (ROOT / page).read_text(encoding="utf-8"), capsys) > 0


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


def test_a_block_that_prints_other_than_shown_fails(tmp_path, capsys):
    page = "```python\nprint(1 + 1)\n```\n\n```text\n3\n```\n"
    with pytest.raises(AssertionError, match="printed 2"):
        run_blocks("made-up.md", page, capsys)
    with pytest.raises(AssertionError, match="no output block"):
        run_blocks("made-up.md", "```python\nprint(2)\n```\n", capsys)
    # The blocks of a page share one namespace, in order.
    assert (
        run_blocks(
            "made-up.md", "```python\nx = 2\n```\n```python\nprint(x)\n```\n```text\n2\n```", capsys
        )
        == 2
    )


def test_the_readme_is_short():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines"


@pytest.mark.parametrize("page", PAGES)
def test_no_page_names_a_commit(page):
    """Which commit measured what is provenance: it goes to CHANGELOG.md, not the manual."""
    named = commits_named((ROOT / page).read_text(encoding="utf-8"))
    assert not named, f"{page} names commits {named}; move that provenance to CHANGELOG.md"


def test_the_commit_pattern():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    full = "bb518205aff6ebdc562250b19fb081941ffb6378"
    for planted, found in [
        ("measured at 843a345", "843a345"),
        ("since bb51820.", "bb51820"),
        (f"3048 of 3907 arrays equal against {full}", full),
        ("(commit a3f1f0f)", "a3f1f0f"),
        ("an export of 5FB3C6D", "5FB3C6D"),
    ]:
        assert commits_named(readme + "\n" + planted + "\n") == [found]
    ordinary = (
        "seeds 1000..1099, 1000000 steps, 12345678 runs, deadbeef, facade, float64, sha256, "
        "1.2345678e5, 12345678e5, 2e+04, 4.9e-16, 0x1f, 1e10, regression_bb51820.json, "
        "abc1234def56789abc1234def56789abc1234def5678"  # 44 digits: longer than a commit
    )
    assert commits_named(ordinary) == []


def test_the_readme_task_table_is_every_id_with_its_robots_and_observation():
    # Each row against the environment made from its id: the preset, the kinematics (a
    # unicycle's speed range as its Unicycle's), and the observation's size per agent.
    pettingzoo = pytest.importorskip("pettingzoo")
    import activetrack  # noqa: F401  (registers the ids)
    from activetrack import Unicycle
    from activetrack._registry import ALL_IDS

    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    section = readme.split("## The tasks", 1)[1].split("\n## ", 1)[0]
    rows = [
        [c.strip() for c in line.strip("|").split("|")]
        for line in section.splitlines()
        if line.startswith("| `activetrack/")
    ]
    assert sorted(r[0].strip("`") for r in rows) == sorted(ALL_IDS)
    for env_id, preset, _, robots, obs in rows:
        env_id = env_id.strip("`")
        env = pettingzoo.make("parallel", env_id)
        try:
            sc = env.unwrapped.scenario if hasattr(env, "unwrapped") else env.scenario
            assert preset.strip("`") == sc.name == ALL_IDS[env_id]
            agent = env.possible_agents[0]
            assert int(obs.split()[0]) == env.observation_space(agent).shape[0], env_id
            kinds = {type(k) for k in sc.kinematics_models}
            if sc.kinematics is None:
                assert robots == "disk", env_id
                continue
            assert kinds == {Unicycle} and robots.startswith("unicycle"), env_id
            speeds = re.search(r"v in \[(\S+), (\S+)\] m/s", robots)
            if speeds:  # (else "as" another row)
                k = sc.kinematics_models[0]
                assert (float(speeds[1]), float(speeds[2])) == (k.v_min, k.v_max), env_id
        finally:
            env.close()
