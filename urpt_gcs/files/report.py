"""Report: the plan summarised for the operator, as a screen of text and as JSON."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from urpt_gcs.bound.certificate import PROVEN_GAP
from urpt_gcs.files.band_report import (
    band_lines,
    band_stop_lines,
    band_stops,
    band_summary,
    eye_heights_m,
)
from urpt_gcs.flight.mission import photo_headings, photo_positions
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.pipeline.settings import settings_record
from urpt_gcs.site.dem import crs_label


def _round(x: float, digits: int = 2) -> float | None:
    return round(x, digits) if math.isfinite(x) else None


# Bright colours that stand apart on a grey hillshade and in Google Earth's imagery, one per
# sortie in turn; the map, KML and GeoJSON share them.
SORTIE_COLOURS = (
    "#ffd400",
    "#00b4ff",
    "#ff3fa4",
    "#5ce65c",
    "#ff8c1a",
    "#a77dff",
    "#00e0c0",
    "#ff4040",
)


def sortie_colour(number: int) -> str:
    """The ``#rrggbb`` colour of sortie ``number`` (from 1)."""
    return SORTIE_COLOURS[(number - 1) % len(SORTIE_COLOURS)]


@dataclass(frozen=True, slots=True)
class FlownStop:
    """A stop as its sortie's mission flies it: the written waypoint, in flight order."""

    order: int
    sortie: int
    lat_deg: float
    lon_deg: float
    sees: tuple[str, ...]
    from_previous_m: float
    eta_s: float


def flown_stops(plan: Plan) -> list[FlownStop]:
    """Every stop of every sortie with what it sees and when the copter gets there.

    Positions are the missions' NAV_WAYPOINT items that take a photo, so whatever draws them
    draws what is flown; ``eta_s`` is from arming, on the plan's
    :class:`~urpt_gcs.problem.flight_time.FlightModel`. In a band plan ``from_previous_m``
    is the horizontal length of the path from the stop before, through the waypoints that
    follow the terrain, and the ETA flies that path
    (:func:`~urpt_gcs.files.band_report.band_stops`).
    """
    tour = plan.tour
    assert tour.points_xy is not None
    names = [t.name for t in plan.targets.targets]
    model = plan.flight_model
    waypoints = [latlon for m in plan.missions for latlon in photo_positions(m)]
    if plan.band_flight is not None:
        return [
            FlownStop(
                order=b.order,
                sortie=b.sortie,
                lat_deg=waypoints[b.order - 1][0],
                lon_deg=waypoints[b.order - 1][1],
                sees=tuple(names[t] for t in np.flatnonzero(tour.sees[b.order - 1]).tolist()),
                from_previous_m=b.from_previous_m,
                eta_s=b.eta_s,
            )
            for b in band_stops(plan)
        ]
    stops = []
    for number, sortie in enumerate(plan.sorties, start=1):
        previous = np.asarray(plan.home_xy)
        eta = model.takeoff_s(plan.altitude_rel_m)
        for k in range(sortie.first, sortie.stop):
            xy = tour.points_xy[k]
            hop = float(np.hypot(*(xy - previous)))
            eta += float(model.leg_s(hop))
            stops.append(
                FlownStop(
                    order=k + 1,
                    sortie=number,
                    lat_deg=waypoints[k][0],
                    lon_deg=waypoints[k][1],
                    sees=tuple(names[t] for t in np.flatnonzero(tour.sees[k]).tolist()),
                    from_previous_m=round(hop, 2),
                    eta_s=round(eta, 1),
                )
            )
            eta += model.stop_s
            previous = xy
    return stops


