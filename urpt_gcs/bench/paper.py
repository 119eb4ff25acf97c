"""The paper's simulation study, reproduced.

Twenty random terrains of 200 x 200 units: a 10 x 10 grid of heights drawn from U(0, 100),
triangulated into a TIN (each grid square split along one diagonal) and rasterised at 0.5
units, so the DEM's bilinear surface follows the TIN's planes. Flight plane at 125. For
m in {4, 6, 8} targets (uniform on the terrain), camera half-angle in {20, 30, 40} degrees and
d in {20, 30, 40} azimuths: 540 instances, all from fixed seeds. The operating area is the
terrain itself: rays stop at its edge. There is no depot, as in the paper.

Per instance: the exact optimum (and whether it is proven) with its time; the heuristic's
tour; the paper's approximation (the path with its circles, and the photo tour flown along
it) with the theorem's factor; the paper's lower bound; and the naive tour over the targets'
nadir points. Then the continuous problem, which the paper's optimum is not the answer to:
the exact tour refined (its stops moved within what they see, on the terrain) and the
certified lower bound of every tour from anywhere on the plane, and the gap between them.
"""

from __future__ import annotations

import csv
import functools
import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pyproj
from affine import Affine

from urpt_gcs.arrays import FloatArray
from urpt_gcs.batch.cluster import map_jobs
from urpt_gcs.batch.table import rows_csv
from urpt_gcs.bound.certificate import Certificate, certify
from urpt_gcs.bound.geometric import DISC_PACKING_ALPHA, greedy_disjoint
from urpt_gcs.files.output import write_all
from urpt_gcs.flight.refinement import Site, refine_along, refine_tour
from urpt_gcs.problem.instance import Covers, Instance
from urpt_gcs.progress import Progress
from urpt_gcs.site.terrain import Terrain
from urpt_gcs.solvers import SOLVERS, SolveSettings, Tour, solve
from urpt_gcs.solvers.approx import paper_path
from urpt_gcs.solvers.exact import solve_exact
from urpt_gcs.visibility.cover import build_instance
from urpt_gcs.visibility.outer import finer_stars, outer_regions
from urpt_gcs.visibility.regions import Camera, visibility_regions

__all__ = [
    "ALTITUDE",
    "BOUND_GAP",
    "BOUND_S",
    "CELL",
    "FOVS_DEG",
    "GRID",
    "PAPER_PROVEN",
    "REFINE_S",
    "SAMPLES",
    "SIZE",
    "TARGET_COUNTS",
    "TERRAINS",
    "Key",
    "Row",
    "continuous_gap_pct",
    "format_tables",
    "instance_job",
    "naive_length",
    "paper_instance",
    "paper_lower_bound",
    "random_targets",
    "read_csv",
    "refine_pct",
    "run_instance",
    "run_paper",
    "study_grid",
    "tin_terrain",
    "write_csv",
]

SIZE = 200.0
GRID = 10
CELL = 0.5
ALTITUDE = 125.0
TERRAINS = 20
TARGET_COUNTS = (4, 6, 8)
FOVS_DEG = (20.0, 30.0, 40.0)
SAMPLES = (20, 30, 40)

# The paper's Table I: instances (of 20) its ILP proved optimal in 900 s, by m, delta, d.
PAPER_PROVEN: dict[tuple[int, float, int], int] = {
    (4, 20.0, 20): 20, (4, 20.0, 30): 20, (4, 20.0, 40): 9,
    (4, 30.0, 20): 20, (4, 30.0, 30): 19, (4, 30.0, 40): 7,
    (4, 40.0, 20): 20, (4, 40.0, 30): 18, (4, 40.0, 40): 13,
    (6, 20.0, 20): 14, (6, 20.0, 30): 0, (6, 20.0, 40): 0,
    (6, 30.0, 20): 10, (6, 30.0, 30): 0, (6, 30.0, 40): 0,
    (6, 40.0, 20): 7, (6, 40.0, 30): 0, (6, 40.0, 40): 0,
    (8, 20.0, 20): 0, (8, 20.0, 30): 0, (8, 20.0, 40): 0,
    (8, 30.0, 20): 0, (8, 30.0, 30): 0, (8, 30.0, 40): 0,
    (8, 40.0, 20): 0, (8, 40.0, 30): 0, (8, 40.0, 40): 0,
}  # fmt: skip

