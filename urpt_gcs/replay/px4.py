"""PX4's own SITL (the SIH quadrotor, headless) started for a replay, and always stopped.

:func:`launch` runs ``run.sh`` of a PX4 SITL build in a fresh scratch folder (PX4 writes its
``rootfs`` there), at the plan's home, with a speed-up and ``TRIG_MODE`` 1 so that photo
commands produce CAMERA_IMAGE_CAPTURED. Parameters are set before boot through rcS's
``PX4_PARAM_<name>`` environment variables, so no restart is needed.

MAVLink is reached on loopback only, on the API link of instance N: PX4 sends to UDP
``14540 + N`` and listens on ``14580 + N``, so a ground station may connect, leave and
connect again (PX4's GCS link, 18570 + N, answers only the first peer it hears). The
instance is the first of 1-9 whose ports and lock file are free. The GCS link sends to
127.0.0.1:14550 until a peer speaks to it, whatever the instance; the launcher speaks to it
first, from a socket of its own, so this SITL never reaches a ground station listening there.

On leaving the ``with`` block (also on Ctrl-C or an error) the process started is sent
SIGTERM by its pid, killed if it does not exit, and ``/tmp/px4_lock-N``,
``/tmp/px4-sock-N`` and the scratch folder are removed.
"""

from __future__ import annotations

import contextlib
import functools
import os
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

from urpt_gcs.errors import LinkError, SettingsError
from urpt_gcs.flight.mission import GeoPoint
from urpt_gcs.replay.launcher import RunningSitl, SitlKind, supervised, tail

__all__ = [
    "ENVIRONMENT",
    "FAILED_TEXTS",
    "GCS_PORT",
    "INSTANCES",
    "LOG_NAME",
    "MODEL",
    "PX4",
    "READY_TEXT",
    "START_TIMEOUT_S",
    "find_build",
    "free_instance",
    "launch",
    "ports",
]

ENVIRONMENT = "URPT_PX4"
MODEL = "sihsim_quadx"
# PX4 caps the API link's remote port at 14549 from instance 10 on; instance 0 is what a
# developer's own SITL uses.
INSTANCES = range(1, 10)
START_TIMEOUT_S = 60.0
READY_TEXT = "Ready for takeoff!"
FAILED_TEXTS = ("ERROR [px4] Startup script returned with return value", "already running")
LOG_NAME = "px4.log"
GCS_PORT = 18570  # + instance: PX4's GCS link listens here
# PX4 exits cleanly on SIGTERM; rcS and its px4-* commands run in the session started for
# it, led by its pid. An error quotes its last three lines that say something, at most 300
# characters.
PX4 = SitlKind(
    "PX4 SITL",
    stop_timeout_s=10.0,
    kill_session=True,
    tail_lines=3,
    tail_separator=" / ",
    count_blank=False,
    tail_chars=300,
)


def ports(instance: int) -> tuple[int, ...]:
    """The loopback UDP ports PX4 SITL instance ``instance`` binds or sends to."""
    return (
        14540 + instance,  # API link: PX4 sends here, the ground station listens
        14580 + instance,  # API link: PX4 listens
        GCS_PORT + instance,  # GCS link
        14280 + instance,  # camera link
        13030 + instance,  # gimbal link
        19450 + instance,  # SIH display link
    )


def _lock(instance: int) -> Path:
    return Path(f"/tmp/px4_lock-{instance}")


def _sock(instance: int) -> Path:
    return Path(f"/tmp/px4-sock-{instance}")


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def free_instance() -> int:
    """The first PX4 instance of 1-9 with no lock file and all its ports free."""
    for instance in INSTANCES:
        if not _lock(instance).exists() and all(_port_free(p) for p in ports(instance)):
            return instance
    raise LinkError(
        "no PX4 SITL instance of 1-9 is free (each has a /tmp/px4_lock-N or a busy UDP port): "
        "stop the other PX4 SITLs and try again"
    )


def find_build(folder: Path | str | None) -> Path:
    """The PX4 SITL folder (the one holding ``run.sh``): ``folder``, else ``$URPT_PX4``.

    Raises
    ------
    SettingsError
        If neither is given, or the folder has no ``run.sh`` and ``bin/px4``.
    """
    given = str(folder) if folder not in (None, "") else os.environ.get(ENVIRONMENT, "")
    if not given:
        raise SettingsError(
            f"--px4 needs the PX4 SITL folder: give --px4 PATH or set {ENVIRONMENT} to the "
            "folder with run.sh"
        )
    path = Path(given).expanduser().resolve()
    for needed in ("run.sh", "bin/px4"):
        if not (path / needed).is_file():
            raise SettingsError(
                f"--px4 {given}: no {needed} there; give the folder of a PX4 SITL build "
                "(the one with run.sh and bin/px4)"
            )
    return path


