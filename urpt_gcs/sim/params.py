"""The simulated vehicle's parameters: the few ArduCopter ones its flight model reads.

Values and units are ArduCopter's defaults (centimetres and cm/s where ArduPilot uses them).
Values travel as ArduPilot sends them: the number cast to a float ("cast" encoding); in PX4
mode integers travel bit for bit in the float field ("bytewise"), as PX4 does.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as mavlink

__all__ = [
    "AUTO_OPTION_ALLOW_ARMING",
    "AUTO_OPTION_TAKEOFF_WITHOUT_THROTTLE",
    "DEFAULTS",
    "INT8",
    "INT16",
    "INT32",
    "REAL32",
    "ParamValue",
    "Params",
]

INT32 = mavlink.MAV_PARAM_TYPE_INT32
INT16 = mavlink.MAV_PARAM_TYPE_INT16
INT8 = mavlink.MAV_PARAM_TYPE_INT8
REAL32 = mavlink.MAV_PARAM_TYPE_REAL32

# AUTO_OPTIONS bits (ArduCopter): 0 allow arming in AUTO, 1 allow take-off without raising
# the throttle.
AUTO_OPTION_ALLOW_ARMING = 1
AUTO_OPTION_TAKEOFF_WITHOUT_THROTTLE = 2

DEFAULTS: dict[str, tuple[float, int]] = {
    "AUTO_OPTIONS": (0, INT32),
    "WPNAV_SPEED": (1000.0, REAL32),
    "WPNAV_SPEED_UP": (250.0, REAL32),
    "WPNAV_SPEED_DN": (150.0, REAL32),
    "WPNAV_ACCEL": (250.0, REAL32),
    "WPNAV_ACCEL_Z": (100.0, REAL32),
    "WPNAV_JERK": (1.0, REAL32),
    "WPNAV_RADIUS": (200.0, REAL32),
    "LAND_SPEED": (50, INT16),
    "LAND_ALT_LOW": (1000, INT16),
    "RTL_ALT": (1500, INT32),
    "RTL_ALT_FINAL": (0, INT32),
    "RTL_SPEED": (0, INT16),
    "RTL_LOIT_TIME": (5000, INT32),
    "DISARM_DELAY": (10, INT8),
    "SYSID_THISMAV": (1, INT16),
    "FRAME_CLASS": (1, INT8),
}


@dataclass(frozen=True, slots=True)
class ParamValue:
    """One parameter as PARAM_VALUE carries it."""

    name: str
    value: float
    param_type: int
    index: int
    count: int


class Params:
    """The parameter table, in a fixed order (PARAM_VALUE indices)."""

    def __init__(self, px4: bool = False) -> None:
        self._values = {name: float(value) for name, (value, _) in DEFAULTS.items()}
        self._types = {name: kind for name, (_, kind) in DEFAULTS.items()}
        self._names = list(DEFAULTS)
        self.px4 = px4

    def __getitem__(self, name: str) -> float:
        return self._values[name]

    def __len__(self) -> int:
        return len(self._names)

    def get(self, name: str) -> ParamValue | None:
        """A parameter by name, or None."""
        if name not in self._values:
            return None
        return self._value(name)

    def at(self, index: int) -> ParamValue | None:
        """A parameter by PARAM_VALUE index, or None."""
        if not 0 <= index < len(self._names):
            return None
        return self._value(self._names[index])

    def all(self) -> list[ParamValue]:
        """Every parameter, in index order (PARAM_REQUEST_LIST)."""
        return [self._value(name) for name in self._names]

    def set(self, name: str, wire_value: float) -> ParamValue | None:
        """Apply a PARAM_SET; unknown names are ignored, as ArduPilot does."""
        if name not in self._values:
            return None
        kind = self._types[name]
        value = self._decode(wire_value, kind)
        self._values[name] = float(round(value)) if kind != REAL32 else value
        return self._value(name)

    def _value(self, name: str) -> ParamValue:
        kind = self._types[name]
        return ParamValue(
            name,
            self._encode(self._values[name], kind),
            kind,
            self._names.index(name),
            len(self._names),
        )

    def _encode(self, value: float, kind: int) -> float:
        if self.px4 and kind != REAL32:
            packed: float = struct.unpack("<f", struct.pack("<i", int(value)))[0]
            return packed
        return value

    def _decode(self, wire: float, kind: int) -> float:
        if self.px4 and kind != REAL32:
            unpacked: int = struct.unpack("<i", struct.pack("<f", wire))[0]
            return float(unpacked)
        return wire