def summary(plan: Plan, files: list[str] | None = None) -> dict[str, Any]:
    """The plan's key figures; what ``summary.json`` holds."""
    tour = plan.tour
    inst = plan.instance
    names = [t.name for t in plan.targets.targets]
    stops = [
        {
            "order": stop.order,
            "sortie": stop.sortie,
            "lat_deg": stop.lat_deg,
            "lon_deg": stop.lon_deg,
            "sees": list(stop.sees),
            "from_previous_m": stop.from_previous_m,
            "eta_s": stop.eta_s,
        }
        for stop in flown_stops(plan)
    ]
    band = plan.band_flight is not None
    if band:
        for entry, b in zip(stops, band_stops(plan), strict=True):
            entry["height_amsl_m"] = b.amsl_m
            entry["height_above_home_m"] = b.above_home_m
            entry["height_above_surface_m"] = _round(b.above_surface_m)
    sorties = [
        {
            "sortie": n,
            "stops": s.stop - s.first,
            "length_m": round(s.length_m, 2),
            "flight_time_s": round(s.flight_time_s, 1),
        }
        for n, s in enumerate(plan.sorties, start=1)
    ]
    return {
        "targets": len(names),
        "target_names": names,
        "viewpoints": inst.n_viewpoints,
        "tour_stops": len(tour.order),
        # What is flown: every sortie from home and back, added up (the tour itself with one
        # sortie). The bound holds for it: sorties joined at home are one closed tour.
        "tour_length_m": round(plan.flown_length_m, 3),
        # Certified for every flight from home that photographs every target, from anywhere
        # on the plane; rounded down, and the gap up, so that neither claims too much.
        "lower_bound_m": math.floor(plan.lower_bound_m * 1000.0) / 1000.0,
        "gap_pct": _round_up(100.0 * plan.flown_gap, 2),
        "proven_optimal": plan.proven_optimal,
        "proven_gap_pct": 100.0 * PROVEN_GAP,
        # The solver's own claim: no tour over the candidate viewpoints is shorter.
        "optimal_over_candidates": plan.optimal_over_candidates,
        **_refinement(plan),
        "bound": _bound(plan),
        # In a band the solver's tour is costed in seconds (see band.estimate_s).
        "solver_tour_length_m": None
        if band
        else round(
            tour.length if plan.sortie_order is None else plan.sortie_order.tour_length_m, 3
        ),
        "solver_proven_optimal": tour.proven_optimal,
        "sortie_order": _sortie_order(plan),
        "solver": tour.solver,
        "solve_s": round(tour.solve_s, 3),
        "flight_time_s": round(plan.flight_time_s, 1),
        # No plane in a band: each stop has its own height (band, stops).
        "altitude_amsl_m": None if band else round(plan.camera.altitude_m, 2),
        "altitude_above_home_m": None if band else round(plan.altitude_rel_m, 2),
        "terrain_max_m": round(plan.terrain_max_m, 2),
        "fov_deg": plan.camera.fov_deg,
        "samples": plan.settings.samples,
        "firmware": plan.mission.firmware,
        "hold_s": plan.settings.mission.hold_s,
        "cruise_speed_m_s": plan.settings.mission.cruise_speed_m_s,
        "home": {
            "lat_deg": plan.mission.home.lat_deg,
            "lon_deg": plan.mission.home.lon_deg,
            "ground_m": round(plan.home_ground_m, 2),
            "source": plan.home_source,
        },
        "dem": {
            "path": str(plan.dem.path),
            "crs": plan.crs.to_string(),
            "cell_m": round(plan.terrain.cell_m, 4),
            "read_window_px": list(plan.terrain.read_window_px),
            "source_shape_px": list(plan.terrain.source_shape_px),
            "crs_name": crs_label(plan.crs, code_first=True),
            "source_crs": crs_label(plan.dem.crs),
            "band": plan.dem.band,
            "vertical_unit": plan.dem.vertical_unit.name,
            "vertical_unit_to_m": plan.dem.vertical_unit.to_m,
            "vertical_unit_declared": plan.dem.vertical_unit.declared,
            "planned_in_source_crs": plan.crs == plan.dem.horizontal_crs,
        },
        "min_clearance_m": plan.settings.min_clearance_m,
        "min_leg_clearance_m": _round(
            min((leg.min_clearance_m for leg in plan.legs), default=math.nan)
        ),
        "sorties": sorties,
        "max_agl_m": plan.settings.max_agl_m,
        "endurance_min": plan.settings.endurance_min,
        "geofence_vertices": len(plan.geofence_latlon),
        "stops": stops,
        "timings_s": {k: round(v, 3) for k, v in plan.timings_s.items()},
        "warnings": list(plan.warnings),
        # Every setting the plan was made with, so that a later plan can use them again
        # (``plan --resume``).
        "settings": settings_record(plan.settings),
        "files": files or [],
        **_frame_camera(plan),
        **_altitude_curve(plan),
        **({"band": band_summary(plan)} if band else {}),
    }


