"""Fleet planning: the makespan bound and the planner against brute force, the separation
along tracks against dense sampling, and fleet plans of the demo and a real raster checked
independently on every vehicle's written mission."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import DEMO, REAL_DEMS, needs_shared
from support.independent import check_mission, load_raster, read_waypoints_file
from support.sortie_brute import VARIED_MODELS
from support.targets import valid_targets

import urpt_gcs.pipeline.fleet as fleet_module
from urpt_gcs.bound.sorties import sortie_bound
from urpt_gcs.cli import main
from urpt_gcs.errors import SettingsError
from urpt_gcs.pipeline.separation import Track, closest, pair_closest, timing_slack_s
from urpt_gcs.pipeline.settings import FleetSettings, PlanSettings, VehicleSpec
from urpt_gcs.problem.flight_time import FlightModel
from urpt_gcs.problem.instance import Geometry, Instance
from urpt_gcs.site.targets import read_targets
from urpt_gcs.solvers import solve
from urpt_gcs.solvers.base import SolveSettings
from urpt_gcs.solvers.fleet import Vehicle, restrict, solve_fleet
from urpt_gcs.solvers.fleet_bound import fleet_budget, makespan_bound

ALTITUDE_M = 40.0
FOV_DEG = 30.0


def _tiny_fleet(
    seed: int, vehicles: int, endurance_s: float | None = None, one_home: bool = False
) -> tuple[list[Vehicle], Instance]:
    """Four targets, two viewpoints each inside the cone (a viewpoint sees every target
    whose cone holds it), and homes of their own (or the first vehicle's for all)."""
    rng = np.random.default_rng(seed)
    targets = rng.uniform(0.0, 400.0, (4, 2))
    cone = ALTITUDE_M * math.tan(math.radians(FOV_DEG))
    angle = rng.uniform(0.0, 2.0 * math.pi, 8)
    radius = cone * np.sqrt(rng.uniform(0.0, 0.95, 8))
    points = np.repeat(targets, 2, axis=0) + radius[:, None] * np.column_stack(
        [np.cos(angle), np.sin(angle)]
    )
    near = np.hypot(*(points[:, None, :] - targets[None, :, :]).transpose(2, 0, 1)) <= cone
    vp, tg = np.nonzero(near)
    geometry = Geometry(targets, np.zeros(4), ALTITUDE_M, FOV_DEG, 0.0)
    homes = rng.uniform(0.0, 400.0, (vehicles, 2))
    if one_home:
        homes[:] = homes[0]
    out = []
    for k in range(vehicles):
        inst = Instance.from_cover_pairs(
            vp, tg, points, 4, depot_xy=(float(homes[k, 0]), float(homes[k, 1])), geometry=geometry
        )
        model = FlightModel.arducopter(cruise_m_s=4.0 + k, hold_s=2.0)
        out.append(Vehicle(inst, model, ALTITUDE_M, endurance_s))
    return out, out[0].instance


def _brute_makespan(vehicles: list[Vehicle], offsets_s: tuple[float, ...] | None = None) -> float:
    """All assignments of the targets to the vehicles, each vehicle's least flight time over
    every sequence of distinct viewpoints that sees its share (a share of s targets never
    needs more than s stops, and a stop left out never lengthens a flight), after its start
    delay in ``offsets_s``."""
    offsets = offsets_s or (0.0,) * len(vehicles)
    m = vehicles[0].instance.n_targets
    best = []
    for vehicle in vehicles:
        inst = vehicle.instance
        assert inst.points_xy is not None
        covers = inst.covers.dense()
        least = np.full(1 << m, math.inf)
        least[0] = 0.0
        for size in range(1, m + 1):
            for seq in itertools.permutations(range(inst.n_viewpoints), size):
                seen = covers[list(seq)].any(axis=0)
                mask = int(sum(1 << t for t in np.flatnonzero(seen)))
                least[mask] = min(least[mask], vehicle.time_s(inst.points_xy[list(seq)]))
        # Seeing more than a share is as good as seeing the share.
        for mask in range(1 << m):
            for sup in range(1 << m):
                if sup & mask == mask:
                    least[mask] = min(least[mask], least[sup])
        best.append(least)
    value = math.inf
    for assignment in itertools.product(range(len(vehicles)), repeat=m):
        masks = [0] * len(vehicles)
        for t, k in enumerate(assignment):
            masks[k] |= 1 << t
        value = min(
            value,
            max(offsets[k] + best[k][masks[k]] if masks[k] else 0.0 for k in range(len(vehicles))),
        )
    return value


@pytest.mark.parametrize(
    ("seed", "count", "endurance_s"),
    [(0, 2, None), (3, 3, None), (2, 2, 200.0), (7, 2, 180.0), (8, 3, 230.0)],
)
def test_bound_and_planned_makespan_bracket_the_brute_force_optimum(
    seed: int, count: int, endurance_s: float | None
) -> None:
    """With an endurance, flights are cut into sorties (the brute force cuts each of its
    sequences at its best, as the planner does)."""
    vehicles, reference = _tiny_fleet(seed, count, endurance_s)
    optimum = _brute_makespan(vehicles)
    single = solve(reference, "exact", SolveSettings(time_limit_s=0.5))
    tours = solve_fleet(vehicles, single.order, reference, "exact", SolveSettings(time_limit_s=1.0))
    bound = makespan_bound(vehicles, single.lower_bound)
    assert 0.0 < bound.bound_s <= optimum + 1e-6
    assert tours.makespan_s >= optimum - 1e-6
    # The tours are real: every target seen by some vehicle, each time measured again here.
    seen = np.zeros(4, dtype=bool)
    for vehicle, order, time_s in zip(vehicles, tours.orders, tours.times_s, strict=True):
        seen |= vehicle.instance.covers.seen(list(order))
        assert vehicle.instance.points_xy is not None
        assert vehicle.time_s(vehicle.instance.points_xy[list(order)]) == pytest.approx(time_s)
    assert seen.all()
    # The search never ends worse than where it started.
    assert tours.makespan_s <= max(tours.start_times_s) + 1e-9


@pytest.mark.parametrize(
    ("seed", "offsets_s"), [(0, (60.0, 0.0)), (3, (0.0, 90.0, 30.0)), (7, (0.0, 150.0))]
)
def test_start_delays_are_counted_by_the_search_and_the_naive_split(
    seed: int, offsets_s: tuple[float, ...]
) -> None:
    """A vehicle that starts late ends later: the search shares the targets with that
    counted, never ending after the naive split started with the same delays, nor before
    the brute-force optimum with them."""
    vehicles, reference = _tiny_fleet(seed, len(offsets_s))
    optimum = _brute_makespan(vehicles, offsets_s)
    single = solve(reference, "exact", SolveSettings(time_limit_s=0.5))
    tours = solve_fleet(
        vehicles, single.order, reference, "exact", SolveSettings(time_limit_s=1.0), offsets_s
    )
    assert tours.offsets_s == offsets_s
    finish = max(
        (
            o + t
            for o, t, order in zip(offsets_s, tours.times_s, tours.orders, strict=True)
            if order
        ),
        default=0.0,
    )
    assert tours.makespan_s >= finish - 1e-9
    assert tours.makespan_s >= optimum - 1e-6
    assert tours.makespan_s <= tours.naive_makespan_s + 1e-9
    # Held back long enough, the late vehicle flies less than the others.
    late = int(np.argmax(offsets_s))
    others = [t for k, t in enumerate(tours.times_s) if k != late]
    if offsets_s[late] >= 90.0:
        assert tours.times_s[late] <= max(others) + 1e-9


@pytest.mark.parametrize(
    ("seed", "count", "endurance_s"),
    [(0, 2, None), (3, 3, None), (2, 2, 200.0), (7, 2, 180.0), (8, 3, 230.0), (5, 2, 150.0)],
)
def test_sortie_share_of_the_bound_stays_under_the_brute_force_optimum(
    seed: int, count: int, endurance_s: float | None
) -> None:
    """Vehicles of different speeds from one home: the sorties' bound over the targets'
    cone discs, within the fleet's weakest budget, shared among them, is under the
    optimum and adds to the other parts where they are weak."""
    vehicles, reference = _tiny_fleet(seed, count, endurance_s, one_home=True)
    optimum = _brute_makespan(vehicles)
    single = solve(reference, "exact", SolveSettings(time_limit_s=0.5))
    g = reference.geometry
    assert g is not None and reference.depot_xy is not None
    reach = g.cone_radius_m
    home = np.asarray(reference.depot_xy)
    distance = np.maximum(np.hypot(*(g.targets_xy - home).T) - reach, 0.0)
    sorties = sortie_bound(
        g.targets_xy, reach, distance, single.lower_bound, fleet_budget(vehicles)
    )
    bound = makespan_bound(vehicles, single.lower_bound, sorties)
    without = makespan_bound(vehicles, single.lower_bound)
    assert 0.0 < bound.sorties_s <= optimum + 1e-6
    assert bound.bound_s <= optimum + 1e-6
    assert bound.bound_s >= without.bound_s


@pytest.mark.parametrize("model", VARIED_MODELS)
def test_leg_times_grow_and_are_subadditive(model: FlightModel) -> None:
    """The reach bound needs it: a chain of legs is never quicker than one leg of their sum."""
    d = np.concatenate([np.linspace(0.0, 6.0, 301), np.linspace(6.0, 400.0, 400)])
    a, b = np.meshgrid(d, d)
    for leg in (model.leg_s, model.return_s):
        assert (np.diff(leg(d)) >= 0.0).all()
        assert (leg(a) + leg(b) >= leg(a + b) - 1e-9).all()
    fastest = np.minimum(model.leg_s(d), model.return_s(d))
    faster = model.return_s if model.return_m_s >= model.cruise_m_s else model.leg_s
    assert np.allclose(fastest, faster(d))


def test_restrict_keeps_exactly_the_viewpoints_and_pairs_of_the_share() -> None:
    _, reference = _tiny_fleet(7, 1)
    dense = reference.covers.dense()
    share = [3, 1]
    sub, kept = restrict(reference, share)
    expect = np.flatnonzero(dense[:, share].any(axis=1))
    assert kept.tolist() == expect.tolist()
    assert (sub.covers.dense() == dense[np.ix_(kept, share)]).all()
    assert sub.points_xy is not None and reference.points_xy is not None
    assert (sub.points_xy == reference.points_xy[kept]).all()


def _random_track(rng: np.random.Generator, start_s: float) -> Track:
    n = 8
    t = start_s + np.cumsum(rng.uniform(1.0, 20.0, n))
    xyz = rng.uniform(-50.0, 50.0, (n, 3))
    air = rng.uniform(size=n - 1) < 0.8
    return Track(t, xyz, air)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("horizontal", [False, True])
def test_closest_approach_matches_dense_sampling(seed: int, horizontal: bool) -> None:
    rng = np.random.default_rng(seed)
    a, b = _random_track(rng, 0.0), _random_track(rng, rng.uniform(0.0, 30.0))
    found = closest(a, b, horizontal)
    lo, hi = max(a.t_s[0], b.t_s[0]), min(a.t_s[-1], b.t_s[-1])
    t = np.linspace(lo, hi, 200_001)

    def sample(tr: Track) -> tuple[np.ndarray, np.ndarray]:
        pos = np.column_stack([np.interp(t, tr.t_s, tr.xyz[:, i]) for i in range(3)])
        seg = np.clip(np.searchsorted(tr.t_s, t, side="right") - 1, 0, len(tr.airborne) - 1)
        return pos, tr.airborne[seg]

    pa, fa = sample(a)
    pb, fb = sample(b)
    d = pa - pb
    if horizontal:
        d[:, 2] = 0.0
    dist = np.linalg.norm(d, axis=1)[fa & fb]
    if dist.size == 0:
        assert found is None
        return
    assert found is not None
    assert found[0] <= dist.min() + 1e-9
    # Dense samples come within one step's travel of the true least distance.
    step = (hi - lo) / 200_000 * 2.0 * 50.0
    assert dist.min() - found[0] <= step + 1e-6


@pytest.mark.parametrize("seed", range(4))
def test_closest_approach_holds_with_either_vehicle_early_or_late(seed: int) -> None:
    # The planned approach is the least over the other vehicle running up to the slack early
    # or late; dense samples of the shifts and of the time find nothing closer.
    rng = np.random.default_rng(100 + seed)
    a, b = _random_track(rng, 0.0), _random_track(rng, rng.uniform(0.0, 30.0))
    found = pair_closest([a, b], 0, 1)
    slack = timing_slack_s(a, b)
    assert slack >= 10.0
    least = math.inf
    for shift in np.linspace(-slack, slack, 161):
        moved = Track(b.t_s + shift, b.xyz, b.airborne)
        lo, hi = max(a.t_s[0], moved.t_s[0]), min(a.t_s[-1], moved.t_s[-1])
        if hi <= lo:
            continue
        t = np.linspace(lo, hi, 20_001)
        pa = np.column_stack([np.interp(t, a.t_s, a.xyz[:, i]) for i in range(3)])
        pb = np.column_stack([np.interp(t, moved.t_s, moved.xyz[:, i]) for i in range(3)])
        sa = np.clip(np.searchsorted(a.t_s, t, side="right") - 1, 0, len(a.airborne) - 1)
        sb = np.clip(np.searchsorted(moved.t_s, t, side="right") - 1, 0, len(b.airborne) - 1)
        both = a.airborne[sa] & moved.airborne[sb]
        if both.any():
            least = min(least, float(np.linalg.norm(pa - pb, axis=1)[both].min()))
    if found is None:
        assert least == math.inf
        return
    # The dense shifts hold the planner's whole-second ones: nothing it tried was closer
    # than it says (within the time samples' step), and no shift can be farther than none.
    assert least <= found.distance_m + 0.5
    assert found.distance_m <= closest(a, b, horizontal=False)[0] + 1e-9  # type: ignore[index]


def _fleet_run(tmp_path: Path, dem: Path, targets: Path, *extra: str) -> dict:
    out = tmp_path / "out"
    result = CliRunner().invoke(
        main,
        [
            "plan",
            "--dem",
            str(dem),
            "--targets",
            str(targets),
            "--out",
            str(out),
            "--time-limit",
            "1.5",
            "--json",
            *extra,
        ],
    )
    assert result.exit_code == 0, result.output
    data: dict = json.loads((out / "summary.json").read_text())
    return data


def _check_fleet_folder(
    out: Path, dem: Path, targets: list[tuple[str, float, float]], data: dict, spacing: float
) -> None:
    fleet = data["fleet"]
    by_name = {name: (name, lat, lon) for name, lat, lon in targets}
    seen: set[str] = set()
    layers = []
    raster = load_raster(dem)
    for v in fleet["vehicles"]:
        folder = out / v["dir"]
        files = sorted(folder.glob("mission*.waypoints"))
        assert len(files) == v["sorties"]
        mine = [by_name[n] for n in v["targets"]]
        # Seen from the vehicle's own written waypoints at its own layer; legs clear.
        assert check_mission(dem, files, mine, fov_deg=30.0, min_clearance_m=10.0) == []
        seen |= set(v["targets"])
        flown = read_waypoints_file(files[0])
        amsl = {round(w[2], 2) for f in files for w in read_waypoints_file(f).waypoints}
        assert len(amsl) == 1
        layer = amsl.pop()
        layers.append(layer)
        home_ground = float(raster.height(np.array([flown.home[1]]), np.array([flown.home[0]]))[0])
        assert layer - home_ground <= 120.0 + 0.05
        own = json.loads((folder / "summary.json").read_text())
        assert own["flight_time_s"] == pytest.approx(v["flight_time_s"], abs=0.1)
    assert seen == set(by_name)
    if fleet["separation"]["mode"] == "altitude":
        ordered = sorted(layers)
        assert all(b - a >= spacing - 0.05 for a, b in itertools.pairwise(ordered))
    finish = [v["start_delay_s"] + v["flight_time_s"] for v in fleet["vehicles"]]
    assert fleet["makespan_s"] == pytest.approx(max(finish), abs=0.2)
    assert fleet["makespan_s"] >= fleet["makespan_bound_s"] > 0.0


def _demo_targets() -> list[tuple[str, float, float]]:
    return [(t.name, t.lat_deg, t.lon_deg) for t in read_targets(DEMO / "targets.kml").targets]


@pytest.mark.parametrize("count", [2, 3])
def test_demo_fleet_sees_every_target_from_distinct_layers(tmp_path: Path, count: int) -> None:
    extra = ["--vehicles", str(count)] + (["--no-map"] if count == 3 else [])
    data = _fleet_run(tmp_path, DEMO / "site.tif", DEMO / "targets.kml", *extra)
    assert len(data["fleet"]["vehicles"]) == count
    _check_fleet_folder(tmp_path / "out", DEMO / "site.tif", _demo_targets(), data, 10.0)
    closest_m = data["fleet"]["separation"]["closest_approach_m"]
    assert closest_m is not None and closest_m >= 10.0 - 0.05
    geo = json.loads((tmp_path / "out" / "plan.geojson").read_text())
    routes = [f["properties"] for f in geo["features"] if f["properties"]["kind"] == "sortie"]
    assert {r["vehicle"] for r in routes} == set(range(1, count + 1))
    colours = {r["vehicle"]: r["colour"] for r in routes}
    assert len(set(colours.values())) == count
    for name in ("map.png", "map.html"):
        assert ((tmp_path / "out" / name).exists()) == (count == 2)
    kml = ET.parse(tmp_path / "out" / "plan.kml").getroot()
    q = "{http://www.opengis.net/kml/2.2}"
    folders = {f.findtext(f"{q}name") for f in kml.iter(f"{q}Folder")}
    assert {f"Vehicle {k}" for k in range(1, count + 1)} <= folders


def test_time_separation_from_homes_of_their_own(tmp_path: Path) -> None:
    fleet = tmp_path / "fleet.toml"
    fleet.write_text(
        "[[vehicle]]\nhome_lat = 47.68876\nhome_lon = 9.42309\n\n"
        "[[vehicle]]\nhome_lat = 47.68990\nhome_lon = 9.42150\nspeed_m_s = 6.0\n"
    )
    data = _fleet_run(
        tmp_path,
        DEMO / "site.tif",
        DEMO / "targets.kml",
        "--fleet",
        str(fleet),
        "--separation",
        "time",
        "--min-separation",
        "15",
        "--no-map",
    )
    _check_fleet_folder(tmp_path / "out", DEMO / "site.tif", _demo_targets(), data, 0.0)
    f = data["fleet"]
    assert {v["altitude_m"] for v in f["vehicles"]} == {f["vehicles"][0]["altitude_m"]}
    assert f["vehicles"][1]["speed_m_s"] == 6.0
    assert f["vehicles"][1]["home_lat"] == pytest.approx(47.68990, abs=1e-7)
    assert f["separation"]["closest_horizontal_m"] >= 15.0


def test_one_vehicle_is_the_plain_plan(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """--vehicles 1 runs exactly the single-vehicle plan, with the same settings."""
    import urpt_gcs.pipeline.fleet
    import urpt_gcs.pipeline.planner

    calls = []

    def record(*args: object, **kwargs: object) -> None:
        calls.append(args)
        raise SystemExit(0)

    def no_fleet(*args: object, **kwargs: object) -> None:
        raise AssertionError("the fleet planner ran for one vehicle")

    monkeypatch.setattr(urpt_gcs.pipeline.planner, "plan", record)
    monkeypatch.setattr(urpt_gcs.pipeline.fleet, "plan_fleet", no_fleet)
    base = ["plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml")]
    for extra in ([], ["--vehicles", "1"]):
        CliRunner().invoke(main, [*base, "--out", str(tmp_path / "o"), *extra])
    assert len(calls) == 2
    assert calls[0] == calls[1]


@needs_shared(REAL_DEMS)
def test_real_raster_fleet(tmp_path: Path) -> None:
    dem = REAL_DEMS / "odm_dsm_utm51n.tif"
    targets = valid_targets(dem, 10, seed=3)
    csv = tmp_path / "targets.csv"
    csv.write_text(
        "name,lat,lon\n" + "".join(f"{n},{lat:.9f},{lon:.9f}\n" for n, lat, lon in targets)
    )
    data = _fleet_run(tmp_path, dem, csv, "--vehicles", "2", "--no-map")
    _check_fleet_folder(tmp_path / "out", dem, targets, data, 10.0)


def test_track_follows_the_plan_through_every_stop_in_the_planned_time() -> None:
    """Sorties back to back: the track's length in time is the plan's flight time (summed by
    the sortie splitter), it passes over every stop at the plane and starts and ends on the
    ground at home."""
    from urpt_gcs.pipeline.planner import plan
    from urpt_gcs.pipeline.separation import track
    from urpt_gcs.pipeline.settings import PlanSettings

    settings = PlanSettings(solve=SolveSettings(time_limit_s=0.5), endurance_min=4.0)
    result = plan(DEMO / "site.tif", DEMO / "targets.kml", settings)
    assert len(result.sorties) > 1
    tr = track(result)
    assert tr.t_s[-1] == pytest.approx(result.flight_time_s, abs=1e-6)
    ground = result.mission.home.amsl_m
    eye = ground + result.altitude_rel_m
    assert tr.xyz[0].tolist() == pytest.approx([*result.home_xy, ground])
    assert tr.xyz[-1].tolist() == pytest.approx([*result.home_xy, ground])
    assert result.tour.points_xy is not None
    for x, y in result.tour.points_xy.tolist():
        at = np.flatnonzero(np.hypot(tr.xyz[:, 0] - x, tr.xyz[:, 1] - y) < 1e-9)
        assert at.size >= 2 and np.allclose(tr.xyz[at, 2], eye)
    assert not tr.airborne[0] and not tr.airborne[-1]


def test_a_second_sharing_that_is_refused_leaves_the_first(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """When separation delays a vehicle, the targets are shared out again with the delays
    counted; if that second sharing is refused (a vehicle idle, no delays that keep them
    apart), the first stands and the plan is not refused."""
    real = fleet_module._shared
    calls: list[object] = []

    def shared(*args: Any, **kwargs: Any) -> Any:
        calls.append((args[5], kwargs.get("naive", False)))
        if len(calls) > 1:
            raise SettingsError("vehicle 2 has nothing left to photograph")
        tours, plans, separation = real(*args, **kwargs)
        # As if separation had held vehicle 2 back.
        delays = (0.0, *(30.0 for _ in plans[1:]))
        return tours, plans, dataclasses.replace(separation, start_delays_s=delays)

    monkeypatch.setattr(fleet_module, "_shared", shared)
    settings = PlanSettings(solve=SolveSettings(time_limit_s=2.0))
    fleet = FleetSettings((VehicleSpec(), VehicleSpec()))
    result = fleet_module.plan_fleet(DEMO / "site.tif", DEMO / "targets.kml", settings, fleet)
    # The first sharing, the second (refused), then the naive split to compare (refused too).
    assert calls == [(None, False), ((0.0, 30.0), False), ((0.0, 30.0), True)]
    assert result.naive_flown_s == math.inf
    assert result.separation.start_delays_s == (0.0, 30.0)
    first, second = (p.flight_time_s for p in result.plans)
    assert result.makespan_s == pytest.approx(max(first, 30.0 + second))
    assert result.makespan_s >= result.bound.bound_s


def test_a_searched_sharing_that_flies_later_gives_way_to_the_naive_split(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """The search compares estimates; margins and refinement change the flights after it.
    Whatever it hands on, the plan never lands after the naive split finished and flown the
    same way: here the search is made to give one vehicle every stop, and the naive split's
    two flights are kept."""
    from urpt_gcs.solvers.fleet import FleetTours

    real = fleet_module.solve_fleet
    handed: list[FleetTours] = []

    def one_does_all(vehicles: Any, single_order: Any, reference: Any, *rest: Any) -> FleetTours:
        tours = real(vehicles, single_order, reference, *rest)
        same = vehicles[0].instance.points_xy
        assert all(np.array_equal(v.instance.points_xy, same) for v in vehicles)
        everything = tuple(dict.fromkeys(v for order in tours.orders for v in order))
        times = (vehicles[0].time_s(same[list(everything)]), *(0.0 for _ in vehicles[1:]))
        worse = dataclasses.replace(
            tours,
            orders=(everything, *(() for _ in vehicles[1:])),
            targets=(tuple(range(reference.n_targets)), *(() for _ in vehicles[1:])),
            times_s=times,
        )
        handed.append(worse)
        return worse

    monkeypatch.setattr(fleet_module, "solve_fleet", one_does_all)
    fleet_file = tmp_path / "fleet.toml"
    fleet_file.write_text(
        "[[vehicle]]\nhome_lat = 47.68876\nhome_lon = 9.42309\n\n"
        "[[vehicle]]\nhome_lat = 47.68990\nhome_lon = 9.42150\n"
    )
    from urpt_gcs.pipeline.settings import read_fleet

    fleet = FleetSettings(read_fleet(fleet_file), separation="time")
    settings = PlanSettings(solve=SolveSettings(time_limit_s=2.0))
    result = fleet_module.plan_fleet(DEMO / "site.tif", DEMO / "targets.kml", settings, fleet)
    assert handed, "the search was not asked"
    assert math.isfinite(result.naive_flown_s)
    assert result.makespan_s == pytest.approx(result.naive_flown_s)
    # Both vehicles fly, and the fleet lands well before one vehicle flying every stop.
    flying = [p for p in result.flying if p is not None]
    assert len(flying) == 2
    assert result.makespan_s < 0.8 * handed[0].times_s[0]
    seen = {t.name for p in flying for t in p.targets.targets}
    assert seen == {t.name for t in read_targets(DEMO / "targets.kml").targets}


def test_a_fleet_file_is_read_from_a_path_given_as_text(tmp_path: Path) -> None:
    from urpt_gcs.pipeline.settings import read_fleet

    fleet = tmp_path / "fleet.toml"
    fleet.write_text("[[vehicle]]\nspeed_m_s = 6.0\n\n[[vehicle]]\nendurance_min = 12\n")
    assert read_fleet(str(fleet)) == read_fleet(fleet)
    assert [v.speed_m_s for v in read_fleet(str(fleet))] == [6.0, None]
    with pytest.raises(SettingsError, match="does not exist"):
        read_fleet(str(tmp_path / "missing.toml"))


def test_a_fleet_file_with_a_byte_order_mark_is_read(tmp_path: Path) -> None:
    from urpt_gcs.pipeline.settings import read_fleet

    # As Notepad saves UTF-8: the mark is no TOML statement.
    fleet = tmp_path / "fleet.toml"
    fleet.write_bytes(b"\xef\xbb\xbf[[vehicle]]\nspeed_m_s = 6.0\n\n[[vehicle]]\n")
    assert [v.speed_m_s for v in read_fleet(fleet)] == [6.0, None]


def test_a_vehicle_too_slow_to_help_stays_on_the_ground(tmp_path: Path) -> None:
    """A fleet whose second vehicle flies 0.1 m/s was refused ("no split ... fits") though
    the first alone flies the site: now the first flies every target, the second is left
    idle with the reason in the summary and no mission, and the fleet lands no later than
    the first vehicle planned alone."""
    fleet = tmp_path / "fleet.toml"
    fleet.write_text("[[vehicle]]\n\n[[vehicle]]\nspeed_m_s = 0.1\n")
    out = tmp_path / "out"
    base = [
        "plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml"),
        "--no-map", "--time-limit", "2",
    ]  # fmt: skip
    result = CliRunner().invoke(main, [*base, "--out", str(out), "--fleet", str(fleet)])
    assert result.exit_code == 0, result.output
    data = json.loads((out / "summary.json").read_text())
    first, second = data["fleet"]["vehicles"]
    names = [name for name, _, _ in _demo_targets()]
    assert sorted(first["targets"] + second["targets"]) == sorted(names)
    assert not first["idle"] and first["targets"]
    assert second["idle"] is True and second["targets"] == [] and second["sorties"] == 0
    assert second["speed_m_s"] == 0.1 and "0.1 m/s" in second["idle_reason"]
    assert second["start_delay_s"] == 0.0
    assert list((out / "vehicle_2").iterdir()) == []
    assert "vehicle 2 stays on the ground: at 0.1 m/s" in result.output
    # The flying vehicle's missions, checked independently, see every target.
    flying = {**data, "fleet": {**data["fleet"], "vehicles": [first]}}
    _check_fleet_folder(out, DEMO / "site.tif", _demo_targets(), flying, 10.0)
    # The first vehicle planned alone, with the same time limit. The fleet's single tour
    # gets only part of that limit, hence a little room.
    alone = CliRunner().invoke(main, [*base, "--out", str(tmp_path / "alone"), "--quiet"])
    assert alone.exit_code == 0, alone.output
    alone_s = json.loads((tmp_path / "alone" / "summary.json").read_text())["flight_time_s"]
    assert data["fleet"]["makespan_s"] <= alone_s * 1.01


def test_a_fleet_that_cannot_reach_a_target_is_refused_in_one_line(tmp_path: Path) -> None:
    """No vehicle reaches any target and back within half a minute: no share fits."""
    fleet = tmp_path / "fleet.toml"
    fleet.write_text("[[vehicle]]\nendurance_min = 0.5\n\n[[vehicle]]\nendurance_min = 0.5\n")
    result = CliRunner().invoke(
        main,
        [
            "plan", "--dem", str(DEMO / "site.tif"), "--targets", str(DEMO / "targets.kml"),
            "--out", str(tmp_path / "out"), "--fleet", str(fleet), "--no-map", "--quiet",
        ],
    )  # fmt: skip
    assert result.exit_code == 1
    line = result.stderr.strip()
    assert "\n" not in line and line.startswith("urpt-gcs: error: no split of the targets")
    assert "none of vehicles 1, 2 can fly to target 'T01 north gate'" in line
    assert "raise the endurance in --fleet" in line
    assert not (tmp_path / "out").exists()
