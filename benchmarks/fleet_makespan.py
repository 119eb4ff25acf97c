"""Benchmark: fleet plans for K = 1..4 vehicles against the naive split, with the bound.

    .venv/bin/python benchmarks/fleet_makespan.py [--targets 100] [--time-limit 20]
        [--raster odm_dsm_utm51n.tif] [--box M] [--seed 3] [--max-vehicles 4]
        [--min-vehicles 1] [--separation altitude|time]

Targets are placed on valid ground of a real raster beside the checkout (``../shared/dem``,
as the tests place them). Each K is planned by :func:`urpt_gcs.pipeline.fleet.plan_fleet`,
as ``plan --vehicles K`` plans it: the single-vehicle tour, the fleet search, every
vehicle's plan (refined, checked as written, its sorties searched) and the separation along
the planned tracks, which may start a vehicle late. The makespan is when the last vehicle
lands, from the first take-off, start delays included.

The naive split is the single-vehicle tour cut into K contiguous pieces of least longest
flight, each flown as cut from home on the same layer (its times are the flight model's), and
started with the same delays as the plan ("naive"); "naive flown" is the same cut finished as
the plans are (each piece carried onto its vehicle's layer, margins, refinement, checks as
written, sorties, separation), which the plan never lands after. The bound is the plan's
makespan bound; its parts are printed: the farthest out-and-back, the work shared, the
pigeonhole, and the sorties' bound shared among the vehicles.
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

from urpt_gcs.pipeline.fleet import plan_fleet  # noqa: E402
from urpt_gcs.pipeline.settings import (  # noqa: E402
    FleetSettings,
    PlanSettings,
    VehicleSpec,
)
from urpt_gcs.solvers.base import SolveSettings  # noqa: E402


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
    parser.add_argument("--min-vehicles", type=int, default=1)
    parser.add_argument("--separation", choices=("altitude", "time"), default="altitude")
    args = parser.parse_args()
    dem = REPO.parent / "shared" / "dem" / args.raster
    if not dem.exists():
        sys.exit(f"no raster at {dem}: this benchmark needs ../shared/dem")
    targets = valid_targets(dem, args.targets, seed=args.seed, box_m=args.box)
    settings = PlanSettings(solve=SolveSettings(time_limit_s=args.time_limit, seed=args.seed))
    print(
        f"{args.raster}, {len(targets)} targets"
        + ("" if args.box is None else f" in a {args.box:g} m box")
        + f", endurance {settings.endurance_min:g} min, "
        f"{settings.mission.cruise_speed_m_s:g} m/s, {settings.mission.hold_s:g} s hold, "
        f"separation {args.separation}, time limit {args.time_limit:g} s"
    )
    print(
        f"{'K':>2s} {'naive (min)':>11s} {'naive flown':>11s} {'ours (min)':>10s} "
        f"{'vs naive':>8s} {'vs flown':>8s} "
        f"{'delays (s)':>12s} {'bound (min)':>11s} {'gap':>7s} "
        f"{'reach / share / pigeonhole / sorties (min)':>42s} {'plan s':>7s}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "targets.csv"
        csv.write_text(
            "name,lat,lon\n" + "".join(f"{n},{la:.9f},{lo:.9f}\n" for n, la, lo in targets)
        )
        for k in range(args.min_vehicles, args.max_vehicles + 1):
            fleet = FleetSettings((VehicleSpec(),) * k, separation=args.separation)
            started = time.perf_counter()
            result = plan_fleet(dem, csv, settings, fleet)
            took = time.perf_counter() - started
            delays = result.separation.start_delays_s
            naive = max(d + t for d, t in zip(delays, result.tours.naive_times_s, strict=True))
            ours, b, flown = result.makespan_s, result.bound, result.naive_flown_s
            print(
                f"{k:2d} {_minutes(naive):>11s} {_minutes(flown):>11s} {_minutes(ours):>10s} "
                f"{100.0 * (ours - naive) / naive:+7.1f}% {100.0 * (ours - flown) / flown:+7.1f}% "
                f"{'/'.join(f'{d:.0f}' for d in delays):>12s} {_minutes(b.bound_s):>11s} "
                f"{100.0 * result.gap:6.1f}% {_minutes(b.reach_s):>9s} / "
                f"{_minutes(b.share_s)} / {_minutes(b.pigeonhole_s)} / {_minutes(b.sorties_s)} "
                f"{took:7.1f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