def _command_links(build: Path, into: Path) -> None:
    """``px4-<module>`` commands for rcS, as links to ``bin/px4``.

    PX4 picks the module from the name it is run by. A build copied without its symlinks
    (an archive or a store that keeps only their target's name) leaves these as plain files
    rcS cannot run; links made here work either way.
    """
    into.mkdir()
    for entry in (build / "bin").iterdir():
        if entry.name.startswith("px4-") and not entry.name.endswith(".sh"):
            (into / entry.name).symlink_to(build / "bin" / "px4")


def _environment(home: GeoPoint, speedup: float, commands: Path) -> dict[str, str]:
    env = dict(os.environ)
    env.update(
        PATH=f"{commands}{os.pathsep}{env.get('PATH', '')}",
        PX4_SIM_MODEL=MODEL,
        PX4_HOME_LAT=f"{home.lat_deg:.7f}",
        PX4_HOME_LON=f"{home.lon_deg:.7f}",
        PX4_HOME_ALT=f"{home.amsl_m:.2f}",
        PX4_SIM_SPEED_FACTOR=f"{speedup:g}",
        # Start the camera trigger: each photo command then gives CAMERA_IMAGE_CAPTURED.
        PX4_PARAM_TRIG_MODE="1",
    )
    return env


def _wait_ready(
    process: subprocess.Popen[bytes], log: Path, timeout_s: float, claim: socket.socket, port: int
) -> None:
    deadline = time.monotonic() + timeout_s
    while True:
        # PX4's UDP link takes the first loopback sender as its peer; a byte that is no
        # MAVLink is enough and starts nothing (no GCS heartbeat, no link-loss failsafe).
        with contextlib.suppress(OSError):
            claim.sendto(b"\0", ("127.0.0.1", port))
        text = log.read_text(errors="replace") if log.exists() else ""
        if READY_TEXT in text:
            return
        if process.poll() is not None or any(failed in text for failed in FAILED_TEXTS):
            raise LinkError(f"PX4 SITL did not start (it said: {tail(log, PX4) or 'nothing'})")
        if time.monotonic() > deadline:
            raise LinkError(
                f"PX4 SITL was not ready for take-off within {timeout_s:g} s (last said: "
                f"{tail(log, PX4) or 'nothing'}): the machine may be too busy; try a lower "
                "--speedup"
            )
        time.sleep(0.1)


@contextlib.contextmanager
def launch(
    folder: Path | str | None,
    home: GeoPoint,
    speedup: float,
    *,
    instance: int | None = None,
    start_timeout_s: float = START_TIMEOUT_S,
) -> Iterator[RunningSitl]:
    """Run PX4 SITL (SIH quadrotor) at ``home`` for the duration of the ``with`` block.

    Parameters
    ----------
    folder
        The PX4 SITL build, the folder with ``run.sh``; None or "" reads ``$URPT_PX4``.
    home
        Where the vehicle starts; its ``amsl_m`` is the ground's altitude there.
    speedup
        PX4_SIM_SPEED_FACTOR: simulated seconds per wall second.
    instance
        PX4 instance (1-9); None picks the first free one.
    start_timeout_s
        Wall-clock limit for the boot ("Ready for takeoff!").

    Yields
    ------
    RunningSitl
        Its connection string and pid.

    Raises
    ------
    SettingsError
        If the folder is not a PX4 SITL build or ``instance`` is out of range.
    LinkError
        If PX4 does not start or does not get ready in time.
    """
    build = find_build(folder)
    if instance is None:
        instance = free_instance()
    elif instance not in INSTANCES:
        raise SettingsError(f"PX4 instance {instance} is out of range; use 1 to 9")
    elif _lock(instance).exists():
        raise LinkError(
            f"PX4 instance {instance} is in use ({_lock(instance)} exists): stop that SITL "
            "or pick another instance"
        )
    with supervised(PX4, f"urpt-px4-{instance}-") as run:
        scratch = run.folder
        log = scratch / LOG_NAME
        claim = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        run.on_stop(claim.close)
        run.on_stop(functools.partial(_remove_leftovers, instance))
        claim.bind(("127.0.0.1", 0))
        _command_links(build, scratch / "bin")
        process = run.start(
            [str(build / "run.sh"), "-i", str(instance)],
            scratch,
            log,
            env=_environment(home, speedup, scratch / "bin"),
        )
        _wait_ready(process, log, start_timeout_s, claim, GCS_PORT + instance)
        yield RunningSitl(
            f"udpin://127.0.0.1:{14540 + instance}", process.pid, instance, scratch, speedup
        )


def _remove_leftovers(instance: int) -> None:
    """PX4's lock file and socket of ``instance``, which it leaves behind when killed."""
    for leftover in (_lock(instance), _sock(instance)):
        with contextlib.suppress(FileNotFoundError):
            leftover.unlink()
