"""The README's Python examples run as written, on the demo site.

Each ```python block is executed in a folder of its own holding the demo's ``site.tif`` and
``targets.kml``, the names the README uses, so a renamed field or argument fails here before a
reader copies it.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from conftest import DEMO, REPO

BLOCK = re.compile(r"^```python\n(.*?)^```", re.DOTALL | re.MULTILINE)
BLOCKS = BLOCK.findall((REPO / "README.md").read_text(encoding="utf-8"))


def test_the_readme_has_python_examples() -> None:
    assert BLOCKS, "README.md has no ```python block; update this test if that is intended"


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_python_block_runs(
    index: int,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    for name in ("site.tif", "targets.kml"):
        (tmp_path / name).symlink_to(DEMO / name)
    monkeypatch.chdir(tmp_path)
    code = compile(BLOCKS[index], f"README.md python block {index + 1}", "exec")
    exec(code, {"__name__": "__readme__"})
    assert capsys.readouterr().out.strip(), "the example printed nothing"
