"""The compiled kernels' plumbing: lazy compilation, kernels calling kernels, the disk cache."""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from activetrack._jit import Kernel, kernel


@kernel
def _square(x: float) -> float:
    return x * x


@kernel
def _sum_of_squares(v: np.ndarray) -> float:
    out = 0.0
    for x in v:
        out += _square(x)  # a kernel calling a kernel
    return out


@pytest.mark.kernels
def test_kernels_call_kernels_and_keep_the_python_function() -> None:
    assert isinstance(_sum_of_squares, Kernel)
    v = np.array([1.0, 2.0, 3.0])
    assert _sum_of_squares(v) == 14.0
    assert _sum_of_squares.py_func(v) == 14.0  # the source, as plain Python
    assert _sum_of_squares.__name__ == "_sum_of_squares"


#: The module whose kernels the ``kernels`` command must compile in the test below: every
#: other library kernel module's cached machine code is copied into the test's cache first.
#: One of ``compile_all``'s direct calls reaches it (``case1_critical_points``), and it
#: compiles in about a second where compiling every kernel takes a minute.
LEFT_OUT = "activetrack.solvers._coefficients"


def _prime_cache(cache: Path) -> set[str]:
    """Copy the library's cached kernels (the suite's, from numba's default cache) into
    ``cache``, laid out as numba lays out ``NUMBA_CACHE_DIR``, except :data:`LEFT_OUT`'s;
    return the stems of the modules copied.

    ``compile_all`` first, in this process: it loads (or, on a fresh clone, compiles once
    for the whole suite) every kernel the command reaches, so the copy is complete. Only
    a speed-up: a file numba does not accept (another layout, a stale stamp) is compiled
    again by the command, and the assertions below hold either way.
    """
    import numba

    from activetrack._jit import KERNELS
    from activetrack.kernel_cache import KERNEL_MODULES, compile_all

    if not numba.config.DISABLE_JIT:
        compile_all()
    copied = set()
    for k in KERNELS:
        if k.py_func.__module__ not in KERNEL_MODULES or k.py_func.__module__ == LEFT_OUT:
            continue
        source = Path(os.path.abspath(k.py_func.__code__.co_filename))
        # Where this process's numba caches it (as ``kernel_cache.cache_folders``).
        here = getattr(getattr(k.dispatcher, "_cache", None), "cache_path", None)
        if not here or source.stem in copied:
            continue
        folder = source.parent
        # numba's NUMBA_CACHE_DIR layout: <dir>/<source folder name>_<sha1 of its path>/.
        dest = cache / f"{folder.name}_{hashlib.sha1(str(folder).encode()).hexdigest()}"
        for path in Path(here).glob(f"{source.stem}.*.nb[ic]"):
            dest.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, dest / path.name)
            copied.add(source.stem)
    return copied


def _counts(report: str) -> tuple[int, int]:
    """Return (compiled, loaded) from the command's first line."""
    m = re.search(r"(\d+) compiled, (\d+) loaded from the cache", report)
    assert m, report
    return int(m[1]), int(m[2])


def test_the_kernels_command_compiles_caches_and_clears(tmp_path) -> None:
    """``activetrack kernels``: compiles into the cache, a second process loads, --clear.

    The cache starts with every library kernel module's machine code but one
    (:data:`LEFT_OUT`): the first run must compile that module's kernels into
    ``NUMBA_CACHE_DIR`` (and load the others from there), the second compile nothing,
    ``--clear`` delete every file. (Compiling all of them from an empty cache took a
    minute of the suite; the suite compiles them all in its own cache anyway.)

    (``import activetrack`` imports no numba: ``tests/test_layers.py``.)"""
    cache = tmp_path / "cache"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env.pop("NUMBA_DISABLE_JIT", None)
    copied = _prime_cache(cache)
    left_out = LEFT_OUT.rsplit(".", 1)[1]
    assert left_out not in copied

    def run(*args: str) -> str:
        cmd = [sys.executable, "-m", "activetrack.cli", "kernels", *args]
        return subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout

    def files(stem: str = "*") -> list[Path]:
        return sorted(cache.rglob(f"{stem}.*.nb[ic]"))

    first = run()
    compiled, _ = _counts(first)
    assert compiled > 0, first
    # What it compiled went to NUMBA_CACHE_DIR: the left-out module's index and code.
    assert {p.suffix for p in files(left_out)} == {".nbi", ".nbc"}
    assert f"cache: {cache}" in first
    second = run()
    compiled, loaded = _counts(second)
    assert compiled == 0 and loaded > 0, second
    every = files()
    cleared = run("--clear")
    removed = int(cleared.split()[1])
    assert removed == len(every) > 0 and not files()


def test_the_kernels_command_rejects_an_unknown_option(capsys) -> None:
    from activetrack.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["kernels", "--clean"])
    assert exc.value.code == 2
    assert "unrecognized arguments: --clean" in capsys.readouterr().err


#: A kernel outside the library calling a library kernel from another file (the case
#: numba's own per-file stamp misses): the x of the point within reach 1 of (cx, 0)
#: farthest from the origin, ``cx + 1`` for cx > 0.
_CALLER = """
from activetrack._jit import kernel
from activetrack.kinematics._kernels import fallback_point


@kernel
def farthest_x(cx):
    return fallback_point(cx, 0.0, 1.0)[0]
"""

