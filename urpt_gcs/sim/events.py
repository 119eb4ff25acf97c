"""What the simulated vehicle has to tell the ground station, queued for the server to send."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = [
    "Current",
    "Event",
    "Photo",
    "PhotoTaken",
    "Reached",
    "Text",
]


@dataclass(frozen=True, slots=True)
class Photo:
    """A photo taken by DO_DIGICAM_CONTROL: where and when (simulated seconds)."""

    index: int
    time_s: float
    lat_e7: int
    lon_e7: int
    alt_amsl_m: float
    alt_rel_m: float
    # The vehicle's heading when the photo was taken, degrees clockwise from north.
    heading_deg: float = 0.0


@dataclass(frozen=True, slots=True)
class Text:
    """A STATUSTEXT."""

    severity: int
    text: str


@dataclass(frozen=True, slots=True)
class Current:
    """The mission item now flown changed (MISSION_CURRENT)."""

    seq: int


@dataclass(frozen=True, slots=True)
class Reached:
    """A navigation item was completed (MISSION_ITEM_REACHED)."""

    seq: int


@dataclass(frozen=True, slots=True)
class PhotoTaken:
    """A photo was taken (CAMERA_FEEDBACK)."""

    photo: Photo


Event = Text | Current | Reached | PhotoTaken
