"""map.html as a person opens it: in a real headless Chromium, from a file:// URL, offline.

Three plans are written as ``plan`` writes them (:mod:`support.map_pages`): the demo with a
frame camera and target names that are markup or TeX, a plan inside a height band on the
ridge site, and a fleet of two. Each page must load without an error or a network request,
hold every layer under its stable name with the plan's counts, show the names as written, and
draw a map (a screenshot of each is kept in the test's folder, its path printed). One browser
serves the module.

Chromium comes from Debian's package (``make test`` installs it where apt-get can); without
/usr/bin/chromium, or without Playwright, the module skips in one line saying why.
tests/files/test_map_page_source.py checks the page's source without a browser.
"""

from __future__ import annotations

import importlib.util
import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image
from support.map_pages import BAND_M, HOSTILE, write_band, write_fleet, write_framed

from urpt_gcs.files.mapbase import map_transformer, sortie_routes
from urpt_gcs.files.report import sortie_colour
from urpt_gcs.pipeline.fleet import FleetPlan
from urpt_gcs.pipeline.result import Plan

CHROMIUM = Path("/usr/bin/chromium")
if not CHROMIUM.exists():
    pytest.skip(f"no Chromium at {CHROMIUM}: apt-get install chromium", allow_module_level=True)
if importlib.util.find_spec("playwright") is None:
    pytest.skip("no Playwright: pip install -e '.[test]'", allow_module_level=True)

from playwright.sync_api import sync_playwright  # noqa: E402

# Headless, and nothing of Chromium's own that would reach the network.
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
PAGES = ["framed", "band", "fleet"]
# The text of every tooltip shown (each is drawn in a shadow root of its own).
TOOLTIP_TEXT = """() => {
    const out = [];
    const walk = (root) => {
        for (const el of root.querySelectorAll("*")) {
            if (el.classList.contains("bk-Tooltip") && el.shadowRoot)
                for (const child of el.shadowRoot.children)
                    if (child.tagName !== "STYLE") out.push(child.innerText);
            if (el.shadowRoot) walk(el.shadowRoot);
        }
    };
    walk(document);
    return out.join("\\n");
}"""


@pytest.fixture(scope="module")
def framed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Plan, Path]:
    return write_framed(tmp_path_factory.mktemp("framed"))


@pytest.fixture(scope="module")
def band(tmp_path_factory: pytest.TempPathFactory) -> tuple[Plan, Path]:
    return write_band(tmp_path_factory.mktemp("band"))


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> tuple[FleetPlan, Path]:
    return write_fleet(tmp_path_factory.mktemp("fleet"))


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    with sync_playwright() as driver:
        launched = driver.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield launched
        launched.close()


class Opened:
    """A page loaded in the browser, with everything it reported while it loaded."""

    def __init__(self, browser: Any, path: Path) -> None:
        self.errors: list[str] = []
        self.requests: list[str] = []
        self.failed: list[str] = []
        self.dialogs: list[str] = []
        self.page = browser.new_page(viewport={"width": 1400, "height": 1000})
        page = self.page
        page.on("console", lambda m: self.errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: self.errors.append(str(e)))
        page.on("request", lambda r: self.requests.append(r.url))
        page.on("requestfailed", lambda r: self.failed.append(f"{r.url}: {r.failure}"))
        page.on("dialog", lambda d: (self.dialogs.append(d.message), d.dismiss()))
        page.goto(path.resolve().as_uri())
        # Idle: every view drawn, the DSM's picture included.
        page.wait_for_function(
            "() => window.Bokeh && Bokeh.documents.length > 0 && Bokeh.documents[0].is_idle",
            timeout=20_000,
        )

    def model(self, name: str) -> dict[str, Any] | None:
        """The renderer ``name``: its data's columns and its glyph's colours; None if the
        page has none of that name."""
        found: dict[str, Any] | None = self.page.evaluate(
            """(name) => {
                const r = Bokeh.documents[0].get_model_by_name(name);
                if (r == null) return null;
                const columns = r.data_source.data;
                const data = {};
                for (const [k, v] of columns instanceof Map ? columns : Object.entries(columns))
                    data[k] = Array.from(v);
                const glyph = r.glyph;
                return {
                    data: data,
                    line_color: glyph.line_color ?? null,
                    fill_color: glyph.fill_color ?? null,
                    visible: r.visible,
                };
            }""",
            name,
        )
        return found

    def names(self) -> list[str]:
        """The name of every model of the page that has one."""
        names: list[str] = self.page.evaluate(
            """() => [...Bokeh.documents[0].all_models]
                .map((m) => m.name).filter((n) => typeof n === "string" && n !== "")"""
        )
        return names

    def legend(self, figure: str = "map") -> dict[str, list[str]]:
        """The legend of ``figure``: each entry's label -> the names of its renderers."""
        items: dict[str, list[str]] = self.page.evaluate(
            """(figure) => {
                const fig = Bokeh.documents[0].get_model_by_name(figure);
                const legend = fig.right.find((m) => m.type === "Legend");
                const out = {};
                for (const item of legend.items)
                    out[item.label.value] = item.renderers.map((r) => r.name);
                return out;
            }""",
            figure,
        )
        return items

    def close(self) -> None:
        self.page.close()


