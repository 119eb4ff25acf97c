"""Demo site: a synthetic Pix4D-like DSM and a target file to try the planner on.

The site is 500 m × 500 m of farmland north of Lake Constance (UTM 32N) at 0.5 m: rolling
ground at about 410–430 m AMSL, flat-roofed buildings, a 30 m cliff, a gully, a mast and a few
trees, with the ragged nodata border of a photogrammetry footprint. Several targets sit where a
wall, the cliff or the gully hides part of their nadir neighbourhood, so their visibility regions
are not plain discs. The layout is fixed; the seed only varies the hills and the border.
"""

from __future__ import annotations

import math
import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rasterio
from numpy.typing import NDArray
from pyproj import Transformer
from rasterio.transform import Affine

from urpt_gcs.errors import OutputError, SettingsError

__all__ = [
    "EPSG",
    "KML_NS",
    "NODATA",
    "NORTH_M",
    "RES_M",
    "SIZE_M",
    "SIZE_PX",
    "WEST_M",
    "DemoPoint",
    "DemoSite",
    "Grid",
    "make_demo_site",
]

EPSG = 32632
WEST_M, NORTH_M = 531_500.0, 5_282_200.0
RES_M = 0.5
SIZE_PX = 1000
SIZE_M = SIZE_PX * RES_M
NODATA = -10000.0
KML_NS = "http://www.opengis.net/kml/2.2"

Grid = NDArray[np.float64]

# Flat-roofed boxes in site metres (east from the west edge, north from the south edge):
# e0, e1, n0, n1, height above the ground at the box centre. The four 20 m wings enclose a
# 14 m × 14 m courtyard (e 243–257, n 313–327).
_BOXES: tuple[tuple[float, float, float, float, float], ...] = (
    (108.0, 152.0, 180.0, 200.0, 12.0),  # warehouse
    (202.0, 218.0, 134.0, 146.0, 8.0),  # house
    (291.0, 309.0, 191.0, 209.0, 25.0),  # office
    (225.0, 275.0, 327.0, 343.0, 20.0),  # courtyard block, north wing
    (225.0, 275.0, 297.0, 313.0, 20.0),  # south wing
    (225.0, 243.0, 313.0, 327.0, 20.0),  # west wing
    (257.0, 275.0, 313.0, 327.0, 20.0),  # east wing
    (328.0, 332.0, 118.0, 122.0, 38.0),  # mast
)
_TREES: tuple[tuple[float, float, float], ...] = (  # e, n, height
    (185.0, 398.0, 15.0),
    (197.0, 405.0, 17.0),
    (208.0, 396.0, 13.0),
    (192.0, 416.0, 16.0),
    (214.0, 412.0, 14.0),
)
_GULLY = ((45.0, 270.0), (215.0, 238.0))  # centre line; 12 m deep, 2 m floor, 7 m rim to rim
_CLIFF_M = 30.0  # the cliff rises eastwards over 4 m from its foot at e = _cliff_foot_e(n)


def _cliff_foot_e(n: float) -> float:
    return 372.0 + 6.0 * math.sin(n / 35.0)


_GULLY_MID = tuple((a + b) / 2.0 for a, b in zip(*_GULLY, strict=True))
# Targets: name, e, n, what hides part of the nadir neighbourhood ("" for open ground).
_TARGETS: tuple[tuple[str, float, float, str], ...] = (
    ("T01 north gate", 250.0, 420.0, ""),
    ("T02 hilltop", 120.0, 390.0, ""),
    ("T03 warehouse wall", 130.0, 202.0, "12 m warehouse wall 2 m south"),
    ("T04 warehouse roof", 115.0, 190.0, ""),
    ("T05 courtyard", 250.0, 320.0, "20 m wings 7 m away on all sides"),
    ("T06 cliff foot", _cliff_foot_e(280.0) - 2.0, 280.0, "30 m cliff 2 m east"),
    ("T07 cliff top", _cliff_foot_e(300.0) + 20.0, 300.0, ""),
    ("T08 gully bed", _GULLY_MID[0], _GULLY_MID[1], "12 m deep gully walls 3.5 m away"),
    ("T09 mast base", 330.0, 115.5, "38 m mast 2.5 m north"),
    ("T10 office roof", 300.0, 200.0, ""),
    ("T11 office wall", 289.0, 200.0, "25 m office wall 2 m east"),
    ("T12 west field", 90.0, 120.0, ""),
    ("T13 south field", 340.0, 85.0, ""),
    ("T14 east plateau", 415.0, 200.0, ""),
    ("T15 car park", 190.0, 300.0, ""),
    ("T16 orchard", 200.0, 385.0, ""),
)
_HOME = ("Home", 250.0, 95.0, "")


