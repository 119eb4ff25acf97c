"""Benchmark: a CETSP instance made from a TSPLIB file (every city a disc of one radius),
solved and bounded as ``bench cetsp`` does, to see the planner at 10 000+ discs.

    .venv/bin/python benchmarks/cetsp_tsplib.py PATH/usa13509.tsp [--radius 2000]
        [--time 300] [--seed 0] [--out DIR]

PATH is a TSPLIB ``EUC_2D`` file (``NODE_COORD_SECTION`` of ``index x y`` lines), such as
``usa13509.tsp`` from any copy of TSPLIB; nothing of it is kept in the project. The instance
is written in the layout of ``bench/cetsp`` (``# NAME ... depot=none`` then ``x y r`` per
line) to a temporary folder, or to ``--out`` to keep it, and solved with the time limit and
one thread, as ``urpt-gcs bench cetsp`` solves the classic instances. Printed: the discs, the
wall time, the tour's length (recomputed here from its points, and every disc checked to be
within its radius of the tour), the length over the candidate points before the order
search, the certified lower bound, the gap between them, and the peak memory.
"""

from __future__ import annotations

import argparse
import resource
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def read_tsplib(path: Path) -> list[tuple[float, float]]:
    """The cities of a TSPLIB ``EUC_2D`` file, in file order."""
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        sys.exit(f"{path}: cannot be read ({exc.strerror}); give the path of a TSPLIB file")
    header = {}
    body = None
    for i, line in enumerate(lines):
        if line.strip().startswith("NODE_COORD_SECTION"):
            body = i + 1
            break
        key, _, value = line.partition(":")
        header[key.strip().upper()] = value.strip()
    if body is None:
        sys.exit(f"{path}: no NODE_COORD_SECTION; give a TSPLIB file with city coordinates")
    kind = header.get("EDGE_WEIGHT_TYPE", "")
    if kind not in {"EUC_2D", "CEIL_2D", "ATT"}:
        sys.exit(f"{path}: EDGE_WEIGHT_TYPE {kind or '(none)'}; give a planar (EUC_2D) file")
    cities = []
    for line in lines[body:]:
        parts = line.split()
        if not parts or parts[0] == "EOF":
            break
        cities.append((float(parts[1]), float(parts[2])))
    return cities


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("tsplib", type=Path)
    parser.add_argument("--radius", type=float, default=2000.0)
    parser.add_argument("--time", type=float, default=300.0)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()

    import numpy as np

    from urpt_gcs.bench.cetsp import read_instance
    from urpt_gcs.solvers import SolveSettings
    from urpt_gcs.solvers.continuous import solve_regions

    cities = read_tsplib(args.tsplib)
    name = f"{args.tsplib.stem}_r{args.radius:g}"
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.out or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{name}.txt"
        path.write_text(
            f"# {name} source={args.tsplib.name} depot=none\n"
            + "".join(f"{x:.6f} {y:.6f} {args.radius:.6f}\n" for x, y in cities)
        )
        regions = read_instance(path)
    settings = SolveSettings(time_limit_s=args.time, seed=args.seed, threads=1)
    started = time.perf_counter()
    tour = solve_regions(regions, settings)
    wall = time.perf_counter() - started

    # Checked here, apart from the solver: the length of the closed polyline, and the
    # distance from every disc's centre to it.
    pts = np.asarray(tour.points_xy, dtype=np.float64)
    a, b = pts, np.roll(pts, -1, axis=0)
    length = float(np.hypot(*(b - a).T).sum())
    discs = np.asarray(regions.discs)
    worst = 0.0
    for lo in range(0, len(discs), 512):
        c = discs[lo : lo + 512, :2, None]
        d = (b - a).T[None]
        t = np.clip(((c - a.T[None]) * d).sum(1) / np.maximum((d * d).sum(1), 1e-300), 0, 1)
        near = a.T[None] + t[:, None, :] * d
        gap = np.hypot(*(c - near).transpose(1, 0, 2)).min(axis=1) - discs[lo : lo + 512, 2]
        worst = max(worst, float(gap.max()))
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(
        f"{name}: {len(cities)} discs of radius {args.radius:g}, {args.time:g} s asked, "
        f"{wall:.1f} s wall\n"
        f"  tour {tour.length:.1f} (checked here: {length:.1f}, every disc within "
        f"{max(worst, 0.0):.3g} of it), discrete {tour.discrete_length:.1f}\n"
        f"  certified lower bound {tour.lower_bound:.1f} ({tour.bound.method}), "
        f"{100.0 * tour.gap:.2f} % from the tour; peak memory {peak_mib:.0f} MiB"
    )
    if worst > 1e-6 * args.radius or abs(length - tour.length) > 1e-6 * length:
        sys.exit("the tour does not check: see the figures above")


if __name__ == "__main__":
    main()
