"""The ``activetrack`` command line (console script ``activetrack.cli:main``): the front door.

Each layer owns its subcommands: :mod:`activetrack.baselines.cli` adds ``simulate`` and
``evaluate``, :mod:`activetrack.train.cli` adds ``train``. A layer's module has
``add_parsers(subparsers)``, which adds its subcommands with all their options and sets
``func`` (the function that runs the command) and ``parser`` (its own parser, for error
messages). The front door imports a layer only when one of its commands is used, so
``activetrack --help`` lists the commands from :data:`COMMANDS` without importing the
layers (nor torch), and the core never depends on the layers above it.

Errors. Input is checked before any computation (the config dataclasses, policy files,
the output folder). A ``ValueError`` from a command is reported as argparse reports its
own errors: the command's usage and ``activetrack <command>: error: <message>``, exit
status 2. An ``OSError`` while writing outputs is reported the same way with status 1;
outputs are committed together, so the previous ones are then still in place (the message
says so). SIGINT and SIGTERM exit with 130 and 143 (:func:`main`).

This module also holds the small argparse helpers the layers share.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import math
import os
import signal
import sys
import threading
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

#: command -> (the module that owns it, its one-line summary in ``activetrack --help``).
COMMANDS: dict[str, tuple[str, str]] = {
    "simulate": (
        "activetrack.baselines.cli",
        "compare planners in the closed tracking loop (Monte Carlo over seeds)",
    ),
    "evaluate": (
        "activetrack.baselines.cli",
        "evaluate policies (planners or trained policy.zip files) on held-out seeds",
    ),
    "train": (
        "activetrack.train.cli",
        "train a policy: imitation of GSR (bc, dagger) or PPO (the [rl] extra)",
    ),
    "bench-learn": (
        "activetrack.train.cli",
        "benchmark BenchMARL's MARL algorithms on tasks: curves, marl-eval JSON, evaluation",
    ),
    "kernels": (
        "activetrack.kernel_cache",
        "compile the numba kernels now (or clear their cache) and report time and folder",
    ),
}


# Shared argparse helpers ------------------------------------------------------------------
def positive_int(text: str) -> int:
    """Parse an integer >= 1 (argparse ``type``)."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return value


def nonneg_int(text: str) -> int:
    """Parse an integer >= 0 (argparse ``type``)."""
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text}")
    return value


#: The largest seed a command takes (RLlib's; numpy and torch take it too).
MAX_SEED = 2**31 - 1


def seed_int(text: str) -> int:
    """Parse a seed, an integer in [0, MAX_SEED] (argparse ``type``)."""
    value = int(text)
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, {MAX_SEED}], got {text}")
    return value


