"""Helpers the tests share: an independent line-of-sight checker, the simulated vehicle
fixture, a MAVLink peer and fleet set-ups."""
