"""Start ArduPilot's own ArduCopter SITL for a replay, and always stop it again.

:func:`launch` runs the ``arducopter`` binary the operator built (``--ardupilot PATH``) in a
fresh scratch folder, where it writes its ``eeprom.bin``, logs and terrain cache, so no
parameter of an earlier run leaks in. It starts at the plan's home with a speed-up, with
ArduPilot's default copter parameters (``copter.parm`` found beside the binary or in the
ArduPilot checkout it was built in) and our own few on top: a servo-triggered camera, without
which ArduPilot sends no CAMERA_FEEDBACK and a replay sees no photos.

SITL binds its TCP ports on every interface; we only ever connect over 127.0.0.1. The
process is stopped by the pid it was started with, on success, error and Ctrl-C alike, and
the scratch folder removed.
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

from urpt_gcs.errors import LinkError, SettingsError
from urpt_gcs.flight.mission import RELATIVE_ALT_FRAMES, GeoPoint, Mission
from urpt_gcs.replay.launcher import Launch, RunningSitl, SitlKind, supervised, tail

__all__ = [
    "ARDUCOPTER",
    "BINARY_NAME",
    "CAMERA_PARAMS",
    "CHECKOUT_DEFAULTS",
    "DEFAULTS_NAME",
    "ENV_VAR",
    "INSTANCES",
    "PORT_STEP",
    "SERIAL0_PORT",
    "SERIAL1_PORT",
    "START_TIMEOUT_S",
    "find_defaults",
    "launch",
    "resolve_binary",
    "unreachable_hint",
]

BINARY_NAME = "arducopter"
ENV_VAR = "URPT_ARDUPILOT"
DEFAULTS_NAME = "copter.parm"
# Where copter.parm sits relative to build/sitl/bin/arducopter in an ArduPilot checkout.
CHECKOUT_DEFAULTS = Path("..", "..", "..", "Tools", "autotest", "default_params", DEFAULTS_NAME)
# CAM1_TYPE 1 (servo) alone is reset to 0 by AP_Camera's parameter conversion on a fresh
# eeprom; with a servo output assigned to the camera trigger (function 10) it survives.
CAMERA_PARAMS = {"CAM1_TYPE": 1, "SERVO9_FUNCTION": 10}
# ArduPilot adds 10 * instance to every port. 0 to 2 are left to SITLs the operator runs
# himself (0 is sim_vehicle.py's default), so a replay never connects to one of those.
INSTANCES = range(3, 10)
SERIAL0_PORT = 5760
SERIAL1_PORT = 5762
PORT_STEP = 10
# At 10x the TCP port is open within 0.2 s of start; a loaded machine may take much longer.
START_TIMEOUT_S = 30.0
# Its last five lines of output go into an error, blank ones left out.
ARDUCOPTER = SitlKind(
    "ArduCopter SITL",
    stop_timeout_s=5.0,
    kill_session=False,
    tail_lines=5,
    tail_separator=" | ",
    count_blank=True,
)


def resolve_binary(path: Path | str | None) -> Path:
    """The ``arducopter`` binary named by ``--ardupilot PATH`` (or ``$URPT_ARDUPILOT``).

    ``path`` is the binary itself or a folder holding it.

    Raises
    ------
    SettingsError
        If no path is given, or it names no executable ``arducopter``.
    """
    if path is None or str(path) == "":
        raise SettingsError(
            f"no ArduCopter SITL given: pass --ardupilot PATH (the arducopter binary or its "
            f"folder) or set {ENV_VAR}"
        )
    given = Path(path).expanduser()
    binary = given / BINARY_NAME if given.is_dir() else given
    if not binary.exists():
        raise SettingsError(
            f"--ardupilot '{given}': no {BINARY_NAME} there: build ArduPilot's SITL "
            "(./waf configure --board sitl && ./waf copter) and give build/sitl/bin/arducopter"
        )
    if not binary.is_file() or not os.access(binary, os.X_OK):
        raise SettingsError(
            f"--ardupilot '{binary}' is not an executable file: give the arducopter binary "
            f"(chmod +x it if it is one)"
        )
    return binary.resolve()


def unreachable_hint(mission: Mission) -> str:
    """Why a flight of ``mission`` on SITL may never end, to add to the error, or ''.

    SITL holds the ground flat at home's altitude (it knows no terrain): a waypoint below home
    (a plan inside a height band over a valley writes them) is under its ground. The copter
    lands on the way there and waits, armed in AUTO, for a waypoint it never reaches.
    """
    heights = [item.z for item in mission.items if item.frame in RELATIVE_ALT_FRAMES]
    below = [z for z in heights if z < 0.0]
    if not below:
        return ""
    return (
        f": {len(below)} of its waypoints are below home (down to {min(below):g} m); a "
        "simulator that holds the ground flat at home's altitude (ArduPilot's SITL does) "
        "lands short of them and never ends the mission"
    )


def find_defaults(binary: Path) -> Path:
    """ArduPilot's default parameters for the copter model, beside ``binary`` or in its checkout.

    Raises
    ------
    SettingsError
        If neither place holds ``copter.parm``.
    """
    for candidate in (binary.parent / DEFAULTS_NAME, binary.parent / CHECKOUT_DEFAULTS):
        if candidate.is_file():
            return candidate.resolve()
    raise SettingsError(
        f"--ardupilot '{binary}': no {DEFAULTS_NAME} beside it: put ArduPilot's "
        f"Tools/autotest/default_params/{DEFAULTS_NAME} in {binary.parent}"
    )


def _ports_free(instance: int) -> bool:
    """True if the instance's MAVLink TCP ports can be bound now (nobody listens there)."""
    base = SERIAL0_PORT + PORT_STEP * instance
    for port in (base, base + 2, base + 3):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            try:
                probe.bind(("0.0.0.0", port))
            except OSError:
                return False
    return True


