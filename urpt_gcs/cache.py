"""Where numba keeps the compiled kernels: the user's cache folder, shared by every checkout.

numba caches a ``cache=True`` kernel beside its source (``__pycache__``) unless told
otherwise, so each clone or fresh install compiled the kernels again (about a minute). This
module runs when ``urpt_gcs`` is first imported, before anything imports numba (numba reads
its settings once, on import), and points the cache at ``<user cache>/urpt-gcs/numba``:

- ``NUMBA_CACHE_DIR``, unless the user has set it;
- ``NUMBA_CACHE_LOCATOR_CLASSES``, unless set, so that urpt-gcs's own kernels are keyed by
  their source's content rather than by the checkout's path (numba's own key), and two clones
  of one version share one compile. Other packages' kernels are located as numba always does.

A cache folder that cannot be created or written to (a read-only or missing home) is replaced
by a temporary one removed at exit: the kernels compile on every run, and nothing fails.
"""

from __future__ import annotations

import atexit
import os
import shutil
import sys
import tempfile
from pathlib import Path
from typing import Any

import platformdirs

APP_NAME = "urpt-gcs"
# numba's default order after ours, so that other packages' kernels are cached as before.
_LOCATORS = (
    "urpt_gcs._numba_locator.KernelCacheLocator",
    "UserProvidedCacheLocator",
    "InTreeCacheLocator",
    "UserWideCacheLocator",
    "IPythonCacheLocator",
    "ZipCacheLocator",
)


def default_cache_dir() -> Path:
    """The folder urpt-gcs caches compiled kernels in when ``NUMBA_CACHE_DIR`` is not set."""
    return Path(platformdirs.user_cache_dir(APP_NAME, appauthor=False)) / "numba"


def _writable(folder: Path) -> bool:
    # The same test numba makes before it caches anything there.
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
    except OSError:
        return False
    return True


def _temporary_dir() -> Path:
    folder = Path(tempfile.mkdtemp(prefix="urpt-gcs-numba-"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    return folder


def configure_numba_cache() -> Path:
    """Point numba's cache at the user's cache folder, unless the user chose one.

    Returns
    -------
    Path
        The folder numba will cache in: ``NUMBA_CACHE_DIR`` as the user set it, else
        :func:`default_cache_dir`, else (not writable) a temporary folder removed at exit.
    """
    chosen = os.environ.get("NUMBA_CACHE_DIR")
    if chosen is not None:
        return Path(chosen)
    folder = default_cache_dir()
    if not _writable(folder):
        folder = _temporary_dir()
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    os.environ.setdefault("NUMBA_CACHE_LOCATOR_CLASSES", ",".join(_LOCATORS))
    config: Any = sys.modules.get("numba.core.config")
    if config is not None:
        # numba came first (a user's own import): it has read its settings already.
        config.CACHE_DIR = os.environ["NUMBA_CACHE_DIR"]
        config.CACHE_LOCATOR_CLASSES = os.environ["NUMBA_CACHE_LOCATOR_CLASSES"]
    return folder


__all__ = ["APP_NAME", "configure_numba_cache", "default_cache_dir"]
