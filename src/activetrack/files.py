"""Safe output files: every file is written to a temporary file in its folder and renamed.

A write that fails half-way (disk full, a file size limit, an interrupt) leaves the
previous file in place and no temporary file behind:

- :func:`atomic_path` yields a temporary path beside the target (same suffix, so tools
  that pick a format from the suffix, like matplotlib, still do); on success the file is
  flushed to disk and renamed onto the target, on failure it is removed;
- :func:`atomic_write_bytes`, :func:`atomic_write_text`, :func:`atomic_write_json` write
  one file that way;
- :func:`prepare_output_dir` checks an output folder before any computation, locks it for
  the run and returns a :class:`RunOutputs`: the run writes its files *and folders* (TensorBoard
  logs, checkpoints) into a private staging folder ``OUT/.tmp-run-*`` and commits them
  together at the end; the folder then holds either every new output or every old one (a
  rename cannot run out of space; SIGINT and SIGTERM are held back during the renames, so
  only a hard crash, such as SIGKILL, between two renames can mix them). A second run on
  the same folder is refused while the first one runs (:func:`prepare_output_dir`).

Signals: :func:`signals_deferred` holds SIGINT and SIGTERM back during a few file
operations; :func:`keep_signal_handlers` restores the handlers a library (Ray) replaces.

Nothing here imports numpy or the layers above the core.
"""

from __future__ import annotations

import contextlib
import contextvars
import json
import os
import shutil
import signal
import tempfile
import threading
import weakref
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

try:  # POSIX: the output folder is locked with flock (elsewhere: checked at the commit)
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

__all__ = [
    "Interrupted",
    "RunOutputs",
    "atomic_path",
    "keep_signal_handlers",
    "recorded_runs",
    "signals_deferred",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "prepare_output_dir",
]

#: Prefix of the temporary files this module creates (hidden, recognizable).
TEMP_PREFIX = ".tmp-"
#: Prefix of a run's staging folder inside its output folder.
STAGING_PREFIX = f"{TEMP_PREFIX}run-"
#: The signals a run's file operations hold back (and the command line handles).
SIGNALS = (signal.SIGINT, signal.SIGTERM)
_HAS_SIGMASK = hasattr(signal, "pthread_sigmask")


