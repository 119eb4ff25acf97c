"""Targets: the points to photograph, read from KML/KMZ, GeoJSON or CSV."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True, slots=True)
class Target:
    """A named point on the ground, WGS84 degrees."""

    name: str
    lat_deg: float
    lon_deg: float


@dataclass(frozen=True, slots=True)
class TargetSet:
    """The targets of one file and the take-off point it names, if any."""

    targets: tuple[Target, ...]
    home: Target | None
    source: str


def read_targets(path: Path) -> TargetSet:
    raise NotImplementedError
