"""numba cache locator for urpt-gcs's kernels; numba imports it (see :mod:`urpt_gcs.cache`)."""

from __future__ import annotations

import hashlib
from pathlib import Path
from types import FunctionType
from typing import Any

from numba.core.caching import UserProvidedCacheLocator


class KernelCacheLocator(UserProvidedCacheLocator):
    """Cache a kernel of urpt_gcs under ``NUMBA_CACHE_DIR``, keyed by its source's content.

    numba's own locator names the sub-folder after the source's absolute path, so every clone
    compiles again; here the name is the module's and a hash of its source, so identical
    sources share compiled code and different versions sit side by side.
    """

    @classmethod
    def get_suitable_cache_subpath(cls, py_file: str) -> str:
        path = Path(py_file)
        digest = hashlib.sha256(path.read_bytes()).hexdigest()[:16]
        return f"{path.parent.name}.{path.stem}-{digest}"

    @classmethod
    def from_function(cls, py_func: FunctionType, py_file: str) -> Any:
        module = getattr(py_func, "__module__", None) or ""
        if module != "urpt_gcs" and not module.startswith("urpt_gcs."):
            return None
        return super().from_function(py_func, py_file)  # type: ignore[no-untyped-call]
