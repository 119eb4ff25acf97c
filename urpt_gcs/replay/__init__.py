"""Replay: fly a plan on real ArduCopter or PX4 SITL, or on the simulated copter, and judge its
photos."""

__all__: list[str] = []