if TYPE_CHECKING:
    from distributed import Client

Key = tuple[int, int, float, int]  # one instance: terrain, m, fov, d


@dataclass(frozen=True, slots=True)
class Row:
    """One instance's results; the columns of ``results.csv``."""

    terrain: int
    m: int
    fov_deg: float
    d: int
    viewpoints: int
    optimum: float
    proven: bool
    exact_s: float
    heuristic: float
    heuristic_s: float
    heuristic_solver: str
    approx: float
    approx_path: float
    approx_discs: int
    theorem_factor: float
    lower_bound: float
    naive: float
    # The exact tour refined on the terrain, and the certified bound of the continuous problem.
    refined: float = 0.0
    refine_s: float = 0.0
    certified_bound: float = 0.0
    bound_s: float = 0.0
    bound_method: str = ""


def tin_terrain(seed: int) -> Terrain:
    """A random TIN terrain of the paper, rasterised at ``CELL`` units."""
    rng = np.random.default_rng([seed, 2019])
    heights = rng.uniform(0.0, 100.0, (GRID, GRID))  # heights[i, j] at x = i*s, y = j*s
    spacing = SIZE / (GRID - 1)
    n = round(SIZE / CELL)
    centres = (np.arange(n) + 0.5) * CELL
    x = centres[None, :]  # columns run east
    y = SIZE - centres[:, None]  # rows run south from the north edge
    gx, gy = x / spacing, y / spacing
    i = np.minimum(np.floor(gx).astype(int), GRID - 2)
    j = np.minimum(np.floor(gy).astype(int), GRID - 2)
    u, v = gx - i, gy - j
    z00, z10 = heights[i, j], heights[i + 1, j]
    z01, z11 = heights[i, j + 1], heights[i + 1, j + 1]
    lower = u + v <= 1.0  # the triangle (00, 10, 01); else (11, 01, 10)
    z = np.where(
        lower,
        z00 + u * (z10 - z00) + v * (z01 - z00),
        z11 + (1.0 - u) * (z01 - z11) + (1.0 - v) * (z10 - z11),
    )
    return Terrain(
        elevation_m=np.ascontiguousarray(z, dtype=np.float64),
        transform=Affine(CELL, 0.0, 0.0, 0.0, -CELL, SIZE),
        crs=pyproj.CRS.from_epsg(3857),
        source=f"paper TIN {seed}",
        read_window_px=(0, 0, n, n),
        source_shape_px=(n, n),
    )


def random_targets(terrain_seed: int, m: int) -> FloatArray:
    """``m`` target positions, uniform on the terrain (fixed per terrain and m)."""
    rng = np.random.default_rng([terrain_seed, m, 7])
    return rng.uniform(CELL, SIZE - CELL, (m, 2))


def paper_instance(
    terrain: Terrain, targets_xy: FloatArray, fov_deg: float, samples: int
) -> Instance:
    """The GTSP of one study instance (no depot)."""
    ground = terrain.sample(targets_xy[:, 0], targets_xy[:, 1])
    camera = Camera(altitude_m=ALTITUDE, fov_deg=fov_deg)
    regions = visibility_regions(terrain, targets_xy, ground, camera, samples)
    top = float(np.nanmax(terrain.elevation_m))
    return build_instance(terrain, regions, targets_xy, ground, camera, None, top)


def paper_lower_bound(targets_xy: FloatArray, fov_deg: float) -> float:
    """The paper's ``k/2 * alpha * h tan(delta)``, h the plane height (terrain from 0)."""
    radius = ALTITUDE * math.tan(math.radians(fov_deg))
    k = len(greedy_disjoint(targets_xy, radius))
    return 0.5 * k * DISC_PACKING_ALPHA * radius if k >= 3 else 0.0


def naive_length(targets_xy: FloatArray) -> float:
    """Shortest closed tour over the targets' nadir points (fly over every target)."""
    m = len(targets_xy)
    tsp = Instance(covers=Covers.identity(m), points_xy=np.asarray(targets_xy, dtype=np.float64))
    found = solve_exact(tsp)
    assert found is not None
    return found[1]


