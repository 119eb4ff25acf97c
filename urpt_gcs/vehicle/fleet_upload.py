"""Put a fleet plan on its vehicles: each vehicle's mission verified on its own.

Each vehicle is reached on its own connection (one URL per vehicle, in vehicle order), or all
of them on one link by their MAVLink system ids. Every mission file is read and checked
before anything is sent, each against what the fleet's ``summary.json`` records for its
vehicle; then each vehicle gets :func:`urpt_gcs.vehicle.link.upload_with_fence`, the
verified upload with read-back. A vehicle either holds its whole mission, verified, or is
reported as failed with the reason; one vehicle's failure does not stop the others.
"""

from __future__ import annotations

import asyncio
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from urpt_gcs.errors import SettingsError, UrptError
from urpt_gcs.files.fleet_folder import FleetFolder, FleetVehicle
from urpt_gcs.files.mission_file import read_fence, read_mission
from urpt_gcs.files.plan_check import check_missions
from urpt_gcs.flight.geofence import Geofence
from urpt_gcs.flight.mission import Mission
from urpt_gcs.progress import Progress
from urpt_gcs.vehicle.link import UploadReport, UploadSettings, refuse_unfit, upload_with_fence
from urpt_gcs.vehicle.mavsdk_link import connect, connect_systems

__all__ = [
    "FleetUploadReport",
    "VehicleUpload",
    "check_connections",
    "check_sortie",
    "parse_system_ids",
    "report_lines",
    "upload_fleet",
]


@dataclass(frozen=True, slots=True)
class VehicleUpload:
    """One vehicle's upload: ``report`` when verified, else ``error`` (one line)."""

    vehicle: FleetVehicle
    connection: str
    mission_file: Path | None
    sorties: int
    report: UploadReport | None = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.report is not None


@dataclass(frozen=True, slots=True)
class FleetUploadReport:
    """Every vehicle's upload, in vehicle order."""

    vehicles: tuple[VehicleUpload, ...]
    sortie: int

    @property
    def failed(self) -> tuple[VehicleUpload, ...]:
        """The vehicles that were to get a mission and do not hold it verified."""
        return tuple(v for v in self.vehicles if v.mission_file is not None and not v.ok)

    @property
    def ok(self) -> bool:
        return not self.failed


def parse_system_ids(text: str) -> tuple[int, ...]:
    """``1,2,3`` as system ids; SettingsError naming --sysid otherwise."""
    try:
        ids = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise SettingsError(
            f"--sysid {text!r} is not a list of system ids: give e.g. --sysid 1,2,3"
        ) from None
    bad = [i for i in ids if not 1 <= i <= 255]
    if bad:
        raise SettingsError(f"--sysid {text!r}: system id {bad[0]} is not 1 to 255")
    if len(set(ids)) != len(ids):
        raise SettingsError(f"--sysid {text!r} names a system id twice: give each vehicle its own")
    return ids


def check_connections(
    fleet: FleetFolder, urls: Sequence[str], system_ids: Sequence[int] | None
) -> None:
    """Refuse a connection list that does not match the fleet, before anything is sent."""
    count = len(fleet.vehicles)
    if system_ids is not None:
        if len(urls) != 1:
            raise SettingsError(
                f"--sysid names vehicles on one link, but {len(urls)} --connect were given: "
                "give one --connect with --sysid, or one --connect per vehicle without it"
            )
        if len(system_ids) != count:
            raise SettingsError(
                f"{count} vehicles in '{fleet.folder}' but {len(system_ids)} system ids in "
                f"--sysid: give one id per vehicle, in vehicle order"
            )
        return
    if len(urls) != count:
        raise SettingsError(
            f"{count} vehicles in '{fleet.folder}' but {len(urls)} --connect URLs: give one "
            "--connect per vehicle, in vehicle order (or one --connect with --sysid 1,2,...)"
        )