def _listening(port: int) -> bool:
    # A bare TCP connect, closed at once: SITL counts it as its first client and carries on
    # booting, and accepts the ground station's connection right after.
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.settimeout(0.5)
        try:
            probe.connect(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _write_params(folder: Path) -> Path:
    params = folder / "urpt-gcs.parm"
    params.write_text("".join(f"{name} {value}\n" for name, value in CAMERA_PARAMS.items()))
    return params


def _start(
    run: Launch,
    binary: Path,
    defaults: Path,
    home: GeoPoint,
    speedup: float,
    instance: int,
    folder: Path,
) -> tuple[subprocess.Popen[bytes], Path]:
    params = _write_params(folder)
    log = folder / "arducopter.log"
    command = [
        str(binary),
        "--model",
        "+",
        "--speedup",
        f"{speedup:g}",
        "--defaults",
        f"{defaults},{params}",
        "--home",
        f"{home.lat_deg:.7f},{home.lon_deg:.7f},{home.amsl_m:.2f},0",
        "-I",
        str(instance),
    ]
    return run.start(command, folder, log), log


def _wait_up(process: subprocess.Popen[bytes], port: int, log: Path, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise LinkError(
                f"ArduCopter SITL exited with status {process.returncode} at start: "
                f"{tail(log, ARDUCOPTER) or 'no output'}"
            )
        if _listening(port):
            return
        time.sleep(0.05)
    raise LinkError(
        f"ArduCopter SITL did not open TCP port {port} within {timeout_s:g} s: "
        f"{tail(log, ARDUCOPTER) or 'no output'}; check the binary runs on this machine"
    )


@contextlib.contextmanager
def launch(
    binary: Path | str | None,
    home: GeoPoint,
    speedup: float,
    *,
    instance: int | None = None,
    start_timeout_s: float = START_TIMEOUT_S,
) -> Iterator[RunningSitl]:
    """Run ArduCopter SITL at ``home`` for the duration of the ``with`` block.

    Parameters
    ----------
    binary
        The ``arducopter`` binary or a folder holding it (see :func:`resolve_binary`).
    home
        Where it starts, altitude in m AMSL (the plan's home), heading north.
    speedup
        Simulated seconds per wall second.
    instance
        ``-I`` instance (ports 5760 + 10 * instance ...); None takes the first free one of
        3 to 9.
    start_timeout_s
        How long its MAVLink port may take to open.

    Yields
    ------
    RunningSitl
        Where to connect, and its pid.

    Raises
    ------
    SettingsError
        If the binary or its default parameters cannot be found.
    LinkError
        If no instance is free or SITL does not come up in time (with its last output lines).
    """
    path = resolve_binary(binary)
    defaults = find_defaults(path)
    if not (1.0 <= speedup <= 1000.0):
        raise SettingsError(f"--speedup {speedup} is out of range; use 1 to 1000")
    if instance is not None and not 0 <= instance <= 99:
        raise SettingsError(f"SITL instance {instance} is out of range; use 0 to 99")
    candidates = [instance] if instance is not None else list(INSTANCES)
    with supervised(ARDUCOPTER, "urpt-arducopter-") as run:
        folder = run.folder
        for number in candidates:
            if not _ports_free(number):
                continue
            run_dir = folder / f"instance-{number}"
            run_dir.mkdir()
            process, log = _start(run, path, defaults, home, speedup, number, run_dir)
            port = SERIAL0_PORT + PORT_STEP * number
            try:
                _wait_up(process, port, log, start_timeout_s)
            except LinkError:
                # Another SITL may have taken the ports between the probe and the start.
                if process.poll() is not None and "bind" in tail(log, ARDUCOPTER, 20).lower():
                    continue
                raise
            yield RunningSitl(
                url=f"tcpout://127.0.0.1:{port}",
                pid=process.pid,
                instance=number,
                folder=folder,
                speedup=speedup,
                second_url=f"tcp:127.0.0.1:{SERIAL1_PORT + PORT_STEP * number}",
            )
            return
        raise LinkError(
            f"no free ArduCopter SITL instance among {', '.join(map(str, candidates))} (TCP "
            f"ports {SERIAL0_PORT + PORT_STEP * candidates[0]} and up are taken): stop the "
            "other SITLs and try again"
        )
