"""Targets that appear and leave: :class:`BirthProcess`, the scenario field ``births``.

Until now every target was there from the first step to the last. With a birth process a
scenario's ``n_targets`` K is the number of target *slots*, the most present at once; each
copy keeps, per slot, whether a target is ``present`` (:mod:`activetrack.world.track_management`
carries it and the team's tracks). Every step, after the present targets move:

1. **departure**: a present target whose true position has left the closed rectangle
   ``region`` is gone (its slot frees up);
2. **birth**: ``n ~ Poisson(rate)`` targets arrive (:meth:`BirthProcess.count`); they take
   the free slots (neither a present target nor a track the team still holds) in slot
   order, and arrivals beyond the free slots are lost (K caps how many are present). Each
   starts (:meth:`BirthProcess.entry_states`) at a point uniform by length on the region's
   edge, or with ``spawn_areas`` uniform by area in those rectangles, heading for a point
   uniform in the region's central half (the region shrunk by half about its centre) at
   a speed uniform in ``speed`` (so it enters; any further state components are 0).

Episodes start with no target present. The births draw from a generator of their own
(:meth:`numpy.random.Generator.spawn` from the copy's stream at reset), so the copy's other
draws are those of the same world without births.

The other fields are the team's side of it (:mod:`activetrack.world.track_management`):
``delete_after`` steps without a detection drop a track, ``velocity_var`` is a new
track's velocity variance, ``search_cells``, ``search_weight`` and ``search_var`` the
search for targets not yet detected (:mod:`activetrack.models.search_map`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from activetrack.validation import ComparedByValue, FloatArray, as_finite, check_float, check_int

#: Largest accepted expected number of arrivals per step.
RATE_MAX = 100.0
#: Largest accepted coordinate magnitude (m) of the region and the spawn areas.
COORD_MAX = 1e6


def _rectangle(name: str, value: Any) -> tuple[float, float, float, float]:
    """Return ``(xmin, ymin, xmax, ymax)`` checked (finite, at most COORD_MAX, min < max)."""
    try:
        arr = as_finite(name, value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be (xmin, ymin, xmax, ymax), finite: {exc}") from exc
    if arr.shape != (4,) or not (arr[0] < arr[2] and arr[1] < arr[3]):
        raise ValueError(f"{name} must be (xmin, ymin, xmax, ymax) with min < max, got {value!r}")
    if np.any(np.abs(arr) > COORD_MAX):
        raise ValueError(f"{name} must lie within +-{COORD_MAX:g} m, got {value!r}")
    return tuple(float(v) for v in arr)  # type: ignore[return-value]


class BirthProcess(ComparedByValue):
    """Poisson arrivals on a region's edge (or in spawn areas), departure on leaving it.

    Args:
        rate: expected arrivals per step, in [0, 100] (a Poisson process of
            ``rate / dt`` per second).
        region: ``(xmin, ymin, xmax, ymax)`` (m), the watched rectangle; a target that
            leaves it departs.
        speed: ``(lo, hi)``, the arrivals' speed uniform in it (m/s), 0 <= lo <= hi <= 1e3.
        spawn_areas: None (arrivals on the region's edge) or rectangles ``(xmin, ymin,
            xmax, ymax)`` inside the region, one chosen in proportion to its area.
        delete_after: a track not detected for this many steps is dropped, in [1, 1e6].
        velocity_var: a new track's velocity variance per axis (m^2/s^2) > 0; None: ``hi^2``.
        search_cells: cells per axis of the search map, in [1, 100].
        search_weight: the score's weight on the expected number of targets present and
            not yet detected, >= 0.
        search_var: the position variance (m^2) of the search point a slot without a track
            shows the planners, > 0.
    """

    name = "births"
    _FIELDS = ("rate", "region", "speed", "spawn_areas", "delete_after", "velocity_var",
               "search_cells", "search_weight", "search_var")  # fmt: skip

    def __init__(
        self,
        rate: float,
        region: Any,
        *,
        speed: Any = (1.0, 3.0),
        spawn_areas: Any = None,
        delete_after: int = 20,
        velocity_var: float | None = None,
        search_cells: int = 8,
        search_weight: float = 1.0,
        search_var: float = 4.0,
    ) -> None:
        self.rate = check_float("births.rate", rate, 0.0, RATE_MAX)
        self.region = _rectangle("births.region", region)
        sp = as_finite("births.speed", speed)
        if sp.shape != (2,) or not (0.0 <= sp[0] <= sp[1] <= 1e3):
            raise ValueError(
                f"births.speed must be (lo, hi) with 0 <= lo <= hi <= 1e3, got {speed!r}"
            )
        self.speed = (float(sp[0]), float(sp[1]))
        if spawn_areas is not None:
            if isinstance(spawn_areas, (str, bytes)) or not hasattr(spawn_areas, "__len__"):
                raise ValueError(
                    f"births.spawn_areas must be None or rectangles, got {spawn_areas!r}"
                )
            if len(spawn_areas) == 0:
                raise ValueError("births.spawn_areas must hold at least one rectangle (or be None)")
            areas = tuple(
                _rectangle(f"births.spawn_areas[{i}]", a) for i, a in enumerate(spawn_areas)
            )
            x0, y0, x1, y1 = self.region
            for i, (a, b, c, d) in enumerate(areas):
                if a < x0 or b < y0 or c > x1 or d > y1:
                    raise ValueError(f"births.spawn_areas[{i}] must lie inside births.region")
            spawn_areas = areas
        self.spawn_areas = spawn_areas
        self.delete_after = check_int("births.delete_after", delete_after, 1, 10**6)
        hi = self.speed[1]
        if velocity_var is None:
            velocity_var = max(hi * hi, 1e-6)
        self.velocity_var = check_float("births.velocity_var", velocity_var, 0.0, 1e12,
                                        low_open=True)  # fmt: skip
        self.search_cells = check_int("births.search_cells", search_cells, 1, 100)
        self.search_weight = check_float("births.search_weight", search_weight, 0.0, 1e12)
        self.search_var = check_float("births.search_var", search_var, 0.0, 1e12, low_open=True)

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={getattr(self, k)!r}" for k in self._FIELDS)
        return f"BirthProcess({args})"

    # The true targets ------------------------------------------------------------------
    def count(self, rng: np.random.Generator) -> int:
        """Return this step's number of arrivals, ``Poisson(rate)`` (one draw of ``rng``)."""
        return int(rng.poisson(self.rate))

    def entry_states(self, rng: np.random.Generator, n: int, dim: int) -> FloatArray:
        """Return ``n`` arrivals' states (n, dim): position (see the module docstring),
        velocity toward a point uniform in the region's central half at a speed uniform in
        ``speed``, further components 0."""
        x0, y0, x1, y1 = self.region
        out = np.zeros((n, dim))
        for j in range(n):
            if self.spawn_areas is None:  # uniform by length on the perimeter
                w, h = x1 - x0, y1 - y0
                s = rng.random() * 2.0 * (w + h)
                if s < w:
                    pos = (x0 + s, y0)
                elif s < w + h:
                    pos = (x1, y0 + s - w)
                elif s < 2.0 * w + h:
                    pos = (x1 - (s - w - h), y1)
                else:
                    pos = (x0, y1 - (s - 2.0 * w - h))
            else:
                areas = np.array(self.spawn_areas)
                size = (areas[:, 2] - areas[:, 0]) * (areas[:, 3] - areas[:, 1])
                a = areas[rng.choice(len(areas), p=size / size.sum())]
                u = rng.random(2)
                pos = (a[0] + u[0] * (a[2] - a[0]), a[1] + u[1] * (a[3] - a[1]))
            u = rng.random(3)
            # a point of the central half of the region (the region shrunk by half about its
            # centre): every arrival heads well inside, none skims along the edge
            aim = np.array(
                [x0 + (0.25 + 0.5 * u[0]) * (x1 - x0), y0 + (0.25 + 0.5 * u[1]) * (y1 - y0)]
            )
            way = aim - np.asarray(pos)
            norm = math.hypot(way[0], way[1])
            heading = way / norm if norm > 0.0 else np.zeros(2)
            lo, hi = self.speed
            out[j, :2] = pos
            if dim >= 4:
                out[j, 2:4] = (lo + u[2] * (hi - lo)) * heading
        return out

    def inside(self, positions: FloatArray) -> np.ndarray:
        """Return whether positions (..., 2) lie in the closed region (..., bool)."""
        x0, y0, x1, y1 = self.region
        x, y = positions[..., 0], positions[..., 1]
        return (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)


