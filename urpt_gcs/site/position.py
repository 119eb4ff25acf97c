"""A position typed by the operator: ``LAT,LON`` or ``LAT,LON,ALT``."""

from __future__ import annotations

from urpt_gcs.errors import SettingsError

__all__ = ["parse_latlon"]

# The example each form's error gives.
_EXAMPLES = {2: "47.3977,8.5456", 3: "47.3977,8.5456,488"}


def parse_latlon(text: str, setting: str = "home", with_alt: bool = False) -> tuple[float, ...]:
    """The numbers of ``LAT,LON`` (degrees), or of ``LAT,LON,ALT`` (ALT in metres).

    Only the form is checked here; the ranges are the caller's (a plan's home, a simulated
    vehicle's).

    Parameters
    ----------
    text
        As typed: numbers separated by commas.
    setting
        The setting it is, named by the error (a flag on the command line, a key in a file).
    with_alt
        Three numbers, the third an altitude.

    Returns
    -------
    tuple of float
        Two numbers, or three ``with_alt``.

    Raises
    ------
    SettingsError
        Not that many numbers.
    """
    count = 3 if with_alt else 2
    form = "LAT,LON,ALT" if with_alt else "LAT,LON"
    try:
        numbers = tuple(float(part) for part in text.split(","))
    except ValueError:
        numbers = ()
    if len(numbers) != count:
        name = "{" + setting + "}"  # filled with the setting's name where it is shown
        raise SettingsError.about(
            f"{name} {{text!r}} is not {form}: give it as e.g. {name} {_EXAMPLES[count]}",
            text=text,
        )
    return numbers
