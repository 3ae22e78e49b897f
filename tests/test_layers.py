"""The layers depend one way, core <- envs <- baselines <- train, and load only what they need.

Each layer is imported in a fresh interpreter (so nothing an earlier test imported hides
a dependency) and the modules it pulled into ``sys.modules`` are compared with the set
the layering allows. And every import statement of every module's source, lazy ones
(inside functions) included, is read with ``ast``: none names a layer above its module's,
except in the command line's modules (:data:`CLI`).
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

LAYERS = ["activetrack", "activetrack.envs", "activetrack.baselines", "activetrack.train"]
HEAVY = ["gymnasium", "pettingzoo", "torch", "matplotlib", "scipy.stats", "stable_baselines3",
         "numba"]  # fmt: skip

# What importing each layer must not load: the layers above it, and the frameworks it
# does not use at import time (torch only from activetrack.train on; numba in no layer:
# it loads with the first kernel call, activetrack._jit).
FORBIDDEN = {
    "activetrack": {*LAYERS[1:], *HEAVY},
    "activetrack.envs": {"activetrack.baselines", "activetrack.train", "torch",
                         "stable_baselines3", "matplotlib", "scipy.stats", "numba"},
    "activetrack.baselines": {"activetrack.train", "torch", "stable_baselines3", "matplotlib",
                              "numba"},
    "activetrack.train": {"numba"},
}  # fmt: skip


def loaded_after_import(module: str, tmp_path) -> set[str]:
    """Return which of LAYERS and HEAVY are in ``sys.modules`` after importing ``module``."""
    code = (
        "import importlib, json, sys\n"
        f"importlib.import_module({module!r})\n"
        f"print(json.dumps([m for m in {LAYERS + HEAVY!r} if m in sys.modules]))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path
    )
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


@pytest.mark.parametrize("module", LAYERS)
def test_a_layer_loads_no_layer_above_it_nor_unused_frameworks(module, tmp_path):
    loaded = loaded_after_import(module, tmp_path)
    assert "activetrack" in loaded and module in loaded  # the probe itself works
    assert loaded & FORBIDDEN[module] == set(), f"import {module} pulled in {sorted(loaded)}"


def test_envs_import_registers_with_gymnasium_and_pettingzoo(tmp_path):
    # The envs layer is the one that loads the frameworks (registration), not the core.
    assert {"gymnasium", "pettingzoo"} <= loaded_after_import("activetrack.envs", tmp_path)


def test_baselines_import_leaves_scipy_stats_unloaded(tmp_path):
    assert "scipy.stats" not in loaded_after_import("activetrack.baselines", tmp_path)


# Every import statement of every module, lazy ones (inside functions) included ----------

REPO = Path(__file__).resolve().parents[1]
#: Layer folders and their package names, lowest first.
FOLDERS = [
    (REPO / "src" / "activetrack", "activetrack"),
    (REPO / "envs", "activetrack.envs"),
    (REPO / "baselines", "activetrack.baselines"),
    (REPO / "train", "activetrack.train"),
]
#: The command line reaches up (lazily, to run a layer's command): only these modules.
CLI = {"activetrack.cli", "activetrack.kernel_cache", "activetrack.baselines.cli",
       "activetrack.train.cli"}  # fmt: skip


def layer_of(module: str) -> int:
    """Return the index in FOLDERS of the layer that holds ``module`` (-1: not ours)."""
    if module != "activetrack" and not module.startswith("activetrack."):
        return -1
    for i in range(len(FOLDERS) - 1, 0, -1):
        name = FOLDERS[i][1]
        if module == name or module.startswith(name + "."):
            return i
    return 0


def modules() -> list[tuple[str, Path]]:
    """Return (module name, file) of every module of the distribution."""
    out = []
    for folder, package in FOLDERS:
        for path in sorted(folder.rglob("*.py")):
            rel = path.relative_to(folder).with_suffix("").parts
            parts = rel[:-1] if rel[-1] == "__init__" else rel
            out.append((".".join((package, *parts)), path))
    return out


def _statements(tree: ast.Module, lazy: bool):
    """Yield every node of ``tree``, or without ``lazy`` only those that run on import
    (function and lambda bodies left out)."""
    if lazy:
        yield from ast.walk(tree)
        return
    todo: list[ast.AST] = list(tree.body)
    while todo:
        node = todo.pop()
        yield node
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            todo.extend(ast.iter_child_nodes(node))


def imported(module: str, path: Path, lazy: bool = True) -> set[str]:
    """Return every module name ``path`` imports anywhere (``from a import b`` gives a.b too,
    ``importlib.import_module("...")`` with a constant name included), or without ``lazy``
    only where it runs on import (not inside functions)."""
    tree = ast.parse(path.read_text(), str(path))
    is_package = path.name == "__init__.py"
    names: set[str] = set()
    for node in _statements(tree, lazy):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = module.split(".")
                parent = parts if is_package else parts[:-1]
                parent = parent[: len(parent) - (node.level - 1)]
                base = ".".join([*parent, base] if base else parent)
            names.add(base)
            names.update(f"{base}.{a.name}" for a in node.names)
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            names.add(node.args[0].value)
    return names


# The CLI modules run every layer's commands: checked apart (upward imports inside
# functions only), not here.
_NOT_CLI = [(m, p) for m, p in modules() if m not in CLI]


@pytest.mark.parametrize("module,path", _NOT_CLI, ids=[m for m, _ in _NOT_CLI])
def test_no_module_imports_a_layer_above_it(module, path):
    own = layer_of(module)
    above = sorted(n for n in imported(module, path) if layer_of(n) > own)
    assert above == [], f"{module} (layer {FOLDERS[own][1]}) imports {above}"


@pytest.mark.parametrize("module", sorted(CLI))
def test_the_command_line_reaches_up_only_inside_functions(module):
    # Lazily: importing a command module (``activetrack --help``) loads no layer above it.
    own = layer_of(module)
    found = imported(module, dict(modules())[module], lazy=False)
    above = sorted(n for n in found if layer_of(n) > own)
    assert above == [], f"{module} imports {above} when it is imported"


def test_the_import_scan_sees_lazy_imports(tmp_path):
    # The scan itself, on a module written for it: a function-level import, a relative one
    # and an import_module call with a constant name are all found.
    probe = tmp_path / "probe.py"
    probe.write_text(
        "import importlib\n"
        "def f():\n"
        "    from activetrack.train import policy_io\n"
        "    from .. import envs\n"
        "    return importlib.import_module('activetrack.baselines.gsr')\n"
    )
    found = imported("activetrack.world.probe", probe)
    assert {"activetrack.train.policy_io", "activetrack.envs", "activetrack.baselines.gsr"} <= found
    # Without the lazy ones only the module-level import remains.
    assert imported("activetrack.world.probe", probe, lazy=False) == {"importlib"}
    # and on a real lazy import: the kernels command runs GSR, inside a function.
    cache = dict(modules())["activetrack.kernel_cache"]
    assert "activetrack.baselines.GSR" in imported("activetrack.kernel_cache", cache)
    assert layer_of("activetrack.envs.batched") == 1 and layer_of("activetrack.world") == 0
    assert layer_of("numpy") == -1 and layer_of("activetrack.train") == 3


def test_the_scan_covers_every_layer_and_the_cli_modules_exist():
    # An exception for a module that does not exist, or a layer folder found empty, would
    # make the scan pass vacuously.
    names = dict(modules())
    assert CLI <= names.keys()
    for _, package in FOLDERS:
        assert sum(layer_of(n) == layer_of(package) for n in names) > 1, package


#: The core's modules stay small, one job each: about 600 lines at most (the slack of 20
#: lines keeps a docstring's growth from forcing a split; past it, split by job).
CORE_LINES_MAX = 620


@pytest.mark.parametrize(
    "module,path",
    [(m, p) for m, p in modules() if layer_of(m) == 0],
    ids=[m for m, _ in modules() if layer_of(m) == 0],
)
def test_no_module_of_the_core_is_above_about_600_lines(module, path):
    lines = len(path.read_text().splitlines())
    assert lines <= CORE_LINES_MAX, f"{module} has {lines} lines: split it by the jobs it does"