# Seconds per instance for the certified bound, by default, and at most for refinement
# (which ends on its own well before: its steps are down to a centimetre); the bound's
# stars are tightened only while the refined tour is more than BOUND_GAP (a share) above it.
BOUND_S = 10.0
BOUND_GAP = 1e-3
REFINE_S = 30.0


def run_instance(
    terrain_seed: int,
    terrain: Terrain,
    m: int,
    fov_deg: float,
    samples: int,
    heuristic_s: float,
    bound_s: float = BOUND_S,
    bound_gap: float = BOUND_GAP,
) -> Row:
    """Solve one study instance every way."""
    targets = random_targets(terrain_seed, m)
    inst = paper_instance(terrain, targets, fov_deg, samples)
    started = time.perf_counter()
    exact = solve(inst, "exact")
    exact_s = time.perf_counter() - started
    ground = terrain.sample(targets[:, 0], targets[:, 1])
    camera = Camera(altitude_m=ALTITUDE, fov_deg=fov_deg)
    site = Site(terrain, targets, ground, camera)
    refined, done = refine_tour(site, exact, None, REFINE_S)
    regions, ratio = outer_regions(terrain, targets, ground, camera, None)
    paper_bound = paper_lower_bound(targets, fov_deg)
    tighten = finer_stars(terrain, camera)
    cert = certify(regions, refined.length, bound_s, paper_bound, ratio, tighten, bound_gap)
    refined, refine_s = _from_bound(site, cert, refined, done.seconds)
    name = "heuristic" if "heuristic" in SOLVERS else "ortools"
    heur = solve(inst, name, SolveSettings(time_limit_s=heuristic_s, seed=terrain_seed))
    approx = solve(inst, "approx")
    _, bounds = paper_path(inst)
    return Row(
        terrain=terrain_seed,
        m=m,
        fov_deg=fov_deg,
        d=samples,
        viewpoints=inst.n_viewpoints,
        optimum=round(exact.length, 6),
        proven=exact.proven_optimal,
        exact_s=round(exact_s, 4),
        heuristic=round(heur.length, 6),
        heuristic_s=round(heur.solve_s, 4),
        heuristic_solver=name,
        approx=round(approx.length, 6),
        approx_path=round(bounds.path_length_m, 6),
        approx_discs=bounds.chosen,
        theorem_factor=round(bounds.factor, 3),
        lower_bound=round(paper_lower_bound(targets, fov_deg), 6),
        naive=round(naive_length(targets), 6),
        refined=round(refined.length, 6),
        refine_s=round(refine_s, 4),
        # Rounded down: a bound is never shown larger than it is.
        certified_bound=math.floor(cert.lower_bound_m * 1e6) / 1e6,
        bound_s=round(cert.seconds, 4),
        bound_method=cert.method,
    )


def _from_bound(site: Site, cert: Certificate, refined: Tour, seconds: float) -> tuple[Tour, float]:
    """The shorter of the refined tour and the tour read off the bound's relaxed tour and
    refined in turn, and the seconds refinement took in all."""
    found = None
    if cert.relaxed_tour_xy is not None:
        found = refine_along(site, cert.relaxed_tour_xy, None, refined, REFINE_S)
    if found is None:
        return refined, seconds
    again, done = found
    return (again if again.length < refined.length else refined), seconds + done.seconds


def study_grid(quick: bool) -> list[Key]:
    """(terrain, m, fov, d) of every instance; ``quick`` keeps a small subset for CI."""
    if quick:
        return [(t, m, 30.0, 20) for t in range(2) for m in TARGET_COUNTS]
    return [
        (t, m, fov, d)
        for t in range(TERRAINS)
        for m, fov, d in itertools.product(TARGET_COUNTS, FOVS_DEG, SAMPLES)
    ]


@functools.lru_cache(maxsize=4)
def _terrain(seed: int) -> Terrain:
    # Instances of one terrain come in a row: a worker builds each terrain about once.
    return tin_terrain(seed)


def instance_job(
    key: Key, heuristic_s: float, bound_s: float = BOUND_S, bound_gap: float = BOUND_GAP
) -> Row:
    """One study instance, as a job for :func:`urpt_gcs.batch.cluster.map_jobs`."""
    t, m, fov, d = key
    return run_instance(t, _terrain(t), m, fov, d, heuristic_s, bound_s, bound_gap)


