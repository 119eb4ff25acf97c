"""map.html's source, read without a browser: everything it needs is inside it, and names
from the inputs are in it only as data.

tests/files/test_map_page.py opens the same kind of page in Chromium.
"""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import pytest
from support.map_pages import HOSTILE, write_framed

from urpt_gcs.files.mappage import PAGE_TITLE
from urpt_gcs.pipeline.result import Plan

# Where a page would fetch something as it loads: a script, an image, a style sheet, a frame.
FETCHES = re.compile(
    r"""<(?:script|img|link|iframe|source|embed)\b[^>]*\b(?:src|href)\s*=\s*["']?(?:https?:)?//""",
    re.IGNORECASE,
)
# The plot itself, as Bokeh embeds it: the document's JSON.
DOCUMENT = re.compile(r'<script type="application/json"[^>]*>(.*?)</script>', re.DOTALL)


@pytest.fixture(scope="module")
def framed(tmp_path_factory: pytest.TempPathFactory) -> tuple[Plan, Path]:
    return write_framed(tmp_path_factory.mktemp("framed"))


def test_the_page_needs_nothing_from_the_network(framed: tuple[Plan, Path]) -> None:
    _, out = framed
    page = (out / "map.html").read_text(encoding="utf-8")
    assert FETCHES.search(page) is None
    assert re.search(r"<script\b[^>]*\bsrc\s*=", page) is None, "Bokeh's JavaScript is inline"
    assert re.search(r"""\burl\s*\(\s*["']?https?:""", page) is None  # CSS
    documents = DOCUMENT.findall(page)
    assert len(documents) == 1
    plot = documents[0]
    # The plot refers to nothing outside the page: no tiles, no image, no script.
    assert "http://" not in plot and "https://" not in plot
    assert "data:image/png;base64," in plot
    assert f"<title>{PAGE_TITLE}</title>" in page


def test_names_are_data_never_markup(framed: tuple[Plan, Path]) -> None:
    result, out = framed
    page = (out / "map.html").read_text(encoding="utf-8")
    for name in HOSTILE.values():
        if set(name) & set("<>&"):
            assert name not in page, f"{name!r} is in the page as written: markup"
    # In the document's JSON, HTML-escaped: each name comes back whole.
    plot = json.loads(html.unescape(DOCUMENT.findall(page)[0]))
    text = json.dumps(plot, ensure_ascii=False)
    for name in (t.name for t in result.targets.targets):
        assert json.dumps(name, ensure_ascii=False) in text