def check_sortie(fleet: FleetFolder, sortie: int) -> None:
    """Refuse a sortie number no vehicle of the fleet flies, before anything is sent: the
    upload would otherwise skip every vehicle and report none of none verified."""
    most = max(len(v.missions) for v in fleet.vehicles)
    if 1 <= sortie <= most:
        return
    if most == 1:
        raise SettingsError(
            f"--sortie {sortie}: every vehicle of '{fleet.folder}' flies one sortie: give "
            "--sortie 1, or leave it out"
        )
    raise SettingsError(
        f"--sortie {sortie}: the vehicles of '{fleet.folder}' fly at most {most} sorties: give "
        f"--sortie 1 to {most}"
    )


def upload_fleet(
    fleet: FleetFolder,
    urls: Sequence[str],
    system_ids: Sequence[int] | None = None,
    settings: UploadSettings | None = None,
    progress: Progress | None = None,
    sortie: int = 1,
) -> FleetUploadReport:
    """Upload each vehicle's mission (sortie ``sortie`` where it has several) and its fence.

    Parameters
    ----------
    fleet
        The fleet plan (:func:`urpt_gcs.files.fleet_folder.read_fleet`).
    urls
        One MAVSDK connection string per vehicle, in vehicle order; or one, with
        ``system_ids``.
    system_ids
        The vehicles' MAVLink system ids on the one link, in vehicle order.
    settings
        Retries and timeouts, for each vehicle.
    progress
        Called with a short message, prefixed with the vehicle, as each upload goes on.
    sortie
        Which sortie to upload to a vehicle that has several; a vehicle with fewer is skipped,
        and so is a vehicle the plan leaves idle (it is not connected to).

    Returns
    -------
    FleetUploadReport
        Per vehicle, its verified upload or its one-line error.

    Raises
    ------
    SettingsError
        Before anything is sent: connections that do not match the vehicles, or a sortie
        number no vehicle flies.
    MissionFileError
        Before anything is sent, if a vehicle's mission file cannot be read or is not the
        one the fleet's ``summary.json`` records for it
        (:func:`urpt_gcs.files.plan_check.check_missions`).
    """
    check_connections(fleet, urls, system_ids)
    check_sortie(fleet, sortie)
    check_missions(fleet)
    settings = settings or UploadSettings()
    loaded: list[tuple[Mission, Geofence] | None] = []
    for vehicle in fleet.vehicles:
        if sortie > len(vehicle.missions):
            loaded.append(None)
            continue
        path = vehicle.missions[sortie - 1]
        mission = read_mission(path, flag="urpt-gcs upload --fleet")
        refuse_unfit(mission)
        loaded.append((mission, read_fence(path)))
    say = progress or (lambda _msg: None)
    if system_ids is None:
        results = asyncio.run(_by_url(fleet, urls, loaded, settings, say, sortie))
    else:
        results = asyncio.run(_by_sysid(fleet, urls[0], system_ids, loaded, settings, say, sortie))
    return FleetUploadReport(tuple(results), sortie)


def _entry(vehicle: FleetVehicle, connection: str, sortie: int, chosen: bool) -> VehicleUpload:
    path = vehicle.missions[sortie - 1] if chosen else None
    return VehicleUpload(vehicle, connection, path, len(vehicle.missions))


async def _one(
    entry: VehicleUpload,
    load: tuple[Mission, Geofence],
    settings: UploadSettings,
    say: Progress,
) -> VehicleUpload:
    mission, fence = load
    prefix = f"{entry.vehicle.name}: "
    try:
        async with connect(entry.connection, settings.timeout_s) as link:
            report = await upload_with_fence(
                link, mission, settings, lambda m: say(prefix + m), fence
            )
    except UrptError as exc:
        return replace(entry, error=" ".join(str(exc).split()))
    return replace(entry, report=report)