#: Prints the caller's value at cx = 2 and its cache hits and misses. With an argument,
#: first writes that text into the callee's file, after the library was imported.
_RUN = """
import sys
from pathlib import Path

import activetrack.kinematics._kernels
import caller

assert activetrack.kinematics._kernels.__file__.startswith(sys.argv[1])
if len(sys.argv) > 2:
    Path(activetrack.kinematics._kernels.__file__).write_text(sys.argv[2])
x = caller.farthest_x(2.0)
stats = caller.farthest_x.dispatcher.stats
print(x, sum(stats.cache_hits.values()), sum(stats.cache_misses.values()))
"""

_CALLEE_LINE = "return cx + r * (cx / nc), cy + r * (cy / nc)"


def test_an_edit_of_a_callee_file_recompiles_its_callers(tmp_path) -> None:
    """The disk cache follows every kernel source, not only the kernel's own file.

    A copy of the library, a caller kernel in another file, a cache folder of their own;
    each run is a new process. The caller's cached machine code holds the callee's: after
    the callee's file changes, a run must compute with the new callee (numba alone loads
    the caller's old code: 3.0 in the third run). An edit of a library file no kernel reads
    keeps the cache; a file edited while a process runs (it compiled the old source) must
    not leave machine code that a later process loads as the new source's."""
    import activetrack

    package = tmp_path / "lib" / "activetrack"
    shutil.copytree(
        Path(activetrack.__file__).parent, package, ignore=shutil.ignore_patterns("__pycache__")
    )
    # The package's own __init__ imports the whole core; these runs need only the kernels.
    (package / "__init__.py").write_text('"""A copy of the library for one test."""\n')
    (tmp_path / "caller.py").write_text(_CALLER)
    callee = package / "kinematics" / "_kernels.py"
    original = callee.read_text()
    assert original.count(_CALLEE_LINE) == 1
    doubled = original.replace(_CALLEE_LINE, _CALLEE_LINE.replace("r *", "2.0 * r *"))
    env = {
        **os.environ,
        "NUMBA_CACHE_DIR": str(tmp_path / "cache"),
        "PYTHONPATH": os.pathsep.join([str(tmp_path / "lib"), str(tmp_path)]),
    }
    env.pop("NUMBA_DISABLE_JIT", None)

    def run(*edit: str) -> tuple[float, int, int]:
        cmd = [sys.executable, "-c", _RUN, str(package), *edit]
        out = subprocess.run(
            cmd, env=env, cwd=tmp_path, capture_output=True, text=True, check=True
        ).stdout.split()
        return float(out[0]), int(out[1]), int(out[2])

    assert run() == (3.0, 0, 1)  # compiled: 2 + 1
    with open(package / "world.py", "a") as f:  # no kernel reads it
        f.write("\n# an edit\n")
    assert run() == (3.0, 1, 0)  # loaded
    callee.write_text(doubled)
    assert run() == (4.0, 0, 1)  # the new callee: 2 + 2 * 1, compiled again
    # The original source back while a process runs on the doubled one it imported.
    assert run(original) == (4.0, 0, 1)
    assert run() == (3.0, 0, 1)  # not that process's code: compiled from the file


def test_every_library_kernel_module_keys_the_cache() -> None:
    """Every file of the library that defines kernels (found by reading the package
    folders ``pyproject.toml`` names) is among the sources whose digest stamps the cache,
    and a kernel defined in another library module is refused."""
    import tomllib

    from activetrack._jit import KERNEL_MODULES, kernel_source_files

    root = Path(__file__).resolve().parents[2]
    folders = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-dir"
    ]
    decorated = {
        path.resolve()
        for folder in folders.values()
        for path in (root / folder).rglob("*.py")
        if re.search(r"^@(inline_)?kernel\b", path.read_text(encoding="utf-8"), re.MULTILINE)
    }
    files = kernel_source_files()
    assert decorated == {Path(files[name]).resolve() for name in KERNEL_MODULES}
    assert len(decorated) == len(KERNEL_MODULES)

    def elsewhere(x: float) -> float:
        return x

    elsewhere.__module__ = "activetrack.elsewhere"
    with pytest.raises(RuntimeError, match="activetrack.elsewhere defines kernels"):
        kernel(elsewhere)


def test_a_compile_prints_the_notice_once_and_a_warm_cache_prints_nothing(tmp_path):
    from activetrack._jit import COMPILE_NOTICE

    (tmp_path / "twokernels.py").write_text(
        "from activetrack._jit import kernel\n\n"
        "@kernel\ndef inner(x):\n    return x + 1.0\n\n"
        "@kernel\ndef outer(x):\n    return inner(x) * 2.0\n"
    )
    cache = tmp_path / "cache"
    cache.mkdir()
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(tmp_path)}
    env.pop("NUMBA_DISABLE_JIT", None)
    code = "import twokernels as t; print(t.outer(1.0), t.inner(2.0), t.outer(3))"

    def run():
        out = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path,
                             capture_output=True, text=True, check=True)  # fmt: skip
        assert out.stdout.split() == ["4.0", "3.0", "8.0"]  # (x + 1) * 2, x + 1 by hand
        return out.stderr

    first = run()  # an empty cache: three compiles (two kernels, two signatures of outer)
    assert first.count(COMPILE_NOTICE) == 1, first
    assert any(cache.rglob("*.nbi"))  # the cache is now warm
    second = run()
    assert COMPILE_NOTICE not in second, second
