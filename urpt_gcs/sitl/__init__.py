"""A simulated ArduCopter speaking MAVLink, and the replay of a mission against the terrain.

The vehicle is a pure model (:mod:`~urpt_gcs.sitl.model`, :mod:`~urpt_gcs.sitl.store`,
:mod:`~urpt_gcs.sitl.transfer`) behind a MAVLink server loop (:mod:`~urpt_gcs.sitl.server`);
:mod:`~urpt_gcs.sitl.replay` flies a mission on it through the same link code as a real drone
and checks the photos and the track against the DEM.
"""

from __future__ import annotations

from urpt_gcs.sitl.events import Photo
from urpt_gcs.sitl.server import SitlServer
from urpt_gcs.sitl.settings import VehicleSettings, parse_home

__all__ = ["Photo", "SitlServer", "VehicleSettings", "parse_home"]
