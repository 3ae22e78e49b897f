"""Rendering of a tracking episode in the style of the paper's Fig. 4 (no physics here).

The environment records one :class:`Snapshot` per time step in an :class:`EpisodeHistory`
(only when a render mode is set; :meth:`EpisodeHistory.record` reads a world's copy 0);
:class:`TrackingRenderer` draws the history. A frame shows

* every target in its own colour (target 0 as in Fig. 4: true track black, estimate red;
  further targets in :data:`TARGET_COLORS`): its true track (solid, a star at the current
  position), its estimated track (dashed, a cross at the current estimate), the 3-sigma
  ellipses of the position covariance ``P(k|k)_11`` along the track (as in Fig. 4) and
  around the current estimate;
* every sensor in its own colour (matplotlib's ``C0, C1, ...``): its trail of true
  positions and its current position marked by its measurement model
  (:data:`MODEL_MARKERS`: circle range and bearing, square range only, triangle bearing
  only; a legend entry per model present once a team is not all range and bearing,
  so the paper's frames are unchanged);
* each sensor's ``rho`` circle (eq. 14) around every predicted target position
  ``p_T(k|k-1)`` its last move was constrained by;
* with uncertain sensor poses, each sensor's position fix (the position the team
  believes and plans from: a small cross) and the 2-sigma ellipse of its pose
  covariance around the fix;
* with a kinematics that carries a heading or a velocity (:class:`activetrack.Unicycle`,
  :class:`activetrack.DoubleIntegrator`), a thick line in the sensor's colour from its
  position along its heading, :data:`HEADING_LENGTH` ``rho_i`` long (a velocity: that
  length times the speed over the top speed);
* with such a kinematics, the path each sensor drove over the last step (a thick, faint
  line in its colour, :data:`PATH_POINTS` segments): a unicycle's arc, a double
  integrator's parabola, evaluated by the kinematics itself
  (:func:`step_path`: the :meth:`~activetrack.Kinematics.command` that reaches the new
  position from the old state, applied over fractions of the step); the trail joins the
  positions by straight segments;
* with a minimum separation (``d_sep > 0``), each sensor's separation disk: a thin dashed
  circle in its colour of radius ``d_sep / 2`` (one distance for every pair) or its own
  radius ``d_i`` (per-sensor radii, a pair keeping ``d_i + d_j``), so two sensors keep
  the rule exactly when their disks do not overlap (:func:`separation_radii`);
* the step and the posterior trace ``tr P(k|k)_11`` (summed over the targets) above.

With limited sensing (issue 13: occluders, a finite ``max_range`` or ``p_detect < 1``;
none of this is drawn for the paper's open plane, so its frames are unchanged) a frame
also shows

* the occluders as filled grey polygons (:data:`OCCLUDER_FACE`, edged
  :data:`OCCLUDER_EDGE`), drawn first: over the faint grid, under every track, marker,
  line and the legend; they are part of the cached background, redrawn only when the
  layout changes (a new episode's random layout);
* each sensor's sensing range as a thin, sparsely dotted circle of radius
  ``max_range_i`` around the sensor in its colour (only for a finite range);
* the lines of sight of the step: a thin solid line in the sensor's colour from each
  sensor to the true position of each target it measured, and a faint dashed grey line
  (:data:`MISSED_COLOR`) to each target it did not measure (out of range, behind an
  occluder, or a missed detection): a dashed line rather than none, so a frame shows
  which sensor missed which target and why (the line crosses an occluder, leaves the
  range circle, or neither: a missed detection), not only that fewer lines are drawn;
* ``missed n/KM`` in the title line: how many of the K M sensor-target pairs gave no
  measurement at the step.

The frame after a reset (step 0, before any measurement) has no lines of sight and no
count. The view follows the targets and sensors as before; occluders and range circles
are clipped to it.

``rgb_array`` draws on a matplotlib Agg canvas (no window, works headless). ``human``
draws on a pyplot window; without an interactive backend (no display) it warns once and
draws nothing. matplotlib is imported only when something is rendered.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from activetrack.models.sensor import BUILT_IN, SensorModel
from activetrack.validation import FloatArray

#: The sensing layout of the paper's open plane: no occluders, ranges or detections drawn.
_OPEN = (False, False, False)
#: Points per drawn circle or ellipse.
_N_CIRCLE = 65
_UNIT = np.stack(
    [np.cos(np.linspace(0, 2 * np.pi, _N_CIRCLE)), np.sin(np.linspace(0, 2 * np.pi, _N_CIRCLE))]
)
#: At most this many 3-sigma ellipses per target are drawn along the track (evenly spaced).
MAX_ELLIPSES = 25
#: Per target: (true track, estimate, 3-sigma ellipses) colours; cycled for K > 5.
TARGET_COLORS: tuple[tuple[str, str, str], ...] = (
    ("k", "r", "tab:red"),  # Fig. 4's colours
    ("#5c005c", "m", "m"),
    ("#004040", "#008b8b", "#008b8b"),
    ("#4d3800", "#b8860b", "#b8860b"),
    ("#262626", "#7f7f7f", "#7f7f7f"),
)
#: Marker and legend label of each built-in sensor model code (0 range and bearing, 1 range
#: only, 2 bearing only): each model's own :attr:`activetrack.SensorModel.marker` and
#: ``label`` (a model of one's own brings its own).
MODEL_MARKERS: tuple[tuple[str, str], ...] = tuple((m.marker, m.label) for m in BUILT_IN.values())


def _mark_order(mark: tuple[str, str]) -> tuple[int, str]:
    """Return the legend order of a (marker, label): the built-ins' codes first."""
    return (MODEL_MARKERS.index(mark) if mark in MODEL_MARKERS else len(MODEL_MARKERS), mark[1])


