"""The CETSP instances whose best known length is a proven optimum, from the benchmark's
table beside the checkout (none where it is absent)."""

from __future__ import annotations

import csv
from pathlib import Path

__all__ = ["proven_optima"]


def proven_optima(folder: Path, most_discs: int) -> list[tuple[str, float]]:
    """(name, optimum) of the proven instances of at most ``most_discs`` discs."""
    table = folder / "best_known.csv"
    if not table.is_file():
        return []
    with table.open(encoding="utf-8", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["proven_optimal"] == "yes"]
    return [
        (r["name"], float(r["best_known_length"])) for r in rows if int(r["n_discs"]) <= most_discs
    ]
