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
LEFT_OUT = "activetrack._coefficients"


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
