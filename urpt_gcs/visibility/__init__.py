"""What the camera sees: the exact segment test, visibility regions, outer stars and cover sets."""

__all__: list[str] = []
