"""Test-suite configuration: hypothesis runs derandomized by default, so every run (CI
included) draws the same examples; ``HYPOTHESIS_PROFILE=explore`` draws new ones."""

import os
import platform


def _pin_blas_kernels() -> None:
    """Run OpenBLAS's Haswell kernels on any x86-64 CPU that has them (AVX2 and FMA).

    OpenBLAS picks its kernels by CPU (Haswell, SkylakeX, Zen...), and they round
    differently in the last bits; the process noise's square root comes from ``eigh`` of a
    ``Q`` whose eigenvalues come in equal pairs, so a last-bit change rotates it and changes
    a seeded trajectory by O(1). The recordings (``tests/test_regression.py``,
    ``tests/test_world_hashes.py``) were made with the Haswell kernels; pinning them makes
    the suite's seeded figures the same on every such CPU. Must run before NumPy loads
    OpenBLAS; a value already set (by the machine, for a CPU it must guard) is kept.
    """
    if platform.machine() not in ("x86_64", "AMD64"):
        return
    try:
        with open("/proc/cpuinfo") as f:
            flags = next((line.split() for line in f if line.startswith("flags")), [])
    except OSError:
        return
    if {"avx2", "fma"} <= set(flags):
        os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")


_pin_blas_kernels()

from hypothesis import settings  # noqa: E402 (after the BLAS kernels are pinned)

settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