@dataclass(frozen=True, slots=True)
class DemoPoint:
    """A named point of the demo site: UTM metres, DSM elevation and WGS84 degrees."""

    name: str
    x_m: float
    y_m: float
    z_m: float
    lon_deg: float
    lat_deg: float
    hidden_by: str  # what hides part of its nadir neighbourhood; "" on open ground


@dataclass(frozen=True, slots=True)
class DemoSite:
    """The files written by :func:`make_demo_site` and what they contain."""

    dsm_path: Path
    targets_path: Path
    epsg: int
    max_elevation_m: float
    targets: tuple[DemoPoint, ...]
    home: DemoPoint


def _smoothstep(t: Grid) -> Grid:
    c = np.clip(t, 0.0, 1.0)
    return c * c * (3.0 - 2.0 * c)


def _dsm(seed: int) -> NDArray[np.float32]:
    rng = np.random.default_rng(seed)
    centres = (np.arange(SIZE_PX, dtype=np.float64) + 0.5) * RES_M
    e = np.broadcast_to(centres[np.newaxis, :], (SIZE_PX, SIZE_PX))
    n = np.broadcast_to(SIZE_M - centres[:, np.newaxis], (SIZE_PX, SIZE_PX))

    ground: Grid = 408.0 + 0.012 * e + 0.008 * n
    ground += 14.0 * np.exp(-((e - 120.0) ** 2 + (n - 390.0) ** 2) / (2.0 * 45.0**2))
    for ce, cn, amp, sigma in rng.uniform((0, 0, -3, 60), (SIZE_M, SIZE_M, 4, 130), (6, 4)):
        ground += amp * np.exp(-((e - ce) ** 2 + (n - cn) ** 2) / (2.0 * sigma**2))

    # Cliff: a plateau east of a wavy line, full height between n = 140 and 420, ramps beyond.
    foot = 372.0 + 6.0 * np.sin(n / 35.0)
    along = _smoothstep((n - 90.0) / 50.0) * _smoothstep((470.0 - n) / 50.0)
    ground += _CLIFF_M * np.clip((e - foot) / 4.0, 0.0, 1.0) * along

    # Gully: distance to its centre line, fading out over its last 15 % at the east end.
    (ae, an), (be, bn) = _GULLY
    de, dn = be - ae, bn - an
    t = np.clip(((e - ae) * de + (n - an) * dn) / (de * de + dn * dn), 0.0, 1.0)
    dist = np.hypot(e - ae - t * de, n - an - t * dn)
    ground -= 12.0 * np.clip((3.5 - dist) / 2.5, 0.0, 1.0) * np.clip((1.0 - t) / 0.15, 0.0, 1.0)

    dsm: Grid = ground.copy()
    for te, tn, height in _TREES:
        crown = 1.0 - ((e - te) ** 2 + (n - tn) ** 2) / 4.0**2
        dsm = np.maximum(dsm, ground + height * np.sqrt(np.clip(crown, 0.0, 1.0)))
    for e0, e1, n0, n1, height in _BOXES:
        row, col = int((SIZE_M - (n0 + n1) / 2.0) / RES_M), int((e0 + e1) / 2.0 / RES_M)
        dsm[(e >= e0) & (e < e1) & (n >= n0) & (n < n1)] = ground[row, col] + height

    # Footprint: a rounded square whose border band is 16–38 m deep along a wavy edge.
    u, v = (e - SIZE_M / 2.0) / (SIZE_M / 2.0), (n - SIZE_M / 2.0) / (SIZE_M / 2.0)
    phi = np.arctan2(v, u)
    a, b = rng.uniform(0.0, 2.0 * math.pi, 2)
    band_m = 27.0 + 7.0 * np.sin(3.0 * phi + a) + 4.0 * np.sin(8.0 * phi + b)
    inside = (np.abs(u) ** 6 + np.abs(v) ** 6) ** (1.0 / 6.0) < 1.0 - band_m / (SIZE_M / 2.0)
    dsm[~inside] = NODATA
    return dsm.astype(np.float32)


def _bilinear(dsm: NDArray[np.float32], e: float, n: float) -> float:
    col, row = e / RES_M - 0.5, (SIZE_M - n) / RES_M - 0.5
    c0, r0 = math.floor(col), math.floor(row)
    fc, fr = col - c0, row - r0
    cell = dsm[r0 : r0 + 2, c0 : c0 + 2].astype(np.float64)
    weights = np.array([[(1 - fr) * (1 - fc), (1 - fr) * fc], [fr * (1 - fc), fr * fc]])
    return float((cell * weights).sum())