def _round_up(x: float, digits: int = 2) -> float | None:
    if not math.isfinite(x):
        return None
    scale = 10.0**digits
    return math.ceil(x * scale - 1e-9) / scale


def _refinement(plan: Plan) -> dict[str, Any]:
    """The solver's tour before and after its stops were moved within their regions."""
    done = plan.refinement
    if done is None:
        # A band's tour is costed in seconds, not metres.
        discrete = None if plan.band_flight is not None else round(plan.tour.length, 3)
        return {"discrete_length_m": discrete, "refined_length_m": None}
    return {
        "discrete_length_m": round(done.before_m, 3),
        "refined_length_m": round(done.after_m, 3),
        "refine_shortened_pct": round(done.shortened_pct, 3),
        "refine_moves": done.moves,
        "refine_s": round(done.seconds, 3),
    }


def _bound(plan: Plan) -> dict[str, Any] | None:
    """How the certified bound was found."""
    c = plan.certificate
    if c is None:
        return None
    out: dict[str, Any] = {
        "method": c.method,
        "seconds": round(c.seconds, 3),
        "sectors": c.sectors,
        "outer_to_inner_area": _round(c.area_ratio, 3),
        "holding_m": plan.settings.position_tolerance_m,
    }
    found = c.sorties
    if found is not None:
        # What the endurance forces (bound.sorties): rounded down, the gap up.
        time_bound = math.floor(found.flight_time_s * 10.0) / 10.0
        out |= {
            "single_flight_bound_m": math.floor(found.single_m * 1000.0) / 1000.0,
            "sorties_at_least": found.sorties,
            "flight_time_bound_s": time_bound,
            "flight_time_gap_pct": _round_up(
                100.0 * (plan.flight_time_s - time_bound) / time_bound, 2
            )
            if time_bound > 0.0
            else None,
        }
    return out


def _altitude_curve(plan: Plan) -> dict[str, Any]:
    """With --altitude auto: each altitude planned, what it flies, and the one kept."""
    sweep = plan.altitude_sweep
    if sweep is None:
        return {}
    return {
        "altitude_curve": [
            {
                "altitude_amsl_m": p.altitude_m,
                "tour_length_m": None if p.tour_length_m is None else round(p.tour_length_m, 2),
                "flight_time_s": None if p.flight_time_s is None else round(p.flight_time_s, 1),
                "wall_s": round(p.wall_s, 2),
                "error": p.error,
            }
            for p in sweep.points
        ],
        "altitude_best_amsl_m": sweep.best_altitude_m,
        "altitude_sweep_wall_s": round(sweep.wall_s, 2),
    }


def photo_gsd_cm(plan: Plan) -> list[dict[int, float]] | None:
    """The ground resolution of each photo at each target it is counted for, in cm/px: per
    stop of the tour in flight order, target index -> GSD; None for a cone camera, which
    gives none."""
    frame = plan.camera.frame
    tour = plan.tour
    if frame is None:
        return None
    assert tour.points_xy is not None
    eyes = eye_heights_m(plan)
    out = []
    for k, xy in enumerate(tour.points_xy):
        seen = np.flatnonzero(tour.sees[k])
        horizontal = np.hypot(*(plan.targets_xy[seen] - xy).T)
        slant = np.hypot(horizontal, eyes[k] - plan.ground_m[seen])
        out.append(dict(zip(seen.tolist(), frame.gsd_cm(slant).tolist(), strict=True)))
    return out


