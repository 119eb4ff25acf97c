"""numba's cache goes to the user's cache folder, keyed so that every checkout shares it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from urpt_gcs import cache

# What the child prints: where numba caches and which locator a urpt_gcs kernel got.
PROBE = """
import urpt_gcs.visibility.segments as segments
import numba
kernel = segments._corner
print(numba.config.CACHE_DIR)
print(type(kernel._cache._impl.locator).__name__)
print(kernel._cache._cache_path)
print(segments.__file__)
"""


def _probe(env: dict[str, str], cwd: Path) -> list[str]:
    child = subprocess.run(
        [sys.executable, "-c", PROBE], env=env, cwd=cwd, capture_output=True, text=True
    )
    assert child.returncode == 0, child.stderr
    assert child.stderr == ""
    return child.stdout.splitlines()


@pytest.fixture
def fresh_env(tmp_path: Path) -> dict[str, str]:
    """The environment of a user who has set nothing numba-related, with an empty home."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    env["HOME"] = str(tmp_path / "home")
    return env


def test_kernels_cache_in_the_users_cache_folder(fresh_env: dict[str, str], tmp_path: Path) -> None:
    folder = tmp_path / "cache" / "urpt-gcs" / "numba"
    cache_dir, locator, path, _ = _probe(fresh_env, tmp_path)
    assert cache_dir == str(folder)
    assert locator == "KernelCacheLocator"
    assert Path(path).parent == folder
    assert Path(path).name.startswith("visibility.segments-")


def test_the_cache_key_is_the_source_not_the_checkouts_path(
    fresh_env: dict[str, str], tmp_path: Path
) -> None:
    package = Path(cache.__file__).parent
    clone = tmp_path / "elsewhere"
    # A copy of the package at another path, as a second clone would have it.
    shutil.copytree(package, clone / "urpt_gcs", ignore=shutil.ignore_patterns("__pycache__"))
    here = _probe(fresh_env, tmp_path)
    there = _probe({**fresh_env, "PYTHONPATH": str(clone)}, tmp_path)
    assert Path(there[3]).is_relative_to(clone), "the copy was not the one imported"
    assert here[2] == there[2]


def test_a_change_to_another_module_compiles_the_kernel_again(
    fresh_env: dict[str, str], tmp_path: Path
) -> None:
    """A kernel compiles in the kernels it calls from other modules: a cache keyed by its own
    module's source alone would run the old code of a changed callee."""
    package = Path(cache.__file__).parent
    clone = tmp_path / "changed"
    shutil.copytree(package, clone / "urpt_gcs", ignore=shutil.ignore_patterns("__pycache__"))
    callee = clone / "urpt_gcs" / "solvers" / "refine.py"
    callee.write_text(callee.read_text() + "\n# changed\n")
    here = _probe(fresh_env, tmp_path)
    there = _probe({**fresh_env, "PYTHONPATH": str(clone)}, tmp_path)
    assert Path(there[3]).is_relative_to(clone), "the copy was not the one imported"
    assert here[2] != there[2]


def test_a_users_numba_cache_dir_is_kept(fresh_env: dict[str, str], tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    cache_dir, _, path, _ = _probe({**fresh_env, "NUMBA_CACHE_DIR": str(mine)}, tmp_path)
    assert cache_dir == str(mine)
    assert Path(path).parent == mine


def test_an_unwritable_cache_folder_falls_back_to_a_temporary_one(
    fresh_env: dict[str, str], tmp_path: Path
) -> None:
    blocker = tmp_path / "cache"
    blocker.write_text("a file where the cache folder would be\n")
    cache_dir, locator, *_ = _probe(fresh_env, tmp_path)
    assert Path(cache_dir).name.startswith("urpt-gcs-numba-")
    assert locator == "KernelCacheLocator"
    assert not Path(cache_dir).exists(), "the temporary cache folder was left behind"


def test_configure_keeps_an_existing_setting(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert cache.configure_numba_cache() == tmp_path
    assert os.environ["NUMBA_CACHE_DIR"] == str(tmp_path)
