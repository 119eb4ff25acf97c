"""Names are data, and a reader refuses what it cannot read rather than drop it.

Target names reach the map, plan.kml and plan.geojson as the operator wrote them: drawn as
plain text (never as matplotlib math), escaped where a format needs it. A name no output
can hold (a control character, a noncharacter, a lone surrogate), two targets of one name,
a GeoJSON feature without a geometry and a KMZ whose KML to read is not clear are refused at
read time, the way tests/cli/test_bad_inputs.py checks every refusal: exit status 1, exactly
one line on stderr naming the file and the target, no traceback, and nothing written, also
when --out holds an earlier plan (left byte for byte).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import shutil
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any
from xml.etree import ElementTree as ET

import pytest
from click.testing import CliRunner
from conftest import DEMO
from lxml import etree  # pymavlink's dependency: a parser other than ours
from support.targets import write_kmz

import urpt_gcs
from urpt_gcs.cli import main
from urpt_gcs.files import mapview
from urpt_gcs.site.targets import read_targets

BAD = Path(__file__).resolve().parents[1] / "data" / "bad"
SITE = str(DEMO / "site.tif")
TARGETS = str(DEMO / "targets.kml")
KML_NS = "http://www.opengis.net/kml/2.2"
DEMO_SET = read_targets(DEMO / "targets.kml")
assert DEMO_SET.home is not None


def _points(names: Mapping[int, str | None]) -> list[tuple[str | None, float, float]]:
    """The demo's home and targets as (name, lat, lon), target k (1-based) renamed as
    ``names`` says (None: unnamed)."""
    home = DEMO_SET.home
    assert home is not None
    targets = [
        (names.get(k, t.name), t.lat_deg, t.lon_deg)
        for k, t in enumerate(DEMO_SET.targets, start=1)
    ]
    return [(home.name, home.lat_deg, home.lon_deg), *targets]


def demo_csv(path: Path, names: Mapping[int, str | None]) -> Path:
    """The demo's points as CSV: the header is line 1, home line 2, target k line k + 2."""
    with path.open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(["name", "lat", "lon"])
        writer.writerows((n or "", a, o) for n, a, o in _points(names))
    return path


def demo_geojson(path: Path, names: Mapping[int, str | None]) -> Path:
    """The demo's points as GeoJSON: home is feature 1, target k feature k + 1."""
    features = [
        {
            "type": "Feature",
            "properties": {} if n is None else {"name": n},
            "geometry": {"type": "Point", "coordinates": [o, a]},
        }
        for n, a, o in _points(names)
    ]
    path.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    return path


def demo_kml(names: Mapping[int, str | None]) -> bytes:
    """The demo's points as KML: home is placemark 1, target k placemark k + 1."""
    q = f"{{{KML_NS}}}"
    kml = ET.Element(f"{q}kml")
    doc = ET.SubElement(kml, f"{q}Document")
    for n, a, o in _points(names):
        mark = ET.SubElement(doc, f"{q}Placemark")
        if n is not None:
            ET.SubElement(mark, f"{q}name").text = n
        point = ET.SubElement(mark, f"{q}Point")
        ET.SubElement(point, f"{q}coordinates").text = f"{o!r},{a!r}"
    data: bytes = ET.tostring(kml, encoding="utf-8", xml_declaration=True)
    return data


