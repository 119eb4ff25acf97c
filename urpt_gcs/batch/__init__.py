"""Many plans at once, here or on a Dask cluster."""

from __future__ import annotations

__all__: list[str] = []