def _frame_camera(plan: Plan) -> dict[str, Any]:
    """A frame camera's figures: the frame, the headings offered, the ground resolution
    required and reached per target (the finest photo of it), and each photo's heading as
    the mission gives it. Nothing for the cone."""
    camera = plan.camera
    frame = camera.frame
    gsd = photo_gsd_cm(plan)
    if frame is None or gsd is None:
        return {}
    names = [t.name for t in plan.targets.targets]
    finest = [math.inf] * len(names)
    for photo in gsd:
        for t, cm in photo.items():
            finest[t] = min(finest[t], cm)
    reached = {name: round(cm, 3) for name, cm in zip(names, finest, strict=True)}
    worst = max(reached, key=lambda n: reached[n])
    headings = [h for m in plan.missions for h in (photo_headings(m) or [])]
    return {
        "camera": {
            "sensor_mm": [frame.sensor_w_mm, frame.sensor_h_mm],
            "focal_mm": frame.focal_mm,
            "image_px": [frame.image_w_px, frame.image_h_px],
            "headings_offered_deg": camera.heading_choices_deg.tolist(),
            "gsd_cm_required": camera.gsd_cm,
            "gsd_cm_per_target": reached,
            "worst_gsd_cm": reached[worst],
            "worst_gsd_target": worst,
            "photo_headings_deg": [round(h, 2) for h in headings],
        }
    }


def _camera_line(data: dict[str, Any]) -> str:
    camera = data.get("camera")
    if camera is None:
        return f"camera         half-angle {data['fov_deg']:g} deg, {data['samples']} azimuths"
    w, h = camera["sensor_mm"]
    iw, ih = camera["image_px"]
    required = camera["gsd_cm_required"]
    need = "" if required is None else f" (--gsd {required:g})"
    return (
        f"camera         {w:g} x {h:g} mm, {camera['focal_mm']:g} mm, {iw} x {ih} px; "
        f"{len(camera['headings_offered_deg'])} headings, {data['samples']} azimuths\n"
        f"ground res.    worst {camera['worst_gsd_cm']:.2f} cm/px{need}; per target, coarsest "
        f"first: {_coarsest(camera['gsd_cm_per_target'])}"
    )


def _coarsest(per_target: dict[str, float], shown: int = 6) -> str:
    ranked = sorted(per_target.items(), key=lambda kv: -kv[1])
    text = ", ".join(f"{name} {gsd:.2f}" for name, gsd in ranked[:shown])
    return text + (f", ... ({len(ranked) - shown} more)" if len(ranked) > shown else "")


def _sortie_order(plan: Plan) -> dict[str, Any] | None:
    """What reordering the stops for the sorties did (None for one sortie)."""
    found = plan.sortie_order
    if found is None:
        return None
    return {
        "plain_cut_sorties": found.plain_cut_sorties,
        "plain_cut_length_m": round(found.plain_cut_length_m, 3),
        "plain_cut_flight_time_s": round(found.plain_cut_flight_time_s, 1),
        "length_m": round(found.length_m, 3),
        "flight_time_s": round(found.flight_time_s, 1),
        "moves": found.moves,
        "search_s": round(found.search_s, 3),
        "budget_s": round(found.budget_s, 3),
    }


def _minutes(seconds: float) -> str:
    m, s = divmod(round(seconds), 60)
    return f"{m} min {s:02d} s"


