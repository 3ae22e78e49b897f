"""Compiled kernels: numba's ``njit``, deferred until a kernel is first called.

``@kernel`` marks a function written in the subset of Python and NumPy that numba
compiles. The function itself is the implementation (there is no second NumPy copy):
with ``NUMBA_DISABLE_JIT=1`` it runs as plain Python, which the test suite uses to check
the kernels' source line by line. Importing a module with kernels imports nothing from
numba (``import activetrack`` stays fast); the first call compiles the kernel (and the
kernels it calls) for its argument types, one thread, and writes the machine code to
numba's on-disk cache, so the next process loads it instead of compiling.

The cache is numba's own: a ``__pycache__`` folder beside each module when that is
writable (an editable install, a clone), else numba's user-wide cache folder
(``~/.cache/numba`` on Linux, following the platform's user cache directory); the
environment variable ``NUMBA_CACHE_DIR`` moves it anywhere. Deleting the cached files
(``*.nbi``, ``*.nbc``) only costs a recompile.

Numba alone recompiles a function only when *its own* file changes, yet a caller's cached
machine code contains the kernels it calls from other files: after an edit of a callee's
file it would load the caller's old code. So every kernel's cache entry is also stamped
with :func:`sources_digest`, a hash of the source of every module that defines library
kernels (:data:`KERNEL_MODULES`), of the library modules they import (their constants are
compiled in) and of this file (the compile options): any edit of one of them makes every
cached kernel stale, and numba compiles them again (and overwrites the stale files). A
process whose kernel sources changed on disk after it imported them stamps its machine
code so that no other process loads it.

Kernels call kernels by name as usual: a :class:`Kernel` is typed by numba as the
dispatcher it wraps (registered with ``numba.extending.typeof_impl`` on first use), so a
compiled caller calls the compiled callee directly.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.machinery
import importlib.util
import os
import re
import time
from collections.abc import Callable
from typing import Any, Generic, TypeVar

import numpy as np

F = TypeVar("F", bound=Callable[..., Any])

_typed = False  # whether numba knows how to type a Kernel (done once, on first compile)
KERNELS: list[Kernel[Any]] = []  # every kernel defined so far (activetrack.kernel_cache)

#: The library's modules that define kernels (importing them defines them all). Their
#: sources key the cache (:func:`sources_digest`); a library kernel elsewhere is refused.
KERNEL_MODULES = (
    "activetrack.solvers.hessenberg_qr",
    "activetrack.solvers.companion",
    "activetrack.solvers._coefficients",
    "activetrack.solvers._steps",
    "activetrack.solvers._inputs",
    "activetrack.solvers._scalar",
    "activetrack.models.objective",
    "activetrack.estimation._kernels",
    "activetrack.kinematics._kernels",
    "activetrack.kinematics._unicycle_kernels",
    "activetrack.kinematics._path_kernels",
    "activetrack.models._motion_kernels",
    "activetrack.world._loop_kernels",
    "activetrack.models._occluder_kernels",
    "activetrack.world._observation_kernels",
    "activetrack.baselines.gsr_kernel",
    "activetrack.baselines.gsr_command_kernel",
)
_PACKAGE = "activetrack"
# When the kernel modules were imported (they all import this module first): a kernel
# source modified later is not the source this process compiles.
_IMPORTED_AT = time.time()


class Kernel(Generic[F]):
    """A function compiled by numba on its first call (see the module docstring)."""

    def __init__(self, fn: F, inline: bool = False) -> None:
        self.py_func = fn
        self.inline = inline
        self._compiled: Callable[..., Any] | None = None
        functools.update_wrapper(self, fn)
        module = getattr(fn, "__module__", "") or ""
        if module.startswith(_PACKAGE + ".") and module not in KERNEL_MODULES:
            # Its source would not key the cache: its callers could load stale code.
            raise RuntimeError(f"{module} defines kernels: add it to _jit.KERNEL_MODULES")
        KERNELS.append(self)

    @property
    def targetoptions(self) -> dict[str, Any]:
        """Return the options numba's inlining pass reads from a callee (``inline``)."""
        return {"inline": "always"} if self.inline else {}

    @functools.cached_property
    def dispatcher(self) -> Callable[..., Any]:
        """Return numba's dispatcher of the function (created on the first access; later
        accesses are a plain attribute lookup, which hot Python paths rely on)."""
        import numba

        _teach_numba()
        notice_compiling()
        # error_model="numpy": a float division by zero gives inf/NaN instead of raising
        # (no zero test before every division); kernels guard their divisors, so the
        # plain-Python run (NUMBA_DISABLE_JIT=1) takes the same branches.
        options = {"inline": "always"} if self.inline else {}
        options.update(nogil=True, error_model="numpy")
        compiled = numba.njit(cache=True, **options)(self.py_func)
        index = getattr(getattr(compiled, "_cache", None), "_cache_file", None)
        if hasattr(index, "_source_stamp"):
            # numba's stamp of the function's own file, and the digest of every kernel
            # source: an index written under another digest is stale (numba compiles).
            index._source_stamp = (index._source_stamp, sources_digest())
        elif not numba.config.DISABLE_JIT:
            # A numba whose cache this cannot stamp: no disk cache rather than stale code.
            compiled = numba.njit(cache=False, **options)(self.py_func)
        self._compiled = compiled
        return self._compiled

    def __call__(self, *args: Any) -> Any:
        compiled = self._compiled
        if compiled is None:
            compiled = self.dispatcher
        return compiled(*args)


