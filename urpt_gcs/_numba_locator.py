"""numba cache locator for urpt-gcs's kernels; numba imports it (see :mod:`urpt_gcs.cache`)."""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from types import FunctionType
from typing import Any

from numba.core.caching import UserProvidedCacheLocator


class KernelCacheLocator(UserProvidedCacheLocator):
    """Cache a kernel of urpt_gcs under ``NUMBA_CACHE_DIR``, keyed by the package's sources.

    numba's own locator names the sub-folder after the source's absolute path, so every clone
    compiles again; here the name is the module's and a hash of every source of the package,
    so identical sources share compiled code and different versions sit side by side. The
    hash is the whole package's, not the module's: a kernel compiles in the kernels it calls
    from other modules, and must compile again when they change.
    """

    @classmethod
    def get_suitable_cache_subpath(cls, py_file: str) -> str:
        path = Path(py_file)
        return f"{path.parent.name}.{path.stem}-{_package_digest()}"

    @classmethod
    def from_function(cls, py_func: FunctionType, py_file: str) -> Any:
        module = getattr(py_func, "__module__", None) or ""
        if module != "urpt_gcs" and not module.startswith("urpt_gcs."):
            return None
        return super().from_function(py_func, py_file)  # type: ignore[no-untyped-call]


@functools.cache
def _package_digest() -> str:
    """A hash of every Python source of the package, by path and content."""
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for source in sorted(root.rglob("*.py")):
        digest.update(source.relative_to(root).as_posix().encode())
        digest.update(b"\0")
        digest.update(source.read_bytes())
    return digest.hexdigest()[:16]


__all__ = ["KernelCacheLocator"]
