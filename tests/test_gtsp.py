"""Tests for urpt_gcs.gtsp: the dense parts of an instance."""

from __future__ import annotations

import numpy as np
import pytest

from urpt_gcs.gtsp import euclidean_matrix, require_instance_memory
from urpt_gcs.inputs import MEMORY_BUDGET_ENV, MemoryBudgetError


@pytest.mark.parametrize("n", [0, 1, 7, 3000])
def test_euclidean_matrix_in_blocks_equals_the_dense_formula(n: int) -> None:
    xy = np.random.default_rng(n).uniform(-1e4, 1e4, (n, 2))
    diff = xy[:, None, :] - xy[None, :, :]
    dense = np.sqrt(np.einsum("ijk,ijk->ij", diff, diff))
    assert np.array_equal(euclidean_matrix(xy), dense)


def test_instance_memory_is_refused_naming_viewpoints_and_fix(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv(MEMORY_BUDGET_ENV, "1")
    require_instance_memory(10_000, 300)
    with pytest.raises(MemoryBudgetError, match=r"20000 viewpoints .* 3\.00 GiB, .* --samples"):
        require_instance_memory(20_000, 300)
