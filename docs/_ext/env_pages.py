"""Sphinx extension: one page per registered environment id, generated at build time.

For every id of :data:`activetrack._registry.ALL_IDS` it writes ``environments/<Name>.md``
(in the source folder, before Sphinx reads it; the folder is generated, not checked in):
a header table read from the environment itself (the Gymnasium and PettingZoo
environments made from the id, their spaces, the scenario's team, models and episode
length), a GIF of an episode of the expert, a usage example with its output, the expert's
and random motion's figures on the task's held-out episodes, the starting state, reward
and episode end (the environment's docstring sections and the id's scenario), the
keyword arguments with their defaults and accepted values (the scenario's field
specifications, :data:`activetrack.world._scenario_fields.BOUNDS`), then the manual, the
environment classes' docstrings. The GIF and the figures are made by
``python docs/scripts/render_env_media.py`` (checked in under ``_static/envs``); nothing
on these pages is written by hand, so nothing is written twice.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import os
import re
import tempfile
from pathlib import Path
from typing import Any

#: The folder of the generated pages, relative to the documentation's source folder.
OUT_DIR = "environments"
#: The folder of the pages' media (GIFs and figures), relative to the source folder.
MEDIA_DIR = "_static/envs"
#: The documentation's source folder of this checkout.
DOCS = Path(__file__).resolve().parents[1]
#: The command that makes the media (``docs/scripts/render_env_media.py``).
MEDIA_COMMAND = "python docs/scripts/render_env_media.py"
#: The docstring sections of :class:`TrackingParallelEnv` each page shows under its own
#: heading (Gymnasium's manual's sections), with this id's values after them.
SECTIONS = ("Starting State", "Rewards", "Episode End")


def page_name(env_id: str) -> str:
    """Return the page name of an id: ``activetrack/Urban-v0`` -> ``Urban-v0``."""
    return env_id.split("/", 1)[1]


def _code(value: Any) -> str:
    """Return ``value`` as inline code in a Markdown table cell."""
    return "`" + str(value).replace("|", "\\|") + "`"


def header_rows(env_id: str) -> list[tuple[str, str]]:
    """Return the header table of ``env_id`` as (field, Markdown value) rows, read from the
    environments ``gymnasium.make(env_id)`` and ``pettingzoo.make("parallel", env_id)``."""
    import gymnasium
    import pettingzoo

    import activetrack  # noqa: F401  (registers the ids)

    genv = gymnasium.make(env_id)
    penv = pettingzoo.make("parallel", env_id)
    try:
        sc = penv.unwrapped.scenario if hasattr(penv, "unwrapped") else penv.scenario
        agents = list(penv.possible_agents)
        agent0 = agents[0]
        shown = agents if len(agents) <= 4 else [agents[0], "...", agents[-1]]
        return [
            (
                "Import",
                _code(f'gymnasium.make("{env_id}")') + " after " + _code("import activetrack"),
            ),
            ("Gymnasium id", _code(env_id)),
            (
                "PettingZoo id",
                _code(f'pettingzoo.make("parallel", "{env_id}")') + " (or " + _code('"aec"') + ")",
            ),
            ("Scenario preset", _code(sc.name)),
            ("Agents", f"{len(agents)}: " + ", ".join(_code(a) for a in shown)),
            ("Action space (per agent)", _code(penv.action_space(agent0))),
            ("Action space (Gymnasium)", _code(genv.action_space)),
            ("Observation shape (per agent)", _code(penv.observation_space(agent0).shape)),
            ("Observation shape (Gymnasium)", _code(genv.observation_space.shape)),
            (
                "Observation layout",
                "[Concepts: the observation layout](../concepts.md#the-observation-layout)",
            ),
            ("State shape", _code(penv.state_space.shape)),
            ("Episode length", f"{_code(sc.n_steps)} steps of {_code(sc.dt)} s"),
            ("Targets", _code(sc.n_targets)),
            ("Sensor models", ", ".join(_code(s.name) for s in sc.sensor_objects)),
            ("Kinematics", ", ".join(_code(k) for k in sc.kinematics_models)),
        ]
    finally:
        genv.close()
        penv.close()


def _preset_table(preset: str) -> list[str]:
    """Return the Markdown table of a preset's fields (those that differ from the paper's)."""
    from activetrack.world.presets import PRESETS

    fields = {k: v for k, v in PRESETS[preset].items() if k != "name"}
    if not fields:
        return ["None: this is the paper's setup (Section V)."]
    return [
        "| field | value |",
        "|---|---|",
        *(f"| {_code(k)} | {_code(v)} |" for k, v in fields.items()),
    ]


def _rst(doc: str, config: Any) -> str:
    """Return a docstring as an ``{eval-rst}`` block: reStructuredText with Google-style
    sections (``Args:``), converted by napoleon as autodoc would."""
    from sphinx.ext.napoleon import Config, GoogleDocstring

    rst = str(GoogleDocstring(doc, config if config is not None else Config()))
    return "```{eval-rst}\n" + rst + "\n```\n"


def _manual(obj: Any, config: Any, without: tuple[str, ...] = ()) -> str:
    """Return the docstring of ``obj`` as an ``{eval-rst}`` block, less the sections
    ``without`` (shown under their own headings)."""
    doc = inspect.getdoc(obj) or ""
    for name in without:
        doc = _split_section(doc, name)[1]
    return _rst(doc, config)


def _split_section(doc: str, name: str) -> tuple[str, str]:
    """Return the body of the section ``name:`` of a Google-style docstring (dedented) and
    the docstring without it; raise ``ValueError`` if it has no such section."""
    match = re.search(rf"^{re.escape(name)}:\n((?:(?:    .*)?\n)+)", doc + "\n", re.M)
    if match is None:
        raise ValueError(f"the docstring has no section {name!r}")
    body = "\n".join(line[4:] for line in match.group(1).splitlines()).strip()
    rest = (doc + "\n")[: match.start()] + (doc + "\n")[match.end() :]
    return body, rest.strip() + "\n"


def env_section(name: str) -> str:
    """Return the section ``name`` (one of :data:`SECTIONS`) of the docstring of
    :class:`activetrack.envs.TrackingParallelEnv`."""
    from activetrack.envs.tracking_env import TrackingParallelEnv

    return _split_section(inspect.getdoc(TrackingParallelEnv) or "", name)[0]


def _section_values(name: str, sc: Any) -> list[str]:
    """Return the scenario's fields that section ``name`` speaks of, as Markdown lines."""
    fields = {
        "Starting State": ("target_init", "x0", "x0_hat", "P0", "sensor_center",
                           "sensor_radius", "random_occluders"),
        "Rewards": ("objective", "reward_scale", "n_targets"),
        "Episode End": ("n_steps", "dt", "max_trace"),
    }[name]  # fmt: skip
    values = ", ".join(f"{_code(k)} = {_code(repr(getattr(sc, k)))}" for k in fields)
    lines = [f"For this id: {values}."]
    if name == "Episode End":
        end = (
            "no termination (`max_trace` is None)"
            if sc.max_trace is None
            else f"termination once the trace exceeds {sc.max_trace:g}"
        )
        lines.append(
            f"An episode lasts {sc.n_steps} steps ({sc.n_steps * sc.dt:g} s of simulated "
            f"time); {end}."
        )
    return lines


