"""Studies spread over Ray tasks by seed: Monte Carlo runs, evaluation episodes, expert labels.

A study is a list of *jobs*, each a chunk of seeds; :func:`run_tasks` computes
``fn(*job)`` for every job as a Ray task and returns the results in job order, so the
caller assembles exactly what its serial loop would have (the task runs the serial code
path on its seeds: the same function, the same per-seed random streams, so the numbers
are bit-identical whatever the number of workers). No equation is computed here.

- Ray: ``ray.init(address=ADDR)`` joins a running cluster; without an address a local Ray
  with ``num_cpus=workers`` is started for the study (``address="local"``, so a cluster
  someone else started on the machine is never joined by accident) and shut down after
  it. A Ray already initialized by the caller (a notebook, the tests) is used as it is and
  left running.
- Failures: a task whose worker process dies is resubmitted by Ray (``max_retries``);
  results are keyed by job, each job's result is taken once, so a retried chunk is neither
  lost nor counted twice. An exception raised by the code itself is not retried: it
  reaches the caller (as Ray's ``RayTaskError``, which is also an instance of the
  original exception's class).
- Progress: ``on_done(job_index)`` is called as each job completes (``ray.wait``), which
  the callers use to advance their tqdm bar by the chunk's runs.

Ray is imported only inside these functions: the library imports without it, and asking
for workers without it raises :class:`RayNotInstalledError`, which names the extra.
"""

from __future__ import annotations

import re
import socket
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TypeVar

import numpy as np

R = TypeVar("R")

#: How to install Ray with the library.
INSTALL_HINT = 'pip install "activetrack[ray]"'
#: Resubmissions of a task whose worker died (Ray's own default is 3 as well).
MAX_RETRIES = 3
#: Seconds to wait for a cluster's port to answer before Ray is asked to join it (Ray
#: itself retries an unreachable address for minutes).
CONNECT_TIMEOUT = 5.0
#: Jobs per CPU: small enough chunks for a steady progress bar and little lost on a retry,
#: large enough that Ray's per-task overhead stays small beside the runs.
JOBS_PER_CPU = 4


class RayNotInstalledError(ImportError, ValueError):
    """Workers or an address were asked for without Ray installed.

    An ``ImportError`` for library callers, and a ``ValueError`` so the command line
    reports it like any other bad option (usage line, exit status 2).
    """


#: The most local Ray workers a study asks for (a cluster's size comes from --address).
MAX_WORKERS = 1024


def check_options(workers: Any = 1, address: Any = None) -> tuple[int, str | None]:
    """Return ``(workers, address)`` checked and converted (ValueError naming the field).

    ``workers`` is an integer >= 1 (1 with no address: the serial code path);
    ``address`` is None or a non-empty string (a Ray cluster, e.g. ``"auto"`` or
    ``"HOST:6379"``). Either one asking for Ray needs it installed.
    """
    ok = isinstance(workers, (int, np.integer)) and not isinstance(workers, (bool, np.bool_))
    if not ok or not 1 <= workers <= MAX_WORKERS:
        raise ValueError(f"workers must be an integer in [1, {MAX_WORKERS}], got {workers!r}")
    if address is not None and (not isinstance(address, str) or not address.strip()):
        raise ValueError(f"address must be a non-empty string (a Ray cluster), got {address!r}")
    workers, address = int(workers), None if address is None else check_address_form(address)
    if is_distributed(workers, address):
        try:
            import ray  # noqa: F401 (installed and importable; used by the caller next)
        except ImportError:
            what = f"address={address!r}" if address is not None else f"workers={workers}"
            raise RayNotInstalledError(
                f"{what} runs on Ray, which is not installed: {INSTALL_HINT}"
            ) from None
    return workers, address


#: The Ray addresses accepted: ``auto``, ``local``, ``[ray://]HOST:PORT`` (HOST a name, an
#: IPv4 address or a bracketed IPv6 one; PORT decimal digits, checked to be in 1..65535).
_NAMED_ADDRESSES = ("auto", "local")
_HOST_PORT = re.compile(
    r"(?:ray://)?(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):(?P<port>[0-9]{1,5})"
)


def check_address_form(address: str) -> str:
    """Return ``address`` stripped if it is ``"auto"``, ``"local"``, ``HOST:PORT`` or
    ``ray://HOST:PORT`` with PORT in 1..65535; raise ``ValueError`` naming it otherwise."""
    text = address.strip()
    if text in _NAMED_ADDRESSES:
        return text
    m = _HOST_PORT.fullmatch(text)
    if m is None or not 1 <= int(m["port"]) <= 65535:
        raise ValueError(
            "address must be 'auto', 'local', HOST:PORT or ray://HOST:PORT with PORT an "
            f"integer in [1, 65535], got {address!r}"
        )
    return text


def quiet_failure_handler() -> None:
    """Keep Ray's native failure-signal handler out of this (driver) process: it takes a
    SIGTERM that arrives during ``ray.init`` with a stack dump and an abort (exit -6),
    before the caller can clean up. Ray's workers keep theirs."""
    from ray._private import ray_constants

    ray_constants.RAY_DISABLE_FAILURE_SIGNAL_HANDLER = True


