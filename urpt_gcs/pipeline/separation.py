"""Keeping a fleet's vehicles apart: their planned tracks, the closest two come, and the
start delays that keep every pair far enough apart.

A vehicle's :class:`Track` is its plan as the flight-time model flies it (take-off, each leg,
each hold, home, landing). Vehicles take off in turn; each starts at the first whole step of
:data:`DELAY_STEP_S` at which its track stays clear of every earlier one's while both fly,
with either vehicle of a pair up to :func:`timing_slack_s` early or late.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pyproj

from urpt_gcs.arrays import FloatArray
from urpt_gcs.errors import SettingsError
from urpt_gcs.pipeline.area import xy_to_latlon
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.pipeline.settings import FleetSettings, SeparationMode

# Start delays are searched in whole steps of this, up to the undelayed makespan.
DELAY_STEP_S = 5.0
# A vehicle keeps its planned timing only so well (a real copter flew the demo 3 % faster
# than the flight-time model): separation must hold with either vehicle of a pair up to
# this much early or late against the other -- the larger of a fixed time and a share of
# the longer flight -- tried in steps of TIMING_STEP_S.
TIMING_SLACK_S = 10.0
TIMING_SLACK_SHARE = 0.05
TIMING_STEP_S = 1.0
# The longest start delay, as a share of the longest flight; beyond it the plan is refused.
MAX_DELAY_SHARE = 0.5
# Each vehicle's written altitude is rounded to whole centimetres (home down, height up): the
# layers as written may come this much closer than the spacing asked for.
_WRITTEN_ROUNDING_M = 0.05


@dataclass(frozen=True, slots=True)
class Closest:
    """The closest two vehicles come while both are in the air."""

    distance_m: float
    horizontal_m: float
    vehicles: tuple[int, int]
    at_s: float
    where_xy: tuple[float, float]


@dataclass(frozen=True, slots=True)
class Separation:
    """How the vehicles are kept apart, and how close they come as planned."""

    mode: SeparationMode
    layer_spacing_m: float
    min_m: float
    start_delays_s: tuple[float, ...]
    closest: Closest | None
    closest_latlon: tuple[float, float] | None
    closest_horizontal_m: float | None
    timing_slack_s: float = 0.0


@dataclass(frozen=True, slots=True)
class Track:
    """A vehicle's planned position against time: breakpoints ``t_s`` (from its take-off
    command), positions ``xyz`` between which it moves at constant velocity, and whether it
    is in the air on each interval."""

    t_s: FloatArray
    xyz: FloatArray
    airborne: npt.NDArray[np.bool_]

    def shifted(self, delay_s: float) -> Track:
        """The same track started ``delay_s`` later."""
        return Track(self.t_s + delay_s, self.xyz, self.airborne)


def track(plan: Plan) -> Track:
    """The plan's tracks as the flight-time model flies them: on the ground until the
    take-off starts, straight up to the plane, each leg at the time the model gives it, a
    hold at each stop, home, down, and on the ground until the disarm; sorties back to back.

    Parameters
    ----------
    plan
        A vehicle's plan.

    Returns
    -------
    Track
        Its position against time from its take-off command, in the plan's CRS and metres
        above the vertical datum.
    """
    model = plan.flight_model
    ground = plan.mission.home.amsl_m
    eye = ground + plan.altitude_rel_m
    hx, hy = plan.home_xy
    assert plan.tour.points_xy is not None
    times = [0.0]
    points = [(hx, hy, ground)]
    air: list[bool] = []

    def go(duration_s: float, to: tuple[float, float, float], flying: bool) -> None:
        times.append(times[-1] + max(duration_s, 0.0))
        points.append(to)
        air.append(flying)

    climb = model.takeoff_s(plan.altitude_rel_m) - model.start_s
    down = model.landing_s(plan.altitude_rel_m) - model.touchdown_s
    for sortie in plan.sorties:
        go(model.start_s, (hx, hy, ground), False)
        go(climb, (hx, hy, eye), True)
        here = (hx, hy)
        for x, y in plan.tour.points_xy[sortie.first : sortie.stop].tolist():
            go(float(model.leg_s(math.hypot(x - here[0], y - here[1]))), (x, y, eye), True)
            go(model.stop_s, (x, y, eye), True)
            here = (x, y)
        go(float(model.return_s(math.hypot(hx - here[0], hy - here[1]))), (hx, hy, eye), True)
        go(down, (hx, hy, ground), True)
        go(model.touchdown_s, (hx, hy, ground), False)
    return Track(np.asarray(times), np.asarray(points, dtype=np.float64), np.asarray(air))


def _at(tr: Track, t: FloatArray) -> FloatArray:
    return np.column_stack([np.interp(t, tr.t_s, tr.xyz[:, i]) for i in range(3)])


def _flying(tr: Track, t: FloatArray) -> npt.NDArray[np.bool_]:
    i = np.searchsorted(tr.t_s, t, side="right") - 1
    inside = (i >= 0) & (i < len(tr.airborne))
    out: npt.NDArray[np.bool_] = inside & tr.airborne[np.clip(i, 0, len(tr.airborne) - 1)]
    return out


def closest(a: Track, b: Track, horizontal: bool) -> tuple[float, float, FloatArray] | None:
    """The least distance (3-D, or horizontal) between two tracks while both fly, exact for
    their piecewise-constant velocities: (distance, time, midpoint xyz), or None if they are
    never in the air together.

    Parameters
    ----------
    a, b
        The two tracks, on one clock.
    horizontal
        Measure in the horizontal plane only (else 3-D).

    Returns
    -------
    tuple of (float, float, FloatArray) or None
        The least distance, when it occurs and the midpoint between the two there; None if
        they never fly together.
    """
    t = np.union1d(a.t_s, b.t_s)
    t = t[(t >= max(a.t_s[0], b.t_s[0])) & (t <= min(a.t_s[-1], b.t_s[-1]))]
    if len(t) < 2:
        return None
    mid = 0.5 * (t[:-1] + t[1:])
    both = _flying(a, mid) & _flying(b, mid)
    if not both.any():
        return None
    pa, pb = _at(a, t), _at(b, t)
    r = pa - pb
    if horizontal:
        r[:, 2] = 0.0
    r0, r1 = r[:-1][both], r[1:][both]
    dr = r1 - r0
    den = np.einsum("ij,ij->i", dr, dr)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(den > 0.0, np.clip(-np.einsum("ij,ij->i", r0, dr) / den, 0.0, 1.0), 0.0)
    gap = np.linalg.norm(r0 + s[:, None] * dr, axis=1)
    i = int(np.argmin(gap))
    t0, t1 = t[:-1][both][i], t[1:][both][i]
    when = float(t0 + s[i] * (t1 - t0))
    where = 0.5 * (_at(a, np.array([when]))[0] + _at(b, np.array([when]))[0])
    return float(gap[i]), when, where


def timing_slack_s(a: Track, b: Track) -> float:
    """How far early or late one vehicle of a pair may run against the other.

    Parameters
    ----------
    a, b
        The pair's tracks.

    Returns
    -------
    float
        Seconds: :data:`TIMING_SLACK_S` or :data:`TIMING_SLACK_SHARE` of the longer flight,
        whichever is larger.
    """
    longest = max(a.t_s[-1] - a.t_s[0], b.t_s[-1] - b.t_s[0])
    return max(TIMING_SLACK_S, TIMING_SLACK_SHARE * float(longest))


def pair_closest(tracks: Sequence[Track], i: int, j: int) -> Closest | None:
    """The pair's closest approach, the least over ``j`` running early or late against ``i``
    by up to :func:`timing_slack_s` (each shift's approach exact, the shifts in steps of
    :data:`TIMING_STEP_S`); its time is on ``i``'s clock.

    Parameters
    ----------
    tracks
        Every vehicle's track, each with its start delay.
    i, j
        The pair, as indices into ``tracks``.

    Returns
    -------
    Closest or None
        The least 3-D and least horizontal distance over the shifts (vehicles numbered from
        1), or None if the two never fly together.
    """
    a, b = tracks[i], tracks[j]
    slack = timing_slack_s(a, b)
    steps = math.ceil(slack / TIMING_STEP_S)
    best: Closest | None = None
    for shift in np.linspace(-slack, slack, 2 * steps + 1):
        moved = b.shifted(float(shift))
        full = closest(a, moved, horizontal=False)
        if full is None:
            continue
        flat = closest(a, moved, horizontal=True)
        assert flat is not None
        if best is not None and full[0] >= best.distance_m and flat[0] >= best.horizontal_m:
            continue
        found = Closest(
            full[0], flat[0], (i + 1, j + 1), full[1], (float(full[2][0]), float(full[2][1]))
        )
        if best is None:
            best = found
        else:
            # The least of each measure over the shifts (3-D and horizontal apart).
            best = Closest(
                min(best.distance_m, found.distance_m),
                min(best.horizontal_m, found.horizontal_m),
                best.vehicles,
                found.at_s if found.distance_m < best.distance_m else best.at_s,
                found.where_xy if found.distance_m < best.distance_m else best.where_xy,
            )
    return best


def separate(
    plans: Sequence[Plan | None],
    fleet: FleetSettings,
    crs: pyproj.CRS,
    first: Sequence[float] | None = None,
) -> Separation:
    """Start delays that keep every pair apart, and the closest approach they leave.

    Vehicles are taken in turn (:func:`_delays`, for a few orders of take-off); each starts
    at the first step of :data:`DELAY_STEP_S` at which its track stays ``min_m`` from every
    earlier one's while both fly (3-D in altitude mode, less the written altitudes'
    rounding; horizontal in time mode), with either running early or late by up to
    :func:`timing_slack_s`. None up to :data:`MAX_DELAY_SHARE` of the longest
    flight in any order: refused, naming the pair, where and when.

    Parameters
    ----------
    plans
        Every vehicle's plan, in vehicle order; None for a vehicle left idle (it does not
        take off: no start delay, never close to another).
    fleet
        The fleet's settings: separation mode, layer spacing and least distance.
    crs
        The planning CRS the plans share, to give the closest approach in lat/lon.
    first
        Start delays the plans were shared out for: their order of take-off is tried first.

    Returns
    -------
    Separation
        Each vehicle's start delay and the closest approach they leave.

    Raises
    ------
    urpt_gcs.errors.SettingsError
        No start delays up to the cap keep every pair apart.
    """
    flying = [k for k, p in enumerate(plans) if p is not None]
    if len(flying) < len(plans):
        return _with_idle(plans, flying, fleet, crs, first)
    flown = [p for p in plans if p is not None]
    return _separate(flown, fleet, crs, first)


def _with_idle(
    plans: Sequence[Plan | None],
    flying: list[int],
    fleet: FleetSettings,
    crs: pyproj.CRS,
    first: Sequence[float] | None,
) -> Separation:
    """The flying vehicles kept apart, the vehicles named by their numbers in the fleet."""
    flown = [p for p in plans if p is not None]
    try:
        apart = _separate(flown, fleet, crs, None if first is None else [first[k] for k in flying])
    except SettingsError as exc:
        # Its message numbers the flying vehicles only.
        if exc.template is None or not {"a", "b"} <= exc.values.keys():
            raise
        a, b = (flying[exc.values[key] - 1] + 1 for key in ("a", "b"))
        raise SettingsError.about(exc.template, **{**exc.values, "a": a, "b": b}) from None
    delays = [0.0] * len(plans)
    for k, d in zip(flying, apart.start_delays_s, strict=True):
        delays[k] = d
    closest = apart.closest
    if closest is not None:
        pair = (flying[closest.vehicles[0] - 1] + 1, flying[closest.vehicles[1] - 1] + 1)
        closest = dataclasses.replace(closest, vehicles=pair)
    return dataclasses.replace(apart, start_delays_s=tuple(delays), closest=closest)


def _separate(
    plans: Sequence[Plan],
    fleet: FleetSettings,
    crs: pyproj.CRS,
    first: Sequence[float] | None,
) -> Separation:
    base = [track(p) for p in plans]
    horizontal = fleet.separation == "time"
    need = fleet.min_m - (0.0 if horizontal else _WRITTEN_ROUNDING_M)
    # A vehicle held back longer than half the longest flight is all but flying in turn.
    cap = MAX_DELAY_SHARE * max(p.flight_time_s for p in plans)
    # Who takes off first changes the delays: the vehicles in turn as numbered (lowest layer
    # first), the longest flight first, and the highest layer first; the earliest last
    # landing is kept, the first refusal raised if every order is refused.
    count = len(plans)
    turns = [
        *([] if first is None else [sorted(range(count), key=lambda k: (first[k], k))]),
        list(range(count)),
        sorted(range(count), key=lambda k: -plans[k].flight_time_s),
        list(range(count - 1, -1, -1)),
    ]
    best: list[float] | None = None
    refused: SettingsError | None = None
    for turn in turns:
        try:
            delays = _delays(base, turn, need, cap, horizontal, fleet, crs)
        except SettingsError as exc:
            refused = refused or exc
            continue
        finish = max(d + p.flight_time_s for d, p in zip(delays, plans, strict=True))
        if best is None or finish < max(
            d + p.flight_time_s for d, p in zip(best, plans, strict=True)
        ):
            best = delays
    if best is None:
        assert refused is not None
        raise refused
    delays = best
    tracks = [b.shifted(d) for b, d in zip(base, delays, strict=True)]
    found = [
        c
        for i in range(len(tracks))
        for j in range(i + 1, len(tracks))
        if (c := pair_closest(tracks, i, j)) is not None
    ]
    least = min(found, key=lambda c: c.distance_m, default=None)
    flat = min((c.horizontal_m for c in found), default=None)
    where = None if least is None else xy_to_latlon(crs, np.array([least.where_xy]))[0]
    return Separation(
        mode=fleet.separation,
        layer_spacing_m=fleet.layer_spacing_m,
        min_m=fleet.min_m,
        start_delays_s=tuple(delays),
        closest=least,
        closest_latlon=where,
        closest_horizontal_m=flat,
        timing_slack_s=max(
            (
                timing_slack_s(tracks[i], tracks[j])
                for i in range(len(tracks))
                for j in range(i + 1, len(tracks))
            ),
            default=0.0,
        ),
    )


def _delays(
    base: list[Track],
    turn: list[int],
    need: float,
    cap: float,
    horizontal: bool,
    fleet: FleetSettings,
    crs: pyproj.CRS,
) -> list[float]:
    """Start delays with the vehicles taking off in the order ``turn``: each at the first
    step of :data:`DELAY_STEP_S` that keeps it ``need`` from every vehicle before it."""
    delays = [0.0] * len(base)

    def apart(k: int, delay: float, earlier: list[int]) -> Closest | None:
        moved = base[k].shifted(delay)
        worst: Closest | None = None
        for j in earlier:
            c = pair_closest([base[j].shifted(delays[j]), moved], 0, 1)
            if c is None:
                continue
            c = dataclasses.replace(c, vehicles=(min(j, k) + 1, max(j, k) + 1))
            value = c.horizontal_m if horizontal else c.distance_m
            if value < need and (worst is None or value < _value(worst, horizontal)):
                worst = c
        return worst

    for n, k in enumerate(turn[1:], start=1):
        first = apart(k, 0.0, turn[:n])
        delay = 0.0
        clash = first
        while clash is not None:
            delay += DELAY_STEP_S
            if delay > cap:
                assert first is not None
                lat, lon = xy_to_latlon(crs, np.array([first.where_xy]))[0]
                what = " horizontally" if horizontal else ""
                raise SettingsError.about(
                    "vehicles {a} and {b} come within {distance:.1f} m{what} of each other at "
                    "{at:.0f} s after take-off near {lat:.6f}, {lon:.6f}, under the {least:g} m "
                    "required, and no start delay up to {cap:.0f} s avoids it: give the "
                    "vehicles homes further apart in {fleet_file}, or "
                    + ("use {separation} altitude" if horizontal else "raise {layer_spacing_m}"),
                    a=first.vehicles[0],
                    b=first.vehicles[1],
                    distance=_value(first, horizontal),
                    what=what,
                    at=first.at_s,
                    lat=lat,
                    lon=lon,
                    least=fleet.min_m,
                    cap=cap,
                )
            clash = apart(k, delay, turn[:n])
        delays[k] = delay
    return delays


def _value(c: Closest, horizontal: bool) -> float:
    return c.horizontal_m if horizontal else c.distance_m


__all__ = [
    "DELAY_STEP_S",
    "MAX_DELAY_SHARE",
    "TIMING_SLACK_S",
    "TIMING_SLACK_SHARE",
    "TIMING_STEP_S",
    "Closest",
    "Separation",
    "Track",
    "closest",
    "pair_closest",
    "separate",
    "timing_slack_s",
    "track",
]