# name: (makes the --targets file in a folder, words the message must contain)
REFUSED: dict[str, tuple[Callable[[Path], Path], list[str]]] = {
    "name_control_character_csv": (
        lambda d: demo_csv(d / "name_control_character.csv", {1: "gate\x01north"}),
        [
            "name_control_character.csv",
            "row 3",
            "control character U+0001",
            "remove it from the name",
        ],
    ),
    "name_nul_csv": (
        lambda d: demo_csv(d / "name_nul.csv", {3: "wall\x00"}),
        ["name_nul.csv", "row 5", "'wall\\x00'", "control character U+0000"],
    ),
    "name_newline_csv": (
        lambda d: demo_csv(d / "name_newline.csv", {2: "hill\ntop"}),
        ["name_newline.csv", "row 4", "'hill\\ntop'", "control character U+000A"],
    ),
    "name_control_character_geojson": (
        lambda d: demo_geojson(d / "name_control_character.geojson", {2: "\x1b[31mred"}),
        ["name_control_character.geojson", "feature 3", "control character U+001B"],
    ),
    "name_lone_surrogate_geojson": (
        lambda d: demo_geojson(d / "name_lone_surrogate.geojson", {4: "roof\ud800"}),
        ["name_lone_surrogate.geojson", "feature 5", "lone surrogate U+D800"],
    ),
    "name_noncharacter_geojson": (
        lambda d: demo_geojson(d / "name_noncharacter.geojson", {5: "yard\uffff"}),
        ["name_noncharacter.geojson", "feature 6", "noncharacter U+FFFF"],
    ),
    # XML 1.0 allows DEL and the C1 controls, so the KML parser lets them through.
    "name_c1_control_kml": (
        lambda d: _write(d / "name_c1_control.kml", demo_kml({6: "cliff\x85foot"})),
        ["name_c1_control.kml", "placemark 7", "control character U+0085"],
    ),
    "name_control_character_kmz": (
        lambda d: write_kmz(d / "name_control_character.kmz", {"doc.kml": demo_kml({7: "\x7f"})}),
        ["name_control_character.kmz'", "placemark 8", "control character U+007F"],
    ),
    "duplicate_names_csv": (
        lambda d: demo_csv(d / "duplicate_names.csv", {7: "T02 hilltop"}),
        ["duplicate_names.csv", "two targets named 'T02 hilltop'", "row 4 and row 9", "rename"],
    ),
    "duplicate_names_geojson": (
        lambda d: demo_geojson(d / "duplicate_names.geojson", {1: "Mast", 16: "Mast"}),
        ["duplicate_names.geojson", "'Mast'", "feature 2 and feature 17"],
    ),
    "geojson_null_geometry_unnamed": (
        lambda d: _null_geometry(d / "null_geometry.geojson"),
        ["null_geometry.geojson", "feature 4 (unnamed)", "no geometry"],
    ),
    "kmz_several_kml": (
        lambda d: write_kmz(
            d / "kmz_several_kml.kmz",
            {"north.kml": demo_kml({}), "south.kml": demo_kml({}), "files/x.png": b"\x89PNG"},
        ),
        ["kmz_several_kml.kmz", "2 .kml files", "'north.kml'", "'south.kml'", "doc.kml"],
    ),
}


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


def _null_geometry(path: Path) -> Path:
    demo_geojson(path, {3: None})
    doc = json.loads(path.read_text())
    doc["features"][3]["geometry"] = None
    path.write_text(json.dumps(doc))
    return path


def _cli(targets: Path | str, out: Path, *extra: str) -> tuple[int, str]:
    args = ["plan", "--dem", SITE, "--targets", str(targets), "--out", str(out)]
    result = CliRunner().invoke(main, [*args, "--time-limit", "1", *extra])
    return result.exit_code, result.stderr


def _tree(root: Path) -> dict[str, bytes | str]:
    return {
        str(p.relative_to(root)): "<dir>" if p.is_dir() else p.read_bytes()
        for p in sorted(root.rglob("*"))
    }


@pytest.fixture(scope="module")
def previous_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An --out holding a plan of the demo site, with its map, and a file of the operator's."""
    out = tmp_path_factory.mktemp("previous") / "out"
    code, stderr = _cli(TARGETS, out)
    assert code == 0, stderr
    (out / "notes.txt").write_text("the operator's own file\n")
    return out


@pytest.mark.parametrize("prior", ["no_out", "previous_out"])
@pytest.mark.parametrize("case", sorted(REFUSED))
def test_refused_at_read_time(
    case: str, prior: str, tmp_path: Path, request: pytest.FixtureRequest
) -> None:
    make, words = REFUSED[case]
    out = tmp_path / "out"
    if prior == "previous_out":
        shutil.copytree(request.getfixturevalue("previous_out"), out)
    before = _tree(out) if out.exists() else None
    samples = sorted(p.name for p in BAD.iterdir())

    code, stderr = _cli(make(tmp_path), out, "--no-map")

    assert code == 1, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("urpt-gcs: error: targets file '"), lines[0]
    assert "Traceback" not in stderr
    for word in words:
        assert word in lines[0], lines[0]
    if before is None:
        assert not out.exists()
    else:
        assert _tree(out) == before, "an earlier --out was changed"
    assert sorted(p.name for p in BAD.iterdir()) == samples, "a sample folder was written to"