#: The pose ellipses are drawn at this many standard deviations.
POSE_SIGMAS = 2.0
#: Fill and edge colours of the occluders.
OCCLUDER_FACE = "#d0d0d0"
OCCLUDER_EDGE = "#8c8c8c"
#: Colour of the dashed line from a sensor to a target it did not measure.
MISSED_COLOR = "#a0a0a0"
#: The length of a drawn heading, in units of the sensor's ``rho``.
HEADING_LENGTH = 0.5
#: Line style of the sensing range circles: sparse dots (the rho circles are dense ``:``).
RANGE_STYLE = (0, (1, 3))
#: Segments of a drawn path of the last step (:func:`step_path`).
PATH_POINTS = 16
#: Line style of the separation disks.
SEPARATION_STYLE = (0, (4, 2))


def separation_radii(d_sep: Any, m: int) -> FloatArray | None:
    """Return each sensor's separation disk radius (M,) for the scenario field ``d_sep``:
    ``d_sep / 2`` for one distance, the radii themselves for M radii; None when all are
    0 (no separation). Two sensors keep the rule exactly when their disks do not overlap."""
    d = np.asarray(d_sep, dtype=np.float64)
    radii = np.full(m, 0.5 * float(d)) if d.ndim == 0 else np.array(d)
    if radii.shape != (m,) or not np.all(np.isfinite(radii) & (radii >= 0.0)):
        raise ValueError(f"d_sep must be one distance or {m} radii, finite and >= 0, got {d_sep!r}")
    return radii if np.any(radii > 0.0) else None


def step_path(kin: Any, state: FloatArray, point: FloatArray, n: int = PATH_POINTS) -> FloatArray:
    """Return the path (n + 1, 2) a sensor of kinematics ``kin`` (an
    :class:`activetrack.Kinematics` with a ``dt``) drives in one step from ``state`` to
    the reachable ``point``: the positions after fractions ``j / n`` of the step, j = 0..n,
    of the command :meth:`~activetrack.Kinematics.command` gives (held over the step, as
    the world does), each :meth:`~activetrack.Kinematics.apply` of the kinematics bound to
    that fraction of ``dt`` (a unicycle's exact arc, a double integrator's parabola)."""
    state = np.asarray(state, np.float64)
    action = kin.command(np.asarray(point, np.float64), state)
    out = np.empty((n + 1, 2))
    out[0] = state[:2]
    for j in range(1, n + 1):
        out[j] = kin.bind(kin.dt * j / n).apply(action, state)
    return out


@dataclass(frozen=True)
class Snapshot:
    """What is drawn of time step k (float64 copies; K targets, M sensors)."""

    k: int
    targets: FloatArray  # true positions p_T(k), (K, 2)
    estimates: FloatArray  # x_hat(k|k)[:2] per target, (K, 2)
    covs: FloatArray  # P(k|k)[:2, :2] per target, (K, 2, 2)
    sensors: FloatArray  # true sensor positions p_S(k), (M, 2)
    centers: FloatArray  # predictions p_T(k|k-1) the rho circles surround, (K, 2)
    fixes: FloatArray | None = None  # believed sensor positions (uncertain poses), (M, 2)
    # Limited sensing (all None or empty for the paper's unlimited sensing):
    detected: np.ndarray | None = None  # which sensor measured which target at k, (K, M) bool
    occluders: tuple[FloatArray, ...] = ()  # the occluder polygons, (n_i, 2) each
    max_range: FloatArray | None = None  # per-sensor sensing range (inf: unlimited), (M,)
    # A kinematics with a state beyond the position: each sensor's observed features (M, F),
    # a unicycle's heading (cos, sin), a double integrator's velocity over its top speed.
    motion: FloatArray | None = None
    # Each sensor's path over the step that led here (M, PATH_POINTS + 1, 2), rows of NaN
    # for a sensor without one (:func:`step_path`); None: no paths (the reset, the disk).
    path: FloatArray | None = None

    @property
    def n_targets(self) -> int:
        """Return K."""
        return self.targets.shape[0]

    @property
    def limited(self) -> bool:
        """Return whether sensing is limited (detections recorded, occluders or a range)."""
        return self.detected is not None or bool(self.occluders) or self.max_range is not None


def _per_target(value: Any, ndim: int) -> list[np.ndarray]:
    """Return one target's array (``ndim`` dims) or a sequence of them as a list."""
    if isinstance(value, np.ndarray) and value.ndim == ndim:
        return [value]
    return [np.asarray(v) for v in value]