def output_folder(text: str) -> Path:
    """Parse an output folder: a non-empty path (argparse ``type``; ``""`` is not ``.``)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("must be a folder path, got an empty string")
    return Path(text)


def positive_float(text: str) -> float:
    """Parse a finite number > 0 (argparse ``type``)."""
    value = float(text)
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def field_default(cls: type, name: str) -> Any:
    """Return the default of the dataclass field ``name`` of ``cls`` (the one definition)."""
    for f in dataclasses.fields(cls):
        if f.name == name:
            if f.default is not dataclasses.MISSING:
                return f.default
            if f.default_factory is not dataclasses.MISSING:
                return f.default_factory()
            break
    raise KeyError(f"{cls.__name__} has no field {name!r} with a default")


def add_output_arguments(
    parser: argparse.ArgumentParser, default: Path | None, required: bool = False
) -> None:
    """Add ``--out`` and ``--overwrite`` (refuse a folder holding results without it)."""
    kw: dict[str, Any] = {"required": True} if required else {"default": default}
    parser.add_argument(
        "--out",
        type=output_folder,
        help="output folder" + ("" if required else f" (default: {default or 'none'})"),
        **kw,
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the results already in --out (only the files this command writes)",
    )


# The parser and main ----------------------------------------------------------------------
def build_parser(commands: Iterable[str] | None = None) -> argparse.ArgumentParser:
    """Return the ``activetrack`` parser.

    The layers owning ``commands`` (default: every command) add their full subparsers;
    the other commands are listed with their summary only (and cannot be parsed).
    """
    from activetrack import __version__

    wanted = set(COMMANDS) if commands is None else set(commands)
    modules = {COMMANDS[c][0] for c in wanted if c in COMMANDS}
    parser = argparse.ArgumentParser(
        prog="activetrack",
        description="Multi-robot active target tracking (range-bearing, speed and distance "
        "limits): planners, simulation and environments.",
    )
    parser.add_argument("--version", action="version", version=f"activetrack {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    loaded: set[str] = set()
    for name, (module, summary) in COMMANDS.items():
        if module not in modules:
            sub.add_parser(name, help=summary)
        elif module not in loaded:
            importlib.import_module(module).add_parsers(sub)
            loaded.add(module)
    return parser


def _command_of(argv: Sequence[str]) -> str | None:
    """Return the command word of ``argv`` (the first argument that is not an option)."""
    return next((a for a in argv if not a.startswith("-")), None)


class _SignalHandler:
    """Raise :class:`~activetrack.files.Interrupted` on SIGINT or SIGTERM while armed; once
    disarmed (the command has returned, or an interrupt is being reported), ignore them."""

    def __init__(self) -> None:
        self.armed = True
        self.signum: int | None = None  # the signal taken, reported even if a library
        # (Ray's ``get``) turned its exception into a plain KeyboardInterrupt

    def __call__(self, signum: int, frame: Any) -> None:
        if self.armed:
            self.armed = False  # the report of this interrupt is not cut short by another
            self.signum = signum
            from activetrack.files import Interrupted

            raise Interrupted(signum)


def _folders_report(runs: list[Any]) -> str:
    """Return what the output folders of ``runs`` hold now, or that none was touched."""
    if not runs:
        return "no output folder was touched"
    return "; ".join(run.describe() for run in runs)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line with ``argv`` (default ``sys.argv[1:]``); return the exit code.

    SIGINT (Ctrl-C) and SIGTERM stop a command the same way: the run's staged outputs are
    removed, and the exit status is 128 + the signal (130, 143) with one line saying what
    the output folder holds (the previous results, or, if the signal came after the
    commit, the new ones; never a mix). Once the command has returned, a signal changes
    nothing: as the program (``argv`` None) the process exits with the command's status.
    """
    console = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    command = _command_of(argv)
    parser = build_parser([command] if command in COMMANDS else [])
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    sub = getattr(args, "parser", parser)
    from activetrack.files import SIGNALS, recorded_runs

    handler = _SignalHandler()
    in_main = threading.current_thread() is threading.main_thread()
    previous = {s: signal.signal(s, handler) for s in SIGNALS} if in_main else {}
    runs: list[Any] = []
    try:
        with recorded_runs() as runs:
            try:
                code = int(args.func(args) or 0)
            except ValueError as exc:  # bad input, found before computing: argparse style
                sub.print_usage(sys.stderr)
                print(f"{sub.prog}: error: {exc}", file=sys.stderr)
                code = 2
            except OSError as exc:  # e.g. writing the outputs failed
                print(f"{sub.prog}: error: {exc} ({_folders_report(runs)})", file=sys.stderr)
                code = 1
            handler.armed = False  # done: a signal now changes nothing on disk
    except KeyboardInterrupt as exc:  # Ctrl-C or SIGTERM: the staged outputs are removed
        handler.armed = False
        signum = int(getattr(exc, "signum", None) or handler.signum or signal.SIGINT)
        name = signal.Signals(signum).name
        print(f"\n{sub.prog}: interrupted ({name}); {_folders_report(runs)}", file=sys.stderr)
        code = 128 + signum
    finally:
        # Called with arguments (a test, a script): the caller's handlers come back. As
        # the program (no arguments), the process only exits next, with the folder in
        # its final state: a signal now is ignored (Python's finalization would restore
        # the default action, and SIGTERM would kill the process without a word).
        for s, old in previous.items():
            if console:
                signal.signal(s, signal.SIG_IGN)
            else:
                signal.signal(s, signal.SIG_DFL if old is None else old)
    if console and code >= 128 and "ray" in sys.modules:
        # Interrupted with Ray loaded (its session already shut down): the interpreter's
        # finalization can crash in Ray's native core (SIGSEGV) after the message; the
        # folder is final, so leave with the status the message stands for.
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


if __name__ == "__main__":
    raise SystemExit(main())
