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
(``*.nbi``, ``*.nbc``) only costs a recompile; numba also recompiles by itself when a
module's source changes.

Kernels call kernels by name as usual: a :class:`Kernel` is typed by numba as the
dispatcher it wraps (registered with ``numba.extending.typeof_impl`` on first use), so a
compiled caller calls the compiled callee directly.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, Generic, TypeVar

import numpy as np

F = TypeVar("F", bound=Callable[..., Any])

_typed = False  # whether numba knows how to type a Kernel (done once, on first compile)
KERNELS: list[Kernel[Any]] = []  # every kernel defined so far (activetrack.kernel_cache)


class Kernel(Generic[F]):
    """A function compiled by numba on its first call (see the module docstring)."""

    def __init__(self, fn: F, inline: bool = False) -> None:
        self.py_func = fn
        self.inline = inline
        self._compiled: Callable[..., Any] | None = None
        functools.update_wrapper(self, fn)
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
        self._compiled = numba.njit(cache=True, nogil=True, error_model="numpy", **options)(
            self.py_func
        )
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