@dataclass
class EpisodeHistory:
    """The snapshots of the current episode."""

    frames: list[Snapshot] = field(default_factory=list)
    # The last occluder set converted (an immutable Occluders is converted once).
    _occ: tuple[Any, tuple[FloatArray, ...]] = field(default=(None, ()), repr=False)
    # The sensors' states (M, S) at the last step recorded from a world (the paths' start).
    _states: FloatArray | None = field(default=None, repr=False)

    def clear(self) -> None:
        """Forget the episode."""
        self.frames.clear()
        self._states = None

    def append(
        self, k, x_true, x_est, P, sensors, center, fixes=None, *,
        detected=None, occluders=None, max_range=None, motion=None, path=None,
    ) -> None:  # fmt: skip
        """Record time step ``k`` (the position parts are copied).

        ``x_true``, ``x_est``, ``center`` are one target's state (n,) or K of them (a
        (K, n) array or a sequence; the states may differ in dimension), ``P`` one (n, n)
        covariance or K of them; ``sensors`` (M, 2) the true positions, ``fixes`` (M, 2)
        the believed ones (None: poses are known). Limited sensing: ``detected`` (K, M)
        bool, which sensor measured which target at step ``k`` (None: unlimited sensing);
        ``occluders`` an :class:`activetrack.models.occluders.Occluders` or a sequence of (n_i, 2)
        polygons (None: none); ``max_range`` (M,) the sensing ranges, > 0, inf for
        unlimited (None: all unlimited). ``motion`` (M, F), F >= 2: each sensor's heading
        ``(cos, sin)`` or velocity over its top speed, drawn as a short line from the sensor
        (:meth:`activetrack.Kinematics.features`; None: nothing drawn). ``path`` (M, P, 2),
        P >= 2: each sensor's path over the step (a row of NaN: none; None: no paths).
        """
        targets = np.array([v[:2] for v in _per_target(x_true, 1)], dtype=np.float64)
        estimates = np.array([v[:2] for v in _per_target(x_est, 1)], dtype=np.float64)
        covs = np.array([c[:2, :2] for c in _per_target(P, 2)], dtype=np.float64)
        centers = np.array([v[:2] for v in _per_target(center, 1)], dtype=np.float64)
        if not len(targets) == len(estimates) == len(covs) == len(centers):
            raise ValueError(
                f"x_true, x_est, P and center must describe the same number of targets, got "
                f"{len(targets)}, {len(estimates)}, {len(covs)}, {len(centers)}"
            )
        sensors = np.array(sensors, dtype=np.float64)
        if fixes is not None:
            fixes = np.array(fixes, dtype=np.float64)
            if fixes.shape != sensors.shape:
                raise ValueError(f"fixes must have shape {sensors.shape}, got {fixes.shape}")
        shape = (len(targets), sensors.shape[0])
        if detected is not None:
            detected = np.array(detected)
            if detected.dtype != np.bool_ or detected.shape != shape:
                raise ValueError(
                    f"detected must be a bool array of shape {shape}, got "
                    f"{detected.dtype} {detected.shape}"
                )
        if max_range is not None:
            max_range = np.array(max_range, dtype=np.float64)
            if max_range.shape != shape[1:] or not np.all(max_range > 0):
                raise ValueError(
                    f"max_range must be {shape[1]} values in (0, inf], got {max_range!r}"
                )
        if motion is not None:
            motion = np.array(motion, dtype=np.float64)
            if motion.ndim != 2 or motion.shape[0] != shape[1] or motion.shape[1] < 2:
                raise ValueError(f"motion must have shape ({shape[1]}, F >= 2), got {motion.shape}")
        if path is not None:
            path = np.array(path, dtype=np.float64)
            if (
                path.ndim != 3
                or path.shape[0] != shape[1]
                or path.shape[1] < 2
                or path.shape[2] != 2
            ):
                raise ValueError(f"path must have shape ({shape[1]}, P >= 2, 2), got {path.shape}")
        self.frames.append(
            Snapshot(int(k), targets, estimates, covs, sensors, centers, fixes, detected,
                     self._polygons(occluders), max_range, motion, path)
        )  # fmt: skip

    def _polygons(self, occluders: Any) -> tuple[FloatArray, ...]:
        """Return ``occluders`` as a tuple of (n_i, 2) float64 arrays (checked copies)."""
        if occluders is None:
            return ()
        if occluders is self._occ[0]:  # the same immutable Occluders as the last step
            return self._occ[1]
        raw = getattr(occluders, "polygons", occluders)
        polys = tuple(np.array(p, dtype=np.float64) for p in raw)
        for i, p in enumerate(polys):
            if p.ndim != 2 or p.shape[0] < 3 or p.shape[1] != 2 or not np.all(np.isfinite(p)):
                raise ValueError(
                    f"occluders[{i}] must be a finite (n, 2) array with n >= 3, got {p.shape}"
                )
        if hasattr(occluders, "polygons"):  # immutable: convert it once
            self._occ = (occluders, polys)
        return polys

    def record(self, world: Any, centers: FloatArray | None = None, copy: int = 0) -> None:
        """Record the current step of copy ``copy`` of ``world`` (an :class:`activetrack.World`).

        ``centers`` (K, 2): the predictions the step's moves kept ``rho`` from
        (:func:`predicted_positions` before the step); None: the posterior estimates (at
        reset, before any move). The fixes are recorded when the poses are uncertain; with
        limited sensing (``world.scenario.limited_sensing``) the step's detections
        (``world.get("detected", copy)``), the world's occluders and sensing ranges; with a
        kinematics that carries a heading or a velocity its features (``motion``) and, after a
        step, each sensor's path over it from the states recorded last (:func:`step_path`,
        in the frame of the position fixes the world moves).
        """
        g, i = world.get, copy
        K = world.n_targets
        p = world.params
        x_hat = [g("x_hat", i, j) for j in range(K)]
        x_true, drawn = [g("x_true", i, j) for j in range(K)], x_hat
        limited = world.scenario.limited_sensing
        if world.present is not None:  # targets that appear and leave: NaN is not drawn
            none = np.full(2, np.nan)
            x_true = [x if on else none for x, on in zip(x_true, world.present[i], strict=True)]
            drawn = [x if on else none for x, on in zip(x_hat, world.tracked[i], strict=True)]
        self.append(
            g("k", i),
            x_true,
            drawn,
            [g("P", i, j) for j in range(K)],
            g("sensors", i),
            x_hat if centers is None else centers,
            g("fixes", i) if p.pose_cov is not None else None,
            detected=g("detected", i) if limited else None,
            occluders=world.occluders(i) if limited else None,
            max_range=p.max_range if limited else None,
            motion=_headings(world, i),
            path=self._paths(world, i, centers is not None),
        )

    def _paths(self, world: Any, copy: int, stepped: bool) -> FloatArray | None:
        """Return the sensors' paths over the step just taken (M, PATH_POINTS + 1, 2) (NaN
        for a kinematics without a state beyond the position or a ``dt``), or None (no
        sensor has a path, or no step since the last record); remember the states."""
        kins = world.scenario.kinematics_models
        drawn = [k.state_dim > 2 and getattr(k, "dt", None) is not None for k in kins]
        if not any(drawn):
            return None
        states = np.array(world.sensor_states(copy))
        before, self._states = self._states, states
        if not stepped or before is None:
            return None
        out = np.full((len(kins), PATH_POINTS + 1, 2), np.nan)
        for i, kin in enumerate(kins):
            if drawn[i]:
                out[i] = step_path(kin, before[i, : kin.state_dim], states[i, :2])
        return out


