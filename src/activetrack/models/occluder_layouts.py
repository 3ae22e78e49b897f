"""Random occluder layouts: rectangles drawn inside bounds, keeping given points clear.

:func:`random_layout` draws one layout from a :class:`numpy.random.Generator` (also
importable from :mod:`activetrack.models.occluders`), :func:`layout_batch` a scenario's
episodes' layouts, fixed and random; the rectangles are drawn by the compiled
:func:`activetrack.models._occluder_kernels.rectangles_into`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from activetrack.models import _occluder_kernels as ok
from activetrack.validation import FloatArray

if TYPE_CHECKING:
    from activetrack.models.occluders import Occluders

__all__ = ["layout_batch", "random_layout"]


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


def layout_batch(sc: Any, rngs: Any) -> Occluders:
    """Return the batched occluders of a scenario's episodes, one layout drawn from each of
    ``rngs``: the fixed ``sc.occluders`` and ``sc.random_occluders`` rectangles (sides in
    ``sc.occluder_size``, inside ``sc.occluder_bounds``, clear of the sensors' start disk and
    the targets' ``x0_hat`` by ``sc.sensor_radius``; :func:`ok.rectangles_into`).

    Raises ``ValueError`` naming the fields when the rectangles cannot be placed, and
    ``TypeError`` for an rng that is not a ``numpy.random.Generator``.
    """
    from activetrack.models.occluders import Occluders  # noqa: PLC0415 (it imports this module)

    rngs = list(rngs)
    for j, rng in enumerate(rngs):
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rngs[{j}] must be a numpy.random.Generator, got {type(rng).__name__}")
    clear = np.array([sc.sensor_center, *(x[:2] for x in sc.target_states("x0_hat"))], np.float64)
    bounds = np.asarray(sc.occluder_bounds, np.float64)
    sizes = np.asarray(sc.occluder_size, np.float64)
    # Both sets are simple polygons already (the fixed ones checked with the scenario).
    fixed = [np.asarray(poly, np.float64) for poly in sc.occluders]
    counts = np.array([len(p) for p in fixed] + [4] * sc.random_occluders, np.intp)
    if not counts.size:  # an open plane
        return Occluders.stack([Occluders._of_simple([])] * len(rngs))
    vertices = np.empty((len(rngs), int(counts.sum()), 2))
    n_fixed = int(counts[: len(fixed)].sum())
    if fixed:
        vertices[:, :n_fixed] = np.concatenate(fixed)
    for j, rng in enumerate(rngs):
        drawn = vertices[j, n_fixed:].reshape(sc.random_occluders, 4, 2)  # a view
        if ok.rectangles_into(
            rng, bounds, sizes, clear, float(sc.sensor_radius), True, 1000, drawn
        ) >= 0:  # fmt: skip
            raise ValueError(
                f"random_occluders: {sc.random_occluders} rectangles of sides "
                f"{sc.occluder_size} do not fit in occluder_bounds {sc.occluder_bounds} "
                f"clear of the sensors' start disk and the targets' x0_hat by sensor_radius "
                f"{sc.sensor_radius:g}; widen occluder_bounds or lower random_occluders, "
                "occluder_size or sensor_radius"
            )
    return Occluders._stack_simple(vertices, counts)
