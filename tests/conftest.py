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

# Ray starts its workers at nice 15 (RAY_worker_niceness), so beside the other test
# process on a 2-core machine they got a sliver of a core: a Ray test that does 5 s of
# work waited minutes for its workers to import torch. The tests measure Ray's results,
# not its scheduling priority; every Ray the suite starts inherits this.
os.environ.setdefault("RAY_worker_niceness", "0")

from hypothesis import settings  # noqa: E402 (after the BLAS kernels are pinned)

settings.register_profile("ci", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402


@pytest.fixture(scope="session")
def docs_site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Build the manual once per run, as ``make docs`` does (``-W --keep-going``), from a
    copy of ``docs/`` in a temporary folder (the generated pages are written there, not
    into the checkout); return the HTML folder. Skips without the ``[docs]`` extra.

    Under pytest-xdist the workers share one build (the folder common to their temporary
    folders, under a file lock: the first builds, the others wait for it), as xdist's
    documentation shows for a session fixture; the tests only read the site."""
    for module in ("sphinx", "myst_parser", "furo"):
        pytest.importorskip(module, reason="the [docs] extra is not installed")
    if "PYTEST_XDIST_WORKER" not in os.environ:  # one process: nothing to share
        return _build_docs(tmp_path_factory.mktemp("docs"))
    from filelock import FileLock

    shared = tmp_path_factory.getbasetemp().parent / "docs_site"
    with FileLock(str(shared) + ".lock"):
        if not (shared / "built").is_file():
            shutil.rmtree(shared, ignore_errors=True)  # a build that failed part-way
            shared.mkdir()
            _build_docs(shared)
            (shared / "built").touch()
    return shared / "html"


def _build_docs(tmp: Path) -> Path:
    """Return the HTML folder of the manual built in ``tmp`` (asserts sphinx succeeded)."""
    root = Path(__file__).resolve().parents[1]
    src = Path(
        shutil.copytree(
            root / "docs",
            tmp / "src",
            ignore=shutil.ignore_patterns("_build", "environments", "api.rst"),
        )
    )
    out = tmp / "html"
    run = subprocess.run(
        [sys.executable, "-m", "sphinx", "-b", "html", "-W", "--keep-going", "-q", src, out],
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert run.returncode == 0, f"sphinx failed:\n{run.stdout[-4000:]}\n{run.stderr[-4000:]}"
    return out
