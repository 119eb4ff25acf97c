"""Options the commands share, and those built from the settings table.

:func:`setting_options` turns :data:`urpt_gcs.pipeline.options.PLAN_OPTIONS` (or the fleet's)
into click options, so ``urpt-gcs plan`` takes every setting the library and a jobs file know,
with the same default and help. :func:`out_option` is the ``--out`` of every command.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import click

from urpt_gcs.errors import SettingsError
from urpt_gcs.pipeline.options import Option

__all__ = ["SettingChoice", "out_option", "setting_options"]

F = TypeVar("F", bound=Callable[..., Any])

# The click type of each kind (choice and count are built per option).
_TYPES: dict[str, Any] = {
    "number": float,
    "integer": int,
    "text": str,
    "latlon": str,
}
# A choice's metavar in --help: the help text lists the values.
_CHOICE_METAVAR = "TEXT"


class Finite(click.FloatRange):
    """A number of a command's own (seconds, a rate), finite and within the range: click's
    range lets ``nan`` through, which then fails late under another name."""

    name = "number"

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number.", param, ctx)
        return number


POSITIVE = Finite(min=0.0, min_open=True)
NON_NEGATIVE = Finite(min=0.0)


class SettingChoice(click.Choice[str]):
    """A :class:`click.Choice` whose refusal is the library's: ``refuse`` raises the
    :class:`SettingsError` the settings raise for that value (one line, exit 1), so a bad
    ``--solver`` reads as it always has."""

    def __init__(self, choices: Sequence[str], refuse: Callable[[str], object]) -> None:
        super().__init__(choices)
        self.refuse = refuse

    def get_metavar(self, param: click.Parameter, *args: Any, **kwargs: Any) -> str:
        return _CHOICE_METAVAR

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if isinstance(value, str) and value not in self.choices:
            self.refuse(value)
            raise SettingsError(f"{value!r} is not one of {', '.join(map(str, self.choices))}")
        return super().convert(value, param, ctx)


def setting_options(
    options: Sequence[Option],
    refuse: Callable[[Option, str], object],
    after: Mapping[str, Callable[[Any], Any]] | None = None,
) -> Callable[[F], F]:
    """A decorator adding one click option per entry of the settings table, in its order.

    Parameters
    ----------
    options
        From :mod:`urpt_gcs.pipeline.options`.
    refuse
        Called with a choice's option and a value not among its choices: raises the
        library's error for it.
    after
        Options of the command's own placed after the setting of this key (in ``--help``).

    Returns
    -------
    callable
        The decorator; each option's parameter is its key with ``_`` for ``-``.
    """

    def decorate(command: F) -> F:
        for o in reversed(options):
            if after is not None and o.key in after:
                command = after[o.key](command)
            command = _click_option(o, refuse)(command)
        return command

    return decorate


def _click_option(o: Option, refuse: Callable[[Option, str], object]) -> Callable[[F], F]:
    help_text = o.help.format(default=o.default)
    if o.kind == "flag":
        return click.option(o.flag, is_flag=True, help=help_text)
    kind: Any
    if o.kind == "choice":
        kind = SettingChoice(o.choices, lambda value: refuse(o, value))
    elif o.kind == "path":
        kind = click.Path(path_type=Path)
    elif o.kind == "count":
        kind = click.IntRange(min=1)
    elif o.auto:
        kind = str  # a number, or the word auto
    else:
        kind = _TYPES[o.kind]
    default = None if o.unset else o.default
    return click.option(
        o.flag,
        type=kind,
        default=default,
        show_default=o.show_default and default is not None,
        help=help_text,
    )


def out_option(
    help_text: str,
    default: str | None = None,
    required: bool = False,
    path: bool = True,
) -> Callable[[F], F]:
    """``--out``: the folder a command writes.

    Parameters
    ----------
    help_text
        What goes there.
    default
        The folder when not given (shown in ``--help``); None: none.
    required
        The command needs it.
    path
        Pass it as a :class:`pathlib.Path` (else as the text given).
    """
    kind: Any = click.Path(path_type=Path) if path else None
    return click.option(
        "--out",
        "out",
        required=required,
        type=kind,
        default=default,
        show_default=default is not None,
        help=help_text,
    )
