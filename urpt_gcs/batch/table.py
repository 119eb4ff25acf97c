"""Rows of results as CSV: ``batch.csv`` and the benches' ``results.csv``."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import astuple, fields
from typing import Any

__all__ = ["rows_csv"]


def rows_csv(row_type: type[Any], rows: Sequence[Any]) -> str:
    """Dataclass rows as CSV text: a header of the field names, absent values left empty.

    Parameters
    ----------
    row_type
        The rows' dataclass: its fields are the columns.
    rows
        Instances of ``row_type``.

    Returns
    -------
    str
        The CSV text, ``\\n`` line ends.
    """
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([f.name for f in fields(row_type)])
    for row in rows:
        writer.writerow(["" if value is None else value for value in astuple(row)])
    return buffer.getvalue()