def _teach_numba() -> None:
    """Register the numba type of a :class:`Kernel`: the type of its dispatcher."""
    global _typed
    if _typed:
        return
    from numba.extending import typeof_impl

    @typeof_impl.register(Kernel)
    def _typeof_kernel(val: Kernel[Any], c: Any) -> Any:
        return typeof_impl(val.dispatcher, c)

    _typed = True


@functools.cache
def sources_digest() -> str:
    """Return the SHA-256 (hex) of the kernels' sources: the files of
    :data:`KERNEL_MODULES`, of every library module they import (recursively; their
    constants are compiled into the kernels) and of this module, found without importing
    them. A random value instead if one of them changed after this module was imported:
    the process runs the old source, whose machine code no other process must load."""
    files = kernel_source_files()
    now = time.time()
    digest = hashlib.sha256()
    for name, path in sorted(files.items()):
        digest.update(name.encode() + b"\0")
        try:
            # (A time in the future is a skewed clock, not an edit: it would never reuse.)
            if _IMPORTED_AT < os.stat(path).st_mtime <= now:
                return os.urandom(32).hex()
            with open(path, "rb") as f:
                digest.update(hashlib.sha256(f.read()).digest())
        except OSError:  # not a file (a zip import, a frozen app): the name alone
            digest.update(b"?")
    return digest.hexdigest()


# A library module an import statement names: ``from activetrack.x import (a, b)``,
# ``from activetrack import x as y`` or ``import activetrack.x``.
_IMPORTS = re.compile(
    r"^(?:from\s+(activetrack(?:\.\w+)*)\s+import\s+(\([^)]*\)|[^\n]*)"
    r"|import\s+(activetrack(?:\.\w+)*))",
    re.MULTILINE,
)


def kernel_source_files() -> dict[str, str]:
    """Return ``{module name: source file}`` of the modules :func:`sources_digest` reads:
    :data:`KERNEL_MODULES`, this module, and the library modules they import, recursively
    (read as text: nothing is imported but the package itself). A module whose file is
    not found maps to ``""``."""
    files: dict[str, str] = {}
    todo = [*KERNEL_MODULES, __name__]
    while todo:
        name = todo.pop()
        if name in files:
            continue
        path = files[name] = _module_file(name)
        if not path.endswith(".py"):
            continue
        try:
            with open(path, encoding="utf-8") as f:
                text = f.read()
        except OSError:
            continue
        for m in _IMPORTS.finditer(text):
            if m[3]:
                todo.append(m[3])
                continue
            for item in re.sub(r"#[^\n]*", "", m[2]).strip("()\n\t ").split(","):
                sub = f"{m[1]}.{item.split()[0]}" if item.split() else ""
                # ``from package import module`` names the module, else ``m[1]``'s value
                todo.append(sub if sub and _module_file(sub) else m[1])
    return files


