"""Benchmark: fleet makespan for K = 1..4 vehicles against the naive split, with the bound.

    .venv/bin/python benchmarks/fleet_makespan.py [--targets 100] [--time-limit 20]
        [--raster odm_dsm_utm51n.tif] [--box M] [--seed 3] [--max-vehicles 4]

Targets are placed on valid ground of a real raster beside the checkout (``../shared/dem``,
as the tests place them). Every vehicle flies the same layer from the same home, so the
naive split is exactly defined: the single-vehicle tour (solved once, its share of the time
limit) cut into K contiguous pieces of least longest flight, each piece flown as cut from
home. Ours is :func:`urpt_gcs.solvers.fleet.solve_fleet` from that same tour (pieces
re-solved, stops moved between vehicles, per-vehicle GTSP re-solves). Flight times are the
single-vehicle model's (take-off, legs, holds, return, landing; sorties within the
endurance). Start delays for separation are not part of these figures.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from support.targets import valid_targets  # noqa: E402

from urpt_gcs.pipeline.fleet import fleet_problem  # noqa: E402
from urpt_gcs.pipeline.settings import (  # noqa: E402
    FleetSettings,
    PlanSettings,
    VehicleSpec,
)
from urpt_gcs.solvers import choose, prepare, solve  # noqa: E402
from urpt_gcs.solvers.base import SolveSettings  # noqa: E402
from urpt_gcs.solvers.fleet import SINGLE_SHARE, solve_fleet  # noqa: E402
from urpt_gcs.solvers.fleet_bound import makespan_bound  # noqa: E402


def _minutes(seconds: float) -> str:
    return f"{seconds / 60.0:6.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=100)
    parser.add_argument("--time-limit", type=float, default=20.0)
    parser.add_argument("--raster", default="odm_dsm_utm51n.tif")
    parser.add_argument(
        "--box", type=float, default=None, help="keep the targets to a box this wide, metres"
    )
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--max-vehicles", type=int, default=4)
    args = parser.parse_args()
    dem = REPO.parent / "shared" / "dem" / args.raster
    if not dem.exists():
        sys.exit(f"no raster at {dem}: this benchmark needs ../shared/dem")
    targets = valid_targets(dem, args.targets, seed=args.seed, box_m=args.box)
    settings = PlanSettings(solve=SolveSettings(time_limit_s=args.time_limit, seed=args.seed))
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "targets.csv"
        csv.write_text(
            "name,lat,lon\n" + "".join(f"{n},{la:.9f},{lo:.9f}\n" for n, la, lo in targets)
        )
        started = time.perf_counter()
        one = FleetSettings((VehicleSpec(),), separation="time")
        problem = fleet_problem(dem, csv, settings, one)
        prep_s = time.perf_counter() - started
    vehicle, reference = problem.vehicles[0], problem.reference
    solver = choose(reference, settings.solver)
    prepare(solver)
    single_s = SINGLE_SHARE * args.time_limit
    single = solve(reference, solver, SolveSettings(single_s, args.seed))
    assert reference.points_xy is not None
    single_time = vehicle.time_s(reference.points_xy[list(single.order)])
    print(
        f"{args.raster}, {len(targets)} targets"
        + ("" if args.box is None else f" in a {args.box:g} m box")
        + ", "
        f"{reference.n_viewpoints} viewpoints, endurance {settings.endurance_min:g} min, "
        f"{settings.mission.cruise_speed_m_s:g} m/s, {settings.mission.hold_s:g} s hold"
    )
    print(
        f"site, regions and viewpoints {prep_s:.1f} s; single-vehicle tour ({solver}, "
        f"{single_s:.1f} s): {single.length:.0f} m, {_minutes(single_time)} min"
    )
    print(
        f"{'K':>2s} {'naive (min)':>11s} {'ours (min)':>10s} {'vs naive':>8s} "
        f"{'bound (min)':>11s} {'gap':>7s} {'reach / share / pigeonhole (min)':>32s} "
        f"{'moves':>5s} {'search s':>8s}"
    )
    budget = args.time_limit - single_s
    for k in range(1, args.max_vehicles + 1):
        fleet = [vehicle] * k
        settings = SolveSettings(budget, args.seed)
        tours = solve_fleet(fleet, single.order, reference, "auto", settings)
        bound = makespan_bound(fleet, single.lower_bound)
        ours, naive = tours.makespan_s, tours.naive_makespan_s
        gap = (ours - bound.bound_s) / bound.bound_s
        print(
            f"{k:2d} {_minutes(naive):>11s} {_minutes(ours):>10s} "
            f"{100.0 * (ours - naive) / naive:+7.1f}% {_minutes(bound.bound_s):>11s} "
            f"{100.0 * gap:6.1f}% {_minutes(bound.reach_s):>12s} / {_minutes(bound.share_s)} / "
            f"{_minutes(bound.pigeonhole_s)} "
            f"{tours.moves:5d} {tours.search_s:8.1f}"
        )


if __name__ == "__main__":
    main()
