"""The distribution: version, license and citation metadata agree, and the built wheel
installs and runs in a fresh virtual environment (not an editable install) with its type
hints visible to a type checker (PEP 561).
"""

from __future__ import annotations

import importlib.metadata
import json
import shlex
import shutil
import subprocess
import sys
import zipfile
from email.parser import Parser
from pathlib import Path

import pytest
import yaml  # pyyaml, in the dev extra

import activetrack

try:
    import tomllib  # Python >= 3.11
except ModuleNotFoundError:  # 3.10: the same parser as the tomli package (in the dev extra)
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
SUBPACKAGES = ["envs", "baselines", "train"]


def test_version_comes_from_the_distribution_metadata():
    assert activetrack.__version__ == PROJECT["version"]
    assert activetrack.__version__ == importlib.metadata.version("activetrack")


def test_license_file_matches_the_declared_license():
    assert PROJECT["license"] == "MIT" and PROJECT["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text()
    assert text.startswith("MIT License") and "WITHOUT WARRANTY OF ANY KIND" in text


def test_citation_cff_cites_this_version_and_the_paper():
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    # The keys CFF 1.2.0 requires, and the ones GitHub shows.
    assert cff["cff-version"] == "1.2.0"
    assert cff["type"] == "software" and cff["message"] and cff["title"] and cff["authors"]
    assert str(cff["version"]) == PROJECT["version"]
    assert cff["license"] == PROJECT["license"]
    papers = [r for r in cff["references"] if r["type"] == "conference-paper"]
    assert len(papers) == 1
    paper = papers[0]
    assert [a["family-names"] for a in paper["authors"]] == ["Zhou", "Roumeliotis"]
    assert paper["year"] == 2009 and "bearing" in paper["title"]


def test_py_typed_marker_is_in_the_top_package():
    marker = Path(activetrack.__file__).with_name("py.typed")
    assert marker.is_file()


def _copy_source(dest: Path) -> Path:
    """Copy the project without its virtual environment, caches and build outputs."""
    ignore = shutil.ignore_patterns(
        ".git", ".venv", "results", "build", "dist", "*.egg-info", "__pycache__", ".*_cache",
        ".benchmarks", "*.pyc", "_build",
    )  # fmt: skip
    return Path(shutil.copytree(ROOT, dest, ignore=ignore))


def _run(args: list, cwd: Path, timeout: float = 900) -> str:
    out = subprocess.run(args, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    assert out.returncode == 0, f"{args} failed:\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}"
    return out.stdout


def _required(requirements: list[str], missing_ok: bool = False) -> set[str]:
    """Return the (canonical) names of the distributions of this environment that
    ``requirements`` name, with theirs, transitively (extras followed, markers evaluated).
    Each requirement must be met by the version found here; ``missing_ok``: one not
    installed here is left out (with what it requires)."""
    from packaging.requirements import Requirement
    from packaging.utils import canonicalize_name

    todo = [(Requirement(r), "") for r in requirements]
    done: set[tuple[str, str]] = set()  # (distribution, extra) whose requirements are queued
    while todo:
        req, extra = todo.pop()
        if req.marker is not None and not req.marker.evaluate({"extra": extra}):
            continue
        name = canonicalize_name(req.name)
        try:
            dist = importlib.metadata.distribution(name)
        except importlib.metadata.PackageNotFoundError:
            if missing_ok:
                continue
            raise
        assert req.specifier.contains(dist.version, prereleases=True), (req, dist.version)
        for e in {""} | req.extras:
            if (name, e) not in done:
                done.add((name, e))
                todo += [(Requirement(r), e) for r in dist.requires or ()]
    return {name for name, _ in done}


def _link_dependencies(metadata: str, folder: Path) -> set[str]:
    """Link into ``folder`` (to put on a venv's path) every file of the distributions of
    this environment that the wheel's ``metadata`` requires, without extras, transitively;
    return their names. Each requirement must be met by the version found here."""
    folder.mkdir()
    names = _required(Parser().parsestr(metadata).get_all("Requires-Dist"))
    for name in names:
        dist = importlib.metadata.distribution(name)
        assert dist.files, f"{name}: no RECORD"
        site = Path(dist.locate_file(""))
        for top in {f.parts[0] for f in dist.files} - {"..", "__pycache__"}:
            if not (folder / top).exists():
                (folder / top).symlink_to(site / top)
    return names


def _make_rules() -> dict[str, tuple[list[str], list[str]]]:
    """Return the Makefile's rules: target -> (prerequisites, recipe lines), continuation
    lines joined."""
    text = (ROOT / "Makefile").read_text().replace("\\\n", " ")
    rules: dict[str, tuple[list[str], list[str]]] = {}
    recipe: list[str] | None = None
    for line in text.splitlines():
        if line.startswith("\t") and recipe is not None:
            recipe.append(line.strip())
        elif ":" in line and not line.startswith(("#", " ")) and ":=" not in line:
            target, _, prerequisites = line.partition(":")
            recipe = []
            rules[target.strip()] = (prerequisites.split(), recipe)
        elif line.strip() and not line.startswith("#"):
            recipe = None
    return rules


#: Run in a fresh interpreter as if the distributions named in argv[1] and their modules
#: (argv[2]) were not installed: every import finder asked for such a module answers None,
#: as for a module not found (``import`` raises ModuleNotFoundError, and
#: ``importlib.util.find_spec`` answers None), and their metadata is not found; then the
#: CLI on argv[3]; it prints the blocked modules loaded after that (none: what the
#: interpreter's start loaded before, setuptools' ``_distutils_hack`` from its ``.pth``, is
#: no import of the demo's). (Not ``sys.modules[name] = None``: scipy takes a name in
#: ``sys.modules`` for a loaded module.)
WITHOUT_RUN = """
import json, sys

before = set(sys.modules)
from packaging.utils import canonicalize_name

dists, modules = set(json.loads(sys.argv[1])), set(json.loads(sys.argv[2]))


class Without:
    def __init__(self, inner):
        self.inner = inner

    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in modules:
            return None
        return self.inner.find_spec(name, path, target)

    def find_distributions(self, *args, **kwargs):
        found = getattr(self.inner, "find_distributions", lambda *a, **k: ())(*args, **kwargs)
        return [d for d in found if canonicalize_name(d.metadata["Name"] or "") not in dists]

    def __getattr__(self, attr):
        return getattr(self.inner, attr)


sys.meta_path[:] = [Without(f) for f in sys.meta_path]
from activetrack.cli import main

code = main(json.loads(sys.argv[3]))
print("exit", code, "loaded", sorted((set(sys.modules) - before) & modules))
"""


def test_the_demo_installs_and_runs_without_the_extras(tmp_path):
    """``make demo`` installs the project without extras (``pip install -e .``: the core,
    envs and baselines) and runs the demo's command; that command, with one run, runs to
    its results in an interpreter where every module of the extras is unimportable: the
    distributions the extras require, transitively (torch, Ray, SB3, pytest, the other
    dev tools...), less those the base dependencies require."""
    from packaging.utils import canonicalize_name

    rules = _make_rules()
    prerequisites, recipe = rules["demo"]
    assert prerequisites == ["$(DEMO_STAMP)"]  # not the full install's stamp
    installs = [shlex.split(line) for line in rules["$(DEMO_STAMP)"][1] if "pip install" in line]
    targets = [[t for t in cmd[cmd.index("install") + 1 :] if not t.startswith("-")]
               for cmd in installs]  # fmt: skip
    assert targets == [["pip"], ["."]], installs  # pip itself, then the project: no extra
    assert not any("[" in t for cmd in installs for t in cmd)
    (command,) = (shlex.split(line) for line in recipe)
    assert command[0] == "$(VENV)/bin/activetrack" and command[1] == "simulate"
    argv = [{"$(DEMO_RUNS)": "1"}.get(t, t) for t in command[1:]]
    argv[argv.index("--out") + 1] = str(tmp_path / "demo")
    assert "1" in argv and "--planner" in argv

    base = _required(PROJECT["dependencies"])
    extras = [r for reqs in PROJECT["optional-dependencies"].values() for r in reqs]
    left_out = _required(extras, missing_ok=True) - base
    blocked = sorted(
        module
        for module, dists in importlib.metadata.packages_distributions().items()
        if all(canonicalize_name(d) in left_out for d in dists)
    )
    installed = {"torch", "ray", "stable_baselines3", "pytest", "hypothesis", "sympy"}
    installed &= set(importlib.metadata.packages_distributions())
    assert installed <= set(blocked) and "numpy" not in blocked
    out = subprocess.run(
        [sys.executable, "-c", WITHOUT_RUN, *map(json.dumps, (sorted(left_out), blocked, argv))],
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    assert "exit 0 loaded []" in out.stdout, (out.stdout[-2000:], out.stderr[-2000:])
    results = json.loads((tmp_path / "demo" / "results.json").read_text())
    assert sorted(results) == sorted(argv[i + 1] for i, t in enumerate(argv) if t == "--planner")
    assert all(r["seed_range"] == {"first": 0, "last": 0} for r in results.values())


SMOKE = """
import importlib.metadata, sys, sysconfig
import activetrack

assert "gymnasium" not in sys.modules and "pettingzoo" not in sys.modules
assert activetrack.__file__.startswith(sysconfig.get_paths()["purelib"]), activetrack.__file__
assert activetrack.__version__ == importlib.metadata.version("activetrack") == {version!r}

import activetrack.baselines
import activetrack.envs
import gymnasium as gym

env = activetrack.envs.parallel_env(scenario="homogeneous", n_sensors=2, n_steps=3)
obs, infos = env.reset(seed=0)
for k in range(3):
    assert env.agents == ["sensor_0", "sensor_1"], (k, env.agents)
    actions = {{a: env.action_space(a).sample() for a in env.agents}}
    obs, rewards, terminations, truncations, infos = env.step(actions)
assert all(truncations.values()) and not env.agents  # the episode ends after n_steps
single = gym.make("activetrack.envs:activetrack/ActiveTracking-v0", n_steps=2)

# The wheel registers the train layer's policy.zip loader (entry points), which needs the
# [rl] extra this venv does not have: evaluate says so.
import pathlib, tempfile
from activetrack.baselines.evaluation import policy_loaders, resolve_policy

assert policy_loaders()["zip"].value == "activetrack.train.policy_io:load_policy"
with tempfile.TemporaryDirectory() as folder:
    path = pathlib.Path(folder, "policy.zip")
    path.write_bytes(b"")
    try:
        resolve_policy(str(path))
    except ImportError as exc:
        assert "activetrack[rl]" in str(exc), exc
    else:
        raise AssertionError("the policy.zip loader imported without torch")
print("ok", single.reset(seed=0)[0].shape)
"""

# One wrong use per sub-package: a checker that reads the hints reports each line.
USER_CODE = """
import numpy as np

from activetrack import make_scenario
from activetrack.baselines import mean_ci
from activetrack.envs import ENV_ID
from activetrack.train import seed_everything

a: int = make_scenario("paper")
b: int = ENV_ID
c: str = mean_ci(np.ones(3))
d: str = seed_everything(0)
"""


@pytest.mark.slow
def test_built_wheel_installs_and_runs_in_a_fresh_venv(tmp_path):
    src = _copy_source(tmp_path / "src")
    dist = tmp_path / "dist"
    # sdist first, then the wheel built from the sdist: both must carry everything.
    _run([sys.executable, "-m", "build", "--outdir", str(dist), str(src)], cwd=tmp_path)
    (wheel,) = dist.glob("activetrack-*.whl")
    (sdist,) = dist.glob("activetrack-*.tar.gz")
    version = PROJECT["version"]

    names = set(zipfile.ZipFile(wheel).namelist())
    info = f"activetrack-{version}.dist-info"
    assert "activetrack/py.typed" in names
    # The mapped sub-packages land under activetrack/, so the one marker covers them.
    assert {f"activetrack/{p}/__init__.py" for p in SUBPACKAGES} <= names
    assert f"{info}/licenses/LICENSE" in names
    metadata = zipfile.ZipFile(wheel).read(f"{info}/METADATA").decode()
    assert f"\nVersion: {version}\n" in metadata and "\nLicense-Expression: MIT\n" in metadata
    sdist_names = set(subprocess.run(
        ["tar", "-tzf", str(sdist)], capture_output=True, text=True, check=True
    ).stdout.split())  # fmt: skip
    top = f"activetrack-{version}"
    assert {f"{top}/LICENSE", f"{top}/src/activetrack/py.typed"} <= sdist_names

    # A fresh venv (not an editable install) with the wheel installed by pip; its
    # dependencies are this environment's copies of exactly the distributions the wheel
    # requires (Requires-Dist without extras, transitively), not downloaded again: a
    # folder of links to them on the venv's path. So a dependency missing from the wheel's
    # metadata is missing there too (the smoke test's imports fail), and `pip check` fails
    # on a requirement the versions tested here do not satisfy.
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=tmp_path)
    py = venv / "bin" / "python"
    purelib = _run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                   cwd=tmp_path).strip()  # fmt: skip
    deps = _link_dependencies(metadata, tmp_path / "deps")
    assert {"numpy", "scipy", "gymnasium", "pettingzoo", "numba"} <= deps
    assert not {"activetrack", "torch", "pytest", "ray"} & deps  # no extras, not itself
    (Path(purelib) / "activetrack_test_deps.pth").write_text(f"{tmp_path / 'deps'}\n")
    pip = [sys.executable, "-m", "pip", "--python", str(py)]
    _run([*pip, "install", "--quiet", "--no-deps", "--no-index", str(wheel)], cwd=tmp_path)
    _run([*pip, "check"], cwd=tmp_path)
    work = tmp_path / "elsewhere"  # run away from the source tree
    work.mkdir()
    out = _run([str(py), "-c", SMOKE.format(version=version)], cwd=work)
    assert out.split() == ["ok", "(69,)"]  # paper preset: M = 3 sensors, M (5 + 6M) = 69
    assert _run([str(venv / "bin" / "activetrack"), "--version"], cwd=work).split() == [
        "activetrack",
        version,
    ]
    assert "usage: activetrack" in _run([str(venv / "bin" / "activetrack"), "--help"], cwd=work)

    # PEP 561: mypy (from this environment) type-checks user code against the installed
    # wheel; without the marker it would treat activetrack as untyped and report nothing.
    user = work / "user.py"
    user.write_text(USER_CODE.lstrip("\n"))
    args = [sys.executable, "-m", "mypy", "--python-executable", str(py), "--config-file", "",
            "--no-incremental", "--follow-imports", "silent", "--ignore-missing-imports",
            "--no-error-summary", str(user)]  # fmt: skip
    out = subprocess.run(args, cwd=work, capture_output=True, text=True, timeout=900)
    errors = [line for line in out.stdout.splitlines() if ": error:" in line]
    lines = USER_CODE.lstrip("\n").splitlines()
    expected = [i + 1 for i, line in enumerate(lines) if line[:2] in ("a:", "b:", "c:", "d:")]
    assert [int(e.split(":")[1]) for e in errors] == expected, out.stdout + out.stderr
    assert all("Incompatible types in assignment" in e for e in errors), out.stdout
