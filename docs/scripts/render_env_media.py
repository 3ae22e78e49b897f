"""Render the environment pages' media: per registered id, a GIF of an episode of the
expert and the expert's and random motion's figures on the task's held-out episodes.

Usage (from the repository's root; about 13 minutes of CPU for every id)::

    python docs/scripts/render_env_media.py            # every id
    python docs/scripts/render_env_media.py --ids activetrack/Urban-v0

For every id of :data:`activetrack._registry.ALL_IDS` it writes, into ``docs/_static/envs``
(checked in; the environment pages, ``docs/_ext/env_pages.py``, show them):

- ``<Name>.gif``: the episode of seed :data:`SEED` (the first held-out episode) with GSR,
  drawn by the environment's own renderer (:func:`activetrack.envs.record_video`), then
  made small: every :data:`FRAME_STEP`-th frame, :data:`SIZE` pixels square, one palette of
  :data:`COLORS` colours;
- ``<Name>.json``: ``activetrack evaluate --scenario <preset> --policy gsr --policy rm
  --episodes 100 --seed 1000`` (:func:`activetrack.baselines.evaluation.run_evaluation`,
  which prints its table): its ``results.json`` (the summaries: mean trace with its BCa
  bootstrap interval, median, CPU ms per decision...) as ``"results"`` and its
  ``episodes.json`` (every episode's figures) as ``"episodes"``.

OpenBLAS's Haswell kernels are used where the CPU has them, as in the test suite
(``tests/conftest.py``), so the figures are those the tests re-run.
"""

from __future__ import annotations

import os
import platform


def _pin_blas_kernels() -> None:
    """Use OpenBLAS's Haswell kernels on an x86-64 CPU with AVX2 and FMA (before NumPy
    loads OpenBLAS): the kernels the test suite runs, whose rounding the seeded episodes
    depend on (``tests/conftest.py`` explains why)."""
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

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

#: The command that regenerates the media (shown on the pages).
COMMAND = "python docs/scripts/render_env_media.py"
#: The output folder, relative to the repository's root.
OUT = Path("docs/_static/envs")
#: The held-out episodes: seeds SEED .. SEED + EPISODES - 1 (``activetrack evaluate``'s).
SEED, EPISODES = 1000, 100
#: The policies compared: the expert and random motion.
POLICIES = ("gsr", "rm")
#: The GIF: every FRAME_STEP-th frame of the episode (and its last), SIZE x SIZE pixels,
#: one palette of COLORS colours (about 100-200 KB per episode of 50 steps); a longer
#: episode keeps at most about MAX_FRAMES frames (a larger step).
FRAME_STEP, SIZE, COLORS, MAX_FRAMES = 2, 360, 64, 40


def name_of(env_id: str) -> str:
    """Return the file stem of an id: ``activetrack/Urban-v0`` -> ``Urban-v0``."""
    return env_id.split("/", 1)[1]


def evaluate_command(preset: str, episodes: int = EPISODES, seed: int = SEED) -> str:
    """Return the ``activetrack evaluate`` command whose results the JSON holds."""
    policies = " ".join(f"--policy {p}" for p in POLICIES)
    return (
        f"activetrack evaluate --scenario {preset} {policies} --episodes {episodes} --seed {seed}"
    )