def check_reachable(address: str, timeout: float = CONNECT_TIMEOUT) -> None:
    """Raise ``ConnectionError`` unless ``address`` (``HOST:PORT`` or ``ray://HOST:PORT``)
    accepts a TCP connection within ``timeout`` s; ``"auto"`` and ``"local"`` are left to
    Ray. Any other form raises ``ValueError`` (:func:`check_address_form`) before a probe."""
    text = check_address_form(address)
    if text in _NAMED_ADDRESSES:
        return
    host, _, port = text.removeprefix("ray://").rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout):
            pass
    except OSError as exc:
        raise ConnectionError(
            f"cannot reach a Ray cluster at {address!r} ({exc.strerror or exc}); start one "
            "with `ray start --head` or check the address"
        ) from None


def is_distributed(workers: int, address: str | None) -> bool:
    """Return whether ``(workers, address)`` asks for Ray (else: the serial code path)."""
    return workers > 1 or address is not None


def chunks(seeds: Sequence[int], n_chunks: int) -> list[list[int]]:
    """Return ``seeds`` split in order into at most ``n_chunks`` non-empty consecutive chunks."""
    n = max(1, min(int(n_chunks), len(seeds)))
    return [[int(s) for s in part] for part in np.array_split(np.asarray(seeds), n)]


@contextmanager
def session(workers: int = 1, address: str | None = None) -> Iterator[int]:
    """Use Ray inside the block; yield the number of CPUs it offers.

    Joins ``address`` or starts a local Ray with ``workers`` CPUs, and shuts down on exit
    only a Ray it started or joined; a Ray already initialized is used as it is.
    """
    try:
        import ray
    except ImportError:
        raise RayNotInstalledError(f"distributed runs need Ray: {INSTALL_HINT}") from None
    from activetrack.files import keep_signal_handlers

    started = not ray.is_initialized()
    if started and address is not None:
        check_reachable(address)
    try:
        if started:
            # Signals wait until ray.init returns (then the caller's handlers take them, not
            # Ray's, which would exit without the caller's clean-up); shut down in any case.
            quiet_failure_handler()
            with keep_signal_handlers():
                if address is not None:
                    ray.init(address=address, logging_level="warning")
                else:
                    ray.init(
                        address="local",
                        num_cpus=workers,
                        include_dashboard=False,
                        logging_level="warning",
                    )
        yield max(1, int(ray.cluster_resources().get("CPU", workers)))
    finally:
        if started and ray.is_initialized():
            ray.shutdown()


def run_tasks(
    fn: Callable[..., R],
    jobs: Sequence[tuple[Any, ...]],
    *,
    workers: int = 1,
    address: str | None = None,
    on_done: Callable[[int], None] | None = None,
    max_retries: int = MAX_RETRIES,
) -> list[R]:
    """Return ``[fn(*job) for job in jobs]``, each computed as a Ray task, in job order.

    ``fn`` must be importable on the workers (a module-level function of the library);
    its arguments are pickled. ``on_done(i)`` is called once per job as it completes.
    """
    import ray

    ours = not ray.is_initialized()  # the session starts Ray, and its shutdown ends the tasks
    with session(workers, address):
        remote = ray.remote(max_retries=max_retries)(fn)
        index = {remote.remote(*job): i for i, job in enumerate(jobs)}
        results: dict[int, R] = {}
        pending = list(index)
        try:
            while pending:
                ready, pending = ray.wait(pending, num_returns=1)
                for ref in ready:
                    i = index[ref]
                    if i in results:  # cannot happen: one ref, one result
                        raise RuntimeError(f"job {i} completed twice")
                    results[i] = ray.get(ref)
                    if on_done is not None:
                        on_done(i)
        except BaseException:
            # Ray of our own: its shutdown ends the tasks. ``ray.cancel`` would race with a
            # task that is completing, which Ray's core worker can fail on with a native
            # abort ("Tried to complete task that was not pending"), seen on SIGTERM.
            if not ours:
                for ref in pending:
                    ray.cancel(ref)
            raise
    missing = sorted(set(range(len(jobs))) - set(results))
    if missing:
        raise RuntimeError(f"jobs {missing} returned no result")
    return [results[i] for i in range(len(jobs))]


def _on_seeds(fn: Callable[..., R], case: dict[str, Any], seeds: list[int]) -> R:
    """Return ``fn(**case, seeds=seeds)`` (one Ray task of :func:`map_seeds`)."""
    return fn(**case, seeds=seeds)


def map_seeds(
    fn: Callable[..., R],
    cases: Sequence[dict[str, Any]],
    seeds: Sequence[int],
    cpus: int,
    on_done: Callable[[int], None] | None = None,
) -> list[list[R]]:
    """Return, for every case, ``fn(**case, seeds=chunk)`` for the consecutive chunks of
    ``seeds`` in order, each computed as a Ray task (inside :func:`session`).

    The one Ray wrapper of the studies: ``fn`` is the serial function of a chunk of seeds
    (each a use of :func:`activetrack.baselines.rollout.rollout`, whose episodes draw only
    from their own seeds), so joining the chunks gives the serial results.
    ``JOBS_PER_CPU * cpus`` chunks per case; ``on_done(k)`` is called as a chunk of ``k``
    seeds completes.
    """
    parts = chunks(seeds, JOBS_PER_CPU * cpus)
    jobs = [(fn, dict(case), part) for case in cases for part in parts]
    done = run_tasks(
        _on_seeds, jobs, on_done=None if on_done is None else (lambda i: on_done(len(jobs[i][2])))
    )
    return [done[k : k + len(parts)] for k in range(0, len(done), len(parts))]
