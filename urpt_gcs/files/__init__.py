"""What a plan writes: mission files (``formats``), the map, the summary, the KML/GeoJSON
products, the fleet folder, and writing them as one set
(:func:`~urpt_gcs.files.write.write_outputs`)."""

__all__: list[str] = []