def media(env_id: str, srcdir: str | os.PathLike[str] = DOCS) -> tuple[Path, dict[str, Any]]:
    """Return the path of ``env_id``'s GIF and its figures (the JSON beside it), both made
    by :data:`MEDIA_COMMAND`; raise ``FileNotFoundError`` naming the command if missing."""
    folder = Path(srcdir) / MEDIA_DIR
    name = page_name(env_id)
    gif, figures = folder / f"{name}.gif", folder / f"{name}.json"
    for path in (gif, figures):
        if not path.is_file():
            raise FileNotFoundError(
                f"{path} is missing: run `{MEDIA_COMMAND} --ids {env_id}` and commit it"
            )
    data = json.loads(figures.read_text(encoding="utf-8"))
    if data.get("env_id") != env_id:
        raise ValueError(f"{figures} holds the figures of {data.get('env_id')!r}, not {env_id!r}")
    return gif, data


def _g(x: float | None, digits: int = 4) -> str:
    """Return ``x`` to ``digits`` significant digits (``-`` for None)."""
    return "-" if x is None else f"{x:.{digits}g}"


def _sig(x: float, digits: int = 4) -> str:
    """Return ``x`` rounded to ``digits`` significant digits, in fixed notation with its
    trailing zeros (a number the page's output blocks compare to the printed value)."""
    decimals = max(0, digits - 1 - math.floor(math.log10(abs(x)))) if x else digits - 1
    return f"{x:.{decimals}f}"