@pytest.fixture
def opened(browser: Any) -> Iterator[Any]:
    pages: list[Opened] = []

    def open_page(path: Path) -> Opened:
        pages.append(Opened(browser, path))
        return pages[-1]

    yield open_page
    for page in pages:
        page.close()


def _page_of(request: pytest.FixtureRequest, which: str) -> Path:
    return Path(request.getfixturevalue(which)[1]) / "map.html"


# -- the tests ------------------------------------------------------------------------------


@pytest.mark.parametrize("which", PAGES)
def test_the_page_loads_offline_without_errors(
    which: str, request: pytest.FixtureRequest, opened: Any
) -> None:
    path = _page_of(request, which)
    page = opened(path)
    assert page.errors == []
    assert page.failed == []
    assert page.dialogs == []
    assert [u for u in page.requests if not u.startswith(("file:", "data:"))] == []
    assert page.requests[0] == path.resolve().as_uri()


def test_every_layer_is_there_with_the_plans_counts(framed: tuple[Plan, Path], opened: Any) -> None:
    result, out = framed
    page = opened(out / "map.html")
    names = [t.name for t in result.targets.targets]

    targets = page.model("targets")
    assert targets is not None and len(targets["data"]["x"]) == len(names)
    labels = page.model("target-names")
    assert labels is not None and labels["data"]["name"] == names
    stops = page.model("stops")
    assert stops is not None
    assert stops["data"]["order"] == list(range(1, len(result.tour.order) + 1))
    assert all(stops["data"]["gsd"]), "a frame camera gives every stop a GSD"
    routes = sortie_routes(result, map_transformer(result.crs))
    for number, route in enumerate(routes, start=1):
        line = page.model(f"sortie-{number}")
        assert line is not None
        np.testing.assert_allclose(line["data"]["x"], route[:, 0])
        assert line["line_color"] == {"value": sortie_colour(number)}
    assert page.model(f"sortie-{len(routes) + 1}") is None
    regions = page.model("regions")
    shown = [r for r in result.regions if not r.polygon.is_empty]
    assert regions is not None and len(regions["data"]["xs"]) == len(shown)
    frames = page.model("frames")
    assert frames is not None and len(frames["data"]["xs"]) == len(result.tour.order)
    fence = page.model("geofence")
    assert fence is not None and len(fence["data"]["x"]) == len(result.geofence_latlon) + 1
    home = page.model("home")
    assert home is not None
    np.testing.assert_allclose([home["data"]["x"][0], home["data"]["y"][0]], result.home_xy)
    dsm = page.model("dsm")
    assert dsm is not None and dsm["data"]["url"][0].startswith("data:image/png;base64,")
    # Every layer can be hidden from the legend.
    policy = page.page.evaluate(
        """() => Bokeh.documents[0].get_model_by_name("map").right
            .find((m) => m.type === "Legend").click_policy"""
    )
    assert policy == "hide"
    legend = page.legend()
    assert {"DSM", "visibility regions", "targets", "stops", "home", "geofence"} <= set(legend)
    assert {"sortie-1", "sortie-1-casing"} <= {n for group in legend.values() for n in group}


def test_a_band_plan_has_its_profile(band: tuple[Plan, Path], opened: Any) -> None:
    result, out = band
    flight = result.band_flight
    assert flight is not None
    page = opened(out / "map.html")
    assert page.model("regions") is None  # a band plan has none
    waypoints = page.model("waypoints")
    assert waypoints is not None and len(waypoints["data"]["x"]) == flight.inserted
    stops = page.model("stops")
    assert stops is not None and len(stops["data"]["x"]) == len(flight.stops_xyz)
    floor, ceiling = BAND_M
    assert all(floor - 0.1 <= h <= ceiling + 0.1 for h in stops["data"]["above_ground_m"])
    for number, (path, stop_of) in enumerate(
        zip(flight.paths_xyz, flight.path_stop, strict=True), start=1
    ):
        line = page.model(f"profile-{number}")
        assert line is not None
        np.testing.assert_allclose(line["data"]["y"], path[:, 2])
        assert line["visible"] == (number == 1)
        dots = page.model(f"profile-stops-{number}")
        assert dots is not None and len(dots["data"]["z"]) == int((stop_of >= 0).sum())
    assert page.model(f"profile-{len(flight.paths_xyz) + 1}") is None
    legend = page.legend("profiles")
    assert list(legend) == [f"sortie {n}" for n in range(1, len(flight.paths_xyz) + 1)]


