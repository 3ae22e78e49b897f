"""Rendering of a tracking episode in the style of the paper's Fig. 4 (no physics here).

The environment appends one :class:`Snapshot` per time step to an :class:`EpisodeHistory`
(only when a render mode is set); :class:`TrackingRenderer` draws the history: the
target's true and estimated tracks, the 3-sigma ellipses of the position estimate along
the track (as in Fig. 4), the sensors' trails, and each sensor's ``rho`` circle (eq. 14)
around the predicted target position its last move was constrained by.

``rgb_array`` draws on a matplotlib Agg canvas (no window, works headless). ``human``
draws on a pyplot window; without an interactive backend (no display) it warns once and
draws nothing. matplotlib is imported only when something is rendered.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from activetrack.validation import FloatArray

#: Points per drawn circle or ellipse.
_N_CIRCLE = 65
_UNIT = np.stack(
    [np.cos(np.linspace(0, 2 * np.pi, _N_CIRCLE)), np.sin(np.linspace(0, 2 * np.pi, _N_CIRCLE))]
)
#: At most this many 3-sigma ellipses are drawn along the track (evenly spaced).
MAX_ELLIPSES = 25


@dataclass(frozen=True)
class Snapshot:
    """What is drawn of time step k (all float64 copies)."""

    k: int
    target: FloatArray  # true position p_T(k), (2,)
    estimate: FloatArray  # x_hat(k|k)[:2], (2,)
    cov: FloatArray  # P(k|k)[:2, :2], (2, 2)
    sensors: FloatArray  # p_S(k), (M, 2)
    center: FloatArray  # prediction p_T(k|k-1) the rho circles surround, (2,)


@dataclass
class EpisodeHistory:
    """The snapshots of the current episode."""

    frames: list[Snapshot] = field(default_factory=list)

    def clear(self) -> None:
        """Forget the episode."""
        self.frames.clear()

    def append(self, k, x_true, x_est, P, sensors, center) -> None:
        """Record time step ``k`` (arrays are copied)."""
        self.frames.append(
            Snapshot(
                int(k),
                np.array(x_true[:2], dtype=np.float64),
                np.array(x_est[:2], dtype=np.float64),
                np.array(P[:2, :2], dtype=np.float64),
                np.array(sensors, dtype=np.float64),
                np.array(center[:2], dtype=np.float64),
            )
        )


def ellipse(center: FloatArray, cov: FloatArray, n_sigma: float = 3.0) -> FloatArray:
    """Return the closed polyline of the ``n_sigma`` ellipse of ``cov`` at ``center``, (K, 2)."""
    return center + n_sigma * (np.linalg.cholesky(cov) @ _UNIT).T


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
    """Draws an :class:`EpisodeHistory` with matplotlib, reusing one figure."""

    def __init__(self, rho: FloatArray, size: tuple[int, int] = (480, 480), dpi: int = 96) -> None:
        self.rho = np.asarray(rho, dtype=np.float64)
        self.size = size
        self.dpi = dpi
        self._fig: Any = None
        self._canvas: Any = None
        self._art: dict[str, Any] = {}
        self._human = False
        self._warned = False
        self._ellipses: list[tuple[Snapshot, FloatArray]] = []

    # Figure set-up ------------------------------------------------------------------
    def _build(self, human: bool) -> None:
        from matplotlib.collections import LineCollection

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
        art: dict[str, Any] = {
            "ellipses": LineCollection([], colors="tab:red", linewidths=0.6, alpha=0.45),
            "true": ax.plot([], [], "k-", lw=1.2, label="target (true)")[0],
            "est": ax.plot([], [], "r--", lw=1.0, label="target (estimate)")[0],
            "true_now": ax.plot([], [], "k*", ms=9)[0],
            "est_now": ax.plot([], [], "rx", ms=7)[0],
            "now_ellipse": ax.plot([], [], "r-", lw=1.2)[0],
            "trails": [],
            "heads": [],
            "rho": [],
        }
        ax.add_collection(art["ellipses"])
        for c in colors:
            art["trails"].append(ax.plot([], [], "-", color=c, lw=1.0)[0])
            art["heads"].append(ax.plot([], [], "o", color=c, ms=5)[0])
            art["rho"].append(ax.plot([], [], ":", color=c, lw=0.8)[0])
        art["trails"][0].set_label("sensor trails")
        art["rho"][0].set_label("rho circles")
        art["ellipses"].set_label("3-sigma bounds")
        art["title"] = ax.text(
            0.5, 1.015, "", transform=ax.transAxes, ha="center", va="bottom", fontsize=9
        )
        ax.legend(loc="upper left", fontsize=6, framealpha=0.6)
        self._dynamic = [
            art["ellipses"], art["true"], art["est"], *art["trails"], *art["rho"],
            art["now_ellipse"], art["true_now"], art["est_now"], *art["heads"], art["title"],
        ]  # fmt: skip
        if not human:
            # Blitting: the axes, ticks and legend (text is slow) are drawn into a cached
            # background only when the view changes; the data artists on top every frame.
            for a in self._dynamic:
                a.set_animated(True)
        self._fig, self._canvas, self._art, self._human = fig, canvas, art, human
        self._ax = ax
        self._view: tuple[FloatArray, float] | None = None
        self._background = None

    def _update(self, history: EpisodeHistory) -> None:
        frames = history.frames
        art = self._art
        last = frames[-1]
        true = np.array([f.target for f in frames])
        est = np.array([f.estimate for f in frames])
        trails = np.array([f.sensors for f in frames])  # (T, M, 2)
        art["true"].set_data(true[:, 0], true[:, 1])
        art["est"].set_data(est[:, 0], est[:, 1])
        art["true_now"].set_data([last.target[0]], [last.target[1]])
        art["est_now"].set_data([last.estimate[0]], [last.estimate[1]])
        now = ellipse(last.estimate, last.cov)
        art["now_ellipse"].set_data(now[:, 0], now[:, 1])
        stride = max(1, int(np.ceil(len(frames) / MAX_ELLIPSES)))
        art["ellipses"].set_segments(self._ellipses_of(frames)[::stride])
        for i, (trail, head, circle) in enumerate(
            zip(art["trails"], art["heads"], art["rho"], strict=True)
        ):
            trail.set_data(trails[:, i, 0], trails[:, i, 1])
            head.set_data([last.sensors[i, 0]], [last.sensors[i, 1]])
            ring = last.center + self.rho[i] * _UNIT.T
            circle.set_data(ring[:, 0], ring[:, 1])
        trace = float(last.cov[0, 0] + last.cov[1, 1])
        art["title"].set_text(f"step {last.k}   tr P(k|k)_11 = {trace:.3g} m²")
        pts = np.concatenate([true, est, trails.reshape(-1, 2), now])
        self._fit_view(pts.min(0), pts.max(0))

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

    def _ellipses_of(self, frames: list[Snapshot]) -> list[FloatArray]:
        # Each frame's ellipse is computed once; the cache follows the history by identity.
        cache = self._ellipses
        n = len(cache)
        if n and (
            n > len(frames) or cache[0][0] is not frames[0] or cache[-1][0] is not frames[n - 1]
        ):
            cache.clear()
            n = 0
        cache.extend((f, ellipse(f.estimate, f.cov)) for f in frames[n:])
        return [poly for _, poly in cache]

    # Public ------------------------------------------------------------------------
    def rgb_array(self, history: EpisodeHistory) -> np.ndarray:
        """Return the current frame as a uint8 array of shape (height, width, 3)."""
        if self._fig is None or self._human:
            self.close()
            self._build(human=False)
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

        if self._fig is None or not self._human or not plt.fignum_exists(self._fig.number):
            self.close()
            self._build(human=True)
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
