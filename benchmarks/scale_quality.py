"""Benchmark: the solve stage at operator scale, its time and the quality of its tours.

    .venv/bin/python benchmarks/scale_quality.py [--size PX] [--time-limit S] [--seed N]
        [--only-ortools]

On the synthetic sites of ``urpt-gcs bench scale`` (seeded hills, buildings, nodata border):

- 300 targets at ``--time-limit`` (default 5 s): the wall time of the solve stage as the plan
  reports it, which should stay within 10 % of the limit.
- 1000 targets: the heuristic's tour at the limit against a run of it ten times as long on the
  same instance, and against OR-Tools at the same limit. OR-Tools takes at most
  ``routing.MAX_NODES`` (viewpoint, target) nodes, so that comparison is made on the instance
  of the coarsest ``--samples`` it accepts, both solvers on that one instance. Its model is
  dense in those nodes (about 6 GiB at 1000 targets): raise ``URPT_GCS_MEMORY_GIB`` for this
  run, or it reports the refusal.

Every tour is checked to see every target. Lengths are of the closed tour from home, before
it is cut into sorties.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from urpt_gcs.bench.scale import ScaleSite, make_scale_site
from urpt_gcs.errors import UrptError
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.problem.instance import Instance
from urpt_gcs.solvers import SolveSettings, Tour, solve
from urpt_gcs.solvers.clustered import partition_nodes
from urpt_gcs.solvers.routing import MAX_NODES


def _checked(instance: Instance, tour: Tour) -> Tour:
    if -1 in tour.order:
        sys.exit(f"{tour.solver}: a stop that is not an instance viewpoint")
    missed = instance.uncovered(tour.order)
    if missed:
        sys.exit(f"{tour.solver}: {len(missed)} targets unseen")
    return tour


def _solve(instance: Instance, name: str, limit_s: float, seed: int) -> tuple[Tour, float]:
    started = time.perf_counter()
    tour = solve(instance, name, SolveSettings(time_limit_s=limit_s, seed=seed))
    return _checked(instance, tour), time.perf_counter() - started


def _at_300(tmp: Path, size: int, seed: int, limit: float) -> None:
    site = make_scale_site(tmp / "s300", size, 300, seed)
    settings = PlanSettings(solver="heuristic", solve=SolveSettings(time_limit_s=limit))
    p = plan(site.dsm_path, site.targets_path, settings)
    print(
        f"300 targets: solve stage {p.timings_s['solve']:.2f} s at --time-limit {limit:g} "
        f"({p.instance.n_viewpoints} viewpoints), tour {p.tour.length:.0f} m"
    )


def _against_longer(site: ScaleSite, limit: float) -> None:
    settings = PlanSettings(solver="heuristic", solve=SolveSettings(time_limit_s=limit))
    inst = plan(site.dsm_path, site.targets_path, settings).instance
    base, base_s = _solve(inst, "heuristic", limit, 0)
    long, long_s = _solve(inst, "heuristic", 10 * limit, 0)
    print(
        f"1000 targets, --samples {settings.samples} ({inst.n_viewpoints} viewpoints): "
        f"heuristic {limit:g} s: {base.length:.0f} m ({base_s:.1f} s); "
        f"{10 * limit:g} s: {long.length:.0f} m ({long_s:.1f} s), "
        f"the short run {100 * (base.length / long.length - 1):+.2f} %"
    )


def _against_ortools(site: ScaleSite, limit: float) -> None:
    for samples in (16, 12, 8, 6, 4, 3):
        coarse = PlanSettings(
            solver="heuristic", samples=samples, solve=SolveSettings(time_limit_s=limit)
        )
        inst = plan(site.dsm_path, site.targets_path, coarse).instance
        if partition_nodes(inst) <= MAX_NODES:
            break
    else:
        sys.exit("no --samples gives an instance OR-Tools accepts")
    heur, heur_s = _solve(inst, "heuristic", limit, 0)
    print(
        f"1000 targets, --samples {samples} ({inst.n_viewpoints} viewpoints, "
        f"{partition_nodes(inst)} nodes): heuristic {heur.length:.0f} m ({heur_s:.1f} s)"
    )
    for ort_limit in (limit, 10 * limit):
        try:
            ort, ort_s = _solve(inst, "ortools", ort_limit, 0)
        except UrptError as exc:
            print(f"  OR-Tools at {ort_limit:g} s: {exc}")
            continue
        print(
            f"  OR-Tools at {ort_limit:g} s: {ort.length:.0f} m ({ort_s:.1f} s), "
            f"{100 * (ort.length / heur.length - 1):+.2f} % against the heuristic at {limit:g} s"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=10_000)
    ap.add_argument("--time-limit", type=float, default=5.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--only-ortools", action="store_true", help="only the OR-Tools comparison")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="urpt-scale-quality-") as tmp:
        site = make_scale_site(Path(tmp) / "s1000", args.size, 1000, args.seed)
        if not args.only_ortools:
            _at_300(Path(tmp), args.size, args.seed, args.time_limit)
            _against_longer(site, args.time_limit)
        _against_ortools(site, args.time_limit)


if __name__ == "__main__":
    main()