def _with_ci(r: dict[str, Any], key: str, fmt: Any = _g) -> str:
    """Return ``r[key]`` with its ``_ci95`` interval, formatted by ``fmt``."""
    lo, hi = r[f"{key}_ci95"]
    return f"{fmt(r[key])} [{fmt(lo)}, {fmt(hi)}]"


def _ratio(x: float) -> str:
    return f"{x:.3f}"


def figures_table(data: dict[str, Any]) -> list[str]:
    """Return the figures of ``data`` (``render_env_media.py``'s JSON: ``activetrack
    evaluate``'s summaries) as a Markdown table in the reporting protocol's form, one row
    per policy: the IQM, median and mean of the episodes' mean traces with their
    intervals, the track-loss rate where sensing is limited, the paired ratios to GSR."""
    rows = data["results"]
    limited = any("no_detection" in r for r in rows)
    head = ["policy", "IQM trace (m²) [95% CI]", "median [95% CI]", "mean [95% CI]"]
    if limited:
        head += ["track loss [95% CI]", "steps without a detection (fraction)",
                 "longest gap (steps, worst episode)"]  # fmt: skip
    head += ["IQM ratio to GSR [paired 95% CI]", "mean ratio to GSR [paired 95% CI]",
             "RMSE (m)", "NEES", "CPU ms/decision", "return"]  # fmt: skip
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [
            _code(r["label"]),
            _with_ci(r, "iqm_trace"),
            _with_ci(r, "median_trace"),
            _with_ci(r, "mean_trace"),
        ]
        if limited:
            loss = "-" if "track_loss_rate" not in r else _with_ci(r, "track_loss_rate", _ratio)
            cells += [loss, f"{r['no_detection']:.3f}", str(r["longest_gap"])]
        cells += [
            _with_ci(r, "iqm_ratio_to_gsr", _ratio),
            _with_ci(r, "ratio_to_gsr", _ratio),
            f"{r['rmse']:.3f}",
            "-" if r["nees"] is None else f"{r['nees']:.2f}",
            _g(r["cpu_ms_per_decision"], 3),
            f"{r['mean_return']:.2f}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def argument_rows(env_id: str) -> list[tuple[str, str, str, str]]:
    """Return the keyword arguments ``gymnasium.make(env_id, ...)`` and
    ``pettingzoo.make(kind, env_id, ...)`` take, as (name, type, default for this id,
    accepted values) Markdown cells: the environment's own (its constructor's signature)
    and every :class:`activetrack.Scenario` field (its annotation, the id's value, and the
    accepted values of :func:`activetrack.world._scenario_fields.accepted`)."""
    from activetrack._registry import ALL_IDS
    from activetrack.envs.tracking_env import RENDER_MODES, TrackingParallelEnv
    from activetrack.world._scenario_fields import accepted
    from activetrack.world.presets import PRESETS
    from activetrack.world.scenarios import Scenario, make_scenario

    preset = ALL_IDS[env_id]
    sc = make_scenario(preset)
    sig = inspect.signature(TrackingParallelEnv.__init__).parameters
    own = {
        "scenario": (
            preset,
            "a preset name, "
            + ", ".join(repr(p) for p in PRESETS)
            + ", or an activetrack.Scenario",
        ),
        "render_mode": (
            sig["render_mode"].default,
            " or ".join(repr(m) for m in (None, *RENDER_MODES)),
        ),
    }
    rows = []
    for name, (default, values) in own.items():
        rows.append((_code(name), _code(sig[name].annotation), _code(repr(default)), values))
    for f in dataclasses.fields(Scenario):
        if not f.init:
            continue
        default = _code(repr(getattr(sc, f.name)))
        rows.append((_code(f.name), _code(f.type), default, accepted(f.name)))
    rows.append((_code("max_cycles"), _code("int"), _code(repr(sc.n_steps)),
                 "`n_steps` by PettingZoo's name (give one of them)"))  # fmt: skip
    return rows


def usage(env_id: str, data: dict[str, Any]) -> list[str]:
    """Return the page's usage example and its output: the expert's episode of the first
    held-out seed through Gymnasium, whose mean trace is the first of the figures'
    episodes (``data``); the shapes are the environment's spaces."""
    import gymnasium

    import activetrack  # noqa: F401  (registers the ids)

    episodes = data["episodes"]["policies"]["gsr"]
    seed, trace = episodes["seeds"][0], episodes["mean_trace"][0]
    env = gymnasium.make(env_id)
    try:
        obs_shape, act_shape = env.observation_space.shape, env.action_space.shape
        n_steps = env.unwrapped.scenario.n_steps
    finally:
        env.close()
    return [
        "```python",
        "import gymnasium",
        "import numpy as np",
        "",
        "import activetrack  # registers the ids",
        "from activetrack.baselines import GSRPolicy",
        "",
        f'env = gymnasium.make("{env_id}")',
        f"obs, info = env.reset(seed={seed})",
        "print(obs.shape, env.action_space.shape)",
        "",
        "# The expert plans next positions; the environment steps to them.",
        "expert, traces, done = GSRPolicy(), [], False",
        "while not done:",
        "    positions = expert.plan(env.unwrapped.planning_problem())",
        "    obs, reward, terminated, truncated, info = env.unwrapped.step_positions(positions)",
        '    traces.append(info["trace"])',
        "    done = terminated or truncated",
        "print(len(traces), np.mean(traces))",
        "```",
        "",
        "```text",
        f"{obs_shape} {act_shape}",
        f"{n_steps} {_sig(trace)}",
        "```",
    ]


def page(env_id: str, config: Any = None, srcdir: str | os.PathLike[str] = DOCS) -> str:
    """Return the Markdown source of the page of ``env_id`` (its media read from
    ``srcdir``'s :data:`MEDIA_DIR`)."""
    from activetrack._registry import ALL_IDS, TWO_TEAM_ENTRY_POINTS
    from activetrack.envs.centralized import CentralizedTrackingEnv
    from activetrack.envs.tracking_env import TrackingParallelEnv
    from activetrack.world.scenarios import make_scenario

    name = page_name(env_id)
    preset = ALL_IDS[env_id]
    sc = make_scenario(preset)
    rows = header_rows(env_id)
    gif, data = media(env_id, srcdir)
    gsr = data["episodes"]["policies"]["gsr"]
    seeds = gsr["seeds"]
    lines = [
        f"# {name}",
        "",
        "<!-- Generated by docs/_ext/env_pages.py from the environment; do not edit. -->",
        "",
        "| | |",
        "|---|---|",
        *(f"| {field} | {value} |" for field, value in rows),
        "",
        f"![GSR, the expert, on {env_id}, episode seed {seeds[0]}](../{MEDIA_DIR}/{gif.name})",
        "",
        f"The expert (GSR) on the episode of seed {seeds[0]}, drawn by the environment's "
        f'renderer (`render_mode="rgb_array"`, {{py:func}}`activetrack.envs.record_video`); '
        f"made by `{MEDIA_COMMAND}`.",
        "",
        "## Usage",
        "",
        "The expert's episode of the first held-out seed: its mean trace is the first of the",
        "episodes behind the figures below.",
        "",
        *usage(env_id, data),
        "",
        "## The expert and random motion",
        "",
        f"GSR (the expert, Section IV) and random motion (RM) on the task's {len(seeds)} held-out",
        f"episodes, seeds {seeds[0]}..{seeds[-1]}: `{data['evaluate']}` (made, with the GIF, by",
        f"`{MEDIA_COMMAND}`; every episode's figures are in `docs/{MEDIA_DIR}/{name}.json`).",
        "An episode's score is its mean trace, the mean of the posterior position trace over",
        "steps 1..n_steps. The table gives, in the [reporting protocol's](../results/protocol.md)",
        "form, the interquartile mean (IQM), the median and the mean of the episodes' scores",
        "with bootstrap 95% intervals (percentile for the IQM and the median, BCa for the",
        "mean), the ratios of the IQM and of the mean to GSR's with paired intervals on the same",
        "episodes and, where sensing is limited, the track-loss rate (the fraction of (step,",
        "target) pairs in which no sensor measured the target and its position trace was above",
        "the trace of its prior, `tr P0[:2, :2]`). CPU ms/decision was measured on the machine",
        "that ran the script.",
        "",
        *figures_table(data),
        "",
    ]
    for section in SECTIONS:
        lines += [
            f"## {section.capitalize()}",
            "",
            _rst(env_section(section), config),
            *_section_values(section, sc),
            "",
        ]
    lines += [
        "## Arguments",
        "",
        f'The keywords of `gymnasium.make("{env_id}", ...)` and',
        f'`pettingzoo.make("parallel" | "aec", "{env_id}", ...)`: the environment\'s own, then',
        "every scenario field ({py:class}`activetrack.Scenario`), each checked when the",
        "environment is made (a value outside its range raises a `ValueError` naming it).",
        "",
        "| argument | type | default | accepted values |",
        "|---|---|---|---|",
        *(f"| {a} | {t} | {d} | {v} |" for a, t, d, v in argument_rows(env_id)),
        "",
        "## The scenario",
        "",
        f"The preset {_code(preset)} (`activetrack.make_scenario({preset!r})`); its fields that",
        "differ from the paper's defaults:",
        "",
        *_preset_table(preset),
        "",
        "## The multi-agent environment (PettingZoo)",
        "",
        "{py:class}`activetrack.envs.TrackingParallelEnv`:",
        "",
        _manual(TrackingParallelEnv, config, without=SECTIONS),
        "## The single-agent view (Gymnasium)",
        "",
        "{py:class}`activetrack.envs.CentralizedTrackingEnv`:",
        "",
        _manual(CentralizedTrackingEnv, config),
        _manual(inspect.getmodule(CentralizedTrackingEnv), config),
    ]
    if env_id in TWO_TEAM_ENTRY_POINTS:  # PettingZoo's id is the two-team game
        from activetrack.envs.pursuit import PursuitParallelEnv

        lines += [
            "## The two-team game (PettingZoo)",
            "",
            f'`pettingzoo.make("parallel" | "aec", "{env_id}")` is the two-team game',
            "`activetrack.envs.pursuit.PursuitParallelEnv` (the sensors' side as above, the",
            "targets as agents); Gymnasium's view is the sensors' against the fallback:",
            "",
            _manual(PursuitParallelEnv, config),
            _manual(inspect.getmodule(PursuitParallelEnv), config),
        ]
    return "\n".join(lines)


def index_page(ids: list[str]) -> str:
    """Return the Markdown source of the environments' index page: a gallery of the
    expert's GIFs, each linking to its page."""
    lines = [
        "# Environments",
        "",
        "<!-- Generated by docs/_ext/env_pages.py from the registry; do not edit. -->",
        "",
        "Every registered id, for Gymnasium (`gymnasium.make`) and PettingZoo",
        '(`pettingzoo.make("parallel" | "aec", id)`), after `import activetrack`; each',
        f"picture is an episode of the expert (GSR), made by `{MEDIA_COMMAND}`.",
        "",
        "```{toctree}",
        ":maxdepth: 1",
        "",
        *(page_name(i) for i in ids),
        "```",
        "",
    ]
    # Inline images in one paragraph: they flow side by side, each linking to its page.
    lines.append(
        "\n".join(
            f"[![{i}: an episode of the expert](../{MEDIA_DIR}/{page_name(i)}.gif)]"
            f"({page_name(i)}.md)"
            for i in ids
        )
    )
    return "\n".join(lines) + "\n"


def _write(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file renamed into place, and only when
    it changed (so Sphinx does not re-read unchanged pages)."""
    if path.exists() and path.read_text(encoding="utf-8") == text:
        return
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def generate(srcdir: str | os.PathLike[str], config: Any = None) -> list[Path]:
    """Write every registered id's page and the index into ``srcdir/environments``; return
    the pages written (the index first)."""
    from activetrack._registry import ALL_IDS

    out = Path(srcdir) / OUT_DIR
    out.mkdir(exist_ok=True)
    ids = list(ALL_IDS)
    wanted = {
        "index.md": index_page(ids),
        **{f"{page_name(i)}.md": page(i, config, srcdir) for i in ids},
    }
    for stale in out.glob("*.md"):  # an id that was removed loses its page
        if stale.name not in wanted:
            stale.unlink()
    paths = []
    for fname, text in wanted.items():
        _write(out / fname, text)
        paths.append(out / fname)
    return paths


def _on_builder_inited(app: Any) -> None:
    generate(app.srcdir, app.config)


def setup(app: Any) -> dict[str, Any]:
    """Register the page generator with Sphinx."""
    app.connect("builder-inited", _on_builder_inited)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