def _refine_line(data: dict[str, Any]) -> str:
    band = data.get("band")
    if band is not None:
        before, after = band["unrefined_flight_time_s"], data["flight_time_s"]
        if after >= before:
            return "refinement     stops where the solver put them (moving them flew no faster)"
        return (
            f"refinement     stops moved in three dimensions: {_minutes(before)} -> "
            f"{_minutes(after)} of flight"
        )
    if data.get("refined_length_m") is None:
        return f"refinement     off; the solver's tour is {data['discrete_length_m']:.1f} m"
    return (
        f"refinement     stops moved within what they see: {data['discrete_length_m']:.1f} m -> "
        f"{data['refined_length_m']:.1f} m ({data['refine_shortened_pct']:.2f} % shorter)"
    )


def _dem_line(dem: dict[str, Any]) -> str:
    unit = str(dem["vertical_unit"])
    if not dem["vertical_unit_declared"]:
        heights = "DEM heights in metres (no vertical CRS declared)"
    elif dem["vertical_unit_to_m"] != 1.0:
        factor = dem["vertical_unit_to_m"]
        named = f"{unit[: -len('foot')]}feet" if unit.endswith("foot") else f"{unit} ({factor:g} m)"
        heights = f"DEM heights in {named}, converted to metres"
    else:
        heights = "DEM heights in metres"
    where = f"planned in {dem.get('crs_name', dem['crs'])}"
    if not dem["planned_in_source_crs"]:
        where += f" (the DEM is in {dem['source_crs']})"
    return f"dem            {heights}; band {dem['band']}; {where}"


def flight_quality(data: dict[str, Any], short: bool = False) -> str:
    """How far at most the flight is from the shortest possible, in words."""
    if data["proven_optimal"]:
        if short:
            return "proven optimal"
        return (
            f"proven optimal (within {data['proven_gap_pct']:g} % of the certified lower bound "
            f"{data['lower_bound_m']:.1f} m)"
        )
    if data["gap_pct"] is None:
        return "no lower bound" if short else "no lower bound available"
    if short:
        return f"within {_percent(data['gap_pct'])} % of the shortest possible"
    holding = (data.get("bound") or {}).get("holding_m") or 0.0
    over = f" with stops that hold {holding:g} m" if holding > 0.0 else ""
    # In a band the length and its bound are horizontal (the bound of the time is apart).
    what = "horizontal path in the band" if data.get("band") else "flight"
    return (
        f"within {_percent(data['gap_pct'])} % of the shortest possible {what}{over} "
        f"(certified lower bound {data['lower_bound_m']:.1f} m)"
    )


def _percent(pct: float) -> str:
    """A percentage to two significant figures or so, rounded up: never shown smaller."""
    digits = 1 if pct >= 1.0 else 2 if pct >= 0.1 else 3
    scale = 10.0**digits
    return f"{math.ceil(pct * scale - 1e-9) / scale:.{digits}f}"


def _stop_lines(stops: list[dict[str, Any]]) -> list[str]:
    lines = ["stops          #  sortie  from prev   ETA      sees"]
    for stop in stops:
        lines.append(
            f"               {stop['order']:<3d}{stop['sortie']:^7d}"
            f"{stop['from_previous_m']:8.1f} m"
            f"  {_minutes(stop['eta_s']):>9s}  {', '.join(stop['sees'])}"
        )
    return lines


