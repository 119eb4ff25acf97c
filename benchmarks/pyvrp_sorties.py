"""Benchmark: PyVRP beside our sortie planning, at equal wall time on one core.

    .venv/bin/python benchmarks/pyvrp_sorties.py [--time 5 20] [--seed 0] [--only demo ...]

Needs the ``bench`` extra (``pip install -e .[bench]``: PyVRP 0.14.1). Each site's candidate
viewpoints are built as the planner builds them, then restricted to the viewpoints that see
exactly one target (what PyVRP's client groups can express; targets without one are dropped
and counted), in two forms:

- ``groups``: every one-target viewpoint, each target a required client group of its
  viewpoints;
- ``best``: one client per target, its one-target viewpoint nearest to it.

On each, ours (the solver, then the sortie order, sharing the time as ``--time-limit`` is
shared) and PyVRP (``MaxRuntime``) run one after the other for each ``--time``, the process
pinned to one core. Each side's sorties are timed again by ``FlightModel.sortie_s`` and
checked (every target seen once, every sortie within the endurance); a side whose own total
differs from the recomputed one by more than the rounding to centiseconds is reported. Sites:
the demo at ``--endurance`` 4 min, the synthetic scale site (2 km square) with 100 and 300
targets at 20 min, and seeded targets on two rasters of ``../shared/dem`` (``REAL_SITES``).
Figures of past runs are in ``benchmarks/README.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from support.band_sites import seeded_targets_csv  # noqa: E402

from urpt_gcs.bench.pyvrp_sorties import (  # noqa: E402
    SortieCheck,
    SortieRun,
    best_viewpoint_instance,
    check_sorties,
    one_target_instance,
    our_sorties,
    pyvrp_sorties,
)
from urpt_gcs.bench.scale import make_scale_site  # noqa: E402
from urpt_gcs.pipeline.area import altitude_rel, read_area, read_site  # noqa: E402
from urpt_gcs.pipeline.missions import flight_model  # noqa: E402
from urpt_gcs.pipeline.settings import PlanSettings  # noqa: E402
from urpt_gcs.problem.instance import Instance  # noqa: E402
from urpt_gcs.visibility.cover import build_instance  # noqa: E402
from urpt_gcs.visibility.regions import visibility_regions  # noqa: E402

# A side's own total may differ from the recomputed one by the rounding of its times: PyVRP's
# are whole centiseconds rounded up, one per leg, stop, take-off and landing.
REPORT_TOLERANCE_S = 0.01
# The scale site's side in pixels (0.3 m): 2 km.
SCALE_SIZE_PX = 6_667
# Real rasters with seeded targets: how many targets, and the endurance (minutes) that cuts
# their flight into several sorties.
REAL_SITES = (("odm_dsm_utm51n.tif", 100, 5.0), ("arenal_aster_wgs84.tif", 50, 20.0))


@dataclasses.dataclass(frozen=True)
class Site:
    """A site's candidate viewpoints and what the flight needs."""

    name: str
    instance: Instance
    altitude_rel_m: float
    endurance_s: float
    settings: PlanSettings


def _site(name: str, dem: Path, targets: Path, endurance_min: float) -> Site:
    settings = dataclasses.replace(PlanSettings(), endurance_min=endurance_min)
    site = read_site(dem, targets, settings)
    area = read_area(site, settings)
    regions = visibility_regions(
        area.terrain, site.targets_xy, area.ground_m, area.camera, settings.samples, 1
    )
    instance = build_instance(
        area.terrain,
        regions,
        site.targets_xy,
        area.ground_m,
        area.camera,
        site.home_xy,
        area.terrain_max_m,
        1,
    )
    return Site(name, instance, altitude_rel(area), endurance_min * 60.0, settings)