# Signals ----------------------------------------------------------------------------------
@contextlib.contextmanager
def signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM back inside the block; deliver them (once each) after it.

    The renames of a commit and the removal of a staging folder then run to the end: an
    interrupt arrives after them, to the handler that was in place before. Only the main
    thread can set handlers; elsewhere the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []

    def hold(signum: int, frame: Any) -> None:
        if signum not in pending:
            pending.append(signum)

    previous = {s: signal.signal(s, hold) for s in SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        for s in pending:
            signal.raise_signal(s)  # now handled as it would have been


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM during a command (a ``KeyboardInterrupt``, so every clean-up that
    Ctrl-C runs runs for SIGTERM too). ``signum`` is the signal."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextlib.contextmanager
def keep_signal_handlers() -> Iterator[None]:
    """Restore the SIGINT and SIGTERM handlers after the block (``ray.init`` replaces the
    SIGTERM one with its own, which exits without the command's clean-up). A SIGTERM that
    Ray's handler turned into ``SystemExit(15)`` inside the block leaves it as
    :class:`Interrupted`."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in SIGNALS}
    # Blocked meanwhile (in this thread, and in the threads the block starts, which
    # inherit the mask): Ray's native failure handler, installed by ray.init, would take
    # a SIGTERM with a stack dump and an abort. A signal sent meanwhile waits for the end.
    blocked = signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS) if _HAS_SIGMASK else None
    try:
        yield
    except SystemExit as exc:
        if exc.code == signal.SIGTERM:
            raise Interrupted(signal.SIGTERM) from None
        raise
    finally:
        for s, handler in previous.items():
            if handler is not None and signal.getsignal(s) is not handler:
                signal.signal(s, handler)
        if blocked is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, blocked)  # a pending one arrives now


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
    tmp: Path | None = None
    try:
        with signals_deferred():  # an interrupt cannot fall between making and naming it
            tmp = _temp_path(target)
        yield tmp
        _fsync_file(tmp)
        os.replace(tmp, target)
    except BaseException as exc:
        if tmp is None:
            raise
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
    return path.is_dir() and not path.is_symlink() and not any(path.iterdir())


def _holds(folder: Path, name: str) -> bool:
    """Return whether ``folder`` holds results under the owned ``name`` (a file, or a
    non-empty folder for a name ending in ``/``)."""
    p = folder / name.rstrip("/")
    if name.endswith("/"):
        return (p.exists() or p.is_symlink()) and not _is_empty_dir(p)
    return p.exists() or p.is_symlink()


def _remove(path: Path) -> None:
    """Remove a file, a symbolic link or a folder tree (what is not there is fine)."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        _unlink(path)


#: The runs prepared in the current context (for the command line's messages).
_RECORDER: contextvars.ContextVar[list[RunOutputs] | None] = contextvars.ContextVar(
    "activetrack_runs", default=None
)


@contextlib.contextmanager
def recorded_runs() -> Iterator[list[RunOutputs]]:
    """Yield the list of the :class:`RunOutputs` prepared inside the block, in order (the
    command line reports what each output folder holds after an interrupt or an error)."""
    runs: list[RunOutputs] = []
    token = _RECORDER.set(runs)
    try:
        yield runs
    finally:
        _RECORDER.reset(token)


class RunOutputs:
    """The output folder of one run: locked, its outputs staged, then committed together.

    Create it with :func:`prepare_output_dir`, and use it as a context manager around the
    whole run: on leaving the block, uncommitted outputs are discarded, a folder the run
    made and left empty is removed, and the lock is released (:meth:`close`).

    :meth:`staged` returns where one of the owned names goes during the run: a path in
    the private staging folder ``OUT/.tmp-run-*`` (for a folder name, ending in ``/``,
    the folder itself, made empty: TensorBoard logs and checkpoints are read there while
    the run goes on). :meth:`commit` moves every staged output into place, replacing the
    old ones, and removes the owned names this run did not write (e.g. an old figure after
    ``--no-plot``), so no stale output stays beside new ones. :meth:`discard` removes the
    staged outputs: the old ones are untouched until the commit.

    Attributes:
        folder: the output folder.
        owned: the names (files, or folders ending in ``/``) the run may write.
        state: ``"open"``, ``"committed"``, ``"discarded"`` (or ``"failed"``: a rename of
            the commit failed, which a writable folder does not do).
    """

    def __init__(
        self,
        folder: Path,
        owned: tuple[str, ...],
        overwrite: bool = False,
        *,
        previous: tuple[str, ...] = (),
        created: tuple[Path, ...] = (),
        lock_fd: int | None = None,
    ) -> None:
        self.folder = folder
        self.owned = owned
        self.overwrite = overwrite
        self.previous = previous  # the owned names that held results when the run began
        self.state = "open"
        self.folder_removed = False
        self._created = created  # folders made for this run, outermost first
        self._lock_fd = lock_fd
        self._staging: Path | None = None
        self._staged: dict[str, Path] = {}
        # Clean up even if the owner never closes (a library caller; the interpreter exit).
        self._finalizer = weakref.finalize(self, _release, lock_fd)

    def path(self, name: str) -> Path:
        """Return the final path of the owned ``name``."""
        if name not in self.owned:
            raise ValueError(f"{name!r} is not one of this run's outputs {list(self.owned)}")
        return self.folder / name.rstrip("/")

    @property
    def staging(self) -> Path:
        """Return the run's private staging folder (made at the first use)."""
        if self.state != "open":
            raise RuntimeError(f"{self.folder}: this run's outputs are already {self.state}")
        if self._staging is None:
            # An interrupt waits until the folder is made and recorded, so the clean-up
            # that the interrupt runs knows it.
            with signals_deferred():
                self._staging = Path(tempfile.mkdtemp(dir=self.folder, prefix=STAGING_PREFIX))
            os.chmod(self._staging, 0o777 & ~_umask())
        return self._staging

    def staged(self, name: str) -> Path:
        """Return where ``name``'s new content goes until the commit: a path in the staging
        folder (a folder name's folder is made, empty)."""
        self.path(name)  # an owned name
        if name not in self._staged:
            target = self.staging / name.rstrip("/")
            if name.endswith("/"):
                target.mkdir()
            self._staged[name] = target
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
        """Move every staged output into place; return the final paths by name.

        Every staged file is flushed to disk before the first rename, so a failure there
        (the disk full, a file not written) leaves all the old outputs. Without the lock (a
        file system without ``flock``), results that another run wrote meanwhile make the
        commit refuse (``ValueError``) unless the run overwrites. The owned names the run did
        not stage are removed. SIGINT and SIGTERM wait until the renames are done.
        """
        if self.state != "open":
            raise RuntimeError(f"{self.folder}: this run's outputs are already {self.state}")
        try:
            for name, staged in self._staged.items():
                if not name.endswith("/"):
                    _fsync_file(staged)
            appeared = [n for n in self.owned if n not in self.previous and _holds(self.folder, n)]
            if appeared and not self.overwrite:
                raise ValueError(
                    f"{self.folder}: another run wrote results ({', '.join(appeared)}) while "
                    "this one ran; this run's outputs were not written"
                )
        except BaseException as exc:
            self.discard(exc)
            raise
        with signals_deferred():
            old = self.staging / ".old"  # where the replaced outputs go before removal
            old.mkdir()
            written = {}
            try:
                for name in self.owned:
                    final = self.path(name)
                    staged = self._staged.get(name)
                    if staged is not None and not name.endswith("/") and not final.is_dir():
                        os.replace(staged, final)  # a file onto a file: atomic
                    else:
                        if final.exists() or final.is_symlink():
                            os.rename(final, old / final.name)
                        if staged is not None:
                            os.rename(staged, final)
                    if staged is not None:
                        written[name] = final
            except BaseException:
                # A rename failed part-way (it should not: same folder, checked writable):
                # the staging folder, with the replaced outputs in .old, is kept for the
                # user under a name the next run does not clean up.
                kept = self.folder / f".failed-commit-{self.staging.name}"
                with contextlib.suppress(OSError):
                    os.rename(self.staging, kept)
                self.state, self._staging = "failed", None
                raise
            self._staged = {}
            self.state = "committed"
            _fsync_dir(self.folder)
            self._remove_staging()
        return written

    def discard(self, exc: BaseException | None = None) -> None:
        """Remove the staged outputs (the old ones stay); an ``OSError`` that names one of
        them is made to name the output it stood for."""
        with signals_deferred():
            if isinstance(exc, OSError) and exc.filename is not None:
                for name, staged in self._staged.items():
                    if str(exc.filename).startswith(str(staged)):
                        exc.filename = str(self.path(name))
                        break
            self._staged = {}
            if self.state == "open":
                self.state = "discarded"
            self._remove_staging()

    def close(self) -> None:
        """End the run: discard what was not committed, remove the folders made for it if
        the run left them empty, and release the lock (idempotent)."""
        with signals_deferred():
            if self.state == "open":
                self.discard()
            if self.state == "discarded":
                for folder in reversed(self._created):
                    try:
                        folder.rmdir()  # only if empty: someone else's files stay
                    except OSError:
                        break
                    if folder == self.folder:
                        self.folder_removed = True
                self._created = ()
            self._finalizer()

    def describe(self) -> str:
        """Return one sentence saying what the output folder holds after this run."""
        if self.state == "committed":
            return f"{self.folder} holds this run's complete new results"
        if self.state == "failed":
            return (
                f"{self.folder}: the commit failed part-way; the replaced outputs are in "
                f".failed-commit-{STAGING_PREFIX}*/.old there"
            )
        if self.previous:
            return f"{self.folder} still holds its previous results, unchanged"
        removed = " (the folder made for it was removed)" if self.folder_removed else ""
        return f"no results were written to {self.folder}{removed}"

    def _remove_staging(self) -> None:
        if self._staging is not None:
            shutil.rmtree(self._staging, ignore_errors=True)
            self._staging = None

    def __enter__(self) -> RunOutputs:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if exc_type is not None and self.state == "open":
            self.discard(exc)
        self.close()


def _release(lock_fd: int | None) -> None:
    if lock_fd is not None:
        with contextlib.suppress(OSError):
            os.close(lock_fd)  # releases the flock


def _dangling_link(folder: Path) -> Path | None:
    """Return the first of ``folder`` and its parents that is a link to nothing, if any."""
    for p in (*reversed(folder.parents), folder):
        if p.is_symlink() and not p.exists():
            return p
    return None


def _lock(folder: Path) -> int | None:
    """Lock ``folder`` (an existing folder) for this run; return the descriptor holding the
    lock, or None where ``flock`` is unavailable. Raise ``BlockingIOError`` if another run
    holds it."""
    if fcntl is None:  # pragma: no cover - Windows
        return None
    fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise
    except OSError:  # a file system without flock: the commit checks instead
        os.close(fd)
        return None
    return fd


def prepare_output_dir(
    path: str | Path, owned: Iterable[str], overwrite: bool = False
) -> RunOutputs:
    """Check the output folder ``path`` before a run, lock it; return its :class:`RunOutputs`.

    Makes the folder if needed (the :class:`RunOutputs` removes it again if the run writes
    nothing) and locks it for the run: another run on the same folder is refused until this
    one ends. Raises ``ValueError`` naming the folder if it cannot be used (not a folder, a
    link to nothing, a name too long, not writable), if another run holds it, or if it
    already holds one of the ``owned`` names (files, or non-empty folders written as
    ``"name/"``) and ``overwrite`` is false. Nothing is replaced now, with ``overwrite``
    either: the old outputs, folders included, stay until the run commits. Left-over
    staging files of a run that was killed are removed.
    """
    if not str(path).strip():
        raise ValueError(f"the output folder must be a non-empty path, got {str(path)!r}")
    folder = Path(path)
    owned = tuple(owned)
    try:  # a name too long (ENAMETOOLONG) fails already when looked at
        missing = _check_path(folder)
    except OSError as exc:
        raise ValueError(f"{folder}: cannot write to this folder ({exc.strerror or exc})") from exc
    for attempt in range(5):  # the folder may vanish (a run ending) between the steps: retry
        made = False
        try:
            folder.mkdir(parents=True, exist_ok=True)
            made = True
            with signals_deferred():  # the probe never outlives an interrupt
                fd, probe = tempfile.mkstemp(dir=folder, prefix=TEMP_PREFIX)
                os.close(fd)
                os.unlink(probe)
        except OSError as exc:
            if made and isinstance(exc, FileNotFoundError) and attempt < 4:
                continue  # made, then removed by a run ending: make it again
            _remove_empty(missing)
            raise ValueError(
                f"{folder}: cannot write to this folder ({exc.strerror or exc})"
            ) from exc
        try:
            lock_fd = _lock(folder)
        except BlockingIOError:
            raise ValueError(
                f"{folder}: another run is writing to this folder; wait for it to finish, "
                "or choose another folder"
            ) from None
        except FileNotFoundError:
            continue
        if lock_fd is None or _same_folder(lock_fd, folder):
            break
        os.close(lock_fd)  # locked a folder that was removed meanwhile: again
    else:
        raise ValueError(f"{folder}: the folder keeps being removed by another process")
    outputs = RunOutputs(folder, owned, overwrite, created=tuple(missing), lock_fd=lock_fd)
    try:
        if lock_fd is not None:
            for stale in folder.glob(f"{TEMP_PREFIX}*"):  # a killed run's (the folder is ours)
                _remove(stale)
        present = tuple(name for name in owned if _holds(folder, name))
        if present and not overwrite:
            raise ValueError(
                f"{folder}: already holds results ({', '.join(present)}); pass --overwrite to "
                "replace them, or choose another folder"
            )
        for name in present:
            p = folder / name.rstrip("/")
            if not name.endswith("/") and p.is_dir():
                raise ValueError(f"{p}: is a folder, expected a file")
        outputs.previous = present
    except BaseException:
        outputs.close()
        raise
    recorder = _RECORDER.get()
    if recorder is not None:
        recorder.append(outputs)
    return outputs


def _check_path(folder: Path) -> list[Path]:
    """Raise ``ValueError`` if ``folder`` cannot be an output folder; return the folders
    that must be made for it, outermost first."""
    dangling = _dangling_link(folder)
    if dangling is not None:
        raise ValueError(
            f"{folder}: {dangling} is a symbolic link to {os.readlink(dangling)}, "
            "which does not exist"
        )
    if folder.exists() and not folder.is_dir():
        raise ValueError(f"{folder}: exists and is not a folder")
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"{folder}: {existing} is not a folder")
    return [p for p in (folder, *folder.parents) if not p.exists()][::-1]


def _same_folder(fd: int, folder: Path) -> bool:
    try:
        return os.path.samestat(os.fstat(fd), os.stat(folder))
    except FileNotFoundError:
        return False


def _remove_empty(folders: list[Path]) -> None:
    """Remove the (empty) ``folders``, innermost first, stopping at one that is not."""
    for p in reversed(folders):
        try:
            p.rmdir()
        except OSError:
            return