def _write_atomically(path: Path, write: Callable[[Path], None]) -> None:
    """Write through a temporary file in the same folder, so readers never see half a file."""
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        os.close(fd)
        tmp = Path(tmp_name)
        try:
            write(tmp)
            tmp.chmod(0o644)
            os.replace(tmp, path)
        finally:
            tmp.unlink(missing_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc}; check the folder is writable") from exc


def _write_dsm(dsm: NDArray[np.float32], path: Path) -> None:
    profile = {
        "driver": "GTiff",
        "width": SIZE_PX,
        "height": SIZE_PX,
        "count": 1,
        "dtype": "float32",
        "crs": f"EPSG:{EPSG}",
        "transform": Affine(RES_M, 0.0, WEST_M, 0.0, -RES_M, NORTH_M),
        "nodata": NODATA,
        "tiled": True,
        "blockxsize": 256,
        "blockysize": 256,
        "compress": "deflate",
        "predictor": 3,
    }
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(dsm, 1)


def _placemark(parent: ET.Element, point: DemoPoint) -> None:
    placemark = ET.SubElement(parent, f"{{{KML_NS}}}Placemark")
    ET.SubElement(placemark, f"{{{KML_NS}}}name").text = point.name
    about = f"hidden by {point.hidden_by}" if point.hidden_by else "open"
    ET.SubElement(placemark, f"{{{KML_NS}}}description").text = f"{about}; DSM {point.z_m:.1f} m"
    geometry = ET.SubElement(placemark, f"{{{KML_NS}}}Point")
    coords = ET.SubElement(geometry, f"{{{KML_NS}}}coordinates")
    coords.text = f"{point.lon_deg:.9f},{point.lat_deg:.9f},0"


def _write_kml(targets: tuple[DemoPoint, ...], home: DemoPoint, path: Path) -> None:
    ET.register_namespace("", KML_NS)
    kml = ET.Element(f"{{{KML_NS}}}kml")
    document = ET.SubElement(kml, f"{{{KML_NS}}}Document")
    ET.SubElement(document, f"{{{KML_NS}}}name").text = "urpt-gcs demo site"
    _placemark(document, home)
    folder = ET.SubElement(document, f"{{{KML_NS}}}Folder")
    ET.SubElement(folder, f"{{{KML_NS}}}name").text = "Targets"
    for target in targets:
        _placemark(folder, target)
    tree = ET.ElementTree(kml)
    ET.indent(tree)
    tree.write(path, encoding="UTF-8", xml_declaration=True)


def make_demo_site(out_dir: Path, seed: int = 7) -> DemoSite:
    """Write the demo DSM and its targets into a folder.

    Parameters
    ----------
    out_dir : Path
        Folder to write ``site.tif`` and ``targets.kml`` into; created if missing. Existing
        files of those names are replaced atomically.
    seed : int, optional
        Seed of the hills and of the nodata border; the same seed gives identical files.

    Returns
    -------
    DemoSite
        The two paths, the CRS, the highest valid elevation and the targets and home point.

    Raises
    ------
    SettingsError
        If ``seed`` is negative or above 2**32 - 1.
    OutputError
        If the folder or a file in it cannot be written.
    """
    if not 0 <= seed <= 2**32 - 1:
        raise SettingsError(f"--seed {seed} is out of range; use 0 to {2**32 - 1}")
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot create {out_dir}: {exc}") from exc
    dsm = _dsm(seed)
    to_wgs84 = Transformer.from_crs(EPSG, 4326, always_xy=True)

    def point(name: str, e: float, n: float, hidden_by: str) -> DemoPoint:
        x, y = WEST_M + e, NORTH_M - SIZE_M + n
        lon, lat = to_wgs84.transform(x, y)
        return DemoPoint(name, x, y, _bilinear(dsm, e, n), lon, lat, hidden_by)

    targets = tuple(point(*row) for row in _TARGETS)
    home = point(*_HOME)
    dsm_path, targets_path = out_dir / "site.tif", out_dir / "targets.kml"
    _write_atomically(dsm_path, lambda tmp: _write_dsm(dsm, tmp))
    _write_atomically(targets_path, lambda tmp: _write_kml(targets, home, tmp))
    max_m = float(dsm[dsm != NODATA].max())
    return DemoSite(dsm_path, targets_path, EPSG, max_m, targets, home)