def run_paper(
    quick: bool = False,
    out_dir: Path | None = None,
    heuristic_s: float = 1.0,
    progress: Progress | None = None,
    client: Client | None = None,
    grid: Sequence[Key] | None = None,
    bound_s: float = BOUND_S,
    bound_gap: float = BOUND_GAP,
) -> list[Row]:
    """Run the study (or its quick subset); write ``out_dir/results.csv`` if given.

    With a Dask ``client`` (:func:`urpt_gcs.batch.cluster.open_client`) every instance is a task;
    the rows are the same as run here (every seed is fixed), but for the times. ``grid``
    replaces the study's instances; ``bound_s`` is each instance's time for the certified
    bound, which tightens its stars only while the gap is above ``bound_gap`` (a share).
    """
    say = progress or (lambda _msg: None)
    keys = list(study_grid(quick) if grid is None else grid)
    ended = 0

    def done(_index: int, row: Row) -> None:
        nonlocal ended
        ended += 1
        say(
            f"[{ended}/{len(keys)}] terrain {row.terrain} m={row.m} fov={row.fov_deg:g} "
            f"d={row.d}: optimum {row.optimum:.2f} in {row.exact_s:.2f} s"
        )

    job = functools.partial(
        instance_job, heuristic_s=heuristic_s, bound_s=bound_s, bound_gap=bound_gap
    )
    rows = map_jobs(job, keys, client, done)
    if out_dir is not None:
        write_csv(rows, out_dir / "results.csv")
    return rows


def write_csv(rows: Sequence[Row], path: Path) -> None:
    """Write the rows as CSV, all or nothing."""
    write_all(path.parent, {path.name: rows_csv(Row, rows)})


def _cell_table(title: str, rows: Sequence[Row], cell: Callable[[list[Row]], str]) -> str:
    lines = [
        title,
        "m  | " + " | ".join(f"d={d:<2d} δ={fov:g}" for fov in FOVS_DEG for d in SAMPLES),
    ]
    for m in TARGET_COUNTS:
        cells = []
        for fov in FOVS_DEG:
            for d in SAMPLES:
                group = [r for r in rows if (r.m, r.fov_deg, r.d) == (m, fov, d)]
                cells.append(f"{cell(group) if group else '-':>11s}")
        if any(c.strip() != "-" for c in cells):
            lines.append(f"{m:<2d} | " + " | ".join(cells))
    return "\n".join(lines)


def _gap_pct(length: float, optimum: float) -> float:
    """How much longer than the optimum, in percent (0 when both are 0)."""
    if optimum <= 0.0:
        return 0.0 if length <= 1e-9 else math.inf
    return 100.0 * (length / optimum - 1.0)


def continuous_gap_pct(row: Row) -> float:
    """How much longer the refined tour may be than the shortest tour from anywhere on the
    plane, in percent, against the certified bound (0 when both are 0)."""
    return _gap_pct(row.refined, row.certified_bound)


def refine_pct(row: Row) -> float:
    """How much shorter refinement made the exact discrete tour, in percent."""
    return 100.0 * (1.0 - row.refined / row.optimum) if row.optimum > 0.0 else 0.0


def _median_max(values: Sequence[float]) -> str:
    v = np.asarray(values, dtype=np.float64)
    return f"{np.median(v):.2f}/{v.max():.1f}%"


def _mean_ratio(rows: Sequence[Row], field: str) -> str:
    """Mean of ``field / optimum`` over the rows with a positive optimum."""
    ratios = [getattr(r, field) / r.optimum for r in rows if r.optimum > 0.0]
    return f"{np.mean(ratios):.2f}" if ratios else "-"


