"""Independent jobs run in this process or on a Dask cluster, with the same results.

:func:`open_client` starts a local ``dask.distributed`` cluster (worker processes of one
thread each, bound to 127.0.0.1, no dashboard) or connects to a running scheduler, and always
closes what it opened, on an error or Ctrl-C too. :func:`run_jobs` maps a picklable function
over jobs, serially without a client or as one Dask task per job, and returns per job its
value or the exception it raised, with the worker and the wall time; :func:`map_jobs` returns
the values and raises the first error. A job's function must be a module-level function (or a
:func:`functools.partial` of one) of an importable module, so that a worker can load it: the
workers need ``urpt_gcs`` installed, which :func:`probe_workers` checks.

Dask is imported only when a cluster is asked for, so serial runs do not pay for it.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Generic, TypeVar, cast

from urpt_gcs.errors import ClusterError, SettingsError

if TYPE_CHECKING:
    from distributed import Client

__all__ = [
    "CONNECT_TIMEOUT_S",
    "LOCAL",
    "WORKERS_TIMEOUT_S",
    "Done",
    "describe_client",
    "map_jobs",
    "open_client",
    "probe_workers",
    "run_jobs",
]

J = TypeVar("J")
R = TypeVar("R")

LOCAL = "this process"
# How long to wait for a scheduler to answer, and for it to have a worker.
CONNECT_TIMEOUT_S = 10.0
WORKERS_TIMEOUT_S = 30.0
# A local cluster's processes per core: each holds a planner (a few hundred MB), and more
# than a few per core only share the same cores.
WORKERS_PER_CORE = 4


@dataclass(frozen=True, slots=True)
class Done(Generic[R]):
    """One job's end: its value, or the exception it raised; where and how long it ran.

    ``wall_s`` is measured where the job ran (None when the worker died before it ended).
    """

    index: int
    value: R | None
    error: BaseException | None
    worker: str
    wall_s: float | None

    @property
    def ok(self) -> bool:
        return self.error is None


def describe_client(client: Client) -> str:
    """``N workers at ADDRESS`` for messages."""
    info = client.scheduler_info()
    workers = len(info.get("workers", {}))
    return f"{workers} worker{'s' if workers != 1 else ''} at {info.get('address', '?')}"


@contextlib.contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None) -> Iterator[Client]:
    """A Dask client: on a new local cluster of ``workers`` processes, or on ``scheduler``.

    Parameters
    ----------
    scheduler
        Address of a running scheduler (``tcp://host:8786``); None starts a local cluster.
    workers
        Worker processes of the local cluster (one thread each) [default: every core]; not
        used with ``scheduler``.

    Raises
    ------
    SettingsError
        ``workers`` below 1, or given with ``scheduler``.
    ClusterError
        The scheduler does not answer, or has no worker.
    """
    if scheduler is not None and workers is not None:
        raise SettingsError(
            "--workers starts a local cluster and --scheduler uses a running one's workers: "
            "give one of them"
        )
    if workers is not None and workers < 1:
        raise SettingsError(f"--workers {workers} is below 1: give a number of processes")
    most = WORKERS_PER_CORE * (os.cpu_count() or 1)
    if workers is not None and workers > most:
        raise SettingsError(
            f"--workers {workers} is over {WORKERS_PER_CORE} per core ({most} on this "
            f"computer): give at most {most}"
        )
    # Dask loads only when a cluster is used (a lazy load, not a hidden cycle).
    from distributed import Client, LocalCluster

    with contextlib.ExitStack() as stack:
        if scheduler is None:
            with _workers_ignore_ctrl_c():
                cluster = LocalCluster(
                    n_workers=workers or os.cpu_count() or 1,
                    threads_per_worker=1,
                    processes=True,
                    host="127.0.0.1",
                    dashboard_address=None,
                    # The scheduler serves HTTP (health, metrics) even without a dashboard: on
                    # a free port of 127.0.0.1, not on 8787 of every interface.
                    scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                    silence_logs=logging.ERROR,
                )
            stack.enter_context(cluster)
            client = stack.enter_context(Client(cluster))
        else:
            try:
                client = stack.enter_context(Client(scheduler, timeout=CONNECT_TIMEOUT_S))
            except (OSError, TimeoutError, ValueError) as exc:
                raise ClusterError(
                    f"--scheduler {scheduler}: no Dask scheduler answers there "
                    f"({' '.join(str(exc).split()) or type(exc).__name__}): start one "
                    "(`dask scheduler`) or check the address"
                ) from None
            try:
                client.wait_for_workers(1, timeout=WORKERS_TIMEOUT_S)
            except TimeoutError:
                raise ClusterError(
                    f"--scheduler {scheduler} has no workers after {WORKERS_TIMEOUT_S:.0f} s: "
                    f"start some (`dask worker {scheduler}`)"
                ) from None
        yield client


@contextlib.contextmanager
def _workers_ignore_ctrl_c() -> Iterator[None]:
    """Start worker processes that ignore SIGINT (an ignored signal stays ignored in a child).

    Ctrl-C at a terminal reaches every process of the group: the workers would each print
    a traceback, and this process closes them anyway.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def probe_workers(client: Client, paths: Sequence[str]) -> dict[str, list[str]]:
    """Per worker, which of ``paths`` it cannot read; also checks it can import urpt_gcs.

    Raises
    ------
    ClusterError
        A worker cannot run urpt_gcs (not installed there, or another version).
    """
    # Runs on a worker: the version that worker has installed.
    from urpt_gcs import __version__

    try:
        answers: dict[str, tuple[str, list[str]]] = client.run(_unreadable, list(paths))
    except Exception as exc:  # whatever a worker raised, it cannot run our jobs
        address = client.scheduler_info().get("address", "?")
        raise ClusterError(
            f"the workers at {address} cannot run urpt-gcs jobs "
            f"({type(exc).__name__}: {' '.join(str(exc).split())}): install urpt-gcs "
            f"{__version__} in the workers' environment"
        ) from None
    for worker, (version, _) in answers.items():
        if version != __version__:
            raise ClusterError(
                f"worker {worker} runs urpt-gcs {version}, this is {__version__}: install the "
                "same version on every worker"
            )
    return {worker: missing for worker, (_, missing) in answers.items()}


def _unreadable(paths: list[str]) -> tuple[str, list[str]]:
    # Runs on a worker: the version that worker has installed.
    from urpt_gcs import __version__

    return __version__, [p for p in paths if not (os.path.isfile(p) and os.access(p, os.R_OK))]


def _worker_name() -> str:
    # Dask loads only when a cluster is used.
    from distributed import get_worker

    try:
        return str(get_worker().address)
    except ValueError:  # not inside a Dask worker
        return LOCAL


@dataclass(frozen=True, slots=True)
class _Timed(Generic[J, R]):
    """A job function that also reports its worker and wall time, and returns what it raised
    rather than raise it, so that a failed job still says where it ran (picklable if ``fn``
    is)."""

    fn: Callable[[J], R]

    def __call__(self, job: J) -> tuple[R | None, Exception | None, str, float]:
        started = time.perf_counter()
        try:
            value, error = self.fn(job), None
        except Exception as exc:  # the job's failure is its result; the others go on
            value, error = None, exc
        return value, error, _worker_name(), time.perf_counter() - started


def run_jobs(
    fn: Callable[[J], R],
    jobs: Sequence[J],
    client: Client | None = None,
    done: Callable[[Done[R]], None] | None = None,
) -> list[Done[R]]:
    """Run ``fn`` on every job: in this process (no client) or one Dask task per job.

    Parameters
    ----------
    fn
        A picklable function of one job; a pure function of it, so that where it runs does
        not change its value.
    jobs
        Picklable jobs.
    client
        A Dask client, or None to run the jobs here, one after the other.
    done
        Called as each job ends (in the order they end), on this process's main thread.

    Returns
    -------
    list of Done
        In the order of ``jobs``. A job that raised holds its exception; the others still run
        (serially too). Ctrl-C cancels the jobs not yet ended and is raised again.
    """
    ends: list[Done[R] | None] = [None] * len(jobs)

    def finish(end: Done[R]) -> None:
        ends[end.index] = end
        if done is not None:
            done(end)

    if client is None:
        timed = _Timed(fn)
        for index, job in enumerate(jobs):
            value, error, worker, wall_s = timed(job)
            finish(Done(index, value, error, worker, wall_s))
        return [end for end in ends if end is not None]

    # Dask loads only when a cluster is used.
    from distributed import as_completed

    futures = client.map(_Timed(fn), list(jobs), pure=False)
    index_of = {future.key: k for k, future in enumerate(futures)}
    try:
        for future in as_completed(futures):
            index = index_of[future.key]
            try:
                value, error, worker, wall_s = future.result()
            except Exception as exc:  # the worker died, or the result did not come back
                finish(Done(index, None, exc, "unknown", None))
            else:
                finish(Done(index, value, error, worker, wall_s))
    finally:
        client.cancel([f for f in futures if not f.done()])
    return [end for end in ends if end is not None]


def map_jobs(
    fn: Callable[[J], R],
    jobs: Sequence[J],
    client: Client | None = None,
    done: Callable[[int, R], None] | None = None,
) -> list[R]:
    """The values of ``fn`` on every job, in order, here or on ``client``; the first error
    (in the order of ``jobs``) is raised once every job has ended."""

    def each(end: Done[R]) -> None:
        if done is not None and end.error is None:
            done(end.index, cast(R, end.value))

    ends = run_jobs(fn, jobs, client, each)
    for end in ends:
        if end.error is not None:
            raise end.error
    return [cast(R, end.value) for end in ends]
