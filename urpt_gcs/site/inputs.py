"""Input files and memory: the checks every reader and every big allocation makes first.

Every file urpt-gcs reads must be a regular file (a symlink is followed to one): a FIFO
blocks the reader forever and a link to ``/dev/zero`` never ends, so both are refused from
``os.stat`` before the file is opened. Text inputs are read through :func:`read_capped`,
which reads at most one byte past the cap, so even a file that grows while it is read stays
bounded.

Arrays whose size follows from the inputs (DEM windows, dense distance matrices) are
estimated first and refused by :func:`require_memory` when they would not fit the memory
budget (see :func:`memory_budget_bytes`).
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from urpt_gcs.errors import UrptError

__all__ = [
    "GTSPLIB_MAX_BYTES",
    "MISSION_FILE_MAX_BYTES",
    "SETTINGS_FILE_MAX_BYTES",
    "TARGETS_MAX_BYTES",
    "read_capped",
    "read_settings_text",
    "require_regular_file",
    "shown_path",
]

# Size caps of text inputs: far above any real file, far below what would exhaust memory.
TARGETS_MAX_BYTES = 64 * 2**20
MISSION_FILE_MAX_BYTES = 16 * 2**20
GTSPLIB_MAX_BYTES = 64 * 2**20
# A fleet file or a batch's jobs file: a few hundred vehicles or sites fit in far less.
SETTINGS_FILE_MAX_BYTES = 4 * 2**20

# The longest file name most file systems take (NAME_MAX).
_NAME_MAX = 255

_KINDS = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a folder"),
)


def _kind(mode: int) -> str:
    return next((kind for test, kind in _KINDS if test(mode)), "not a file")


def shown_path(path: Path | str, limit: int = 200) -> str:
    """A path for a message: one line, at most ``limit`` characters, quoted."""
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in str(path))
    return f"'{text[:limit]}...'" if len(text) > limit else f"'{text}'"


def require_regular_file(
    path: Path, what: str, flag: str, error: type[UrptError]
) -> os.stat_result:
    """Check that ``path`` is, or links to, a regular file, before anyone opens it.

    Parameters
    ----------
    path
        The file as the operator gave it.
    what
        What the file is, for the message: ``"DEM"``, ``"targets file"``, ...
    flag
        Where the operator gave it, for the fix: ``"--dem"``, ``"urpt-gcs upload"``, ...
    error
        The error class to raise (the reader's own).

    Returns
    -------
    os.stat_result
        The status of the file the path resolves to.

    Raises
    ------
    UrptError
        Of class ``error``, with one line naming the file and what to give instead: if the
        path does not exist, is too long, or resolves to a folder, FIFO, device or socket.
    """
    name = f"{what} {shown_path(path)}"
    try:
        status = path.stat()
    except FileNotFoundError:
        # A dangling link exists as a name; saying so saves a puzzled operator a minute.
        dangling = path.is_symlink()
        problem = "is a link to a file that does not exist" if dangling else "does not exist"
        raise error(f"{name} {problem}: check the path given to {flag}") from None
    except OSError as exc:
        if exc.errno == errno.ENAMETOOLONG:
            longest = max((len(part) for part in path.parts), default=0)
            figure = (
                f"a name of {longest} characters"
                if longest > _NAME_MAX
                else f"a path of {len(str(path))} characters"
            )
            raise error(
                f"{name} has {figure}, too long for the file system: "
                f"give {flag} a shorter path (move or rename the file)"
            ) from None
        reason = exc.strerror or type(exc).__name__
        raise error(f"{name} cannot be read ({reason}): check the path given to {flag}") from None
    if stat.S_ISREG(status.st_mode):
        return status
    kind = _kind(status.st_mode)
    if path.is_symlink():
        kind = f"a link to {shown_path(path.resolve())}, {kind}"
    if stat.S_ISDIR(status.st_mode):
        raise error(f"{name} is {kind}: give {flag} the file inside it")
    raise error(f"{name} is {kind}, not a regular file: give {flag} a regular file")


def read_capped(
    path: Path, what: str, flag: str, error: type[UrptError], cap_bytes: int, fix: str
) -> bytes:
    """The bytes of a regular file of at most ``cap_bytes``, read with a bounded read.

    Parameters
    ----------
    path, what, flag, error
        As for :func:`require_regular_file`.
    cap_bytes
        The largest file accepted.
    fix
        What to do about a file over the cap, for the message.

    Raises
    ------
    UrptError
        Of class ``error``: everything :func:`require_regular_file` refuses, a file over the
        cap (by its size, or by what a read finds if it grows), or a file that cannot be read.
    """
    status = require_regular_file(path, what, flag, error)
    name = f"{what} {shown_path(path)}"
    if status.st_size > cap_bytes:
        raise error(_over_cap(name, status.st_size, cap_bytes, fix))
    try:
        # O_NONBLOCK: if the path was swapped for a FIFO since the check, open must not hang.
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise error(f"{name} cannot be read ({reason}): check the file's permissions") from None
    with os.fdopen(fd, "rb") as stream:
        if not stat.S_ISREG(os.fstat(stream.fileno()).st_mode):
            raise error(f"{name} is no longer a regular file: give {flag} a regular file")
        try:
            data = stream.read(cap_bytes + 1)
        except OSError as exc:
            reason = exc.strerror or type(exc).__name__
            raise error(f"{name} cannot be read ({reason}): check the file") from None
    if len(data) > cap_bytes:
        raise error(_over_cap(name, len(data), cap_bytes, fix, grew=True))
    return data


def read_settings_text(path: Path, what: str, flag: str, error: type[UrptError]) -> str:
    """The text of a TOML settings file (a fleet file, a jobs file), read as
    :func:`read_capped` reads, at most :data:`SETTINGS_FILE_MAX_BYTES`; a UTF-8 byte-order
    mark, which some editors write, is dropped.

    Raises
    ------
    UrptError
        Of class ``error``: everything :func:`read_capped` refuses, or text that is not UTF-8.
    """
    data = read_capped(
        path, what, flag, error, SETTINGS_FILE_MAX_BYTES, f"check the path given to {flag}"
    )
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise error(f"{what} {shown_path(path)} is not UTF-8 text: save it as UTF-8") from None


def _over_cap(name: str, size: int, cap_bytes: int, fix: str, grew: bool = False) -> str:
    figure = f"grew past {_size(cap_bytes)} while read" if grew else f"is {_size(size)}"
    return f"{name} {figure}, over the {_size(cap_bytes)} limit: {fix}"


def _size(nbytes: float) -> str:
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if nbytes >= scale:
            return f"{nbytes / scale:.1f} {unit}"
    return f"{int(nbytes)} bytes"
