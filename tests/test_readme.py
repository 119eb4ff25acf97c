"""The README's Python examples run as written, on the demo site.

Each ```python block is executed in a folder of its own holding the demo's ``site.tif`` and
``targets.kml``, the names the README uses, so a renamed field or argument fails here before a
reader copies it. A block that starts with ``# needs a vehicle`` is compiled, and every
``urpt_gcs.NAME`` it uses must be in the public API, but it is not run.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from conftest import DEMO, REPO

BLOCK = re.compile(r"^```python\n(.*?)^```", re.DOTALL | re.MULTILINE)
BLOCKS = BLOCK.findall((REPO / "README.md").read_text(encoding="utf-8"))
NEEDS_VEHICLE = "# needs a vehicle"


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
    if BLOCKS[index].startswith(NEEDS_VEHICLE):
        import urpt_gcs

        used = {
            node.attr
            for node in ast.walk(ast.parse(BLOCKS[index]))
            if isinstance(node, ast.Attribute)
            and isinstance(node.value, ast.Name)
            and node.value.id == "urpt_gcs"
        }
        assert used and used <= set(urpt_gcs.__all__), used - set(urpt_gcs.__all__)
        print("compiled")
        return
    exec(code, {"__name__": "__readme__"})
    assert capsys.readouterr().out.strip(), "the example printed nothing"