MATH_NAMES = {1: "$$", 2: "$\\invalidcommand{x}$", 3: "a $x^2$ b", 4: "$", 5: "50$ & 5 %"}


@pytest.mark.parametrize("fleet", [[], ["--vehicles", "2"]], ids=["one", "fleet"])
def test_names_like_math_are_drawn_as_plain_text(
    fleet: list[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    drawn: list[str] = []

    def keep_texts(figure: Any) -> Any:
        figure.canvas.draw()  # every text laid out, as savefig does
        for text in figure.findobj(lambda a: hasattr(a, "get_parse_math")):
            if not text.get_parse_math():
                drawn.append(text.get_text())
        return figure

    one, many = mapview.map_figure, mapview.fleet_figure
    monkeypatch.setattr(mapview, "map_figure", lambda *a: keep_texts(one(*a)))
    monkeypatch.setattr(mapview, "fleet_figure", lambda *a: keep_texts(many(*a)))
    out = tmp_path / "out"

    code, stderr = _cli(demo_csv(tmp_path / "math.csv", MATH_NAMES), out, *fleet)

    assert code == 0, stderr
    assert "Traceback" not in stderr
    png = (out / "map.png").read_bytes()
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    assert set(MATH_NAMES.values()) <= set(drawn)


MARKUP_NAMES = {
    1: 'a<b & "c"',
    2: "]]> &amp; <!-- x -->",
    3: "it's <Placemark>",
    4: "Zürich 📷",
    5: "tab\there",
}


def test_names_with_markup_round_trip_through_plan_kml_and_geojson(tmp_path: Path) -> None:
    out = tmp_path / "out"

    code, stderr = _cli(demo_csv(tmp_path / "markup.csv", MARKUP_NAMES), out, "--no-map")

    assert code == 0, stderr
    expected = [t.name for t in DEMO_SET.targets]
    for k, name in MARKUP_NAMES.items():
        expected[k - 1] = name.replace("\t", " ")  # a tab is read as a space
    parser = etree.XMLParser(resolve_entities=False, no_network=True)
    root = etree.parse(str(out / "plan.kml"), parser).getroot()
    ns = {"k": KML_NS}
    folder = root.xpath("//k:Folder[k:name='Targets']", namespaces=ns)[0]
    assert folder.xpath("k:Placemark/k:name/text()", namespaces=ns) == expected
    features = json.loads((out / "plan.geojson").read_text(encoding="utf-8"))["features"]
    assert [f["properties"]["name"] for f in features if f["properties"]["kind"] == "target"] == (
        expected
    )


@pytest.mark.parametrize(
    ("rename", "expected"),
    [
        ({0: "a\x01b"}, "has target 1 'a\\x01b' whose name holds the control character U+0001"),
        ({2: "\u202egnp.exe"}, "has target 3 '\\u202egnp.exe' whose name holds the invisible"),
        ({1: DEMO_SET.targets[0].name}, f"has two targets named '{DEMO_SET.targets[0].name}'"),
    ],
)
def test_a_target_set_built_in_python_is_held_to_the_files_rules(
    rename: Mapping[int, str], expected: str
) -> None:
    """The public API takes targets already read; their names are checked as a file's are,
    before any work, so that plan.kml stays XML and every name says which target it is."""
    targets = tuple(
        dataclasses.replace(t, name=rename.get(k, t.name)) for k, t in enumerate(DEMO_SET.targets)
    )
    site = dataclasses.replace(DEMO_SET, targets=targets, source="my targets")

    with pytest.raises(urpt_gcs.TargetsError) as refused:
        urpt_gcs.plan(DEMO / "site.tif", site)

    assert str(refused.value).startswith(f"targets file 'my targets' {expected}")
