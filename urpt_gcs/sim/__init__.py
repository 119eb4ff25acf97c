"""A simulated ArduCopter speaking MAVLink, and the replay of a mission against the terrain.

The vehicle is a pure model (:mod:`~urpt_gcs.sim.model`, :mod:`~urpt_gcs.sim.store`,
:mod:`~urpt_gcs.sim.transfer`) behind a MAVLink server loop (:mod:`~urpt_gcs.sim.server`);
:mod:`~urpt_gcs.replay.fly` flies a mission on it through the same link code as a real drone
and checks the photos and the track against the DEM.
"""

from __future__ import annotations

from urpt_gcs.sim.events import Photo
from urpt_gcs.sim.server import SitlServer
from urpt_gcs.sim.settings import VehicleSettings, parse_home

__all__ = ["Photo", "SitlServer", "VehicleSettings", "parse_home"]
