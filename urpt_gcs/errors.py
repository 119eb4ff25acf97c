"""Errors raised by urpt-gcs.

Every error the operator can cause derives from :class:`UrptError`; the CLI catches that root
only, prints the message on one line and exits 1. Each message names the input at fault and
what to do about it. Anything else escaping is a bug.

The tree::

    UrptError
    ├── SettingsError (ValueError)   a flag or setting out of range
    ├── DemError (ValueError)        the elevation raster cannot be used
    ├── TargetsError (ValueError)    the target file cannot be used
    ├── PlanError (RuntimeError)     the inputs are valid but no safe plan exists
    ├── MissionFileError (ValueError) a .plan or .waypoints file cannot be used
    ├── OutputError (OSError)        an output cannot be written
    ├── JobsFileError (ValueError)   a batch's jobs file cannot be used
    ├── ClusterError (ConnectionError) the Dask cluster cannot be reached or cannot run the jobs
    └── LinkError (ConnectionError)  the vehicle cannot be reached or refused the mission
        ├── MissionRejected           the vehicle answered MISSION_ACK with a refusal
        └── LinkTimeout               the vehicle stopped answering (in urpt_gcs.vehicle.protocol)
"""

from __future__ import annotations

import errno
import os
from collections.abc import Mapping
from typing import Any

__all__ = [
    "ClusterError",
    "DemError",
    "JobsFileError",
    "LinkError",
    "MissionFileError",
    "OutputError",
    "PlanError",
    "SettingsError",
    "TargetsError",
    "UrptError",
    "memory_error_message",
    "os_error_message",
]


class UrptError(Exception):
    """Root of every error urpt-gcs reports to the operator."""


class SettingsError(UrptError, ValueError):
    """A setting (CLI flag or API argument) is outside its valid range.

    One made by :meth:`about` names each setting by its library name (``fov_deg``); the CLI
    shows it with the setting's flag (``--fov``) and a jobs file with its key (``fov``), by
    :meth:`naming`.
    """

    def __init__(
        self, message: str, template: str | None = None, values: Mapping[str, Any] | None = None
    ) -> None:
        super().__init__(message)
        self.template = template
        self.values = dict(values or {})

    @classmethod
    def about(cls, template: str, **values: Any) -> SettingsError:
        """The error whose message is ``template`` with each ``{setting}`` named and each
        ``{value}`` given as a keyword filled in (with its format: ``{value!r}``, ``{value:g}``).

        Parameters
        ----------
        template
            The message; a replacement field not among ``values`` is the name of a setting.
        **values
            The values the message quotes.

        Returns
        -------
        SettingsError
            Its text names the settings by their library names.
        """
        return cls(_fill(template, values, {}), template, values)

    def naming(self, names: Mapping[str, str]) -> str:
        """The message with each setting called as ``names`` calls it (a flag, a key); a
        setting ``names`` lacks keeps its library name.

        Parameters
        ----------
        names
            Library name -> the name to show.

        Returns
        -------
        str
            The message; ``str(self)`` for an error not made by :meth:`about`.
        """
        if self.template is None:
            return str(self)
        return _fill(self.template, self.values, names)


class _Names(dict[str, Any]):
    """The values of a message, and any other field as the name of a setting."""

    def __init__(self, values: Mapping[str, Any], names: Mapping[str, str]) -> None:
        super().__init__(values)
        self.names = names

    def __missing__(self, key: str) -> str:
        return self.names.get(key, key)


def _fill(template: str, values: Mapping[str, Any], names: Mapping[str, str]) -> str:
    return template.format_map(_Names(values, names))


class DemError(UrptError, ValueError):
    """The elevation raster is missing, unreadable or unusable."""


class TargetsError(UrptError, ValueError):
    """The target file is missing, malformed or its points are unusable."""


class PlanError(UrptError, RuntimeError):
    """The inputs are valid but no plan meeting the safety rules exists."""


class MissionFileError(UrptError, ValueError):
    """A mission file (.plan, .waypoints) is not one urpt-gcs can use."""


class OutputError(UrptError, OSError):
    """An output file or folder cannot be written."""


class JobsFileError(UrptError, ValueError):
    """A batch's jobs file is missing, is not TOML, or names a setting or path it cannot use."""


class ClusterError(UrptError, ConnectionError):
    """The Dask scheduler cannot be reached, has no workers, or its workers cannot run jobs."""


class LinkError(UrptError, ConnectionError):
    """The vehicle cannot be reached, or it did not accept the mission as sent."""


# What to do about the OSErrors an operator can cause or cure.
_OS_FIXES = {
    errno.ENAMETOOLONG: "give a shorter name",
    errno.ENOSPC: "free some disk space or write elsewhere",
    errno.EDQUOT: "free some disk space or write elsewhere",
    errno.EACCES: "check its permissions or use another folder",
    errno.EPERM: "check its permissions or use another folder",
    errno.EROFS: "write to another folder",
    errno.ENOENT: "check the path",
    errno.ENOTDIR: "check the path: a part of it is a file",
    errno.EISDIR: "give a file, not a folder",
    errno.EMFILE: "close other programs' files and run again",
    errno.ENOMEM: "free some memory and run again",
}


def os_error_message(exc: OSError) -> str:
    """One line naming the file (when the error knows it), the reason and what to do.

    Parameters
    ----------
    exc
        An error of the operating system, not one of ours.

    Returns
    -------
    str
        The line, without a prefix.
    """
    reason = exc.strerror or errno.errorcode.get(exc.errno or 0, "") or str(exc) or "I/O error"
    fix = _OS_FIXES.get(exc.errno or 0, "check the path, the permissions and the free space")
    names = [os.fsdecode(n) for n in (exc.filename, exc.filename2) if n is not None]
    where = " -> ".join(f"'{_shorten(name)}'" for name in names)
    return f"{where + ': ' if where else ''}{reason}: {fix}"


def memory_error_message(exc: MemoryError) -> str:
    """One line with the size that could not be had (numpy says it) and what to change.

    Parameters
    ----------
    exc
        The allocation that failed.

    Returns
    -------
    str
        The line, without a prefix.
    """
    detail = " ".join(str(exc).split())
    return (
        f"out of memory{f' ({detail})' if detail else ''}: plan fewer targets at a time, "
        "lower --samples, or use a smaller DEM"
    )


def _shorten(name: str, limit: int = 120) -> str:
    return name if len(name) <= limit else f"{name[: limit // 2]}...{name[-limit // 2 :]}"
