"""Operator scale: ``plan`` on a large synthetic Pix4D-like DSM, stage by stage.

The site is a square of ``size_px`` cells at 0.3 m in UTM 32N (10 000 px is 3 km): float32,
256-px deflate tiles, rolling hills, flat-roofed buildings and the ragged nodata border of a
photogrammetry footprint, written one tile at a time so that a raster of any size is made in
the memory of a few tiles. Targets are spread uniformly over the valid ground, home is the
centre. Each plan runs in a process of its own, so one run's peak RSS says nothing about
another's, and the read-only time (the windows the plan read, read again by rasterio alone, in
yet another fresh process so no block cache helps) is the floor the terrain stages compare to.
"""

from __future__ import annotations

import math
import resource
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import rasterio
import rasterio.errors
import rasterio.windows
from numpy.typing import NDArray
from pyproj import Transformer
from rasterio.transform import Affine

from urpt_gcs.batch.table import rows_csv
from urpt_gcs.errors import OutputError, SettingsError, UrptError
from urpt_gcs.processes import WorkerDied, run_owned

__all__ = [
    "BASE_M",
    "EPSG",
    "NODATA",
    "RES_M",
    "TERRAIN_STAGES",
    "TILE_PX",
    "Grid",
    "ScaleRow",
    "ScaleSite",
    "format_table",
    "make_scale_site",
    "run_scale",
]

EPSG = 32632
WEST_M, NORTH_M = 500_000.0, 5_300_000.0
RES_M = 0.3
TILE_PX = 256
# The raster's side: a footprint must fit 60 m inside the smallest; the largest is written
# tile by tile but read whole by the planner, whose float32 copy must fit the memory.
SCALE_MIN_SIZE_PX = 500
SCALE_MAX_SIZE_PX = 30_000
# The most targets of one site: ten times the largest the benchmark's goals name.
SCALE_MAX_TARGETS = 100_000
NODATA = -10000.0
BASE_M = 400.0

Grid = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class ScaleSite:
    """A generated site: the DSM, the targets file and what they hold."""

    dsm_path: Path
    targets_path: Path
    size_px: int
    n_targets: int


@dataclass(frozen=True, slots=True)
class _Features:
    """The seeded shapes of a site, in site metres (east and north of the south-west corner)."""

    hills: NDArray[np.float64]  # (k, 4): e, n, amplitude m, sigma m
    boxes: NDArray[np.float64]  # (k, 5): e0, e1, n0, n1, roof height above base m
    border_phase: tuple[float, float]
    size_m: float


