"""Safe output files: every file is written to a temporary file in its folder and renamed.

A write that fails half-way (disk full, a file size limit, an interrupt) leaves the
previous file in place and no temporary file behind:

- :func:`atomic_path` yields a temporary path beside the target (same suffix, so tools
  that pick a format from the suffix, like matplotlib, still do); on success the file is
  flushed to disk and renamed onto the target, on failure it is removed;
- :func:`atomic_write_bytes`, :func:`atomic_write_text`, :func:`atomic_write_json` write
  one file that way;
- :func:`prepare_output_dir` checks an output folder before any computation and returns
  a :class:`RunOutputs`, which stages all of a run's files and commits them together: the
  folder then holds either every new file or every old one (a rename cannot run out of
  space, so only a crash between two renames can mix them).

Nothing here imports numpy or the layers above the core.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

__all__ = [
    "RunOutputs",
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "prepare_output_dir",
]

#: Prefix of the temporary files this module creates (hidden, recognizable).
TEMP_PREFIX = ".tmp-"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync_dir(folder: Path) -> None:
    """Flush a folder's entries (the renames) to disk, where the platform allows it."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _fsync_file(path: Path) -> None:
    with open(path, "rb+") as f:
        f.flush()
        os.fsync(f.fileno())


def _temp_path(target: Path) -> Path:
    """Create and return an empty temporary file beside ``target`` with the same suffix."""
    fd, name = tempfile.mkstemp(
        dir=target.parent, prefix=f"{TEMP_PREFIX}{target.stem}-", suffix=target.suffix
    )
    os.close(fd)
    # mkstemp makes the file private (0600); outputs get the usual mode (0666 minus umask).
    os.chmod(name, 0o666 & ~_umask())
    return Path(name)


def _unlink(path: Path) -> None:
    with contextlib.suppress(FileNotFoundError):
        path.unlink()


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write ``path``'s new content to; rename it into place.

    The temporary file is in the same folder (so the rename is atomic) and has the same
    suffix. If the block raises, the temporary file is removed and ``path`` is untouched.
    """
    target = Path(path)
    tmp = _temp_path(target)
    try:
        yield tmp
        _fsync_file(tmp)
        os.replace(tmp, target)
    except BaseException as exc:
        _unlink(tmp)
        if isinstance(exc, OSError) and exc.filename in (None, str(tmp)):
            exc.filename = str(target)  # the user's file, not the temporary (or no) name
        raise
    _fsync_dir(target.parent)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; return the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically; return the path."""
    return atomic_write_bytes(path, text.encode(encoding))


def json_text(obj: Any, *, indent: int | None = 2, default: Callable[[Any], Any] | None = None):
    """Return ``obj`` as standard JSON text ending with a newline (numpy values via
    ``default``); a NaN or infinity raises ``ValueError`` (JSON has neither: write None)."""
    return json.dumps(obj, indent=indent, default=default, allow_nan=False) + "\n"


def atomic_write_json(
    path: str | Path,
    obj: Any,
    *,
    indent: int | None = 2,
    default: Callable[[Any], Any] | None = None,
) -> Path:
    """Write ``obj`` as JSON to ``path`` atomically; return the path.

    The text is serialized before the file is opened, so an object that is not
    serializable raises ``TypeError`` and leaves no file.
    """
    return atomic_write_text(path, json_text(obj, indent=indent, default=default))


def _is_empty_dir(path: Path) -> bool:
    return path.is_dir() and not any(path.iterdir())


