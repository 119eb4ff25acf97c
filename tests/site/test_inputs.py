"""Input files and the memory budget: regular files only, bounded reads, refusals up front."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np
import pytest
import rasterio
from rasterio.transform import from_origin

from urpt_gcs.errors import TargetsError
from urpt_gcs.memory import (
    MEMORY_BUDGET_ENV,
    MemoryBudgetError,
    memory_budget_bytes,
    require_memory,
)
from urpt_gcs.site.dem import open_dem
from urpt_gcs.site.inputs import read_capped, require_regular_file
from urpt_gcs.site.reading import read_terrain


def _read(path: Path, cap: int = 1024) -> bytes:
    return read_capped(path, "targets file", "--targets", TargetsError, cap, "make it smaller")


def test_a_regular_file_and_a_link_to_one_are_read(tmp_path: Path) -> None:
    path = tmp_path / "t.kml"
    path.write_bytes(b"abc")
    link = tmp_path / "link.kml"
    link.symlink_to(path)
    assert _read(path) == b"abc"
    assert _read(link) == b"abc"


@pytest.mark.parametrize(
    ("device", "kind"), [("/dev/zero", "character device"), ("/dev/urandom", "character device")]
)
def test_a_link_to_a_device_is_refused_before_reading(
    tmp_path: Path, device: str, kind: str
) -> None:
    if not os.path.exists(device):
        pytest.skip(f"{device} is absent")
    link = tmp_path / "t.kml"
    link.symlink_to(device)
    with pytest.raises(TargetsError, match=f"a link to '{device}', a {kind}") as info:
        _read(link, cap=2**40)
    assert "'" + str(link) + "'" in str(info.value)


def test_a_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "t.kml"
    os.mkfifo(fifo)
    outcome: list[BaseException] = []

    def read() -> None:
        try:
            _read(fifo)
        except TargetsError as exc:
            outcome.append(exc)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout=10.0)
    if reader.is_alive():
        # Unblock the reader so that the test process can end.
        with open(fifo, "wb"):
            pass
        pytest.fail("reading a FIFO blocked")
    assert outcome and "FIFO" in str(outcome[0])


def test_a_file_over_the_cap_names_its_size_and_the_cap(tmp_path: Path) -> None:
    path = tmp_path / "t.kml"
    path.write_bytes(b"x" * 3000)
    with pytest.raises(TargetsError, match=r"is 2\.9 KiB, over the 1\.0 KiB limit: make it"):
        _read(path)


def test_missing_dangling_and_too_long(tmp_path: Path) -> None:
    with pytest.raises(TargetsError, match="does not exist: check the path given to --targets"):
        _read(tmp_path / "absent.kml")
    dangling = tmp_path / "dangling.kml"
    dangling.symlink_to(tmp_path / "absent.kml")
    with pytest.raises(TargetsError, match="a link to a file that does not exist"):
        _read(dangling)
    long = tmp_path / ("x" * 300 + ".kml")
    with pytest.raises(TargetsError, match="a name of 304 characters, too long") as info:
        _read(long)
    assert len(str(info.value)) < 400


def test_a_folder_is_refused(tmp_path: Path) -> None:
    with pytest.raises(TargetsError, match="is a folder: give --targets the file inside it"):
        require_regular_file(tmp_path, "targets file", "--targets", TargetsError)


def test_memory_budget_setting(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(MEMORY_BUDGET_ENV, "0.5")
    assert memory_budget_bytes() == 2**29
    with pytest.raises(MemoryBudgetError, match=r"a table would need 1\.00 GiB, over .* 0\.50 GiB"):
        require_memory(2**30, "a table", "use a smaller one")
    require_memory(2**28, "a table", "use a smaller one")
    monkeypatch.setenv(MEMORY_BUDGET_ENV, "lots")
    with pytest.raises(ValueError, match=MEMORY_BUDGET_ENV):
        memory_budget_bytes()
    monkeypatch.delenv(MEMORY_BUDGET_ENV)
    assert 0 < memory_budget_bytes() <= 4 * 2**30


def test_a_dem_window_over_the_budget_is_refused_before_reading(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    path = tmp_path / "dem.tif"
    profile = {"driver": "GTiff", "height": 400, "width": 400, "count": 1, "dtype": "float32"}
    transform = from_origin(500_000.0, 5_200_000.0, 1.0, 1.0)
    with rasterio.open(path, "w", crs="EPSG:32632", transform=transform, **profile) as dst:
        dst.write(np.full((400, 400), 100.0, dtype=np.float32), 1)
    info = open_dem(path)
    area = (500_000.0, 5_199_600.0, 500_400.0, 5_200_000.0)
    assert read_terrain(info, info.horizontal_crs, area).elevation_m.shape == (400, 400)
    monkeypatch.setenv(MEMORY_BUDGET_ENV, "0.001")
    with pytest.raises(MemoryBudgetError, match=r"DEM '.*dem.tif': the window of 400 x 400"):
        read_terrain(info, info.horizontal_crs, area)
