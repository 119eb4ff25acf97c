"""Many plans at once, here or on a Dask cluster."""
