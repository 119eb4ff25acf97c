"""Mission items as they travel (MISSION_ITEM_INT), and the outcome of checking a read-back.

These describe what goes over the wire whoever sends it: the vehicle link uploads them and
compares the vehicle's read-back (:mod:`urpt_gcs.vehicle.readback` for a mission,
:func:`urpt_gcs.flight.geofence.compare_fence` for a fence), and the geofence is built as them.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from urpt_gcs.flight.mission import Mission

__all__ = ["MISSION_TYPE", "Comparison", "WireItem", "wire_items"]

MISSION_TYPE = mavlink.MAV_MISSION_TYPE_MISSION


@dataclass(frozen=True, slots=True)
class WireItem:
    """One MISSION_ITEM_INT: x and y are degrees * 1e7 for a global frame."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int = MISSION_TYPE

    @property
    def params(self) -> tuple[float, float, float, float]:
        """param1..param4."""
        return (self.param1, self.param2, self.param3, self.param4)


def wire_items(mission: Mission) -> tuple[WireItem, ...]:
    """The items to upload, seq from 0, the first one ``current`` (as MAVSDK requires)."""
    return tuple(
        WireItem(
            seq=seq,
            frame=item.frame,
            command=item.command,
            current=1 if seq == 0 else 0,
            autocontinue=int(item.autocontinue),
            param1=item.params[0],
            param2=item.params[1],
            param3=item.params[2],
            param4=item.params[3],
            x=item.x_int,
            y=item.y_int,
            z=item.z,
        )
        for seq, item in enumerate(mission.upload_items())
    )


@dataclass(frozen=True, slots=True)
class Comparison:
    """The outcome of comparing a read-back with what was sent."""

    mismatches: tuple[str, ...]
    warnings: tuple[str, ...]

    @property
    def equal(self) -> bool:
        """True when nothing that matters differs."""
        return not self.mismatches