def test_a_fleet_page_colours_each_vehicle_apart(
    fleet: tuple[FleetPlan, Path], opened: Any
) -> None:
    result, out = fleet
    page = opened(out / "map.html")
    names = page.names()
    flying = [(k, p) for k, p in enumerate(result.flying, start=1) if p is not None]
    assert len(flying) == 2, "both vehicles fly"
    assert "stops" not in names and "targets" not in names
    colours = {}
    legend = page.legend()
    for number, vehicle in flying:
        prefix = f"vehicle-{number}-"
        mine = {n for n in names if n.startswith(prefix)}
        lines = [page.model(f"{prefix}sortie-{s}") for s in range(1, len(vehicle.sorties) + 1)]
        seen = {line["line_color"]["value"] for line in lines if line is not None}
        stops = page.model(f"{prefix}stops")
        targets = page.model(f"{prefix}targets")
        assert stops is not None and targets is not None
        seen |= set(stops["data"]["colour"]) | set(targets["data"]["colour"])
        assert len(stops["data"]["x"]) == len(vehicle.tour.order)
        assert targets["data"]["name"] == [t.name for t in vehicle.targets.targets]
        assert len(seen) == 1, f"vehicle {number} in several colours: {seen}"
        colours[number] = seen.pop()
        # One legend entry shows or hides all of the vehicle and nothing else.
        entry = [group for label, group in legend.items() if label.startswith(f"vehicle {number}:")]
        assert len(entry) == 1 and set(entry[0]) == mine
    assert len(set(colours.values())) == len(colours)
    assert colours == {k: sortie_colour(k) for k, _ in flying}


def test_hostile_names_are_shown_literally(framed: tuple[Plan, Path], opened: Any) -> None:
    _, out = framed
    page = opened(out / "map.html")
    labels = page.model("target-names")
    assert labels is not None
    for k, name in HOSTILE.items():
        assert labels["data"]["name"][k - 1] == name
    # Under the pointer: each stop that sees one of them says it in its tooltip, as text.
    stops = page.model("stops")
    assert stops is not None
    hovered = 0
    for i, sees in enumerate(stops["data"]["sees"]):
        wanted = [n for n in HOSTILE.values() if n in sees.split(", ")]
        if not wanted:
            continue
        x, y = page.page.evaluate(
            """(i) => {
                const doc = Bokeh.documents[0];
                const root = Object.values(Bokeh.index)[0];
                const view = root.owner.find_one(doc.get_model_by_name("map"));
                const data = doc.get_model_by_name("stops").data_source.data;
                const column = (k) => (data instanceof Map ? data.get(k) : data[k]);
                const box = view.canvas_view.el.getBoundingClientRect();
                return [
                    box.left + view.frame.x_scale.compute(column("x")[i]),
                    box.top + view.frame.y_scale.compute(column("y")[i]),
                ];
            }""",
            i,
        )
        page.page.mouse.move(x, y)
        page.page.wait_for_function(
            f"(name) => ({TOOLTIP_TEXT})().includes(name)", arg=wanted[0], timeout=5_000
        )
        text = page.page.evaluate(TOOLTIP_TEXT)
        for name in wanted:
            assert name in text, text
        hovered += 1
    assert hovered >= 1
    # Nothing became markup: no element the names spell, no script run.
    assert _deep_count(page, "img") == 0
    assert _deep_count(page, "b") == 0
    assert page.dialogs == []
    assert page.errors == []


def _deep_count(page: Opened, selector: str) -> int:
    """How many elements match ``selector`` in the page and every shadow root in it."""
    count: int = page.page.evaluate(
        """(selector) => {
            let n = 0;
            const walk = (root) => {
                n += root.querySelectorAll(selector).length;
                for (const el of root.querySelectorAll("*")) if (el.shadowRoot) walk(el.shadowRoot);
            };
            walk(document);
            return n;
        }""",
        selector,
    )
    return count


@pytest.mark.parametrize("which", PAGES)
def test_a_screenshot_shows_a_map(
    which: str, request: pytest.FixtureRequest, opened: Any, tmp_path: Path
) -> None:
    page = opened(_page_of(request, which))
    shot = tmp_path / f"map-{which}.png"
    page.page.screenshot(path=str(shot), full_page=True)
    print(f"screenshot of the {which} page: {shot}")
    data = shot.read_bytes()
    assert data.startswith(b"\x89PNG\r\n\x1a\n")
    assert len(data) > 50_000
    with Image.open(io.BytesIO(data)) as image:
        pixels = np.asarray(image.convert("RGB")).reshape(-1, 3)
    # A map, not a blank or one-colour page: many colours, and no one colour everywhere.
    colours, counts = np.unique(pixels, axis=0, return_counts=True)
    assert len(colours) > 1000
    assert counts.max() < 0.6 * len(pixels)
