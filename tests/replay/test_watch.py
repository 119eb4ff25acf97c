"""What the replay keeps of the positions a vehicle sends, and what it says when a flight
does not end."""

from __future__ import annotations

from typing import Any

from urpt_gcs.flight.mission import GeoPoint, MissionSettings, build_mission
from urpt_gcs.replay.ardupilot import unreachable_hint
from urpt_gcs.replay.fly import _Watch


def _position(time_ms: int, lat: int, lon: int) -> dict[str, Any]:
    return {"time_boot_ms": time_ms, "lat": lat, "lon": lon, "relative_alt": 0}


def test_positions_before_the_vehicle_has_one_are_not_tracked() -> None:
    # ArduCopter sends GLOBAL_POSITION_INT at 0, 0 until its EKF has an origin; in a track
    # they would put a fix on the equator at Greenwich (infinite in the site's UTM zone).
    watch = _Watch(link=None, system_id=1)  # type: ignore[arg-type]
    watch._position(_position(3_679, 0, 0))
    assert watch.track == []
    watch._position(_position(20_000, -39_881_099, -790_736_624))
    assert [(p.time_s, p.lat_deg, p.lon_deg) for p in watch.track] == [
        (20.0, -3.9881099, -79.0736624)
    ]


def test_a_flight_that_does_not_end_names_the_waypoints_below_home() -> None:
    home = GeoPoint(-3.99, -79.07, 2200.0)
    settings = MissionSettings(firmware="ardupilot")
    above = build_mission(home, [(-3.991, -79.071)], 40.0, settings)
    assert unreachable_hint(above) == ""
    valley = build_mission(
        home, [(-3.991, -79.071), (-3.992, -79.072)], 40.0, settings, heights_rel_m=[-38.8, 20.0]
    )
    hint = unreachable_hint(valley)
    assert "1 of its waypoints are below home (down to -38.8 m)" in hint
    assert "ArduPilot's SITL" in hint