def _small_gif(frames: list[Any], path: Path, fps: float) -> None:
    """Write RGB frames (PIL images) as a small GIF: every FRAME_STEP-th one and the last,
    resized, with one shared palette; atomically."""
    from PIL import Image

    from activetrack.files import atomic_path

    step = max(FRAME_STEP, len(frames) // MAX_FRAMES)
    kept = frames[::step]
    if (len(frames) - 1) % step:
        kept.append(frames[-1])
    kept = [f.resize((SIZE, SIZE), Image.Resampling.LANCZOS) for f in kept]
    # One palette for the whole episode, from a few frames side by side.
    sample = kept[:: max(1, len(kept) // 5)]
    mosaic = Image.new("RGB", (SIZE * len(sample), SIZE))
    for i, f in enumerate(sample):
        mosaic.paste(f, (i * SIZE, 0))
    palette = mosaic.quantize(colors=COLORS, method=Image.Quantize.FASTOCTREE)
    quantized = [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in kept]
    with atomic_path(path) as tmp:
        quantized[0].save(
            tmp, format="GIF", save_all=True, append_images=quantized[1:], loop=0,
            duration=round(1000.0 * step / fps), optimize=True,
        )  # fmt: skip


def render_gif(env_id: str, path: Path, seed: int = SEED) -> Path:
    """Record the episode ``seed`` of GSR in ``env_id`` with :func:`record_video` and write
    it small to ``path``; return ``path``."""
    from PIL import Image, ImageSequence

    from activetrack._registry import ALL_IDS
    from activetrack.baselines.policy_specs import resolve_policy
    from activetrack.envs import TrackingParallelEnv, record_video

    env = TrackingParallelEnv(ALL_IDS[env_id], render_mode="rgb_array")
    try:
        with tempfile.TemporaryDirectory() as tmp:
            full = record_video(Path(tmp) / "episode.gif", resolve_policy("gsr"), env=env,
                                seed=seed)  # fmt: skip
            with Image.open(full) as im:
                frames = [f.convert("RGB") for f in ImageSequence.Iterator(im)]
        _small_gif(frames, path, env.metadata["render_fps"])
    finally:
        env.close()
    return path


def figures(env_id: str, episodes: int = EPISODES, seed: int = SEED) -> dict[str, Any]:
    """Return the figures of GSR and RM on ``env_id``'s held-out episodes: what
    ``activetrack evaluate`` prints (to stdout) and writes (``results`` and ``episodes``)."""
    from activetrack._registry import ALL_IDS
    from activetrack.baselines.evaluation import run_evaluation

    preset = ALL_IDS[env_id]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        run_evaluation(list(POLICIES), preset, episodes, seed, out_dir=out, plot=False,
                       progress=False)  # fmt: skip
        results = json.loads((out / "results.json").read_text(encoding="utf-8"))
        per_episode = json.loads((out / "episodes.json").read_text(encoding="utf-8"))
    return {
        "env_id": env_id,
        "scenario": preset,
        "command": COMMAND,
        "evaluate": evaluate_command(preset, episodes, seed),
        "results": results,
        "episodes": per_episode,
    }


def main(argv: list[str] | None = None) -> int:
    """Write the media of the ids asked for (all by default) and print what it wrote."""
    from activetrack._registry import ALL_IDS
    from activetrack.files import atomic_write_text

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ids", nargs="+", choices=list(ALL_IDS), default=list(ALL_IDS),
                        help="the ids to render (default: every registered id)")  # fmt: skip
    parser.add_argument("--out", type=Path, default=OUT, help=f"folder (default {OUT})")
    parser.add_argument(
        "--episodes", type=int, default=EPISODES,
        help=f"held-out episodes from seed {SEED} (default %(default)s)",
    )  # fmt: skip
    parser.add_argument("--no-gif", action="store_true", help="only the figures")
    parser.add_argument("--no-figures", action="store_true", help="only the GIFs")
    args = parser.parse_args(argv)
    if args.out.exists() and not args.out.is_dir():
        parser.error(f"--out {args.out} is not a folder")
    args.out.mkdir(parents=True, exist_ok=True)
    for env_id in args.ids:
        start = time.perf_counter()
        name = name_of(env_id)
        if not args.no_gif:
            gif = render_gif(env_id, args.out / f"{name}.gif")
            print(f"wrote {gif} ({gif.stat().st_size / 1024:.0f} KB)")
        if not args.no_figures:
            data = figures(env_id, args.episodes)
            path = args.out / f"{name}.json"
            atomic_write_text(path, json.dumps(data, indent=1) + "\n")
            print(f"wrote {path}")
        print(f"{env_id}: {time.perf_counter() - start:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