def _sites(tmp: Path, only: list[str] | None) -> Iterator[Site]:
    def wanted(name: str) -> bool:
        return only is None or any(o in name for o in only)

    if wanted("demo"):
        demo = REPO / "missions" / "demo"
        yield _site("demo", demo / "site.tif", demo / "targets.kml", 4.0)
    for count in (100, 300):
        if wanted(f"scale {count}"):
            s = make_scale_site(tmp / f"scale{count}", SCALE_SIZE_PX, count, 1)
            yield _site(f"scale {count}", s.dsm_path, s.targets_path, 20.0)
    for raster, count, endurance in REAL_SITES:
        name = f"{raster.split('_')[0]} {count}"
        dem = REPO.parent / "shared" / "dem" / raster
        if not wanted(name):
            continue
        if not dem.exists():
            print(f"no raster at {dem}: {name} skipped", file=sys.stderr)
            continue
        csv = tmp / f"{raster}.csv"
        seeded_targets_csv(dem, count, 1, csv)
        yield _site(name, dem, csv, endurance)


def _side(run: SortieRun, check: SortieCheck, endurance_s: float) -> str:
    problems = []
    if check.uncovered:
        problems.append(f"{len(check.uncovered)} targets unseen")
    if check.repeated:
        problems.append(f"{len(check.repeated)} targets seen twice")
    if check.over_endurance:
        problems.append(f"{len(check.over_endurance)} sorties over the endurance")
    if abs(run.reported_s - check.flight_time_s) > REPORT_TOLERANCE_S * (
        1 + sum(len(r) + 3 for r in run.routes)
    ):
        problems.append(f"reports {run.reported_s:.2f} s")
    verdict = "ok" if not problems and run.feasible else "; ".join(problems) or "infeasible"
    return (
        f"{len(run.routes)} | {check.flight_time_s / 60:.2f} min | {check.length_m / 1000:.2f} km "
        f"| {check.longest_s / 60:.2f} of {endurance_s / 60:g} | {run.wall_s:.1f} s | {verdict}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--time", type=float, nargs="+", default=[5.0, 20.0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--only", nargs="+", default=None, help="sites whose name has these")
    args = parser.parse_args()
    cpu = min(os.sched_getaffinity(0))
    print(
        "| instance | form | targets | viewpoints | time | ours: sorties | flight | length "
        "| longest (min) | wall | check | PyVRP: sorties | flight | length | longest (min) "
        "| wall | check | PyVRP against ours |"
    )
    print("|---" * 18 + "|")
    with tempfile.TemporaryDirectory(prefix="urpt-pyvrp-") as tmp:
        for site in _sites(Path(tmp), args.only):
            restricted, _, kept = one_target_instance(site.instance)
            dropped = site.instance.n_targets - kept.size
            best, _ = best_viewpoint_instance(restricted)
            model = flight_model(site.settings)
            for form, inst in (("groups", restricted), ("best", best)):
                for limit in args.time:
                    everything = os.sched_getaffinity(0)
                    os.sched_setaffinity(0, {cpu})
                    try:
                        ours = our_sorties(
                            inst, site.altitude_rel_m, model, site.endurance_s, limit, args.seed
                        )
                        theirs = pyvrp_sorties(
                            inst, site.altitude_rel_m, model, site.endurance_s, limit, args.seed
                        )
                    finally:
                        os.sched_setaffinity(0, everything)
                    checks = [
                        check_sorties(
                            inst, run.routes, site.altitude_rel_m, model, site.endurance_s
                        )
                        for run in (ours, theirs)
                    ]
                    diff = 100.0 * (checks[1].flight_time_s / checks[0].flight_time_s - 1.0)
                    targets = f"{inst.n_targets}" + (f" ({dropped} dropped)" if dropped else "")
                    print(
                        f"| {site.name} | {form} | {targets} | {inst.n_viewpoints} | {limit:g} s "
                        f"| {_side(ours, checks[0], site.endurance_s)} "
                        f"| {_side(theirs, checks[1], site.endurance_s)} | {diff:+.2f} % |",
                        flush=True,
                    )


if __name__ == "__main__":
    main()
