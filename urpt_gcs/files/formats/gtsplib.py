"""GTSPLIB files: read benchmark instances and tours, write planning instances.

Reading follows TSPLIB (Reinelt 1991) plus the ``GTSP_SET_SECTION``: header lines
``KEY : value`` (colon and spaces optional), then sections whose numbers may be spread over
lines in any way. Distances are the TSPLIB integers, computed by the TSPLIB rules (``EUC_2D``,
``CEIL_2D``, ``ATT``, ``GEO``) or read from an ``EXPLICIT`` full or triangular matrix (an
``AGTSP`` full matrix stays asymmetric; an explicit diagonal is kept as given, solvers never
use self-loops; a computed one is 0). Each set becomes a target, each node a viewpoint.

Writing maps a planning instance onto GTSPLIB as the paper's reduction does:

- node ``k`` (1-based) is the ``k``-th (viewpoint, target) pair with ``covers[v, t]``, in the
  order of ``numpy.nonzero(covers)``: a viewpoint seeing several targets is a copy per target;
- set ``t + 1`` holds target ``t``'s nodes; a depot is the last node, alone in set ``m + 1``;
- ``EDGE_WEIGHT_TYPE: EUC_2D`` on integer centimetres, ``round(100 x) - min`` and
  ``round(100 y) - min`` over all nodes: a unit of distance is 1 cm, coordinates are >= 0.

A tour of the file visits one node per set; mapping its nodes back to viewpoints (and
dropping repeats) gives a tour of the instance of the same length, up to the rounding.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from urpt_gcs.arrays import BoolArray, FloatArray
from urpt_gcs.errors import SettingsError
from urpt_gcs.files.output import check_file, commit
from urpt_gcs.problem.instance import Covers, Instance, euclidean_matrix
from urpt_gcs.site.inputs import GTSPLIB_MAX_BYTES, read_capped

__all__ = ["export_gtsplib", "read_gtsplib", "read_tour", "write_gtsplib"]

# Where GTSPLIB files come from, for the messages about them.
BENCH_FLAG = "urpt-gcs bench gtsplib"

_COORDINATE_TYPES = ("EUC_2D", "CEIL_2D", "ATT", "GEO")
_WEIGHT_TYPES = (*_COORDINATE_TYPES, "EXPLICIT")
_FORMATS = (
    "FULL_MATRIX",
    *(f"{s}_{d}{o}" for s in ("UPPER", "LOWER") for d in ("", "DIAG_") for o in ("ROW", "COL")),
)
# The TSPLIB geographic constants, exactly as the library defines them.
_GEO_PI = 3.141592
_GEO_RRR = 6378.388
_KEY_LINE = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)\s*:?\s*(.*)")


@dataclass(slots=True)
class _Section:
    line: int
    tokens: list[tuple[str, int]] = field(default_factory=list)


@dataclass(slots=True)
class _File:
    """A TSPLIB-style file split into header values and section tokens, with line numbers."""

    path: Path
    last_line: int = 0
    header: dict[str, tuple[str, int]] = field(default_factory=dict)
    sections: dict[str, _Section] = field(default_factory=dict)

    def error(self, line: int, problem: str) -> SettingsError:
        return SettingsError(f"GTSPLIB file '{self.path}', line {line}: {problem}")

    def value(self, key: str) -> tuple[str, int]:
        if key not in self.header:
            raise self.error(self.last_line, f"end of file reached without a {key} line")
        return self.header[key]

    def word(self, key: str, choices: tuple[str, ...]) -> str:
        value, line = self.value(key)
        word = value.split()[0].upper() if value.split() else ""
        if word not in choices:
            raise self.error(line, f"{key} {value!r} is not one of {', '.join(choices)}")
        return word

    def count(self, key: str) -> int:
        value, line = self.value(key)
        if not value.isdigit() or int(value) == 0:
            raise self.error(line, f"{key} {value!r} is not a positive whole number")
        return int(value)

    def section(self, name: str) -> _Section:
        if name not in self.sections:
            raise self.error(self.last_line, f"end of file reached without a {name}")
        return self.sections[name]

    def numbers(self, name: str, expected: int, what: str) -> FloatArray:
        section = self.section(name)
        if len(section.tokens) != expected:
            raise self.error(
                section.line,
                f"{name} holds {len(section.tokens)} numbers where {what} needs {expected}",
            )
        values = np.empty(expected, dtype=np.float64)
        for i, (text, line) in enumerate(section.tokens):
            try:
                values[i] = float(text)
            except ValueError:
                raise self.error(line, f"{text!r} is not a number") from None
            if not math.isfinite(values[i]):
                raise self.error(line, f"{text!r} is not a finite number")
        return values

    def node(self, text: str, line: int, n: int | None) -> int:
        """A 1-based node id (at most ``n`` if given) as a 0-based index."""
        try:
            number = int(text)
        except ValueError:
            raise self.error(line, f"{text!r} is not a node number") from None
        if number < 1 or (n is not None and number > n):
            raise self.error(line, f"node {number} is outside 1..{n or 'DIMENSION'}")
        return number - 1


def _split(path: Path) -> _File:
    data = read_capped(
        path, "GTSPLIB file", BENCH_FLAG, SettingsError, GTSPLIB_MAX_BYTES, "give a GTSPLIB file"
    )
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise SettingsError(f"GTSPLIB file '{path}' cannot be read as text (not UTF-8)") from exc
    parsed = _File(path)
    current: _Section | None = None
    for number, raw in enumerate(text.splitlines(), start=1):
        parsed.last_line = number
        line = raw.strip()
        if not line:
            continue
        match = _KEY_LINE.fullmatch(line)
        if match is None:
            if current is None:
                raise parsed.error(number, f"{line[:40]!r} is outside any section")
            current.tokens.extend((token, number) for token in line.split())
            continue
        key, value = match.group(1).upper(), match.group(2).strip()
        if key == "EOF":
            break
        if key.endswith("_SECTION"):
            if key in parsed.sections:
                raise parsed.error(number, f"{key} appears twice")
            current = _Section(number, [(token, number) for token in value.split()])
            parsed.sections[key] = current
            continue
        current = None
        if key in parsed.header and key != "COMMENT":
            raise parsed.error(number, f"{key} appears twice")
        parsed.header[key] = (value, number)
    return parsed


def _coordinate_distances(kind: str, xy: FloatArray) -> FloatArray:
    """The TSPLIB integer distances between all pairs of nodes, as float64."""
    if kind == "GEO":
        # Coordinates are DDD.MM (degrees, minutes); the whole part is C's truncation.
        degrees = np.trunc(xy)
        radians = _GEO_PI * (degrees + 5.0 * (xy - degrees) / 3.0) / 180.0
        lat, lon = radians[:, 0], radians[:, 1]
        q1 = np.cos(lon[:, None] - lon[None, :])
        q2 = np.cos(lat[:, None] - lat[None, :])
        q3 = np.cos(lat[:, None] + lat[None, :])
        cosine = np.clip(0.5 * ((1.0 + q1) * q2 - (1.0 - q1) * q3), -1.0, 1.0)
        dist: FloatArray = np.trunc(_GEO_RRR * np.arccos(cosine) + 1.0)
    else:
        dx = xy[:, None, 0] - xy[None, :, 0]
        dy = xy[:, None, 1] - xy[None, :, 1]
        squared = dx * dx + dy * dy
        if kind == "EUC_2D":
            dist = np.floor(np.sqrt(squared) + 0.5)
        elif kind == "CEIL_2D":
            dist = np.ceil(np.sqrt(squared))
        else:  # ATT: pseudo-Euclidean, rounded up whenever nint rounded down.
            r = np.sqrt(squared / 10.0)
            t = np.floor(r + 0.5)
            dist = np.where(t < r, t + 1.0, t)
    np.fill_diagonal(dist, 0.0)
    return dist


def _explicit_distances(parsed: _File, n: int) -> FloatArray:
    fmt = parsed.word("EDGE_WEIGHT_FORMAT", _FORMATS)
    if fmt == "FULL_MATRIX":
        full = parsed.numbers("EDGE_WEIGHT_SECTION", n * n, f"FULL_MATRIX of {n} nodes")
        return full.reshape(n, n)
    # A column-wise triangle lists the other side's row-wise one; the fill is symmetric.
    lower = fmt.startswith("LOWER") != fmt.endswith("_COL")
    offset = 0 if "_DIAG_" in fmt else -1 if lower else 1
    rows, cols = (np.tril_indices if lower else np.triu_indices)(n, k=offset)
    values = parsed.numbers("EDGE_WEIGHT_SECTION", len(rows), f"{fmt} of {n} nodes")
    dist = np.zeros((n, n), dtype=np.float64)
    dist[rows, cols] = values
    dist[cols, rows] = values
    return dist


def _coordinates(parsed: _File, n: int) -> FloatArray:
    values = parsed.numbers("NODE_COORD_SECTION", 3 * n, f"DIMENSION {n} (id x y per node)")
    tokens = parsed.section("NODE_COORD_SECTION").tokens
    xy = np.full((n, 2), np.nan)
    for k in range(n):
        text, line = tokens[3 * k]
        node = parsed.node(text, line, n)
        if not np.isnan(xy[node, 0]):
            raise parsed.error(line, f"node {node + 1} has coordinates twice")
        xy[node] = values[3 * k + 1 : 3 * k + 3]
    return xy


def _covers(parsed: _File, n: int) -> BoolArray:
    """``covers[node, set]`` from the GTSP_SET_SECTION."""
    section = parsed.section("GTSP_SET_SECTION")
    m = parsed.count("GTSP_SETS")
    covers = np.zeros((n, m), dtype=bool)
    tokens = iter(section.tokens)
    for text, line in tokens:
        try:
            set_id = int(text)
        except ValueError:
            raise parsed.error(line, f"{text!r} is not a set number") from None
        if not 1 <= set_id <= m:
            raise parsed.error(line, f"set {set_id} is outside 1..{m} (GTSP_SETS)")
        if covers[:, set_id - 1].any():
            raise parsed.error(line, f"set {set_id} appears twice")
        members: list[int] = []
        for member, member_line in tokens:
            if member.strip() == "-1":
                break
            members.append(parsed.node(member, member_line, n))
        else:
            raise parsed.error(parsed.last_line, f"set {set_id} is not terminated by -1")
        if not members:
            raise parsed.error(line, f"set {set_id} has no nodes")
        covers[members, set_id - 1] = True
    absent = np.flatnonzero(~covers.any(axis=0)) + 1
    if absent.size:
        raise parsed.error(section.line, f"GTSP_SET_SECTION lacks set(s) {absent[:5].tolist()}")
    return covers


def read_gtsplib(path: Path) -> Instance:
    """Read a GTSPLIB instance.

    Parameters
    ----------
    path
        A ``.gtsp`` file of type GTSP or AGTSP.

    Returns
    -------
    Instance
        One viewpoint per node, one target per set, the TSPLIB integer distances (float64),
        no depot; ``points_xy`` holds the coordinates unless the weights are EXPLICIT.

    Raises
    ------
    SettingsError
        The file cannot be read or is not valid GTSPLIB; the message names the line.
    """
    parsed = _split(path)
    parsed.word("TYPE", ("GTSP", "AGTSP"))
    n = parsed.count("DIMENSION")
    kind = parsed.word("EDGE_WEIGHT_TYPE", _WEIGHT_TYPES)
    points: FloatArray | None = None
    if kind == "EXPLICIT":
        distance = _explicit_distances(parsed, n)
    else:
        points = _coordinates(parsed, n)
        distance = _coordinate_distances(kind, points)
    covers = _covers(parsed, n)
    name = parsed.header.get("NAME", (path.stem, 0))[0] or path.stem
    return Instance(
        covers=Covers.from_dense(covers), distance=distance, points_xy=points, name=name
    )


def read_tour(path: Path) -> list[int]:
    """Read the first tour of a TSPLIB tour file.

    Parameters
    ----------
    path
        A ``.tour`` file: a ``TOUR_SECTION`` of 1-based node ids terminated by ``-1``.

    Returns
    -------
    list of int
        The tour's nodes, 0-based, in order.

    Raises
    ------
    SettingsError
        The file cannot be read or holds no valid tour.
    """
    parsed = _split(path)
    section = parsed.section("TOUR_SECTION")
    tour: list[int] = []
    for text, line in section.tokens:
        if text == "-1":
            break
        tour.append(parsed.node(text, line, None))
    else:
        raise parsed.error(parsed.last_line, "TOUR_SECTION is not terminated by -1")
    if "DIMENSION" in parsed.header and parsed.count("DIMENSION") != len(tour):
        value, line = parsed.header["DIMENSION"]
        raise parsed.error(line, f"DIMENSION {value} but the tour lists {len(tour)} nodes")
    return tour


def _positions(instance: Instance) -> FloatArray:
    """The viewpoints' positions, then the depot's, checked against the distances."""
    points = instance.points_xy
    if points is None or (instance.has_depot and instance.depot_xy is None):
        raise SettingsError(
            "the instance lacks viewpoint or depot positions: only a planning instance can be "
            "written as a EUC_2D GTSPLIB file"
        )
    # On the plane the distances are Euclidean by construction; a matrix must be checked.
    pairs = [] if instance.distance is None else [(instance.distance, euclidean_matrix(points))]
    if instance.depot_distance is not None and instance.depot_xy is not None:
        to_depot = np.hypot(*(points - np.asarray(instance.depot_xy)).T)
        pairs.append((instance.depot_distance, np.vstack([to_depot, to_depot])))
        points = np.vstack([points, [instance.depot_xy]])
    if not all(np.allclose(given, plane, rtol=1e-9, atol=1e-6) for given, plane in pairs):
        raise SettingsError(
            "the instance's distances are not the Euclidean distances between its points: "
            "a EUC_2D GTSPLIB file cannot express them"
        )
    return points


def write_gtsplib(instance: Instance, name: str, comment: str = "") -> str:
    """The planning instance as a GTSPLIB file (see the module docstring for the mapping).

    Parameters
    ----------
    instance
        An instance with viewpoint positions (and the depot's, if it has a depot) whose
        distances are the Euclidean distances between them, in metres.
    name
        The file's ``NAME``.
    comment
        Put in front of the ``COMMENT`` line, which also states the units and the mapping.

    Returns
    -------
    str
        The file's text: ``TYPE: GTSP``, ``EDGE_WEIGHT_TYPE: EUC_2D`` in centimetres.

    Raises
    ------
    SettingsError
        The instance has no positions, or distances EUC_2D cannot express.
    """
    points = _positions(instance)
    vp, tg = instance.covers.pairs()
    m = instance.n_targets
    xy = np.vstack([points[vp], points[instance.n_viewpoints :]])
    cm = np.rint(xy * 100.0).astype(np.int64)
    cm -= cm.min(axis=0)
    members = [np.flatnonzero(tg == t) + 1 for t in range(m)]
    if instance.depot_distance is not None:
        members.append(np.array([len(xy)]))
    depot = f"depot = node {len(xy)} in set {m + 1}, " if instance.has_depot else ""
    about = f"{m} targets, {len(vp)} (viewpoint, target) nodes, {depot}EUC_2D in centimetres"
    lines = [
        f"NAME : {' '.join(name.split()) or 'urpt'}",
        f"COMMENT : {' '.join(f'{comment}; {about}'.split()) if comment else about}",
        f"TYPE : GTSP\nDIMENSION : {len(xy)}\nGTSP_SETS : {len(members)}",
        "EDGE_WEIGHT_TYPE : EUC_2D\nNODE_COORD_SECTION",
        *(f"{k} {x} {y}" for k, (x, y) in enumerate(cm.tolist(), start=1)),
        "GTSP_SET_SECTION",
        *(f"{k} {' '.join(map(str, nodes.tolist()))} -1" for k, nodes in enumerate(members, 1)),
        "EOF",
    ]
    return "\n".join(lines) + "\n"


def export_gtsplib(instance: Instance, path: Path, comment: str = "") -> Path:
    """Write ``instance`` as a GTSPLIB file, atomically (see :func:`write_gtsplib`).

    Parameters
    ----------
    instance
        A planning instance.
    path
        The file to write; its stem is the ``NAME``. Its folder is created if need be.
    comment
        Put in front of the ``COMMENT`` line.

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    SettingsError
        The instance cannot be written as GTSPLIB.
    OutputError
        The file cannot be written.
    """
    folder = check_file(path, "--export-gtsp")
    text = write_gtsplib(instance, path.stem, comment)
    return commit([(folder, {path.name: text})])[0]