class RunOutputs:
    """The output folder of one run: staged files, committed together.

    Create it with :func:`prepare_output_dir`. :meth:`staged` returns a temporary path for
    one of the owned names; :meth:`commit` renames every staged file into place and removes
    the owned files that this run did not write (e.g. an old figure after ``--no-plot``),
    so no stale output stays beside new ones; :meth:`discard` removes the staged files. As
    a context manager it discards on an exception (it never commits by itself).

    Attributes:
        folder: the output folder.
        owned: the names (files, or folders ending in ``/``) the run may write.
    """

    def __init__(self, folder: Path, owned: tuple[str, ...]) -> None:
        self.folder = folder
        self.owned = owned
        self._staged: dict[str, Path] = {}

    def path(self, name: str) -> Path:
        """Return the final path of the owned ``name``."""
        if name not in self.owned:
            raise ValueError(f"{name!r} is not one of this run's outputs {list(self.owned)}")
        return self.folder / name.rstrip("/")

    def staged(self, name: str) -> Path:
        """Return the temporary path where ``name``'s new content goes (created empty; the
        folder too, if it does not exist yet)."""
        final = self.path(name)
        if name not in self._staged:
            self.folder.mkdir(parents=True, exist_ok=True)
            self._staged[name] = _temp_path(final)
        return self._staged[name]

    def write_bytes(self, name: str, data: bytes) -> Path:
        """Stage ``data`` as ``name``; return the final path."""
        self.staged(name).write_bytes(data)
        return self.path(name)

    def write_text(self, name: str, text: str) -> Path:
        """Stage ``text`` (UTF-8) as ``name``; return the final path."""
        return self.write_bytes(name, text.encode("utf-8"))

    def write_json(self, name: str, obj: Any, **kwargs: Any) -> Path:
        """Stage ``obj`` as JSON (see :func:`json_text`) as ``name``; return the final path."""
        return self.write_text(name, json_text(obj, **kwargs))

    def commit(self) -> dict[str, Path]:
        """Rename every staged file into place; return the written paths by name.

        Every staged file is flushed to disk before the first rename, so a failure there
        (the disk full) leaves all the old outputs. Owned files the run did not stage are
        removed (owned folders, written during the run, are left alone).
        """
        try:
            for tmp in self._staged.values():
                _fsync_file(tmp)
        except BaseException as exc:
            self.discard(exc)
            raise
        written = {}
        for name, tmp in self._staged.items():
            os.replace(tmp, self.path(name))
            written[name] = self.path(name)
        for name in self.owned:
            if name.endswith("/") or name in self._staged:
                continue
            _unlink(self.path(name))
        self._staged = {}
        _fsync_dir(self.folder)
        return written

    def discard(self, exc: BaseException | None = None) -> None:
        """Remove every staged temporary file (the old outputs stay); an ``OSError`` that
        names one of them is made to name the output it stood for."""
        for name, tmp in self._staged.items():
            _unlink(tmp)
            if isinstance(exc, OSError) and exc.filename == str(tmp):
                exc.filename = str(self.path(name))
        self._staged = {}

    def __enter__(self) -> RunOutputs:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is not None:
            self.discard(exc)


def prepare_output_dir(
    path: str | Path, owned: Iterable[str], overwrite: bool = False
) -> RunOutputs:
    """Check the output folder ``path`` before a run; return its :class:`RunOutputs`.

    Checks that the folder, or the nearest existing folder above it, can take a new file
    (the folder itself is made when the first output is staged, so a run that fails or is
    interrupted before writing leaves no empty folder behind). Raises ``ValueError``
    naming the folder if it cannot be used, or if it already holds one of
    the ``owned`` names (files, or non-empty folders written as ``"name/"``) and
    ``overwrite`` is false. With ``overwrite``, owned folders are emptied now (the run
    writes into them as it goes); owned files are replaced only when the run commits, so
    the old ones survive a failed run.
    """
    if not str(path).strip():
        raise ValueError(f"the output folder must be a non-empty path, got {str(path)!r}")
    folder = Path(path)
    owned = tuple(owned)
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{folder}: exists and is not a folder")
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"{folder}: {existing} is not a folder")
    try:
        fd, probe = tempfile.mkstemp(dir=existing, prefix=TEMP_PREFIX)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise ValueError(f"{folder}: cannot write to this folder ({exc.strerror or exc})") from exc
    present = []
    for name in owned:
        p = folder / name.rstrip("/")
        if (name.endswith("/") and p.exists() and not _is_empty_dir(p)) or (
            not name.endswith("/") and p.exists()
        ):
            present.append(name)
    if present and not overwrite:
        raise ValueError(
            f"{folder}: already holds results ({', '.join(present)}); pass --overwrite to "
            "replace them, or choose another folder"
        )
    for name in present:
        p = folder / name.rstrip("/")
        if name.endswith("/"):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            else:
                _unlink(p)
        elif p.is_dir():
            raise ValueError(f"{p}: is a folder, expected a file")
    return RunOutputs(folder, owned)