def _module_file(name: str) -> str:
    """Return the source file of module ``name`` of the library, or ``""``, importing at
    most its parent packages' ``__init__`` (``activetrack`` itself: already imported)."""
    parent = name.rpartition(".")[0]
    try:
        if not parent:
            spec = importlib.util.find_spec(name)
        else:
            outer = importlib.util.find_spec(parent)
            paths = outer.submodule_search_locations if outer is not None else None
            spec = importlib.machinery.PathFinder.find_spec(name, list(paths or ()))
    except (ImportError, ValueError):
        return ""
    origin = getattr(spec, "origin", None)
    return origin if isinstance(origin, str) and os.path.isfile(origin) else ""


#: The line printed (to stderr, once a process) when a kernel is compiled rather than
#: loaded from the cache: a fresh install's first step compiles for about a minute.
COMPILE_NOTICE = (
    "activetrack: compiling activetrack kernels, once, ~1 min (cached afterwards; "
    "'activetrack kernels' compiles them ahead of time)"
)
_noticed: list[bool] = []  # [True] once the notice is armed (one listener a process)


def notice_compiling() -> None:
    """Arm the compile notice: on numba's first cache miss in this process (its
    ``numba:compile`` event, which a kernel loaded from the cache does not raise) print
    :data:`COMPILE_NOTICE` once to stderr. Idempotent."""
    if _noticed:
        return
    _noticed.append(True)
    import sys

    from numba.core import event

    class _Notice(event.Listener):
        printed = False

        def on_start(self, ev: Any) -> None:
            if not self.printed:
                self.printed = True
                print(COMPILE_NOTICE, file=sys.stderr, flush=True)

        def on_end(self, ev: Any) -> None:
            pass

    event.register("numba:compile", _Notice())


def kernel(fn: F) -> F:
    """Return ``fn`` as a :class:`Kernel`: compiled with numba on its first call."""
    return Kernel(fn)  # type: ignore[return-value]


def inline_kernel(fn: F) -> F:
    """Return ``fn`` as a :class:`Kernel` that numba inlines into the kernels calling it
    (``inline="always"``): a row function called once per row of a loop, whose many array
    arguments would otherwise cost a call and reference counting per row."""
    return Kernel(fn, inline=True)  # type: ignore[return-value]


def as_rows(a: Any, shape: tuple[int, ...], tail: tuple[int, ...] = (), dtype: Any = None) -> Any:
    """Return ``a`` broadcast to ``shape + tail`` as C-contiguous, writable rows
    ``(prod(shape), *tail)``: what the kernels take (one numba signature per dtype), copied
    only when needed."""
    full = shape + tail
    if (  # the common case, already in shape: a view, no NumPy function calls
        type(a) is np.ndarray
        and a.shape == full
        and a.dtype == (np.float64 if dtype is None else dtype)
        and a.flags.c_contiguous
        and a.flags.writeable
    ):
        return a.reshape((-1, *tail))
    a = np.asarray(a, dtype=np.float64 if dtype is None else dtype)
    if a.shape != full:
        a = np.broadcast_to(a, full)
    a = a.reshape((-1, *tail))
    return a if a.flags.c_contiguous and a.flags.writeable else a.copy()


def per_sensor_rows(v: Any, batch: tuple[int, ...], m: int, dtype: Any = np.float64) -> Any:
    """Return a per-sensor value (a scalar, (M,) or ``batch + (M,)``) as kernel rows: (1, M)
    when the batch shares it, else (B, M)."""
    a = np.asarray(v, dtype)
    return as_rows(a, () if a.ndim <= 1 else batch, (m,), dtype)
