"""The compiled kernels' plumbing: lazy compilation, kernels calling kernels, the disk cache."""

from __future__ import annotations

import json
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


_PROBE = """
import json, sys
import numpy as np
import activetrack
assert "numba" not in sys.modules  # importing the library compiles nothing
from activetrack.companion import monic_roots, _roots_rows
monic_roots(np.ones((2, 10)))
stats = _roots_rows.dispatcher.stats
print(json.dumps({"hits": sum(stats.cache_hits.values()),
                  "misses": sum(stats.cache_misses.values())}))
"""


def test_a_second_process_loads_the_kernels_from_the_cache(tmp_path) -> None:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("NUMBA_DISABLE_JIT", None)

    def run() -> dict[str, int]:
        out = subprocess.run(
            [sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, check=True
        )
        return json.loads(out.stdout.strip().splitlines()[-1])

    first, second = run(), run()
    assert first == {"hits": 0, "misses": 1}  # compiled and written to the new cache
    assert second == {"hits": 1, "misses": 0}  # loaded, not compiled
    assert any(p.suffix == ".nbi" for p in (tmp_path / "cache").rglob("*"))
