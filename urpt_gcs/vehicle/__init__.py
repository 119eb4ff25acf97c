"""The drone link: MAVSDK connections, verified uploads with read-back, and fleet uploads."""

__all__: list[str] = []
