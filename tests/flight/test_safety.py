"""Preflight safety: legs against the terrain, height above ground, sorties, geofence, and
the KML/GeoJSON exports read back by third-party readers."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pyproj
import pytest
import shapely
from click.testing import CliRunner
from conftest import DEMO, WriteDem, grid_xy
from fastkml import kml as fastkml
from shapely.geometry import Point, shape
from support.independent import check_mission, leg_clearances, load_raster, read_waypoints_file

from urpt_gcs.cli import main
from urpt_gcs.errors import PlanError
from urpt_gcs.files.products import write_products
from urpt_gcs.flight.sorties import order_sorties
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.problem.flight_time import FlightModel, split_sorties
from urpt_gcs.site.targets import read_targets
from urpt_gcs.solvers import SolveSettings, Tour

ORIGIN = (500_000.0, 5_200_000.0)
TO_GEO = pyproj.Transformer.from_crs("EPSG:32632", "EPSG:4326", always_xy=True)
FAST = SolveSettings(time_limit_s=1.0)


def _csv(path: Path, points: list[tuple[str, float, float]]) -> Path:
    rows = []
    for name, x, y in points:
        lon, lat = TO_GEO.transform(ORIGIN[0] + x, ORIGIN[1] - y)
        rows.append(f"{name},{lat:.9f},{lon:.9f}")
    path.write_text("name,lat,lon\n" + "\n".join(rows) + "\n")
    return path


def test_leg_through_a_ridge_is_refused(tmp_path: Path, write_dem: WriteDem) -> None:
    """Flat ground at 100 m, a 4 m wide ridge rising to 200 m across the middle, flight plane
    at 150 m: targets on both sides force a leg across the ridge."""
    x, _ = grid_xy((400, 400), 0.5, ORIGIN)
    z = np.full((400, 400), 100.0)
    z[np.abs(x - ORIGIN[0] - 100.0) < 2.0] = 200.0
    dem = write_dem(z, origin=ORIGIN)
    targets = _csv(
        tmp_path / "t.csv", [("West", 60.0, 100.0), ("East", 140.0, 100.0), ("Home", 60.0, 150.0)]
    )
    with pytest.raises(PlanError, match=r"leg \d .*cuts .* into the terrain"):
        plan(dem, targets, PlanSettings(altitude_m=150.0, solve=FAST))
    # The same ridge under a plane 30 m above it is flown.
    ok = plan(dem, targets, PlanSettings(altitude_m=230.0, solve=FAST))
    assert min(leg.min_clearance_m for leg in ok.legs) >= 30.0 - 0.5


def test_clearance_over_a_thin_wall_is_exact(tmp_path: Path, write_dem: WriteDem) -> None:
    """Flat ground at 100 m in 10 m cells, a wall one pixel wide rising to 140 m between the
    targets, plane at 160 m: the legs across it clear it by exactly 20 m, which dense
    independent samples of the written legs confirm."""
    z = np.full((40, 40), 100.0)
    z[:, 20] = 140.0
    dem = write_dem(z, res=10.0, origin=ORIGIN)
    targets = _csv(
        tmp_path / "t.csv", [("West", 145.0, 195.0), ("East", 265.0, 195.0), ("Home", 145.0, 95.0)]
    )
    result = plan(dem, targets, PlanSettings(altitude_m=160.0, solve=FAST))
    reported = np.array([leg.min_clearance_m for leg in result.legs])
    out = tmp_path / "out"
    write_products(result, out, with_map=False)
    flown = read_waypoints_file(out / "mission.waypoints")
    dense = np.array(leg_clearances(load_raster(dem), [flown], cells_per_sample=1 / 4096)[0])
    assert np.all(reported <= dense + 1e-6)
    assert np.all(reported >= dense - 0.01)
    # Legs across the wall (|x - 205 m| changes sign) meet its top.
    assert np.isclose(reported.min(), 160.0 - 140.0 + (result.altitude_rel_m - 60.0), atol=0.02)


def test_short_endurance_splits_into_sorties_that_together_see_everything(
    tmp_path: Path,
) -> None:
    # At the default 5 m/s the demo's farthest stop alone needs 3.4 min; 4 min makes 3
    # sorties of the tour found today.
    settings = PlanSettings(solve=FAST, endurance_min=4.0)
    result = plan(DEMO / "site.tif", DEMO / "targets.kml", settings)
    assert len(result.sorties) >= 2
    for sortie in result.sorties:
        assert sortie.flight_time_s <= 4.0 * 60.0
    out = tmp_path / "out"
    data = write_products(result, out, with_map=False)
    files = sorted(out.glob("mission_*.waypoints"))
    assert [f.name for f in files] == [
        f"mission_{k}.waypoints" for k in range(1, len(result.sorties) + 1)
    ]
    assert len(list(out.glob("mission_*.plan"))) == len(files)
    assert not (out / "mission.plan").exists()
    targets = [(t.name, t.lat_deg, t.lon_deg) for t in read_targets(DEMO / "targets.kml").targets]
    assert (
        check_mission(DEMO / "site.tif", files, targets, fov_deg=30.0, min_clearance_m=10.0) == []
    )
    assert any("sorties" in w for w in data["warnings"])
    # Each sortie returns home: its last item is RTL.
    for f in out.glob("mission_*.plan"):
        items = json.loads(f.read_text())["mission"]["items"]
        assert items[-1]["command"] == 20


def test_max_agl_warns_and_strict_refuses(tmp_path: Path) -> None:
    base = [
        "plan",
        "--dem",
        str(DEMO / "site.tif"),
        "--targets",
        str(DEMO / "targets.kml"),
        "--time-limit",
        "0.5",
        "--no-map",
        "--max-agl",
        "50",
    ]
    warn = CliRunner().invoke(main, [*base, "--out", str(tmp_path / "a"), "--json"])
    assert warn.exit_code == 0, warn.output
    assert any("--max-agl 50" in w for w in json.loads(warn.stdout)["warnings"])
    strict = CliRunner().invoke(main, [*base, "--out", str(tmp_path / "b"), "--strict"])
    assert strict.exit_code == 1
    (error,) = strict.stderr.strip().splitlines()
    assert "--max-agl 50" in error
    assert not (tmp_path / "b").exists()


@pytest.fixture(scope="module")
def demo_outputs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("demo")
    result = plan(DEMO / "site.tif", DEMO / "targets.kml", PlanSettings(solve=FAST))
    data = write_products(result, out, with_map=False)
    return out, data


def test_geofence_encloses_the_flight(demo_outputs: tuple[Path, dict]) -> None:
    out, _ = demo_outputs
    doc = json.loads((out / "mission.plan").read_text())
    (polygon,) = doc["geoFence"]["polygons"]
    assert polygon["inclusion"] is True
    fence = shapely.Polygon([(lon, lat) for lat, lon in polygon["polygon"]])
    home_lat, home_lon, _ = doc["mission"]["plannedHomePosition"]
    assert fence.contains(Point(home_lon, home_lat))
    for item in doc["mission"]["items"]:
        if item["command"] == 16:
            assert fence.contains(Point(item["params"][5], item["params"][4]))


def _kml_folders(path: Path) -> tuple[Any, dict[str, list[Any]]]:
    doc = fastkml.KML.from_string(path.read_bytes())
    (document,) = doc.features
    return document, {f.name: list(f.features) for f in document.features}


def test_kml_read_back_by_fastkml(demo_outputs: tuple[Path, dict]) -> None:
    out, data = demo_outputs
    _, folders = _kml_folders(out / "plan.kml")
    assert len(folders["Targets"]) == data["targets"]
    assert len(folders["Visibility regions"]) == data["targets"]
    route, *stops = folders["Sortie 1"]
    assert len(stops) == data["tour_stops"]
    coords = list(route.geometry.coords)
    assert len(coords) == data["tour_stops"] + 2
    assert {round(c[2], 2) for c in coords} == {data["altitude_amsl_m"]}
    first = stops[0].geometry
    assert first.x == pytest.approx(data["stops"][0]["lon_deg"], abs=1e-7)
    assert first.y == pytest.approx(data["stops"][0]["lat_deg"], abs=1e-7)
    names = {p.name for p in folders["Targets"]}
    assert names == set(data["target_names"])


def test_kml_styles_tell_targets_stops_and_regions_apart(demo_outputs: tuple[Path, dict]) -> None:
    out, _ = demo_outputs
    document, folders = _kml_folders(out / "plan.kml")
    styles = {style.id: style for style in document.styles}
    assert {"target", "home", "region", "sortie-1"} <= styles.keys()
    used = {folder: {mark.style_url.url for mark in marks} for folder, marks in folders.items()}
    assert used["Targets"] == {"#target"}
    assert used["Visibility regions"] == {"#region"}
    assert used["Sortie 1"] == {"#sortie-1"}
    colours = {
        style_id: next(
            part.color for part in styles[style_id].styles if type(part).__name__ != "LabelStyle"
        )
        for style_id in ("target", "region", "sortie-1")
    }
    assert len(set(colours.values())) == 3, colours


def test_geojson_read_back_by_shapely(demo_outputs: tuple[Path, dict]) -> None:
    out, data = demo_outputs
    collection = json.loads((out / "plan.geojson").read_text())
    kinds: dict[str, list] = {}
    for feature in collection["features"]:
        kinds.setdefault(feature["properties"]["kind"], []).append(shape(feature["geometry"]))
    assert len(kinds["target"]) == data["targets"]
    assert len(kinds["stop"]) == data["tour_stops"]
    assert all(g.is_valid and g.area > 0 for g in kinds["region"])
    (tour,) = kinds["sortie"]
    # Each target lies inside its own region polygon.
    for region, target in zip(kinds["region"], kinds["target"], strict=True):
        assert region.buffer(1e-9).contains(Point(target.x, target.y))
    geod = pyproj.Geod(ellps="WGS84")
    assert geod.geometry_length(tour) == pytest.approx(data["tour_length_m"], rel=2e-3)


# --- a plan in sorties, as written and as drawn ----------------------------------------------

# At the default 5 m/s the demo's tour needs 3 sorties at 4 min (the farthest stop alone
# takes 3.4 min).
SORTIE_ENDURANCE_MIN = 4.0


@pytest.fixture(scope="module")
def sortie_plan(tmp_path_factory: pytest.TempPathFactory) -> tuple[Plan, Path, dict]:
    out = tmp_path_factory.mktemp("sorties")
    settings = PlanSettings(solve=FAST, endurance_min=SORTIE_ENDURANCE_MIN)
    result = plan(DEMO / "site.tif", DEMO / "targets.kml", settings)
    data = write_products(result, out, with_map=True)
    return result, out, data


def _flown_routes(out: Path) -> list[list[tuple[float, float]]]:
    """Each sortie from its mission_N.waypoints, read with pymavlink: home, waypoints, home
    as (longitude, latitude)."""
    files = sorted(out.glob("mission_*.waypoints"), key=lambda f: int(f.stem.split("_")[1]))
    routes = []
    for f in files:
        flown = read_waypoints_file(f)
        home = (flown.home[1], flown.home[0])
        routes.append([home, *((w[1], w[0]) for w in flown.waypoints), home])
    return routes


def _same_route(drawn: list[tuple[float, ...]], flown: list[tuple[float, float]]) -> None:
    assert len(drawn) == len(flown)
    np.testing.assert_allclose(np.array(drawn)[:, :2], np.array(flown), rtol=0, atol=1e-9)


def test_the_tour_is_split_into_sorties(sortie_plan: tuple[Plan, Path, dict]) -> None:
    result, out, data = sortie_plan
    print(f"\n{len(result.sorties)} sorties at --endurance {SORTIE_ENDURANCE_MIN:g} min")
    assert len(result.sorties) >= 2
    assert len(_flown_routes(out)) == len(result.sorties) == len(data["sorties"])


def test_summary_reports_the_sorties_as_flown(sortie_plan: tuple[Plan, Path, dict]) -> None:
    """The reported length is every written sortie's legs, home -> stops -> home, measured
    independently (pymavlink's loader, geodesics); the bound stays below it and the gap is
    against it."""
    _, out, data = sortie_plan
    geod = pyproj.Geod(ellps="WGS84")
    routes = _flown_routes(out)
    assert len(routes) >= 3
    legs = [geod.line_length(*zip(*route, strict=True)) for route in routes]
    for leg, reported in zip(legs, data["sorties"], strict=True):
        assert reported["length_m"] == pytest.approx(leg, rel=2e-3)
    print(f"\nflown {sum(legs):.1f} m in {len(legs)} sorties, {data['flight_time_s']:.0f} s")
    assert data["tour_length_m"] == pytest.approx(sum(legs), rel=2e-3)
    assert data["flight_time_s"] == pytest.approx(
        sum(s["flight_time_s"] for s in data["sorties"]), abs=0.5
    )
    assert data["lower_bound_m"] <= data["tour_length_m"]
    bound = data["lower_bound_m"]
    assert data["gap_pct"] == pytest.approx(100 * (data["tour_length_m"] - bound) / bound, abs=0.01)
    assert data["proven_optimal"] is False
    found = data["sortie_order"]
    assert found["flight_time_s"] <= found["plain_cut_flight_time_s"]
    assert found["flight_time_s"] == pytest.approx(data["flight_time_s"], abs=0.5)
    assert found["search_s"] <= found["budget_s"] + 0.5


def test_kml_draws_exactly_the_flown_sorties(sortie_plan: tuple[Plan, Path, dict]) -> None:
    result, out, data = sortie_plan
    document, folders = _kml_folders(out / "plan.kml")
    stops_seen = []
    for number, flown in enumerate(_flown_routes(out), start=1):
        route, *stops = folders[f"Sortie {number}"]
        _same_route(list(route.geometry.coords), flown)
        # The stops, numbered in flight order, sit on the route's waypoints.
        _same_route([(s.geometry.x, s.geometry.y) for s in stops], flown[1:-1])
        stops_seen += [int(s.name) for s in stops]
        assert {s.style_url.url for s in [route, *stops]} == {f"#sortie-{number}"}
    assert stops_seen == list(range(1, data["tour_stops"] + 1))
    colours = {
        next(p.color for p in style.styles if type(p).__name__ == "LineStyle")
        for style in document.styles
        if style.id.startswith("sortie-")
    }
    assert len(colours) == len(result.sorties)


def test_geojson_draws_exactly_the_flown_sorties(sortie_plan: tuple[Plan, Path, dict]) -> None:
    _, out, data = sortie_plan
    features = json.loads((out / "plan.geojson").read_text())["features"]
    routes = [f for f in features if f["properties"]["kind"] == "sortie"]
    stops = [f for f in features if f["properties"]["kind"] == "stop"]
    flown = _flown_routes(out)
    assert [r["properties"]["sortie"] for r in routes] == list(range(1, len(flown) + 1))
    for route, legs in zip(routes, flown, strict=True):
        line = shape(route["geometry"])
        assert isinstance(line, shapely.LineString) and line.is_closed
        _same_route(list(line.coords), legs)
        number = route["properties"]["sortie"]
        mine = [s for s in stops if s["properties"]["sortie"] == number]
        assert route["properties"]["stops"] == len(mine)
        _same_route([shape(s["geometry"]).coords[0] for s in mine], legs[1:-1])
        etas = [s["properties"]["eta_s"] for s in mine]
        assert etas == sorted(etas) and etas[0] > 0.0
        assert etas[-1] < route["properties"]["flight_time_s"]
    assert [s["properties"]["order"] for s in stops] == list(range(1, len(stops) + 1))
    # What each stop sees, together every target; as summary.json says.
    seen = {name for s in stops for name in s["properties"]["sees"]}
    assert seen == set(data["target_names"])
    assert [s["properties"]["sees"] for s in stops] == [s["sees"] for s in data["stops"]]
    assert [s["properties"]["eta_s"] for s in stops] == [s["eta_s"] for s in data["stops"]]


def test_map_draws_exactly_the_flown_sorties(sortie_plan: tuple[Plan, Path, dict]) -> None:
    from urpt_gcs.files.mapview import map_figure

    result, out, data = sortie_plan
    assert (out / "map.png").read_bytes().startswith(b"\x89PNG")
    ax = map_figure(result, data).axes[0]  # the other is the colour bar
    drawn = {line.get_gid(): line for line in ax.get_lines() if line.get_gid()}
    to_geo = pyproj.Transformer.from_crs(result.crs, "EPSG:4326", always_xy=True)
    flown = _flown_routes(out)
    assert sorted(drawn) == [f"sortie {n}" for n in range(1, len(flown) + 1)]
    colours = set()
    for number, legs in enumerate(flown, start=1):
        line = drawn[f"sortie {number}"]
        lon, lat = to_geo.transform(*line.get_data())
        _same_route(list(zip(lon, lat, strict=True)), legs)
        colours.add(line.get_color())
    assert len(colours) == len(flown)
    labels = sorted(int(t.get_text()) for t in ax.texts if t.get_text().isdigit())
    assert labels == list(range(1, data["tour_stops"] + 1))


# --- the stop order searched for the sorties ---------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_sortie_order_never_flies_longer_than_the_plain_cut(seed: int) -> None:
    """From a nearest-neighbour tour of random stops, the search's order cuts into sorties
    of no more total flight time than the tour cut as it is, and its figure is the DP's."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(-400.0, 400.0, size=(60, 2))
    todo, order = list(range(1, len(xy))), [0]
    while todo:
        last = xy[order[-1]]
        nxt = min(todo, key=lambda i: float(np.hypot(*(xy[i] - last))))
        todo.remove(nxt)
        order.append(nxt)
    stops = xy[order]
    tour = Tour(
        order=tuple(order),
        length=0.0,
        lower_bound=0.0,
        proven_optimal=False,
        solver="test",
        solve_s=0.0,
        points_xy=stops,
        sees=np.eye(len(stops), dtype=np.bool_),
    )
    model = FlightModel.arducopter(cruise_m_s=5.0, hold_s=2.0)
    names = [f"stop {k}" for k in range(len(stops))]
    endurance = 6.0 * 60.0
    plain = split_sorties(stops, (0.0, 0.0), 60.0, model, endurance, names)
    assert len(plain) >= 3
    searched, found = order_sorties(
        tour, (0.0, 0.0), 60.0, model, endurance, names, budget_s=1.0, seed=seed
    )
    assert found is not None
    assert searched.points_xy is not None
    cut = split_sorties(searched.points_xy, (0.0, 0.0), 60.0, model, endurance, names)
    total = sum(s.flight_time_s for s in cut)
    print(f"\nseed {seed}: {sum(s.flight_time_s for s in plain):.0f} s -> {total:.0f} s")
    assert total <= sum(s.flight_time_s for s in plain) + 1e-6
    assert found.flight_time_s == pytest.approx(total)
    assert found.search_s <= 1.5
    # The same stops, each still with what it sees.
    assert sorted(map(tuple, searched.points_xy.tolist())) == sorted(map(tuple, stops.tolist()))
    for k, point in enumerate(searched.points_xy):
        (i,) = np.flatnonzero((stops == point).all(axis=1))
        assert (searched.sees[k] == tour.sees[i]).all()
        assert searched.order[k] == tour.order[i]


def test_searched_sorties_that_fail_a_check_fall_back_to_the_tours_order(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The sortie search joins stops the solver never joined; when the flight it found fails
    a check (here: made to fail), the plan flies the tour's own order, checked, and says so."""
    import urpt_gcs.pipeline.missions as missions

    real = missions._write_missions
    calls: list[Tour] = []

    def failing_first(site: Any, area: Any, tour: Tour, settings: Any) -> Any:
        calls.append(tour)
        if len(calls) == 1:
            raise PlanError("leg 3 (stop 2 -> stop 9) cuts 1.0 m into the terrain")
        return real(site, area, tour, settings)

    monkeypatch.setattr(missions, "_write_missions", failing_first)
    settings = PlanSettings(solve=FAST, endurance_min=SORTIE_ENDURANCE_MIN, certify=False)
    result = plan(DEMO / "site.tif", DEMO / "targets.kml", settings)
    assert len(calls) == 2
    assert calls[0].points_xy is not None and calls[1].points_xy is not None
    changed = not np.array_equal(calls[0].points_xy, calls[1].points_xy)
    assert changed, "the search changed nothing: no fallback tested"
    assert result.sortie_order is None
    assert any("the tour's own order is flown" in w for w in result.warnings)
    assert result.tour.points_xy is not None
    np.testing.assert_array_equal(result.tour.points_xy, calls[1].points_xy)
    assert len(result.sorties) >= 2