def _headings(world: Any, copy: int) -> FloatArray | None:
    """Return copy ``copy``'s sensors' kinematic features (M, F >= 2) to draw, or None."""
    feats = world._motion_features(copy)
    return None if feats is None or feats.shape[-1] < 2 else feats


def _same_polygons(a: tuple[FloatArray, ...], b: tuple[FloatArray, ...]) -> bool:
    """Return whether two occluder layouts are equal (cheap when they are one object)."""
    return a is b or (
        len(a) == len(b) and all(np.array_equal(p, q) for p, q in zip(a, b, strict=True))
    )


def _segments(a: FloatArray, b: FloatArray) -> FloatArray:
    """Return the segments ``a[i] -> b[i]`` (broadcast) as one polyline broken by NaN rows."""
    a, b = np.broadcast_arrays(a, b)
    out = np.full((a.shape[0], 3, 2), np.nan)
    out[:, 0], out[:, 1] = a, b
    return out.reshape(-1, 2)


def predicted_positions(world: Any, copy: int = 0) -> FloatArray:
    """Return the predicted target positions ``p_T(k+1|k)`` of copy ``copy`` of ``world``,
    (K, 2)."""
    return np.array([world.get("x_pred", copy, j)[:2] for j in range(world.n_targets)])


def ellipse(center: FloatArray, cov: FloatArray, n_sigma: float = 3.0) -> FloatArray:
    """Return the closed polyline of the ``n_sigma`` ellipse of ``cov`` at ``center``, (65, 2)."""
    return center + n_sigma * (np.linalg.cholesky(cov) @ _UNIT).T


def _psd_root(cov: FloatArray) -> FloatArray:
    """Return ``S`` with ``S S^T = cov`` for symmetric PSD (possibly singular) ``cov``."""
    w, v = np.linalg.eigh(cov)
    return v * np.sqrt(np.clip(w, 0.0, None))[..., None, :]


def _interactive_backend() -> bool:
    import matplotlib

    backend = matplotlib.get_backend().lower()
    try:
        from matplotlib.backends import BackendFilter, backend_registry

        interactive = backend_registry.list_builtin(BackendFilter.INTERACTIVE)
    except ImportError:  # matplotlib < 3.9
        from matplotlib import rcsetup

        interactive = rcsetup.interactive_bk
    return backend in {b.lower() for b in interactive}