def format_tables(rows: Sequence[Row]) -> str:
    """The analogues of the paper's Tables I-III, and the naive strategy.

    Instances whose optimum is 0 (one viewpoint sees every target) have no ratio; they are
    counted apart.
    """
    if not rows:
        return "no instances"

    def proven(g: list[Row]) -> str:
        paper = PAPER_PROVEN.get((g[0].m, g[0].fov_deg, g[0].d))
        return f"{sum(r.proven for r in g)}/{len(g)} ({paper})"

    def heur_gap(g: list[Row]) -> str:
        return f"{np.mean([_gap_pct(r.heuristic, r.optimum) for r in g]):.3f}%"

    exact_s = np.array([r.exact_s for r in rows])
    gaps = np.array([_gap_pct(r.heuristic, r.optimum) for r in rows])
    positive = [r for r in rows if r.optimum > 0.0]
    zero = len(rows) - len(positive)
    lb_ok = all(r.lower_bound <= r.optimum + 1e-6 for r in rows)
    factor_ok = all(r.approx_path <= r.theorem_factor * r.optimum for r in positive)
    bounds = [r.lower_bound / r.optimum for r in positive]
    cont = np.array([continuous_gap_pct(r) for r in rows])
    shorter = np.array([refine_pct(r) for r in rows])
    cert_ok = all(r.certified_bound <= r.refined + 1e-6 for r in rows)
    parts = [
        _cell_table("Table I: proven optimal here (the paper's ILP in 900 s)", rows, proven),
        _cell_table("Table II: heuristic's mean gap to the optimum", rows, heur_gap),
        _cell_table(
            "Table III: approximation's flown tour / optimum",
            rows,
            lambda g: _mean_ratio(g, "approx"),
        ),
        _cell_table(
            "Naive (fly over every target) / optimum", rows, lambda g: _mean_ratio(g, "naive")
        ),
        _cell_table(
            "Continuous gap: refined tour against the certified bound (median/max)",
            rows,
            lambda g: _median_max([continuous_gap_pct(r) for r in g]),
        ),
        _cell_table(
            "Refinement: how much shorter than the exact discrete optimum (mean)",
            rows,
            lambda g: f"{np.mean([refine_pct(r) for r in g]):.2f}%",
        ),
        f"instances {len(rows)}; proven optimal {sum(r.proven for r in rows)}; exact time "
        f"median {np.median(exact_s):.3f} s, max {exact_s.max():.3f} s; {zero} with optimum 0 "
        "(one viewpoint sees every target)",
        f"heuristic ({rows[0].heuristic_solver}) gap to optimum: mean {gaps.mean():.4f} %, "
        f"max {gaps.max():.4f} %, at the optimum on {int(np.sum(gaps < 1e-6))}/{len(rows)}",
        f"paper's lower bound <= optimum on every instance: {lb_ok}; positive on "
        f"{sum(r.lower_bound > 0 for r in rows)}/{len(rows)}; mean bound / optimum "
        f"{np.mean(bounds) if bounds else math.nan:.3f}",
        f"continuous problem: refined tour against the certified bound, gap median "
        f"{np.median(cont):.3f} %, mean {cont.mean():.3f} %, max {cont.max():.3f} %, within 1 % "
        f"on {int(np.sum(cont <= 1.0))}/{len(rows)}; bound <= refined tour on every instance: "
        f"{cert_ok}; refinement shortened the discrete optimum by {shorter.mean():.2f} % on "
        f"average (max {shorter.max():.2f} %); bound time median "
        f"{np.median([r.bound_s for r in rows]):.2f} s",
        f"approximation path <= theorem factor x optimum on the {len(positive)} instances with "
        f"optimum > 0: {factor_ok}; mean path / optimum {_mean_ratio(positive, 'approx_path')},"
        f" mean factor {np.mean([r.theorem_factor for r in rows]):.1f}; where the optimum is 0 "
        f"the bound cannot hold and the path is {_zero_paths(rows)}",
    ]
    return "\n\n".join(parts)


def _zero_paths(rows: Sequence[Row]) -> str:
    paths = [r.approx_path for r in rows if r.optimum <= 0.0]
    return f"{np.mean(paths):.1f} on average" if paths else "-"


def read_csv(path: Path) -> list[Row]:
    """Rows back from a ``results.csv`` written by :func:`write_csv`."""
    kinds = {f: type(v) for f, v in asdict(_EXAMPLE).items()}
    rows = []
    with path.open(newline="") as fh:
        for record in csv.DictReader(fh):
            values: dict[str, Any] = {
                k: (record[k] == "True") if kinds[k] is bool else kinds[k](record[k]) for k in kinds
            }
            rows.append(Row(**values))
    return rows


_EXAMPLE = Row(
    0, 0, 0.0, 0, 0, 0.0, False, 0.0, 0.0, 0.0, "", 0.0, 0.0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
    0.0, "",
)  # fmt: skip
