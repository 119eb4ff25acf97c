"""Work in spawned processes that this process owns, whatever stops it.

:func:`run_owned` runs ``func(job)`` for every job in fresh processes (spawned, not forked:
the parent holds threads), at most ``workers`` at a time, and returns the results in the jobs'
order. What it guarantees, where a pool does not:

- **Ctrl-C reaches the parent alone.** A terminal's Ctrl-C goes to the whole process group;
  a child that took it would print its own traceback. Each child is started with SIGINT
  ignored, which it keeps through ``exec``, so it never runs a Python handler for it.
- **No child outlives the call.** Whatever leaves the call (a result, an error, Ctrl-C,
  SIGTERM raised as KeyboardInterrupt by the program's handler) first terminates every child
  still running, waits for it, and kills one that lingers.
- **Nothing to leak or deadlock on.** Results come back through one pipe per child; there is
  no shared queue or semaphore for a killed child to hold, and none for the resource tracker
  to find leaked.

A child that dies without a result (killed, out of memory) raises :class:`WorkerDied` in the
parent, naming the job.
"""

from __future__ import annotations

import multiprocessing
import signal
import threading
import traceback
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection, wait
from typing import Any, TypeVar

__all__ = ["WorkerDied", "run_owned"]

J = TypeVar("J")
R = TypeVar("R")

# How long a terminated child may take to exit before it is killed.
TERMINATE_WAIT_S = 5.0


class WorkerDied(RuntimeError):
    """A child process ended without sending its result."""


def run_owned(func: Callable[[J], R], jobs: Sequence[J], workers: int) -> list[R]:
    """``[func(job) for job in jobs]``, each call in a spawned process, ``workers`` at a time.

    Parameters
    ----------
    func
        A module-level function (it is pickled by name); an exception it raises is raised
        here, in the parent, for the first job that failed.
    jobs
        Its arguments, each picklable.
    workers
        The most children alive at once (at least 1).

    Returns
    -------
    list
        The results, in the jobs' order.

    Raises
    ------
    WorkerDied
        A child ended without a result (killed, or crashed in C).
    """
    context = multiprocessing.get_context("spawn")
    results: dict[int, R] = {}
    running: dict[Connection, tuple[int, Any]] = {}
    waiting = list(enumerate(jobs))[::-1]
    try:
        while waiting or running:
            while waiting and len(running) < max(1, workers):
                index, job = waiting.pop()
                reader, writer = context.Pipe(duplex=False)
                child = context.Process(target=_child, args=(func, job, writer), daemon=True)
                _start_without_sigint(child)
                writer.close()
                running[reader] = (index, child)
            for ready in wait(list(running)):
                assert isinstance(ready, Connection)
                index, child = running.pop(ready)
                try:
                    ok, value = ready.recv()
                except EOFError:
                    child.join()
                    raise WorkerDied(
                        f"job {index + 1} of {len(jobs)}: its process ended with exit code "
                        f"{child.exitcode} before sending a result"
                    ) from None
                finally:
                    ready.close()
                child.join()
                if not ok:
                    raise value
                results[index] = value
    finally:
        _stop_all([child for _, child in running.values()])
        for reader in running:
            reader.close()
    return [results[i] for i in range(len(jobs))]


def _start_without_sigint(child: Any) -> None:
    if threading.current_thread() is not threading.main_thread():
        child.start()  # only the main thread may change a signal's disposition
        return
    # An ignored signal stays ignored through exec (a blocked mask does not: the start
    # clears it). This thread blocks SIGINT meanwhile, so that a Ctrl-C in the moment of
    # the start waits for the parent's own handler instead of being ignored.
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            child.start()
        finally:
            signal.signal(signal.SIGINT, previous)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _child(func: Callable[[Any], Any], job: Any, out: Connection) -> None:
    try:
        value = func(job)
    except Exception as exc:
        try:
            out.send((False, exc))
        except Exception:
            # An exception that cannot be pickled still comes back, as its text.
            out.send((False, RuntimeError("".join(traceback.format_exception_only(exc)))))
    else:
        out.send((True, value))
    finally:
        out.close()


def _stop_all(children: Sequence[Any]) -> None:
    for child in children:
        if child.is_alive():
            child.terminate()
    for child in children:
        child.join(TERMINATE_WAIT_S)
        if child.is_alive():
            child.kill()
            child.join()
