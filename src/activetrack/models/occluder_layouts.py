"""Random occluder layouts: rectangles drawn inside bounds, keeping given points clear.

:func:`random_layout` draws one layout from a :class:`numpy.random.Generator` (the
rectangles are drawn by the compiled
:func:`activetrack.models._occluder_kernels.rectangles_into`); it is also importable from
:mod:`activetrack.models.occluders`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from activetrack.models import _occluder_kernels as ok
from activetrack.validation import FloatArray

if TYPE_CHECKING:
    from activetrack.models.occluders import Occluders

__all__ = ["random_layout"]


#: The smallest side of a random rectangle, relative to the bounds' scale.
_MIN_SIDE = 1e-6


def random_layout(
    rng: np.random.Generator,
    n: int,
    bounds: Sequence[float],
    size_range: Sequence[float],
    *,
    clear: FloatArray | None = None,
    clearance: float = 0.0,
    rotate: bool = True,
    max_tries: int = 1000,
) -> Occluders:
    """Return ``n`` random rectangles inside ``bounds`` keeping the ``clear`` points clear.

    ``bounds`` = ``(xmin, ymin, xmax, ymax)``; each rectangle's side lengths are uniform in
    ``size_range = (lo, hi)``, its orientation uniform (or axis-aligned with
    ``rotate=False``), its centre uniform among the positions keeping it inside ``bounds``.
    Rectangles may overlap. With ``clear`` (k, 2), a rectangle is redrawn while any clear
    point is inside it or closer than ``clearance`` to it; after ``max_tries`` draws of one
    rectangle a ``ValueError`` is raised. Deterministic given ``rng``'s state.
    """
    if not isinstance(n, (int, np.integer)) or isinstance(n, bool) or n < 0:
        raise ValueError(f"n must be an integer >= 0, got {n!r}")
    bx = np.asarray(bounds, np.float64)
    if bx.shape != (4,) or not np.all(np.isfinite(bx)) or bx[2] <= bx[0] or bx[3] <= bx[1]:
        raise ValueError(
            f"bounds must be finite (xmin, ymin, xmax, ymax) with min < max, got {bounds!r}"
        )
    sz = np.asarray(size_range, np.float64)
    if sz.shape != (2,) or not np.all(np.isfinite(sz)) or not 0 < sz[0] <= sz[1]:
        raise ValueError(f"size_range must be (lo, hi) with 0 < lo <= hi, got {size_range!r}")
    least = _MIN_SIDE * max(1.0, float(np.max(np.abs(bx))))
    if sz[0] < least:  # else a rectangle could be degenerate at the occluders' tolerance
        raise ValueError(
            f"size_range must be (lo, hi) with lo >= {least:g} ({_MIN_SIDE:g} times the "
            f"bounds' scale), got {size_range!r}"
        )
    if not np.isfinite(clearance) or clearance < 0:
        raise ValueError(f"clearance must be finite and >= 0, got {clearance!r}")
    pts = np.empty((0, 2)) if clear is None else np.asarray(clear, np.float64).reshape(-1, 2)
    if not np.all(np.isfinite(pts)):
        raise ValueError("clear must be finite (no NaN or inf)")
    from activetrack.models.occluders import Occluders  # noqa: PLC0415 (it imports this module)

    return Occluders._of_simple(_rectangles(rng, n, bx, sz, pts, clearance, rotate, max_tries))


def _rectangles(
    rng: np.random.Generator, n: int, bx: FloatArray, sz: FloatArray, pts: FloatArray,
    clearance: float, rotate: bool, max_tries: int,
) -> list[np.ndarray]:  # fmt: skip
    """Return :func:`random_layout`'s rectangles (its arguments checked), (4, 2) each
    (:func:`activetrack.models._occluder_kernels.rectangles_into`)."""
    out = np.empty((n, 4, 2))
    clear = np.ascontiguousarray(pts, np.float64).reshape(-1, 2)
    failed = ok.rectangles_into(
        rng, np.ascontiguousarray(bx, np.float64), np.ascontiguousarray(sz, np.float64), clear,
        float(clearance), bool(rotate), int(max_tries), out,
    )  # fmt: skip
    if failed >= 0:
        raise ValueError(
            f"could not place rectangle {failed} in {max_tries} tries (max_tries, bounds, "
            "size_range or clearance too tight)"
        )
    return list(out)  # rectangles of sides >= size_range[0]: simple