def summary_text(data: dict[str, Any]) -> str:
    """One screen of text from :func:`summary`'s dictionary."""
    quality = flight_quality(data)
    home = data["home"]
    lines = [
        f"targets        {data['targets']}  ({', '.join(data['target_names'][:6])}"
        + (", ..." if data["targets"] > 6 else "")
        + ")",
        f"viewpoints     {data['viewpoints']} candidates, {data['tour_stops']} in the tour",
        f"{'flown' if len(data['sorties']) > 1 else 'tour':<15s}"
        f"{data['tour_length_m']:.1f} m{' horizontally' if 'band' in data else ''}, {quality}",
        f"solver         {data['solver']} in {data['solve_s']:.2f} s"
        + (
            f", optimal over the {data['viewpoints']} candidate viewpoints"
            if data["optimal_over_candidates"]
            else ""
        ),
        _refine_line(data),
        f"flight time    {_minutes(data['flight_time_s'])} (estimated at "
        f"{data['cruise_speed_m_s']:g} m/s, {data['hold_s']:g} s hold per photo)",
    ]
    band = data.get("band")
    if band is None:
        lines.append(
            f"altitude       {data['altitude_amsl_m']:.1f} m AMSL, "
            f"{data['altitude_above_home_m']:.1f} m"
            f" above home; highest terrain {data['terrain_max_m']:.1f} m"
        )
    else:
        lines += band_lines(data)
    lines += [
        _camera_line(data),
        f"home           {home['lat_deg']:.7f}, {home['lon_deg']:.7f} ({home['source']})",
        _dem_line(data["dem"]),
    ]
    if band is None:
        lines.append(
            f"clearance      at least {data['min_leg_clearance_m']} m over terrain on every leg"
        )
    lines.append(f"firmware       {data['firmware']}")
    if len(data["sorties"]) > 1:
        lines.append(
            f"sorties        {len(data['sorties'])} (battery --endurance "
            f"{data['endurance_min']:g} min): "
            + ", ".join(
                f"#{s['sortie']} {s['stops']} stops {s['length_m']:.0f} m "
                f"{_minutes(s['flight_time_s'])}"
                for s in data["sorties"]
            )
        )
        bound = data.get("bound") or {}
        if bound.get("sorties_at_least") is not None:
            gap = bound["flight_time_gap_pct"]
            lines.append(
                f"sortie bound   at least {bound['sorties_at_least']} "
                f"sortie{'s' if bound['sorties_at_least'] != 1 else ''} and "
                f"{_minutes(bound['flight_time_bound_s'])} of flight"
                + ("" if gap is None else f" (time within {_percent(max(gap, 0.0))} % of it)")
            )
        found = data["sortie_order"]
        if found is not None:
            lines.append(
                f"sortie order   {_minutes(found['flight_time_s'])} and "
                f"{found['length_m']:.0f} m in all, against "
                f"{_minutes(found['plain_cut_flight_time_s'])} and "
                f"{found['plain_cut_length_m']:.0f} m in {found['plain_cut_sorties']} for the "
                "solver's "
                f"{data['solver_tour_length_m']:.0f} m tour cut as it is "
                f"({found['moves']} moves in {found['search_s']:.1f} s)"
            )
    curve = data.get("altitude_curve")
    if curve is not None:
        lines.append(
            f"altitude auto  {len(curve)} planes in {data['altitude_sweep_wall_s']:.1f} s; "
            f"kept {data['altitude_best_amsl_m']:.1f} m (shortest flight time)"
        )
        for point in curve:
            mark = " <" if point["altitude_amsl_m"] == data["altitude_best_amsl_m"] else ""
            if point["flight_time_s"] is None:
                lines.append(f"               {point['altitude_amsl_m']:7.1f} m  {point['error']}")
                continue
            lines.append(
                f"               {point['altitude_amsl_m']:7.1f} m  tour "
                f"{point['tour_length_m']:7.1f} m  flight {_minutes(point['flight_time_s'])}"
                f"  ({point['wall_s']:.1f} s){mark}"
            )
    shown = data["stops"][:25]
    lines += _stop_lines(shown) if band is None else band_stop_lines(shown, len(shown))
    if len(data["stops"]) > len(shown):
        lines.append(f"               ... {len(data['stops']) - len(shown)} more in summary.json")
    lines += [f"warning        {w}" for w in data["warnings"]]
    if data["files"]:
        lines.append("files          " + "\n               ".join(data["files"]))
    return "\n".join(lines)


__all__ = [
    "SORTIE_COLOURS",
    "FlownStop",
    "flight_quality",
    "flown_stops",
    "photo_gsd_cm",
    "sortie_colour",
    "summary",
    "summary_text",
]