def converted(value: object, sc: Any) -> BirthProcess | None:
    """Return the scenario field ``births`` checked against the scenario ``sc`` (its other
    fields converted): None, or a :class:`BirthProcess` with limited sensing (``max_range``,
    ``p_detect`` < 1 or occluders: a target present is not known until detected), the
    EKF (``estimator='ekf'``), range-and-bearing sensors (a first detection's inverse
    places a new track) and a state with position and velocity first (n >= 4)."""
    if value is None:
        return None
    if not isinstance(value, BirthProcess):
        raise ValueError(f"births must be None or an activetrack.BirthProcess, got {value!r}")
    if not sc.limited_sensing:
        raise ValueError(
            "births needs limited sensing (max_range, p_detect < 1 or occluders): with every "
            "target always measured there is nothing to detect"
        )
    if sc.estimator != "ekf":
        raise ValueError(f"births needs estimator='ekf', got {sc.estimator!r}")
    models = sc.sensor_model if isinstance(sc.sensor_model, tuple) else (sc.sensor_model,)
    if any(m != "range_bearing" for m in models):
        raise ValueError(
            "births needs range_bearing sensors (a track starts at a detection's inverse), "
            f"got sensor_model={sc.sensor_model!r}"
        )
    if any(mdl.dim < 4 for mdl in sc.target_models):
        raise ValueError("births needs target states of position and velocity (n >= 4)")
    return value
