"""Tests for urpt_gcs.site.targets: reading target files and rejecting bad ones."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from support.targets import write_kmz

from urpt_gcs.errors import TargetsError
from urpt_gcs.site.targets import Target, TargetSet, read_targets

DATA = Path(__file__).resolve().parents[1] / "data"
TARGETS = DATA / "targets"
BAD = DATA / "bad"

LAUNCH = Target("Launch", 47.3769, 8.5401)
BRIDGE = Target("Bridge pier", 47.3781, 8.5412)


def _names(result: TargetSet) -> list[str]:
    return [t.name for t in result.targets]


def _assert_error(path: Path, fragment: str) -> str:
    with pytest.raises(TargetsError) as caught:
        read_targets(path)
    message = str(caught.value)
    assert len(message.splitlines()) == 1, message
    assert message.startswith(f"targets file '{path}"), message
    assert fragment in message, message
    return message


# --- good files ----------------------------------------------------------------------------


def test_kml_nested_folders_multigeometry_and_home() -> None:
    result = read_targets(TARGETS / "nested_folders.kml")

    assert result.home == LAUNCH
    assert result.targets == (
        BRIDGE,
        Target("T2", 47.3790, 8.5420),  # unnamed: numbered among targets, home not counted
        Target("Masts-1", 47.3801, 8.5431),
        Target("Masts-2", 47.3802, 8.5432),
    )
    assert result.source == str(TARGETS / "nested_folders.kml")


@pytest.mark.parametrize(
    ("filename", "home", "targets"),
    [
        (
            "google_earth_kml21.kml",
            Target("home", 37.4220, -122.0841),
            (Target("Antenna", 37.4228, -122.0822),),
        ),
        (
            "no_namespace.kml",
            None,
            (Target("Chimney", 48.8584, 2.2945), Target("Gate", 48.8590, 2.2950)),
        ),
    ],
)
def test_kml_other_namespaces(
    filename: str, home: Target | None, targets: tuple[Target, ...]
) -> None:
    result = read_targets(TARGETS / filename)

    assert result.home == home
    assert result.targets == targets


def test_kmz_reads_doc_kml(tmp_path: Path) -> None:
    kml = (TARGETS / "nested_folders.kml").read_bytes()
    path = write_kmz(tmp_path / "targets.kmz", {"files/icon.png": b"\x89PNG", "doc.kml": kml})

    result = read_targets(path)

    assert result == TargetSet(
        read_targets(TARGETS / "nested_folders.kml").targets, LAUNCH, str(path)
    )


@pytest.mark.parametrize(
    "members",
    [
        {"layers/a.KML": "no_namespace", "files/icon.png": ""},  # the only .kml, in a folder
        {"a.kml": "no_namespace", "layers/b.kml": "nested_folders"},  # the only one at the root
        {"b.kml": "nested_folders", "doc.kml": "no_namespace", "c.kml": "nested_folders"},
    ],
    ids=["one_in_a_folder", "one_at_the_root", "doc_kml_among_others"],
)
def test_kmz_reads_its_one_kml_or_its_root_doc_kml(tmp_path: Path, members: dict[str, str]) -> None:
    path = write_kmz(
        tmp_path / "targets.kmz",
        {n: (TARGETS / f"{k}.kml").read_bytes() if k else b"\x89PNG" for n, k in members.items()},
    )

    assert _names(read_targets(path)) == ["Chimney", "Gate"]


@pytest.mark.parametrize(
    ("members", "fragment"),
    [
        (
            ["north.kml", "south.KML", "files/x.kml"],
            "holds 2 .kml files at its root ('north.kml', 'south.KML') and no doc.kml to say "
            "which to read: keep one of them, or name the one to read doc.kml",
        ),
        (
            ["layers/a.KML", "layers/b.kml"],
            "holds 2 .kml files in folders ('layers/a.KML', 'layers/b.kml'), none at its root "
            "to say which to read",
        ),
        (["doc.kml", "DOC.KML"], "holds 2 .kml files named doc.kml ('doc.kml', 'DOC.KML')"),
    ],
)
def test_kmz_with_several_kml_and_no_doc_kml_is_refused(
    tmp_path: Path, members: list[str], fragment: str
) -> None:
    kml = (TARGETS / "no_namespace.kml").read_bytes()
    path = write_kmz(tmp_path / "kmz_several_kml.kmz", dict.fromkeys(members, kml))

    _assert_error(path, fragment)


def test_geojson_names_multipoint_and_home() -> None:
    result = read_targets(TARGETS / "points.geojson")

    assert result.home == Target("Home", 47.3769, 8.5401)
    assert result.targets == (
        Target("Mast", 47.3781, 8.5412),
        Target("Roof", 47.3790, 8.5420),
        Target("7", 47.3795, 8.5425),
        Target("T4", 47.3801, 8.5431),
        Target("T5", 47.3802, 8.5432),
    )


@pytest.mark.parametrize(
    "document",
    [
        '{"type": "Point", "coordinates": [8.5412, 47.3781]}',
        '{"type": "Feature", "properties": {"name": "Bridge pier"},'
        ' "geometry": {"type": "Point", "coordinates": [8.5412, 47.3781]}}',
        '{"type": "GeometryCollection",'
        ' "geometries": [{"type": "Point", "coordinates": [8.5412, 47.3781]}]}',
    ],
)
def test_geojson_single_feature_or_bare_geometry(tmp_path: Path, document: str) -> None:
    path = tmp_path / "one.json"
    path.write_text(document)

    result = read_targets(path)

    assert [(t.lat_deg, t.lon_deg) for t in result.targets] == [(47.3781, 8.5412)]
    assert result.home is None


def test_csv_names_quoting_blank_lines_and_home() -> None:
    result = read_targets(TARGETS / "points.csv")

    assert result.home == LAUNCH
    assert result.targets == (
        BRIDGE,
        Target("T2", 47.3790, 8.5420),
        Target("Tower, east", 47.3801, 8.5431),
    )


def test_csv_semicolons_decimal_commas_and_long_column_names() -> None:
    result = read_targets(TARGETS / "points_semicolon.csv")

    assert result.targets == (BRIDGE, Target("Roof", 47.3790, 8.5420))


def test_csv_lng_column_without_names(tmp_path: Path) -> None:
    path = tmp_path / "points.csv"
    path.write_text("LNG,Lat\n8.5412,47.3781\n8.5420,47.3790\n")

    assert read_targets(path).targets == (
        Target("T1", 47.3781, 8.5412),
        Target("T2", 47.3790, 8.5420),
    )


@pytest.mark.parametrize("name", ["Home", "home", " LAUNCH ", "Launch", "hOmE"])
def test_home_is_detected_case_insensitively(tmp_path: Path, name: str) -> None:
    path = tmp_path / "points.csv"
    path.write_text(f"name,lat,lon\nBridge pier,47.3781,8.5412\n{name},47.3769,8.5401\n")

    result = read_targets(path)

    assert result.home == Target(name.strip(), 47.3769, 8.5401)
    assert result.targets == (BRIDGE,)


def test_a_name_that_only_starts_with_home_is_a_target(tmp_path: Path) -> None:
    path = tmp_path / "points.csv"
    path.write_text("name,lat,lon\nHomestead,47.3781,8.5412\n")

    result = read_targets(path)

    assert result.home is None
    assert _names(result) == ["Homestead"]


def test_source_is_the_path_as_given(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(TARGETS)

    assert read_targets(Path("points.csv")).source == "points.csv"


# --- bad files -----------------------------------------------------------------------------

BAD_FILES = [
    ("kml_malformed.kml", "is not well-formed XML (mismatched tag, line 3, column 65)"),
    ("kml_entity_expansion.kml", "refuses XML entity declarations"),
    ("kml_external_entity.kml", "refuses XML entity declarations"),
    ("kml_no_points.kml", "contains no Point placemarks"),
    ("kml_bad_coordinates.kml", "placemark 2 'Tower' with <coordinates> 'east of the bridge'"),
    ("kml_lon_out_of_range.kml", "point 'Tower' (placemark 2) with longitude 200.0"),
    ("kmz_not_a_zip.kmz", "is not a readable KMZ (zip) archive"),
    ("geojson_polygons_only.geojson", "contains no Point features"),
    (
        "geojson_null_geometry.geojson",
        "has feature 3 'Roof' with no geometry (null): give it a Point geometry or remove",
    ),
    ("geojson_malformed.geojson", "is not valid JSON (Expecting value, line 4, column 1)"),
    ("geojson_not_geojson.json", "is not GeoJSON"),
    (
        "geojson_bad_coordinates.geojson",
        'point in feature 1 with coordinates \'["8.54", "47.37"]\'',
    ),
    ("csv_missing_column.csv", "has no 'lon' column"),
    ("csv_non_numeric.csv", "lat value 'forty-seven' in row 3"),
    ("csv_nan_lat.csv", "point 'Roof' (row 3) with latitude nan, not finite"),
    (
        "csv_lat_out_of_range.csv",
        "point 'Roof' (row 3) with latitude 95.0, outside [-90, 90]",
    ),
    ("csv_header_only.csv", "has a header but no data rows"),
    ("duplicate_targets.kml", "'Bridge' (placemark 1) and point 'Bridge again' (placemark 3)"),
    (
        "duplicate_names.kml",
        "has two targets named 'Roof' (placemark 3 and placemark 5): rename one of them",
    ),
    ("empty.kml", "is empty"),
    ("two_homes.kml", "names two homes, point 'Home' (placemark 1) and point 'launch'"),
    ("only_home.kml", "has no targets besides the home point"),
    ("unknown_extension.txt", "has an unknown extension '.txt'"),
]


@pytest.mark.parametrize(("filename", "fragment"), BAD_FILES)
def test_bad_file_gives_one_line_targets_error(filename: str, fragment: str) -> None:
    _assert_error(BAD / filename, fragment)


def test_entity_expansion_is_refused_quickly_without_expanding() -> None:
    start = time.perf_counter()
    message = _assert_error(BAD / "kml_entity_expansion.kml", "refuses XML entity declarations")

    assert time.perf_counter() - start < 1.0
    assert "lol" not in message


def test_external_entity_is_not_resolved() -> None:
    message = _assert_error(BAD / "kml_external_entity.kml", "refuses XML entity declarations")

    assert "root" not in message


def test_kmz_without_kml(tmp_path: Path) -> None:
    path = write_kmz(
        tmp_path / "kmz_without_kml.kmz", {"files/icon.png": b"\x89PNG", "readme.txt": b"hi"}
    )

    _assert_error(path, "is a KMZ archive without a .kml file inside")


def test_kmz_with_malformed_kml_names_the_member(tmp_path: Path) -> None:
    kml = (BAD / "kml_malformed.kml").read_bytes()
    path = write_kmz(tmp_path / "targets.kmz", {"doc.kml": kml})

    _assert_error(path, "targets.kmz!doc.kml' is not well-formed XML")


def test_csv_not_utf8(tmp_path: Path) -> None:
    path = tmp_path / "csv_not_utf8.csv"
    path.write_bytes("name,lat,lon\nZürich,47.3769,8.5417\n".encode("latin-1"))

    _assert_error(path, "is not UTF-8 text")


def test_geojson_deep_nesting(tmp_path: Path) -> None:
    path = tmp_path / "deep.geojson"
    path.write_text("[" * 100_000 + "]" * 100_000)

    _assert_error(path, "JSON")


def test_missing_file(tmp_path: Path) -> None:
    _assert_error(tmp_path / "nowhere.kml", "does not exist")


def test_folder_instead_of_file(tmp_path: Path) -> None:
    path = tmp_path / "folder.kml"
    path.mkdir()

    _assert_error(path, "is a folder")


@pytest.mark.parametrize(
    ("geometry", "fragment"),
    [
        (None, "feature 2 'Roof' with no geometry (null)"),
        ("POINT (8 47)", "feature 2 'Roof' with no geometry (a JSON string, not a geometry"),
        ("absent", "feature 2 'Roof' with no geometry (the 'geometry' member is missing)"),
    ],
)
def test_geojson_feature_without_a_geometry_is_refused(
    tmp_path: Path, geometry: str | None, fragment: str
) -> None:
    roof: dict[str, object] = {"type": "Feature", "properties": {"name": "Roof"}}
    if geometry != "absent":
        roof["geometry"] = geometry
    point = {"type": "Point", "coordinates": [8.5412, 47.3781]}
    features = [{"type": "Feature", "properties": {}, "geometry": point}, roof]
    path = tmp_path / "null.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))

    _assert_error(path, fragment)


# Each format, with a name holding a character no output can hold: (file name, its text,
# what the message says). A KML can only carry those XML 1.0 allows (DEL and C1 controls).
_KML_NAME = (
    '<kml xmlns="http://www.opengis.net/kml/2.2"><Placemark><name>Roof</name><Point>'
    "<coordinates>8.5420,47.3790</coordinates></Point></Placemark><Placemark><name>{}</name>"
    "<Point><coordinates>8.5412,47.3781</coordinates></Point></Placemark></kml>"
)
_GEOJSON_NAME = (
    '{{"type": "Feature", "properties": {{"name": "{}"}},'
    ' "geometry": {{"type": "MultiPoint", "coordinates": [[8.5412, 47.3781], [8.542, 47.379]]}}}}'
)
UNFIT_NAMES = [
    ("nul.csv", "name,lat,lon\nRoof,47.379,8.542\nMast\0,47.3781,8.5412\n", "row 3", "U+0000"),
    ("bell.csv", "lat;lon;name\n47.3781;8.5412; \x07\n", "row 2", "control character U+0007"),
    ("cr.csv", 'name,lat,lon\nRoof,47.379,8.542\n"a\rb",47.3781,8.5412\n', "row 3", "U+000D"),
    ("fs.csv", "name,lat,lon\n\x1cRoof,47.379,8.542\n", "row 2", "control character U+001C"),
    ("del.kml", _KML_NAME.format("Mast&#x7f;"), "placemark 2", "control character U+007F"),
    ("c1.kml", _KML_NAME.format("Mast\x9b"), "placemark 2", "control character U+009B"),
    ("nel.kml", _KML_NAME.format("Mast&#x85;"), "placemark 2", "control character U+0085"),
    ("esc.geojson", _GEOJSON_NAME.format("\\u001b"), "feature 1", "U+001B"),
    (
        "surrogate.json",
        _GEOJSON_NAME.format("\\udfff"),
        "feature 1",
        "lone surrogate U+DFFF",
    ),
    ("nonchar.geojson", _GEOJSON_NAME.format("\\ufdd0"), "feature 1", "U+FDD0"),
    ("plane_16.geojson", _GEOJSON_NAME.format("\U0010ffff"), "feature 1", "U+10FFFF"),
    # Shown as "Mast gnirw" read right to left: another name than the file's.
    ("rlo.kml", _KML_NAME.format("Mast\u202ewring"), "placemark 2", "text-direction mark U+202E"),
    ("isolate.csv", "name,lat,lon\nRoof\u2067,47.379,8.542\n", "row 2", "U+2067"),
]


@pytest.mark.parametrize(("filename", "text", "where", "what"), UNFIT_NAMES)
def test_a_name_no_output_can_hold_is_refused_in_every_format(
    tmp_path: Path, filename: str, text: str, where: str, what: str
) -> None:
    path = tmp_path / filename
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    message = _assert_error(path, f" ({where}) whose name holds ")

    assert what in message
    assert message.endswith(": remove it from the name")


def test_a_kml_placemark_without_geometry_is_refused_and_a_line_ignored(tmp_path: Path) -> None:
    # It was skipped without a word: a target the file forgot to locate.
    kml = (
        '<kml xmlns="http://www.opengis.net/kml/2.2"><Document>'
        "<Placemark><name>Roof</name><Point><coordinates>8.542,47.379</coordinates></Point>"
        "</Placemark><Placemark><name>Fence</name><LineString><coordinates>8.542,47.379 "
        "8.543,47.379</coordinates></LineString></Placemark>"
        "<Placemark><name>Mast</name><description>north corner</description></Placemark>"
        "</Document></kml>"
    )
    path = tmp_path / "targets.kml"
    path.write_text(kml)
    message = _assert_error(path, "has placemark 3 'Mast' with no geometry")
    assert message.endswith(": give it a Point or remove the placemark")
    path.write_text(
        kml.replace(
            "<Placemark><name>Mast</name><description>north corner</description></Placemark>", ""
        )
    )
    assert [t.name for t in read_targets(path).targets] == ["Roof"]


def test_a_kmz_name_is_checked_as_its_kml(tmp_path: Path) -> None:
    kml = _KML_NAME.format("Mast&#x85;").encode()
    path = write_kmz(tmp_path / "targets.kmz", {"doc.kml": kml})

    _assert_error(path, "targets.kmz' has point 'Mast\\x85' (placemark 2) whose name holds the")


def test_a_tab_in_a_name_is_read_as_a_space(tmp_path: Path) -> None:
    path = tmp_path / "points.csv"
    path.write_text('name,lat,lon\n"Bridge\tpier",47.3781,8.5412\n\t Roof \t,47.379,8.542\n')

    assert _names(read_targets(path)) == ["Bridge pier", "Roof"]


def test_a_name_given_twice_is_refused_in_every_format(tmp_path: Path) -> None:
    csv_path = tmp_path / "twice.csv"
    csv_path.write_text("name,lat,lon\nRoof,47.379,8.542\nMast,47.3781,8.5412\nRoof,47.4,8.6\n")
    _assert_error(csv_path, "has two targets named 'Roof' (row 2 and row 4): rename one of them")
    multi = {"type": "MultiPoint", "coordinates": [[8.5412, 47.3781], [8.542, 47.379]]}
    one = {"type": "Point", "coordinates": [8.6, 47.4]}
    features = [
        {"type": "Feature", "properties": {"name": "Masts"}, "geometry": g} for g in (multi, one)
    ]
    json_path = tmp_path / "twice.geojson"
    json_path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    _assert_error(json_path, "two targets named 'Masts' (feature 1 and feature 2)")


def test_made_up_names_never_take_a_name_the_file_gives(tmp_path: Path) -> None:
    # Target 2 is unnamed (T2), and the file names target 3 T2; a multi-point placemark's
    # second point (Masts-2) meets a placemark named Masts-2.
    path = tmp_path / "points.kml"
    path.write_text(
        '<kml xmlns="http://www.opengis.net/kml/2.2">'
        "<Placemark><name>A</name><Point><coordinates>8.50,47.30</coordinates></Point></Placemark>"
        "<Placemark><Point><coordinates>8.51,47.31</coordinates></Point></Placemark>"
        "<Placemark><name>T2</name><Point><coordinates>8.52,47.32</coordinates></Point>"
        "</Placemark><Placemark><name>Masts</name><MultiGeometry>"
        "<Point><coordinates>8.53,47.33</coordinates></Point>"
        "<Point><coordinates>8.54,47.34</coordinates></Point></MultiGeometry></Placemark>"
        "<Placemark><name>Masts-2</name><Point><coordinates>8.55,47.35</coordinates></Point>"
        "</Placemark><Placemark><Point><coordinates>8.56,47.36</coordinates></Point></Placemark>"
        "</kml>"
    )

    names = _names(read_targets(path))

    assert names == ["A", "T2 (2)", "T2", "Masts-1", "Masts-2 (2)", "Masts-2", "T7"]


@pytest.mark.parametrize(
    "path",
    sorted(TARGETS.iterdir()) + sorted((DATA.parents[1] / "missions").glob("*/targets.*")),
    ids=lambda p: p.name,
)
def test_every_good_sample_and_mission_still_reads(path: Path) -> None:
    names = _names(read_targets(path))

    assert len(set(names)) == len(names)


def test_name_with_newline_keeps_message_on_one_line(tmp_path: Path) -> None:
    path = tmp_path / "points.csv"
    path.write_text('name,lat,lon\n"Roof\nnorth",95,8.5\n')

    _assert_error(path, "point 'Roof\\nnorth' (row 2) with latitude 95.0")


# --- fuzzing -------------------------------------------------------------------------------

SUFFIXES = [".kml", ".kmz", ".geojson", ".json", ".csv"]
SEEDS = {
    ".kml": (TARGETS / "nested_folders.kml").read_bytes(),
    ".kmz": (TARGETS / "nested_folders.kml").read_bytes(),
    ".geojson": (TARGETS / "points.geojson").read_bytes(),
    ".json": (TARGETS / "points.geojson").read_bytes(),
    ".csv": (TARGETS / "points.csv").read_bytes(),
}


@st.composite
def _contents(draw: st.DrawFn) -> tuple[str, bytes]:
    suffix = draw(st.sampled_from(SUFFIXES))
    noise = st.binary(max_size=300) | st.text(max_size=300).map(str.encode)
    if draw(st.booleans()):
        return suffix, draw(noise)
    seed = SEEDS[suffix]  # splice noise into a valid file to get past the parsers
    start = draw(st.integers(0, len(seed)))
    end = draw(st.integers(start, min(len(seed), start + 40)))
    return suffix, seed[:start] + draw(noise) + seed[end:]


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(case=_contents())
def test_fuzz_returns_targets_or_raises_targets_error(
    tmp_path_factory: pytest.TempPathFactory, case: tuple[str, bytes]
) -> None:
    suffix, data = case
    path = tmp_path_factory.mktemp("fuzz") / f"fuzz{suffix}"
    if suffix == ".kmz" and data[:1] == b"<":
        write_kmz(path, {"doc.kml": data})
    else:
        path.write_bytes(data)

    try:
        result = read_targets(path)
    except TargetsError as exc:
        assert len(str(exc).splitlines()) == 1
        assert str(path) in str(exc)
    else:
        assert result.targets
        assert result.source == str(path)


# --- many targets ----------------------------------------------------------------------------


def _csv(path: Path, rows: list[tuple[str, float, float]]) -> Path:
    path.write_text("name,lat,lon\n" + "".join(f"{n},{a!r},{o!r}\n" for n, a, o in rows))
    return path


def test_duplicates_among_many_targets_are_found_across_grid_cells(tmp_path: Path) -> None:
    # A regular grid 1e-5 degrees apart, then one point 0.9e-7 from a grid point on both axes
    # (on the other side of a hash-cell boundary) and, later, an exact copy of another.
    rows = [(f"P{i}", 47.0 + 1e-5 * (i // 100), 8.0 + 1e-5 * (i % 100)) for i in range(5000)]
    assert len(read_targets(_csv(tmp_path / "grid.csv", rows)).targets) == 5000
    near = ("Near P1234", rows[1234][1] - 0.9e-7, rows[1234][2] + 0.9e-7)
    copy = ("Copy P17", rows[17][1], rows[17][2])
    path = _csv(tmp_path / "dup.csv", [*rows, near, copy])
    _assert_error(path, "point 'P1234' (row 1236) and point 'Near P1234' (row 5002) at the same")


def test_points_just_over_the_tolerance_apart_are_distinct(tmp_path: Path) -> None:
    rows = [("A", 47.0, 8.0), ("B", 47.0 + 1.5e-7, 8.0), ("C", 47.0, 8.0 - 1.5e-7)]
    assert len(read_targets(_csv(tmp_path / "close.csv", rows)).targets) == 3


@pytest.mark.parametrize(
    ("name", "text", "fix"),
    [
        (
            "swapped.kml",
            '<kml xmlns="http://www.opengis.net/kml/2.2"><Placemark><name>Temple</name>'
            "<Point><coordinates>13.7563,100.5018</coordinates></Point></Placemark></kml>",
            "KML writes lon,lat",
        ),
        (
            "swapped.geojson",
            '{"type": "Point", "coordinates": [13.7563, 100.5018]}',
            "GeoJSON writes [lon, lat]",
        ),
    ],
)
def test_a_swapped_point_off_the_globe_gets_a_hint_in_the_files_own_order(
    tmp_path: Path, name: str, text: str, fix: str
) -> None:
    path = tmp_path / name
    path.write_text(text)
    message = _assert_error(path, "outside [-90, 90]: did you swap lat and lon?")
    assert fix in message


def test_a_typo_among_good_points_gets_no_swap_hint() -> None:
    message = _assert_error(BAD / "csv_lat_out_of_range.csv", "latitude 95.0")
    assert "swap" not in message


def test_geojson_with_a_projected_crs_member_is_read_in_that_crs() -> None:
    # QGIS writes the GeoJSON 2008 `crs` member; these are three demo points in UTM 32N.
    result = read_targets(TARGETS / "points_utm32n.geojson")
    expected = {"North gate": (47.69168576, 9.42311436), "Hilltop": (47.691422212, 9.421379797)}
    assert _names(result) == list(expected)
    for target in result.targets:
        assert (target.lat_deg, target.lon_deg) == pytest.approx(expected[target.name], abs=1e-8)
    assert result.home is not None
    assert (result.home.lat_deg, result.home.lon_deg) == pytest.approx(
        (47.688761595, 9.423090709), abs=1e-8
    )


@pytest.mark.parametrize("name", ["urn:ogc:def:crs:OGC:1.3:CRS84", "EPSG:4326"])
def test_geojson_with_a_wgs84_crs_member_is_read_as_lon_lat(tmp_path: Path, name: str) -> None:
    path = tmp_path / "wgs84.geojson"
    crs = {"type": "name", "properties": {"name": name}}
    path.write_text(json.dumps({"type": "Point", "coordinates": [8.5412, 47.3781], "crs": crs}))
    (target,) = read_targets(path).targets
    assert (target.lat_deg, target.lon_deg) == (47.3781, 8.5412)


def test_geojson_point_outside_its_crs_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "far.geojson"
    crs = {"type": "name", "properties": {"name": "EPSG:32632"}}
    path.write_text(json.dumps({"type": "Point", "coordinates": [5e8, 5e9], "crs": crs}))
    _assert_error(path, "outside WGS 84 / UTM zone 32N")
