"""The ``urpt-gcs`` program (also ``python -m urpt_gcs``).

The command line imports the planner and its libraries (numpy, rasterio, numba) before any
command runs; Ctrl-C during that second must end like Ctrl-C later: one line, exit 130, no
traceback. So this module imports nothing heavy until it is inside the guard.
"""

from __future__ import annotations

import atexit
import os
import signal
import sys
import threading
from typing import Any

INTERRUPTED_EXIT = 130  # 128 + SIGINT, what a shell reports for a command Ctrl-C stopped
REDELIVER_S = 0.05

_interrupted = threading.Event()
_stopped_by = [int(signal.SIGINT)]


def _interrupt_again(unraisable: Any, previous: Any = sys.unraisablehook) -> None:
    # Ctrl-C that lands in a callback from C (llvmlite calls Python back while numba compiles)
    # cannot propagate: Python prints it as "Exception ignored" and carries on. Deliver it
    # again from another thread, a moment later, when this callback has returned: raised here
    # it would be ignored too.
    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        again = threading.Timer(REDELIVER_S, os.kill, (os.getpid(), signal.SIGINT))
        again.daemon = True
        again.start()
        return
    if _interrupted.is_set():
        # What Ctrl-C broke mid-way (a half-built llvmlite object) failing to clean itself up:
        # the operator has stopped the run and gets the one line, not this.
        return
    previous(unraisable)


def _on_interrupt(signum: int, frame: Any) -> None:
    # Remember the Ctrl-C: a library caught in the middle may turn it into an error of its own
    # (numba, interrupted while it compiles, raises "no compiled object yet").
    _interrupted.set()
    # SIGTERM stops the run the way Ctrl-C does (outputs undone, worker processes stopped,
    # one line), and the exit status says which it was.
    _stopped_by[0] = signum
    raise KeyboardInterrupt


def _say_interrupted() -> None:
    try:
        sys.stderr.write("urpt-gcs: interrupted\n")
        sys.stderr.flush()
    finally:
        _leave_interrupted()


def _leave_interrupted() -> None:
    # Exit 130 without the interpreter's own shutdown. A Ctrl-C that stopped numba mid-compile
    # leaves llvmlite objects half built, and collecting them at shutdown can print a traceback
    # or crash the process (SIGSEGV) after the one line was said. The exit handlers (temporary
    # folders, worker processes) still run, with further Ctrl-Cs ignored.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(128 + _stopped_by[0])


__all__ = ["run"]


def run() -> None:
    """Run the command line on ``sys.argv``; Ctrl-C at any moment exits 130 with one line,
    SIGTERM 143."""
    sys.unraisablehook = _interrupt_again
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _on_interrupt)
    if signal.getsignal(signal.SIGTERM) == signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _on_interrupt)
    try:
        # The command line loads after the Ctrl-C handler is in place.
        from urpt_gcs.cli import main

        main()
    except SystemExit as exc:
        if exc.code == INTERRUPTED_EXIT:
            _leave_interrupted()
        # The command has ended and said so: a signal now, while the interpreter shuts down,
        # would kill the process silently with a status that belies what was done.
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, signal.SIG_IGN)
        raise
    except KeyboardInterrupt:
        # Imports are not done yet (or click is unwinding): print without click.
        _say_interrupted()
    except Exception:
        if _interrupted.is_set():
            _say_interrupted()
        raise


if __name__ == "__main__":
    run()
