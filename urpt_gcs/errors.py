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


class UrptError(Exception):
    """Root of every error urpt-gcs reports to the operator."""


class SettingsError(UrptError, ValueError):
    """A setting (CLI flag or API argument) is outside its valid range."""


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
