"""Benchmark: the GLNS-class heuristic on the GTSPLIB instances GLNS published figures for.

    .venv/bin/python benchmarks/heuristic_gtsplib.py [--seeds 0,1,2] [--time-factor 3]
        [--only NAME[,NAME]] [--no-ortools] [--out results.csv]

Per instance: the best known cost, GLNS's published mean cost, gap and time (default mode,
``glns_default.csv``), ours (mean over the seeds of cost, gap and wall time of
``HeuristicSolver.solve``), and OR-Tools routing given the same time limit. The time limit of
both is ``--time-factor`` times GLNS's mean time; the heuristic usually stops earlier by its
own rule. Compilation of the heuristic's kernels happens once, before any clock starts.
Instances are read with :func:`urpt_gcs.files.formats.gtsplib.read_gtsplib`; run single-threaded.
"""

from __future__ import annotations

import argparse
import csv
import statistics
import time
from pathlib import Path

from urpt_gcs.files.formats.gtsplib import read_gtsplib
from urpt_gcs.solvers.base import SolveSettings
from urpt_gcs.solvers.clustered import cluster_instance
from urpt_gcs.solvers.heuristic import HeuristicSolver, warm_up
from urpt_gcs.solvers.routing import solve_clustered

BENCH = Path(__file__).resolve().parents[2] / "shared" / "bench" / "gtsplib"


def _table(path: Path) -> dict[str, dict[str, str]]:
    with path.open(newline="") as f:
        return {row["instance"]: row for row in csv.DictReader(f)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--time-factor", type=float, default=3.0)
    parser.add_argument("--only", default="")
    parser.add_argument("--no-ortools", action="store_true")
    parser.add_argument("--out", type=Path)
    parser.add_argument("--bench", type=Path, default=BENCH)
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    best = _table(args.bench / "best_known.csv")
    glns = _table(args.bench / "glns_default.csv")
    names = args.only.split(",") if args.only else list(glns)
    started = time.perf_counter()
    warm_up()
    print(f"kernels ready in {time.perf_counter() - started:.1f} s (compiled or loaded)")
    head = (
        f"{'instance':12s} {'best':>9s} | {'GLNS cost':>11s} {'gap%':>6s} {'t s':>6s} | "
        f"{'ours cost':>11s} {'gap%':>6s} {'t s':>6s} {'t/GLNS':>6s} | "
        f"{'OR-Tools':>9s} {'gap%':>6s} {'limit s':>7s}"
    )
    print(head)
    print("-" * len(head))
    rows: list[dict[str, object]] = []
    gaps: list[float] = []
    solver = HeuristicSolver()
    for name in names:
        instance = read_gtsplib(args.bench / f"{name}.gtsp")
        bk = float(best[name]["best_known"])
        g = glns[name]
        glns_s = float(g["glns_default_mean_time_s"])
        limit = args.time_factor * glns_s
        costs, times = [], []
        for seed in seeds:
            tick = time.perf_counter()
            tour = solver.solve(instance, SolveSettings(time_limit_s=limit, seed=seed))
            times.append(time.perf_counter() - tick)
            costs.append(tour.length)
            rows.append(
                {"instance": name, "solver": "heuristic", "seed": seed, "cost": tour.length,
                 "gap_pct": 100 * (tour.length / bk - 1), "time_s": times[-1]}
            )  # fmt: skip
        cost = statistics.fmean(costs)
        gap = 100 * (cost / bk - 1)
        gaps.append(gap)
        ortools = "-"
        ortools_gap = "-"
        if not args.no_ortools:
            clustered = cluster_instance(instance)
            tick = time.perf_counter()
            cycle = solve_clustered(clustered, limit)
            length = clustered.cycle_length(cycle)
            ortools, ortools_gap = f"{length:9.0f}", f"{100 * (length / bk - 1):6.2f}"
            rows.append(
                {"instance": name, "solver": "ortools", "seed": 0, "cost": length,
                 "gap_pct": 100 * (length / bk - 1), "time_s": time.perf_counter() - tick}
            )  # fmt: skip
        mean_t = statistics.fmean(times)
        print(
            f"{name:12s} {bk:9.0f} | {float(g['glns_default_mean_cost']):11.1f} "
            f"{float(g['glns_default_mean_gap_pct']):6.3f} {glns_s:6.2f} | "
            f"{cost:11.1f} {gap:6.3f} {mean_t:6.2f} {max(times) / glns_s:6.2f} | "
            f"{ortools:>9s} {ortools_gap:>6s} {limit:7.2f}",
            flush=True,
        )
    glns_mean = statistics.fmean(float(glns[n]["glns_default_mean_gap_pct"]) for n in names)
    print(f"mean gap: ours {statistics.fmean(gaps):.4f} %, GLNS default {glns_mean:.4f} %")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with args.out.open("w", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)


if __name__ == "__main__":
    main()
