"""The best flight-plane altitude: the same plan over a range of altitudes, kept where the
flight is shortest in time.

A higher plane widens every camera footprint (fewer, farther-apart stops) but lengthens the
climb and descent; a GSD requirement caps it. The range runs from the plane ``--clearance``
above the highest terrain of the operating area (the lowest one a plan accepts) up to
``--max-agl`` above the lowest of home and the targets, and, with ``--gsd``, no higher than a
photo at that resolution still leaves room for the position tolerance. The altitudes are
planned in parallel processes, one per core; the best is planned again here so its plan (with
its terrain and oracle, which do not cross processes) is returned whole.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from pathlib import Path

import numpy as np

from urpt_gcs.errors import SettingsError, UrptError
from urpt_gcs.pipeline.options import FLAGS
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.result import AltitudePoint, AltitudeSweep, Plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.processes import run_owned
from urpt_gcs.progress import Progress

# Altitudes planned by default, the lowest and highest included.
DEFAULT_STEPS = 6
# Headroom kept under the GSD distance for the position tolerance, metres beyond twice it.
_GSD_MARGIN_M = 0.5


def altitude_range(probe: Plan, steps: int) -> list[float]:
    """The altitudes to plan, from the lowest plane ``probe`` (planned at ``--clearance``)
    to the highest ``--max-agl`` and ``--gsd`` allow, ``steps`` of them, to the centimetre.

    Parameters
    ----------
    probe
        The plan at the lowest plane a plan accepts.
    steps
        How many altitudes, the lowest and highest included.

    Returns
    -------
    list of float
        The altitudes, ascending; only the lowest when no higher plane is allowed.
    """
    settings = probe.settings
    low = probe.camera.altitude_m
    base = min(probe.home_ground_m, float(np.min(probe.ground_m)))
    high = base + settings.max_agl_m
    far = probe.camera.max_distance_m
    if math.isfinite(far):
        slack = 2.0 * settings.position_tolerance_m + _GSD_MARGIN_M
        high = min(high, float(np.min(probe.ground_m)) + math.sqrt(max(far**2 - slack**2, 0.0)))
    if high <= low + 0.01 or steps == 1:
        return [round(low, 2)]
    return [round(float(a), 2) for a in np.linspace(low, high, steps)]


def _plan_at(job: tuple[Path, Path, PlanSettings, float]) -> AltitudePoint:
    dem, targets, settings, altitude = job
    started = time.perf_counter()
    try:
        # Only the flight is compared here: the kept plane is certified on its own.
        trial = dataclasses.replace(settings, altitude_m=altitude, workers=1, certify=False)
        result = plan(dem, targets, trial)
    except UrptError as exc:
        # The sweep's record (summary.json, the report) names a setting by its flag, as
        # ``urpt-gcs plan --altitude auto`` has always written it.
        why = exc.naming(FLAGS) if isinstance(exc, SettingsError) else str(exc)
        return AltitudePoint(altitude, None, None, time.perf_counter() - started, why)
    return AltitudePoint(
        altitude, result.flown_length_m, result.flight_time_s, time.perf_counter() - started
    )


def best_altitude(
    dem_path: Path,
    targets_path: Path,
    settings: PlanSettings,
    steps: int = DEFAULT_STEPS,
    processes: int | None = None,
    progress: Progress | None = None,
) -> Plan:
    """Plan at ``steps`` altitudes and return the plan with the shortest flight time, its
    ``altitude_sweep`` holding the whole curve.

    Parameters
    ----------
    dem_path, targets_path, settings
        As for :func:`urpt_gcs.pipeline.planner.plan`; ``settings.altitude_m`` must be None.
    steps
        How many altitudes, the lowest and highest included.
    processes
        Parallel plans (None: one per core).
    progress
        Called with a short message as each stage starts.
    """
    if settings.agl_band_m is not None:
        raise SettingsError.about(
            "{altitude_m} auto sweeps flight planes; {agl_band_m} follows the terrain: give one"
        )
    if settings.altitude_m is not None:
        raise SettingsError.about(
            "{altitude_m} auto chooses the altitude: give it without a number"
        )
    if not 1 <= steps <= 50:
        raise SettingsError.about(
            "{altitude_steps} {value} is out of range: give 1 to 50", value=steps
        )
    say = progress or (lambda _msg: None)
    started = time.perf_counter()
    say("planning the lowest plane")
    probe = plan(dem_path, targets_path, settings)
    altitudes = altitude_range(probe, steps)
    say(f"planning {len(altitudes)} altitudes, {altitudes[0]:.1f}-{altitudes[-1]:.1f} m")
    jobs = [(dem_path, targets_path, settings, a) for a in altitudes[1:]]
    points = [
        AltitudePoint(
            altitudes[0],
            probe.flown_length_m,
            probe.flight_time_s,
            sum(probe.timings_s.values()),
        )
    ]
    workers = min(processes or os.cpu_count() or 1, max(len(jobs), 1))
    if jobs and workers > 1:
        # Processes this one owns: none outlives a Ctrl-C or SIGTERM, none prints its own.
        points += run_owned(_plan_at, jobs, workers)
    else:
        points += [_plan_at(job) for job in jobs]
    flown = [p for p in points if p.flight_time_s is not None]
    best = min(flown, key=lambda p: (p.flight_time_s, p.altitude_m))
    if best.altitude_m == altitudes[0]:
        kept = probe
    else:
        say(f"planning the best altitude, {best.altitude_m:.1f} m")
        kept = plan(
            dem_path, targets_path, dataclasses.replace(settings, altitude_m=best.altitude_m)
        )
    sweep = AltitudeSweep(tuple(points), best.altitude_m, time.perf_counter() - started)
    return dataclasses.replace(kept, altitude_sweep=sweep)


__all__ = ["DEFAULT_STEPS", "altitude_range", "best_altitude"]