def _features(size_px: int, seed: int) -> _Features:
    rng = np.random.default_rng(seed)
    size_m = size_px * RES_M
    n_hills = max(4, round(size_m / 250.0) ** 2 // 2)
    hills = np.column_stack(
        [
            rng.uniform(0.0, size_m, n_hills),
            rng.uniform(0.0, size_m, n_hills),
            rng.uniform(-6.0, 18.0, n_hills),
            rng.uniform(0.05, 0.2, n_hills) * size_m + 40.0,
        ]
    )
    # About one building per hectare, 8-40 m on a side, 4-25 m tall.
    n_boxes = max(1, round(size_m * size_m / 10_000.0))
    e0 = rng.uniform(0.0, size_m, n_boxes)
    n0 = rng.uniform(0.0, size_m, n_boxes)
    boxes = np.column_stack(
        [
            e0,
            e0 + rng.uniform(8.0, 40.0, n_boxes),
            n0,
            n0 + rng.uniform(8.0, 40.0, n_boxes),
            rng.uniform(4.0, 25.0, n_boxes),
        ]
    )
    a, b = rng.uniform(0.0, 2.0 * math.pi, 2)
    return _Features(hills, boxes, (float(a), float(b)), size_m)


def _ground(f: _Features, e: Grid, n: Grid) -> Grid:
    """Rolling ground; ``e`` is a row of eastings and ``n`` a column of northings."""
    z: Grid = BASE_M + 0.004 * e + 0.002 * n
    for ce, cn, amp, sigma in f.hills:
        # A Gaussian is separable: two 1-D factors instead of one exp per cell.
        z = z + amp * np.exp(-((e - ce) ** 2) / (2.0 * sigma**2)) * np.exp(
            -((n - cn) ** 2) / (2.0 * sigma**2)
        )
    return z


def _inside(f: _Features, e: Grid, n: Grid, extra_m: float = 0.0) -> NDArray[np.bool_]:
    """Whether points lie inside the surveyed footprint (and ``extra_m`` further in)."""
    half = f.size_m / 2.0
    u, v = (e - half) / half, (n - half) / half
    phi = np.arctan2(v, u)
    a, b = f.border_phase
    band_m = 45.0 + 12.0 * np.sin(3.0 * phi + a) + 6.0 * np.sin(8.0 * phi + b) + extra_m
    inside: NDArray[np.bool_] = (np.abs(u) ** 6 + np.abs(v) ** 6) ** (1.0 / 6.0) < 1.0 - (
        band_m / half
    )
    return inside


def _tile(f: _Features, col0: int, row0: int, width: int, height: int) -> Any:
    e = (np.arange(col0, col0 + width, dtype=np.float64) + 0.5)[None, :] * RES_M
    n = f.size_m - (np.arange(row0, row0 + height, dtype=np.float64) + 0.5)[:, None] * RES_M
    ground = _ground(f, e, n)
    dsm = np.broadcast_to(ground, (height, width)).copy()
    e_lo, e_hi = float(e[0, 0]), float(e[0, -1])
    n_lo, n_hi = float(n[-1, 0]), float(n[0, 0])
    b = f.boxes
    near = (b[:, 1] >= e_lo) & (b[:, 0] <= e_hi) & (b[:, 3] >= n_lo) & (b[:, 2] <= n_hi)
    for be0, be1, bn0, bn1, height_m in b[near]:
        roof = float(
            _ground(f, np.array([[(be0 + be1) / 2.0]]), np.array([[(bn0 + bn1) / 2.0]]))[0, 0]
        )
        cols = (e[0] >= be0) & (e[0] < be1)
        rows = (n[:, 0] >= bn0) & (n[:, 0] < bn1)
        dsm[np.ix_(rows, cols)] = roof + height_m
    dsm[~_inside(f, e, n)] = NODATA
    return dsm.astype(np.float32)


def check_scale(size_px: int, counts: list[int]) -> None:
    """Refuse a raster side or target count the bench cannot make, before anything is made.

    Raises
    ------
    SettingsError
        Naming the option, its range and the fix.
    """
    if not SCALE_MIN_SIZE_PX <= size_px <= SCALE_MAX_SIZE_PX:
        raise SettingsError(
            f"--size {size_px} is outside {SCALE_MIN_SIZE_PX}..{SCALE_MAX_SIZE_PX} px "
            f"(a {SCALE_MAX_SIZE_PX} px raster is {SCALE_MAX_SIZE_PX**2 * 4 / 2**30:.1f} GiB "
            "of float32): give a side in that range"
        )
    for n in counts:
        if not 1 <= n <= SCALE_MAX_TARGETS:
            raise SettingsError(
                f"--targets {n} is outside 1..{SCALE_MAX_TARGETS}: give a count in that range"
            )


def make_scale_site(
    out_dir: Path, size_px: int = 10_000, n_targets: int = 100, seed: int = 1
) -> ScaleSite:
    """Write a synthetic DSM (``site.tif``) and ``n_targets`` targets (``targets.csv``).

    Parameters
    ----------
    out_dir
        Folder for the two files; created if missing.
    size_px
        Side of the square raster in cells (0.3 m each).
    n_targets
        Targets spread uniformly over the valid ground, at least 60 m inside the footprint.
    seed
        Seed of the hills, buildings, border and targets.

    Returns
    -------
    ScaleSite
        The two paths and the sizes.

    Raises
    ------
    SettingsError
        When the raster is too small for a footprint or no target is asked for.
    OutputError
        When the folder cannot be written.
    """
    check_scale(size_px, [n_targets])
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create {out_dir}: {exc}; check the folder is writable") from exc
    f = _features(size_px, seed)
    dsm_path, targets_path = out_dir / "site.tif", out_dir / "targets.csv"
    profile = {
        "driver": "GTiff",
        "width": size_px,
        "height": size_px,
        "count": 1,
        "dtype": "float32",
        "crs": f"EPSG:{EPSG}",
        "transform": Affine(RES_M, 0.0, WEST_M, 0.0, -RES_M, NORTH_M),
        "nodata": NODATA,
        "tiled": True,
        "blockxsize": TILE_PX,
        "blockysize": TILE_PX,
        "compress": "deflate",
        "predictor": 3,
        "BIGTIFF": "IF_SAFER",
    }
    try:
        with rasterio.open(dsm_path, "w", **profile) as dst:
            for row0 in range(0, size_px, TILE_PX):
                for col0 in range(0, size_px, TILE_PX):
                    w, h = min(TILE_PX, size_px - col0), min(TILE_PX, size_px - row0)
                    window = rasterio.windows.Window(col0, row0, w, h)
                    dst.write(_tile(f, col0, row0, w, h), 1, window=window)
    except (OSError, rasterio.errors.RasterioError) as exc:
        raise OutputError(f"cannot write {dsm_path}: {exc}; check the folder") from exc
    rng = np.random.default_rng(seed + 1)
    chosen: list[NDArray[np.float64]] = []
    count = 0
    while count < n_targets:
        en = rng.uniform(0.0, f.size_m, (4 * n_targets, 2))
        ok = en[_inside(f, en[:, 0], en[:, 1], extra_m=60.0)]
        chosen.append(ok)
        count += len(ok)
    en = np.concatenate(chosen)[:n_targets]
    to_wgs84 = Transformer.from_crs(EPSG, 4326, always_xy=True)
    lon, lat = to_wgs84.transform(WEST_M + en[:, 0], NORTH_M - f.size_m + en[:, 1])
    home_lon, home_lat = to_wgs84.transform(WEST_M + f.size_m / 2.0, NORTH_M - f.size_m / 2.0)
    lines = ["name,lat,lon", f"Home,{home_lat:.9f},{home_lon:.9f}"]
    lines += [
        f"T{k:05d},{a:.9f},{b:.9f}" for k, (a, b) in enumerate(zip(lat, lon, strict=True), start=1)
    ]
    targets_path.write_text("\n".join(lines) + "\n")
    return ScaleSite(dsm_path, targets_path, size_px, n_targets)


@dataclass(frozen=True, slots=True)
class ScaleRow:
    """One plan on one site: per-stage wall times, peak RSS and what came out."""

    targets: int
    size_px: int
    status: str
    wall_s: float
    peak_rss_mb: float
    read_only_s: float | None
    terrain_stages_s: float | None
    ratio: float | None
    viewpoints: int | None
    tour_m: float | None
    timings_s: dict[str, float] = field(default_factory=dict)


def _peak_rss_mb() -> float:
    # Linux reports ru_maxrss in KiB.
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _plan_child(job: tuple[str, str, dict[str, Any]]) -> dict[str, Any]:
    # A fresh process per plan, so its peak memory is the plan's own: the planner loads here.
    from urpt_gcs.pipeline.planner import plan
    from urpt_gcs.pipeline.settings import PlanSettings

    dem, targets, options = job
    start = time.perf_counter()
    try:
        result = plan(Path(dem), Path(targets), PlanSettings(**options))
    except UrptError as exc:
        got = {"status": f"refused: {exc}", "wall_s": time.perf_counter() - start}
    except MemoryError as exc:
        got = {"status": f"crashed: MemoryError {exc}", "wall_s": time.perf_counter() - start}
    else:
        got = {
            "status": "ok",
            "wall_s": time.perf_counter() - start,
            "timings_s": dict(result.timings_s),
            "windows": [tuple(w) for w in _read_windows(result.terrain)],
            "viewpoints": result.instance.n_viewpoints,
            "tour_m": float(result.tour.length),
        }
    return {**got, "peak_rss_mb": _peak_rss_mb()}


def _read_windows(terrain: Any) -> list[tuple[int, int, int, int]]:
    """The source windows the terrain holds: its blocks, clipped to its grid, or its one
    window when it was read whole."""
    col, row, width, height = terrain.read_window_px
    if terrain.blocks_read is None:
        return [(col, row, width, height)]
    bh, bw = terrain.block_px
    out = []
    for j, i in np.argwhere(terrain.blocks_read).tolist():
        c, r = col // bw * bw + i * bw, row // bh * bh + j * bh
        c0, r0 = max(c, col), max(r, row)
        c1, r1 = min(c + bw, col + width), min(r + bh, row + height)
        if c1 > c0 and r1 > r0:
            out.append((c0, r0, c1 - c0, r1 - r0))
    return out


def _read_child(job: tuple[str, list[tuple[int, int, int, int]]]) -> float:
    dem, windows = job
    start = time.perf_counter()
    with rasterio.open(dem) as src:
        for col, row, width, height in windows:
            src.read(1, window=rasterio.windows.Window(col, row, width, height))
    return time.perf_counter() - start


# The stages whose work grows with the area the cones cover, beside the reading itself.
TERRAIN_STAGES = ("visibility", "viewpoints")


def run_scale(
    targets: Sequence[int],
    size_px: int = 10_000,
    out_dir: Path | None = None,
    seed: int = 1,
    plan_options: dict[str, Any] | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[ScaleRow]:
    """Generate a site per target count and plan it, each plan in a fresh process.

    Parameters
    ----------
    targets
        Target counts, one site and plan each.
    size_px
        Side of the raster in cells.
    out_dir
        Where ``results.csv`` goes; the rasters always live in a temporary folder.
    seed
        Seed of the sites.
    plan_options
        Keyword arguments of :class:`urpt_gcs.pipeline.settings.PlanSettings`.
    progress
        Called with a line as each run starts and ends.

    Returns
    -------
    list[ScaleRow]
        One row per target count.
    """
    check_scale(size_px, list(targets))
    say = progress or (lambda _msg: None)
    rows = []
    for count in targets:
        with tempfile.TemporaryDirectory(prefix="urpt-scale-") as tmp:
            say(f"generating {size_px} x {size_px} px with {count} targets")
            site = make_scale_site(Path(tmp), size_px, count, seed)
            say(f"planning {count} targets")
            job = (str(site.dsm_path), str(site.targets_path), plan_options or {})
            try:
                result = run_owned(_plan_child, [job], 1)[0]
            except WorkerDied as exc:
                result = {"status": f"crashed: {exc}"}
            read_s = None
            if result.get("status") == "ok":
                read_job = (str(site.dsm_path), result["windows"])
                read_s = float(run_owned(_read_child, [read_job], 1)[0])
            timings = result.get("timings_s", {})
            stages = sum(timings.get(k, 0.0) for k in TERRAIN_STAGES) if timings else None
            row = ScaleRow(
                targets=count,
                size_px=size_px,
                status=str(result.get("status", "crashed")),
                wall_s=float(result.get("wall_s", math.nan)),
                peak_rss_mb=float(result.get("peak_rss_mb", math.nan)),
                read_only_s=read_s,
                terrain_stages_s=stages,
                ratio=None if read_s is None or stages is None else stages / max(read_s, 1e-9),
                viewpoints=result.get("viewpoints"),
                tour_m=result.get("tour_m"),
                timings_s={k: round(v, 3) for k, v in timings.items()},
            )
            say(format_table([row]).splitlines()[-1])
            rows.append(row)
    if out_dir is not None:
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
            (out_dir / "results.csv").write_text(rows_csv(ScaleRow, rows))
        except OSError as exc:
            raise OutputError(f"cannot write {out_dir / 'results.csv'}: {exc}") from exc
    return rows


def format_table(rows: Sequence[ScaleRow]) -> str:
    """The rows as a plain-text table: per-stage seconds, peak RSS and the ratio."""
    stage_names: list[str] = []
    for row in rows:
        stage_names += [k for k in row.timings_s if k not in stage_names]
    head = ["targets", "px", "wall s", "peak MB", "read s", "vis+vp s", "ratio", *stage_names]
    lines = ["  ".join(f"{h:>9}" for h in head)]
    for row in rows:

        def num(value: float | None, digits: int = 2) -> str:
            return "-" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"

        cells = [
            str(row.targets),
            str(row.size_px),
            num(row.wall_s),
            num(row.peak_rss_mb, 0),
            num(row.read_only_s),
            num(row.terrain_stages_s),
            num(row.ratio),
            *(num(row.timings_s.get(k)) for k in stage_names),
        ]
        lines.append("  ".join(f"{c:>9}" for c in cells))
        if row.status != "ok":
            lines.append(f"    {row.targets} targets: {row.status}")
    return "\n".join(lines)