async def _by_url(
    fleet: FleetFolder,
    urls: Sequence[str],
    loaded: Sequence[tuple[Mission, Geofence] | None],
    settings: UploadSettings,
    say: Progress,
    sortie: int,
) -> list[VehicleUpload]:
    entries = [
        _entry(v, url, sortie, load is not None)
        for v, url, load in zip(fleet.vehicles, urls, loaded, strict=True)
    ]
    work = [
        _one(entry, load, settings, say) if load is not None else _skipped(entry)
        for entry, load in zip(entries, loaded, strict=True)
    ]
    return list(await asyncio.gather(*work))


async def _skipped(entry: VehicleUpload) -> VehicleUpload:
    return entry


async def _by_sysid(
    fleet: FleetFolder,
    url: str,
    system_ids: Sequence[int],
    loaded: Sequence[tuple[Mission, Geofence] | None],
    settings: UploadSettings,
    say: Progress,
    sortie: int,
) -> list[VehicleUpload]:
    entries = [
        _entry(v, f"{url} (system {sysid})", sortie, load is not None)
        for v, sysid, load in zip(fleet.vehicles, system_ids, loaded, strict=True)
    ]
    # A vehicle left idle need not be on the link.
    wanted = [i for v, i in zip(fleet.vehicles, system_ids, strict=True) if not v.idle]
    say(f"waiting for systems {', '.join(map(str, wanted))} on {url}")
    try:
        async with connect_systems(url, wanted, settings.timeout_s) as links:
            results = []
            # One at a time: the links share one MAVSDK instance and its transfer timeout.
            for entry, sysid, load in zip(entries, system_ids, loaded, strict=True):
                if load is None:
                    results.append(entry)
                    continue
                mission, fence = load
                try:
                    report = await upload_with_fence(
                        links[sysid], mission, settings, _prefixed(say, entry.vehicle), fence
                    )
                except UrptError as exc:
                    results.append(replace(entry, error=" ".join(str(exc).split())))
                    continue
                results.append(replace(entry, report=report))
            return results
    except UrptError as exc:
        # The link itself failed: no vehicle on it got a mission.
        message = " ".join(str(exc).split())
        return [e if e.mission_file is None else replace(e, error=message) for e in entries]


def _prefixed(say: Progress, vehicle: FleetVehicle) -> Progress:
    return lambda message: say(f"{vehicle.name}: {message}")


def report_lines(report: FleetUploadReport, folder: Path) -> list[str]:
    """One line per vehicle, then the fleet's verdict."""
    lines = []
    for entry in report.vehicles:
        head = f"{entry.vehicle.name} on {entry.connection}"
        if entry.vehicle.idle:
            lines.append(
                f"{head}: idle in this plan, nothing sent (not connected); it may still hold "
                "an earlier mission: keep it on the ground"
            )
            continue
        if entry.mission_file is None:
            lines.append(
                f"{head}: skipped, it has {entry.sorties} sortie"
                f"{'s' if entry.sorties != 1 else ''}, no sortie {report.sortie}"
            )
            continue
        shown = _shown(entry.mission_file, folder)
        sortie = f" (sortie {report.sortie} of {entry.sorties})" if entry.sorties > 1 else ""
        if entry.report is None:
            lines.append(
                f"{head}: {shown}{sortie} NOT VERIFIED: {entry.error}; upload it again alone: "
                f"urpt-gcs upload {entry.mission_file} --connect URL"
            )
            continue
        up = entry.report
        tries = f"{up.attempts} attempts" if up.attempts > 1 else "1 attempt"
        fence = f"; geofence {up.fence.items} items verified" if up.fence is not None else ""
        lines.append(
            f"{head}: {shown}{sortie} {up.items} items sent, read back identical in "
            f"{up.elapsed_s:.2f} s ({tries}, {up.autopilot}){fence}"
        )
    sent = [v for v in report.vehicles if v.mission_file is not None]
    lines.append(
        f"fleet: {sum(v.ok for v in sent)} of {len(sent)} vehicles hold their mission, verified"
    )
    return lines


def _shown(path: Path, folder: Path) -> str:
    try:
        return str(path.relative_to(folder))
    except ValueError:
        return str(path)
