"""The memory budget: an array over it is refused, with its size, before it is allocated."""

from __future__ import annotations

import os

from urpt_gcs.errors import PlanError, SettingsError

# The environment variable that sets the memory budget, in GiB.
MEMORY_BUDGET_ENV = "URPT_GCS_MEMORY_GIB"
_DEFAULT_BUDGET_BYTES = 4 * 2**30
# Without a setting, the budget is the smaller of 4 GiB and this share of physical memory.
_DEFAULT_BUDGET_SHARE = 0.5


class MemoryBudgetError(PlanError):
    """An array the inputs call for would not fit the memory budget."""


def _gib(nbytes: float) -> str:
    gib = nbytes / 2**30
    if gib < 10.0:  # enough digits that an estimate just over the budget reads as over it
        return f"{gib:.2f} GiB"
    return f"{gib:.1f} GiB" if gib < 1e6 else f"{gib:.1e} GiB"


def memory_budget_bytes() -> int:
    """How much memory one plan's big arrays may take.

    ``URPT_GCS_MEMORY_GIB`` in the environment sets it; otherwise it is the smaller of 4 GiB
    and half the physical memory.

    Raises
    ------
    SettingsError
        If ``URPT_GCS_MEMORY_GIB`` is not a positive number.
    """
    text = os.environ.get(MEMORY_BUDGET_ENV)
    if text is not None:
        try:
            gib = float(text)
        except ValueError:
            gib = float("nan")
        if not gib > 0.0 or gib == float("inf"):
            raise SettingsError(
                f"{MEMORY_BUDGET_ENV}={text!r} is not a positive number of GiB: "
                "set it to e.g. 4, or unset it"
            )
        return int(gib * 2**30)
    try:
        physical = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return _DEFAULT_BUDGET_BYTES
    return int(min(_DEFAULT_BUDGET_BYTES, _DEFAULT_BUDGET_SHARE * physical))


def require_memory(nbytes: float, what: str, fix: str) -> None:
    """Refuse, before allocating, an array (or set of arrays) over the memory budget.

    Parameters
    ----------
    nbytes
        The estimated size in bytes.
    what
        What would be allocated, for the message: ``"a DEM window of 40000 x 40000 cells"``.
    fix
        What the operator can change: ``"lower --altitude/--clearance or narrow the camera"``.

    Raises
    ------
    MemoryBudgetError
        One line naming ``what``, the estimate and the budget in GiB, and ``fix``.
    """
    budget = memory_budget_bytes()
    if nbytes > budget:
        raise MemoryBudgetError(
            f"{what} would need {_gib(nbytes)}, over the memory budget of "
            f"{_gib(budget)} ({MEMORY_BUDGET_ENV}): {fix}"
        )


__all__ = ["MEMORY_BUDGET_ENV", "MemoryBudgetError", "memory_budget_bytes", "require_memory"]
