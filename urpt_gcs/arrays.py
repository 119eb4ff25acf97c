"""The array types every stage shares (numpy arrays of one dtype, any shape)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int64]


def unique_ints(values: npt.ArrayLike) -> IntArray:
    """The distinct values of an integer array, ascending (``np.unique``'s answer), found by
    sorting: numpy's own ``np.unique`` hashes first, which on ten million values takes
    some forty times as long."""
    flat = np.sort(np.asarray(values, dtype=np.int64).ravel())
    if flat.size == 0:
        return flat
    new = np.empty(flat.size, dtype=bool)
    new[0] = True
    np.not_equal(flat[1:], flat[:-1], out=new[1:])
    kept: IntArray = flat[new]
    return kept


__all__ = ["BoolArray", "FloatArray", "IntArray", "unique_ints"]
