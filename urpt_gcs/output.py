"""Writing outputs all-or-nothing: every file is rendered first, then moved into place."""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path

from urpt_gcs.errors import OutputError


def write_all(out_dir: Path, files: Mapping[str, str | bytes]) -> list[Path]:
    """Write ``files`` (name -> content) into ``out_dir`` so that either all appear or none.

    Contents are written to temporary files in ``out_dir`` and renamed into place at the end;
    on any failure the temporaries are removed, and ``out_dir`` too if this call created it.
    """
    created = not out_dir.exists()
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(
            f"output folder '{out_dir}' cannot be created ({exc.strerror}): choose another --out"
        ) from exc
    if not out_dir.is_dir():
        raise OutputError(f"output '{out_dir}' is not a folder: choose another --out")
    temps: list[tuple[Path, Path]] = []
    # mkstemp creates 0600 files; outputs are ordinary files, readable as the umask allows.
    umask = os.umask(0)
    os.umask(umask)
    try:
        for name, content in files.items():
            fd, tmp_name = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=out_dir)
            temps.append((Path(tmp_name), out_dir / name))
            data = content.encode("utf-8") if isinstance(content, str) else content
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
            os.chmod(tmp_name, 0o666 & ~umask)
        for tmp, final in temps:
            os.replace(tmp, final)
    except OSError as exc:
        for tmp, _ in temps:
            with contextlib.suppress(OSError):
                tmp.unlink()
        if created:
            with contextlib.suppress(OSError):
                out_dir.rmdir()
        raise OutputError(
            f"output folder '{out_dir}' is not writable ({exc.strerror}): choose another --out"
        ) from exc
    return [final for _, final in temps]
