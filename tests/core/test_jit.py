"""The compiled kernels' plumbing: lazy compilation, kernels calling kernels, the disk cache."""

from __future__ import annotations

import os
import subprocess
import sys

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


def test_the_kernels_command_compiles_caches_and_clears(tmp_path) -> None:
    """``activetrack kernels``: compiles into the cache, a second process loads, --clear.

    (``import activetrack`` imports no numba: ``tests/test_layers.py``.)"""
    cache = tmp_path / "cache"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env.pop("NUMBA_DISABLE_JIT", None)

    def run(*args: str) -> str:
        cmd = [sys.executable, "-m", "activetrack.cli", "kernels", *args]
        return subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout

    first = run()
    assert "loaded from the cache" in first and " 0 compiled" not in first
    assert f"cache: {cache}" in first
    second = run()
    assert " 0 compiled" in second
    cleared = run("--clear")
    removed = int(cleared.split()[1])
    assert removed > 0 and not list(cache.rglob("*.nbi"))


def test_the_kernels_command_rejects_an_unknown_option(capsys) -> None:
    from activetrack.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["kernels", "--clean"])
    assert exc.value.code == 2
    assert "unrecognized arguments: --clean" in capsys.readouterr().err