class TrackingRenderer:
    """Draws an :class:`EpisodeHistory` with matplotlib, reusing one figure.

    Args:
        rho: per-sensor minimum distance (M,) (eq. 14).
        size: frame (width, height) in pixels.
        dpi: dots per inch of the figure.
        models: per-sensor models (M,): :class:`activetrack.SensorModel` objects
            (``Scenario.sensor_objects``; each drawn with its ``marker``) or the built-ins'
            codes (0 range and bearing, 1 range only, 2 bearing only); None: all range and
            bearing.
        pose_cov: per-sensor pose covariances (M, 2, 2) (``Scenario.pose_covariances``),
            drawn as 2-sigma ellipses around the recorded fixes; None: poses are known.
        separation: per-sensor separation disk radii (M,) (:func:`separation_radii`),
            drawn around the sensors; None: no separation.
    """

    def __init__(
        self,
        rho: FloatArray,
        size: tuple[int, int] = (480, 480),
        dpi: int = 96,
        *,
        models: Any = None,
        pose_cov: Any = None,
        separation: Any = None,
    ) -> None:
        self.rho = np.asarray(rho, dtype=np.float64)
        if self.rho.ndim != 1:
            raise ValueError(f"rho must have shape (M,), got {self.rho.shape}")
        m = self.rho.shape[0]
        if (
            len(size) != 2
            or not all(isinstance(s, (int, np.integer)) and s > 0 for s in size)
            or isinstance(dpi, bool)
            or not isinstance(dpi, (int, np.integer))
            or dpi <= 0
        ):
            raise ValueError(f"size must be two positive integers and dpi one, got {size}, {dpi}")
        self.size = (int(size[0]), int(size[1]))
        self.dpi = int(dpi)
        if models is not None and all(isinstance(v, SensorModel) for v in models):
            if len(models) != m:
                raise ValueError(f"models must hold {m} sensor models, got {len(models)}")
            # (marker, label) per sensor, from the models themselves.
            self._marks = [(v.marker, v.label or v.name) for v in models]
            codes = np.array([-1 if v.code is None else v.code for v in models], np.int8)
        else:
            codes = np.zeros(m, dtype=np.int8) if models is None else np.asarray(models)
            self._marks = None
        if self._marks is None and (
            codes.shape != (m,)
            or codes.dtype.kind not in "iu"
            or not np.all((codes >= 0) & (codes < len(MODEL_MARKERS)))
        ):
            raise ValueError(
                f"models must be {m} integer codes in [0, {len(MODEL_MARKERS) - 1}], got {models!r}"
            )
        self.models = codes.astype(np.int8)
        if self._marks is None:
            self._marks = [MODEL_MARKERS[c] for c in self.models.tolist()]
        self.pose_cov = None
        if pose_cov is not None:
            cov = np.asarray(pose_cov, dtype=np.float64)
            if cov.shape != (m, 2, 2) or not np.all(np.isfinite(cov)):
                raise ValueError(f"pose_cov must be finite with shape ({m}, 2, 2), got {cov.shape}")
            self.pose_cov = cov
            self._pose_rings = POSE_SIGMAS * np.einsum("mij,jk->mki", _psd_root(cov), _UNIT)
        self.separation = None
        if separation is not None:
            sep = np.asarray(separation, dtype=np.float64)
            if sep.shape != (m,) or not np.all(np.isfinite(sep) & (sep >= 0.0)):
                raise ValueError(f"separation must be {m} finite radii >= 0, got {separation!r}")
            self.separation = sep
        self._fig: Any = None
        self._canvas: Any = None
        self._art: dict[str, Any] = {}
        self._human = False
        self._warned = False
        self._layout: tuple[int, bool, tuple[bool, bool, bool], bool] = (1, False, _OPEN, False)
        # Per frame: (snapshot, its K 3-sigma ellipses).
        self._ellipses: list[tuple[Snapshot, list[FloatArray]]] = []

    # Figure set-up ------------------------------------------------------------------
    def _build(
        self,
        human: bool,
        n_targets: int = 1,
        fixes: bool = False,
        sensing: tuple[bool, bool, bool] = _OPEN,
        paths: bool = False,
    ) -> None:
        """Make the figure and its artists for ``n_targets`` targets (and the fixes);
        ``sensing``: whether occluders, sensing ranges and detections are drawn; ``paths``:
        whether the sensors carry a state beyond the position (headings, paths)."""
        from matplotlib.collections import LineCollection, PolyCollection

        figsize = (self.size[0] / self.dpi, self.size[1] / self.dpi)
        if human:
            import matplotlib.pyplot as plt

            fig = plt.figure("activetrack", figsize=figsize, dpi=self.dpi)
            canvas = fig.canvas
        else:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure

            fig = Figure(figsize=figsize, dpi=self.dpi)
            canvas = FigureCanvasAgg(fig)
        from matplotlib.ticker import MaxNLocator

        ax = fig.add_axes((0.1, 0.08, 0.86, 0.84))
        ax.set_xlabel("x (m)", fontsize=8)
        ax.set_ylabel("y (m)", fontsize=8)
        ax.tick_params(labelsize=7)
        # Text layout dominates the drawing time: few ticks, a fixed-position title.
        ax.xaxis.set_major_locator(MaxNLocator(5))
        ax.yaxis.set_major_locator(MaxNLocator(5))
        ax.grid(True, lw=0.3, alpha=0.5)
        colors = [f"C{i % 10}" for i in range(self.rho.shape[0])]
        occluded, ranged, detections = sensing
        art: dict[str, Any] = {"occluders": None, "range": [], "sight": [], "missed": None}
        self._polys: tuple[FloatArray, ...] = ()  # the occluders drawn
        if occluded:  # static: part of the cached background, under every data artist
            art["occluders"] = PolyCollection(
                [], facecolors=OCCLUDER_FACE, edgecolors=OCCLUDER_EDGE, linewidths=0.8,
                zorder=1.6, label="occluders",
            )  # fmt: skip
            ax.add_collection(art["occluders"])
        if ranged:
            for c in colors:
                art["range"].append(ax.plot([], [], ls=RANGE_STYLE, color=c, lw=0.7)[0])
            art["range"][0].set_label("sensing range")
        if detections:
            for c in colors:
                art["sight"].append(ax.plot([], [], "-", color=c, lw=0.7, alpha=0.8)[0])
            art["sight"][0].set_label("lines of sight")
            art["missed"] = ax.plot([], [], ls=(0, (3, 3)), color=MISSED_COLOR, lw=0.7)[0]
            art["missed"].set_label("missed detections")
        targets = []
        for j in range(n_targets):
            true_c, est_c, ell_c = TARGET_COLORS[j % len(TARGET_COLORS)]
            name = "target" if n_targets == 1 else f"target {j}"
            targets.append(
                {
                    "ellipses": LineCollection([], colors=ell_c, linewidths=0.6, alpha=0.45),
                    "true": ax.plot([], [], "-", color=true_c, lw=1.2, label=f"{name} (true)")[0],
                    "est": ax.plot([], [], "--", color=est_c, lw=1.0, label=f"{name} (estimate)")[
                        0
                    ],
                }
            )
        for j, t in enumerate(targets):
            true_c, est_c, _ = TARGET_COLORS[j % len(TARGET_COLORS)]
            t["true_now"] = ax.plot([], [], "*", color=true_c, ms=9)[0]
            t["est_now"] = ax.plot([], [], "x", color=est_c, ms=7)[0]
            t["now_ellipse"] = ax.plot([], [], "-", color=est_c, lw=1.2)[0]
        for t in targets:
            ax.add_collection(t["ellipses"])
        targets[0]["ellipses"].set_label("3-sigma bounds")
        art.update(targets=targets, trails=[], heads=[], rho=[], headings=[], paths=[],
                   separation=[])  # fmt: skip
        for c, (marker, _) in zip(colors, self._marks, strict=True):
            art["trails"].append(ax.plot([], [], "-", color=c, lw=1.0)[0])
            art["heads"].append(ax.plot([], [], marker, color=c, ms=5)[0])
            art["headings"].append(ax.plot([], [], "-", color=c, lw=1.6)[0])
            art["rho"].append(ax.plot([], [], ":", color=c, lw=0.8)[0])
            art["paths"].append(ax.plot([], [], "-", color=c, lw=3.0, alpha=0.45)[0])
            art["separation"].append(ax.plot([], [], ls=SEPARATION_STYLE, color=c, lw=0.6)[0])
        art["trails"][0].set_label("sensor trails")
        art["rho"][0].set_label("rho circles")
        if paths:  # (legend entries only where drawn: the paper's frames are unchanged)
            art["paths"][0].set_label("last step's paths")
        if self.separation is not None:
            art["separation"][0].set_label("separation disks")
        if np.any(self.models):  # a legend entry per model present (not for the paper's team)
            for marker, label in dict.fromkeys(sorted(self._marks, key=_mark_order)):
                ax.plot([], [], marker, ls="none", color="0.35", ms=5, label=label)
        art["fixes"], art["pose"] = [], None
        if fixes:
            for c in colors:
                art["fixes"].append(ax.plot([], [], "+", color=c, ms=6, mew=1.0)[0])
            label = "position fixes"
            if self.pose_cov is not None:
                art["pose"] = LineCollection([], colors=colors, linewidths=0.6, alpha=0.7)
                label += f" ({POSE_SIGMAS:g}-sigma)"
            art["fixes"][0].set_label(label)
        if art["pose"] is not None:
            ax.add_collection(art["pose"])
        art["title"] = ax.text(
            0.5, 1.015, "", transform=ax.transAxes, ha="center", va="bottom", fontsize=9
        )
        ax.legend(loc="upper left", fontsize=6, framealpha=0.6)
        self._dynamic = [
            *art["range"], *([art["missed"]] if detections else []), *art["sight"],
            *(t["ellipses"] for t in targets), *(t["true"] for t in targets),
            *(t["est"] for t in targets), *art["trails"], *art["rho"], *art["separation"],
            *art["paths"],
            *([art["pose"]] if art["pose"] is not None else []),
            *(a for t in targets for a in (t["now_ellipse"], t["true_now"], t["est_now"])),
            *art["heads"], *art["headings"], *art["fixes"], art["title"],
        ]  # fmt: skip
        if not human:
            # Blitting: the axes, ticks and legend (text is slow) are drawn into a cached
            # background only when the view changes; the data artists on top every frame.
            for a in self._dynamic:
                a.set_animated(True)
        self._fig, self._canvas, self._art, self._human = fig, canvas, art, human
        self._layout = (n_targets, fixes, sensing, paths)
        self._ax = ax
        self._view: tuple[FloatArray, float] | None = None
        self._background = None

    def _update(self, history: EpisodeHistory) -> None:
        frames = history.frames
        art = self._art
        last = frames[-1]
        true = np.array([f.targets for f in frames])  # (T, K, 2)
        est = np.array([f.estimates for f in frames])
        trails = np.array([f.sensors for f in frames])  # (T, M, 2)
        polys = self._ellipses_of(frames)
        stride = max(1, int(np.ceil(len(frames) / MAX_ELLIPSES)))
        nows = []
        trace = 0.0
        for j, t in enumerate(art["targets"]):
            t["true"].set_data(true[:, j, 0], true[:, j, 1])
            t["est"].set_data(est[:, j, 0], est[:, j, 1])
            t["true_now"].set_data([last.targets[j, 0]], [last.targets[j, 1]])
            t["est_now"].set_data([last.estimates[j, 0]], [last.estimates[j, 1]])
            now = ellipse(last.estimates[j], last.covs[j])
            t["now_ellipse"].set_data(now[:, 0], now[:, 1])
            t["ellipses"].set_segments([p[j] for p in polys[::stride]])
            nows.append(now)
            if np.isfinite(last.estimates[j, 0]):  # (a slot without a track: not drawn)
                trace += float(last.covs[j, 0, 0] + last.covs[j, 1, 1])
        K = last.n_targets
        for i, (trail, head, circle) in enumerate(
            zip(art["trails"], art["heads"], art["rho"], strict=True)
        ):
            trail.set_data(trails[:, i, 0], trails[:, i, 1])
            head.set_data([last.sensors[i, 0]], [last.sensors[i, 1]])
            ring = self.rho[i] * _UNIT.T
            if K == 1:
                rings = last.centers[0] + ring
            else:  # one line through every target's ring, broken by NaN rows
                rings = np.concatenate(
                    [np.vstack([c + ring, [np.nan, np.nan]]) for c in last.centers]
                )
            circle.set_data(rings[:, 0], rings[:, 1])
        for i, line in enumerate(art["headings"]):  # heading or velocity: HEADING_LENGTH rho
            if last.motion is None:
                line.set_data([], [])
                continue
            tip = last.sensors[i] + HEADING_LENGTH * self.rho[i] * last.motion[i, :2]
            line.set_data([last.sensors[i, 0], tip[0]], [last.sensors[i, 1], tip[1]])
        for i, line in enumerate(art["paths"]):  # the last step's path (NaN rows: none)
            path = np.empty((0, 2)) if last.path is None else last.path[i]
            line.set_data(path[:, 0], path[:, 1])
        for i, line in enumerate(art["separation"]):
            ring = (
                np.empty((0, 2))
                if self.separation is None or self.separation[i] == 0.0
                else last.sensors[i] + self.separation[i] * _UNIT.T
            )
            line.set_data(ring[:, 0], ring[:, 1])
        extra = []
        if art["fixes"]:
            fixes = last.sensors if last.fixes is None else last.fixes
            for i, mark in enumerate(art["fixes"]):
                mark.set_data([fixes[i, 0]], [fixes[i, 1]])
            extra.append(fixes)
            if art["pose"] is not None:
                pose = fixes[:, None, :] + self._pose_rings  # (M, N_CIRCLE, 2)
                art["pose"].set_segments(list(pose))
                extra.append(pose.reshape(-1, 2))
        title = "tr P(k|k)_11" if K == 1 else "Σ tr P(k|k)_11"
        title = f"step {last.k}   {title} = {trace:.3g} m²"
        if last.limited:
            title += self._draw_sensing(last)
        art["title"].set_text(title)
        pts = np.concatenate([true.reshape(-1, 2), est.reshape(-1, 2), trails.reshape(-1, 2),
                              *nows, *extra])  # fmt: skip
        self._fit_view(np.nanmin(pts, 0), np.nanmax(pts, 0))

    def _draw_sensing(self, last: Snapshot) -> str:
        """Draw the occluders, ranges and lines of sight of ``last``; return the title's
        missed-detection count ("" before the first measurement)."""
        art = self._art
        if art["occluders"] is not None and not _same_polygons(last.occluders, self._polys):
            art["occluders"].set_verts(list(last.occluders))
            self._background = None  # the occluders are in the cached background
        self._polys = last.occluders
        if art["range"]:
            for line, center, radius in zip(art["range"], last.sensors, last.max_range,
                                            strict=True):  # fmt: skip
                ring = center + radius * _UNIT.T if np.isfinite(radius) else np.empty((0, 2))
                line.set_data(ring[:, 0], ring[:, 1])
        if last.detected is None or last.k == 0:  # no measurement yet: nothing was missed
            for line in [*art["sight"], *([art["missed"]] if art["missed"] else [])]:
                line.set_data([], [])
            return ""
        seen = last.detected  # (K, M)
        for i, line in enumerate(art["sight"]):
            seg = _segments(last.sensors[i : i + 1], last.targets[seen[:, i]])
            line.set_data(seg[:, 0], seg[:, 1])
        there = np.isfinite(last.targets[:, :1])  # (K, 1): a target absent is not missed
        j, i = np.nonzero(~seen & there)
        seg = _segments(last.sensors[i], last.targets[j])
        art["missed"].set_data(seg[:, 0], seg[:, 1])
        return f"   missed {len(i)}/{int(there.sum()) * seen.shape[1]}"

    def _fit_view(self, lo: FloatArray, hi: FloatArray) -> None:
        """Keep a square view around the data; change it only when the data leaves it
        or fills less than a third of it, so the cached background is rarely redrawn."""
        mid = 0.5 * (lo + hi)
        half = 0.5 * max(float(np.max(hi - lo)), 4.0 * float(np.max(self.rho, initial=1.0)))
        if self._view is not None:
            cmid, chalf = self._view
            inside = float(np.max(np.abs(mid - cmid))) + half <= chalf
            if inside and half >= chalf / 3.0:
                return
        chalf = 1.6 * half  # room to grow: each refit redraws the slow background
        self._view = (mid, chalf)
        self._ax.set_xlim(mid[0] - chalf, mid[0] + chalf)
        self._ax.set_ylim(mid[1] - chalf, mid[1] + chalf)
        self._background = None

    def _ellipses_of(self, frames: list[Snapshot]) -> list[list[FloatArray]]:
        # Each frame's ellipses are computed once; the cache follows the history by identity.
        cache = self._ellipses
        n = len(cache)
        if n and (
            n > len(frames) or cache[0][0] is not frames[0] or cache[-1][0] is not frames[n - 1]
        ):
            cache.clear()
            n = 0
        cache.extend(
            (f, [ellipse(e, c) for e, c in zip(f.estimates, f.covs, strict=True)])
            for f in frames[n:]
        )
        return [polys for _, polys in cache]

    def _layout_of(
        self, history: EpisodeHistory
    ) -> tuple[int, bool, tuple[bool, bool, bool], bool]:
        """Return the (targets, fixes drawn, (occluders, ranges, detections drawn), paths
        drawn) the history needs."""
        last = history.frames[-1]
        if last.sensors.shape[0] != self.rho.shape[0]:
            raise ValueError(
                f"the history has {last.sensors.shape[0]} sensors, the renderer "
                f"{self.rho.shape[0]} (rho)"
            )
        ranged = last.max_range is not None and bool(np.any(np.isfinite(last.max_range)))
        sensing = (bool(last.occluders), ranged, last.detected is not None)
        fixes = last.fixes is not None or self.pose_cov is not None
        return last.n_targets, fixes, sensing, last.motion is not None

    # Public ------------------------------------------------------------------------
    def rgb_array(self, history: EpisodeHistory) -> np.ndarray:
        """Return the current frame as a uint8 array of shape (height, width, 3)."""
        layout = self._layout_of(history)
        if self._fig is None or self._human or layout != self._layout:
            self.close()
            self._build(False, *layout)
        self._update(history)
        canvas = self._canvas
        if self._background is None:
            canvas.draw()  # everything but the animated (data) artists
            self._background = canvas.copy_from_bbox(self._fig.bbox)
        else:
            canvas.restore_region(self._background)
        for a in self._dynamic:
            self._ax.draw_artist(a)
        return np.asarray(canvas.buffer_rgba())[..., :3].copy()

    def show(self, history: EpisodeHistory, fps: float) -> None:
        """Draw the current frame on a window (a no-op with a warning when headless)."""
        if not _interactive_backend():
            if not self._warned:
                warnings.warn(
                    "render_mode='human' needs an interactive matplotlib backend (a display); "
                    "nothing is shown. Use render_mode='rgb_array' to get frames.",
                    stacklevel=3,
                )
                self._warned = True
            return
        import matplotlib.pyplot as plt

        layout = self._layout_of(history)
        if (
            self._fig is None
            or not self._human
            or layout != self._layout
            or not plt.fignum_exists(self._fig.number)
        ):
            self.close()
            self._build(True, *layout)
            plt.show(block=False)
        self._update(history)
        self._fig.canvas.draw_idle()
        plt.pause(1.0 / max(fps, 1e-3))

    def reset(self) -> None:
        """Forget cached drawing data of the previous episode."""
        self._ellipses.clear()

    def close(self) -> None:
        """Close the figure (and its window)."""
        if self._fig is not None and self._human:
            import matplotlib.pyplot as plt

            plt.close(self._fig)
        self._fig = self._canvas = None
        self._art = {}
        self._ellipses.clear()


