"""The shared array helpers against numpy's own answers."""

from __future__ import annotations

import numpy as np
import pytest

from urpt_gcs.arrays import unique_ints


@pytest.mark.parametrize("size", [0, 1, 2, 7, 1000, 200_000])
def test_unique_ints_is_numpys_unique(size: int) -> None:
    rng = np.random.default_rng(size)
    values = rng.integers(-(10**12), 10**12, size) // rng.integers(1, 10**11, size).clip(1)

    got = unique_ints(values)

    assert got.dtype == np.int64
    assert np.array_equal(got, np.unique(values))


def test_unique_ints_flattens_like_numpy() -> None:
    values = np.array([[3, 1], [3, 2]])

    assert unique_ints(values).tolist() == [1, 2, 3]
