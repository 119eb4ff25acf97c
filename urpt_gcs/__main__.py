"""The ``urpt-gcs`` program (also ``python -m urpt_gcs``).

The command line imports the planner and its libraries (numpy, rasterio, numba) before any
command runs; Ctrl-C during that second must end like Ctrl-C later: one line, exit 130, no
traceback. So this module imports nothing heavy until it is inside the guard.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
from typing import Any

INTERRUPTED_EXIT = 130  # 128 + SIGINT, what a shell reports for a command Ctrl-C stopped
REDELIVER_S = 0.05


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
    previous(unraisable)


def run() -> None:
    """Run the command line on ``sys.argv``; Ctrl-C at any moment exits 130 with one line."""
    sys.unraisablehook = _interrupt_again
    try:
        from urpt_gcs.cli import main

        main()
    except KeyboardInterrupt:
        # Imports are not done yet (or click is unwinding): print without click.
        try:
            sys.stderr.write("urpt-gcs: interrupted\n")
            sys.stderr.flush()
        finally:
            sys.exit(INTERRUPTED_EXIT)


if __name__ == "__main__":
    run()