class EpisodeRecorder:
    """One copy's episode of a world, recorded for an environment with a render mode, and
    its frames: the :class:`EpisodeHistory` and, made on the first frame, the renderer.

    Args:
        world: the :class:`activetrack.World` the environment steps.
        mode: ``"rgb_array"`` or ``"human"``.
        fps: frames per second of the ``human`` window.
        copy: the copy of ``world`` recorded.
    """

    def __init__(self, world: Any, mode: str, fps: float, copy: int = 0) -> None:
        self.world, self.mode, self.fps, self.copy = world, mode, fps, copy
        self.history = EpisodeHistory()
        self._renderer: TrackingRenderer | None = None

    def restart(self) -> None:
        """Start a new episode's record from the world's state after its reset."""
        self.history.clear()
        self.history.record(self.world, None, self.copy)  # rho circles about the estimates
        if self._renderer is not None:
            self._renderer.reset()

    def centers(self) -> FloatArray:
        """Return what the next step's moves keep ``rho`` from (call before the step)."""
        return predicted_positions(self.world, self.copy)

    def record(self, centers: FloatArray) -> None:
        """Record the step just taken, whose moves kept ``rho`` from ``centers``."""
        self.history.record(self.world, centers, self.copy)

    def render(self) -> np.ndarray | None:
        """Return the current frame (``rgb_array``), or draw it in the window (``human``)."""
        if not self.history.frames:
            raise RuntimeError("call reset() before render()")
        if self._renderer is None:
            sc = self.world.scenario
            self._renderer = TrackingRenderer(
                self.world.params.rho,
                models=sc.sensor_objects,
                pose_cov=sc.pose_covariances,
                separation=separation_radii(sc.d_sep, sc.n_sensors),
            )
        if self.mode == "rgb_array":
            return self._renderer.rgb_array(self.history)
        self._renderer.show(self.history, self.fps)
        return None

    def close(self) -> None:
        """Close the window, if any (safe to call twice)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __getstate__(self) -> dict[str, Any]:
        # The matplotlib figure is not pickled; it is rebuilt on the next render().
        return {**self.__dict__, "_renderer": None}
