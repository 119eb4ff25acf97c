"""Benchmarks: the solvers on published instance sets, measured and compared.

One module per study, each a library call the ``urpt-gcs bench`` command group wraps:

- :mod:`urpt_gcs.bench.gtsplib`: GTSPLIB instances against best-known values, GLNS's
  published figures and the OR-Tools baseline at equal time.
- :mod:`urpt_gcs.bench.paper`: the paper's simulation study (540 instances on random TIN
  terrains) with the analogues of its Tables I-III.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import astuple, fields
from typing import Any


def rows_csv(row_type: type[Any], rows: Sequence[Any]) -> str:
    """Dataclass rows as CSV text: a header of the field names, absent values left empty."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([f.name for f in fields(row_type)])
    for row in rows:
        writer.writerow(["" if value is None else value for value in astuple(row)])
    return buffer.getvalue()
