"""The shape of the package: module size, no import cycle of two, a declared public API.

Which layer may import which is import-linter's to check (``[tool.importlinter]`` in
pyproject.toml, run by ``make test``); these are the rules it has no contract for.
"""

from __future__ import annotations

import ast
from pathlib import Path

import grimp

import urpt_gcs

PACKAGE = Path(urpt_gcs.__file__).parent
# Past this a module holds more than one concern: split it by concern.
MAX_MODULE_LINES = 700


def _modules() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def _name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def test_no_module_is_over_the_line_limit() -> None:
    too_long = {
        _name(path): count
        for path in _modules()
        if (count := len(path.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert not too_long, f"modules over {MAX_MODULE_LINES} lines: {too_long}"


def test_no_two_modules_import_each_other() -> None:
    # Every import counts: at module level, inside a function, under TYPE_CHECKING.
    graph = grimp.build_graph("urpt_gcs", exclude_type_checking_imports=False, cache_dir=None)
    pairs = sorted(
        (a, b)
        for a in graph.modules
        for b in graph.find_modules_directly_imported_by(a)
        if a < b and graph.direct_import_exists(importer=b, imported=a)
    )
    assert not pairs, "modules that import each other:\n" + "\n".join(
        f"  {a} <-> {b}" for a, b in pairs
    )


def _defines_all(path: Path) -> bool:
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        targets = (
            node.targets
            if isinstance(node, ast.Assign)
            else [node.target]
            if isinstance(node, ast.AnnAssign)
            else []
        )
        if any(isinstance(t, ast.Name) and t.id == "__all__" for t in targets):
            return True
    return False


def test_every_module_declares_its_public_names() -> None:
    missing = [_name(path) for path in _modules() if not _defines_all(path)]
    assert not missing, "modules without __all__:\n" + "\n".join(f"  {m}" for m in missing)
