"""A peer CETSP solver's command line and output: the protocol, read and checked.

The peer is a command template (``--peer``) whose placeholders are filled per instance:

- ``{instance}``: the instance file's absolute path (required);
- ``{name}``: the instance's name (its file name without ``.txt``);
- ``{time_s}``: the seconds it has (the time limit ours gets);
- ``{seed}``: the seed (the one ours gets).

Its output protocol: when it finishes, stdout holds a line ``TOUR x1 y1 x2 y2 ...``, the
tour's turn points in visiting order (the tour closes from the last back to the first).
Where it prints several, the last counts. A line ``LENGTH L`` is the length the peer
claims; it is shown beside the length, never used: the length is always recomputed from the
points, and the tour is checked to touch every disc (a leg passes within the disc's radius
of its centre, within :data:`TOUCH_TOL`) and, where the instance has a depot, to pass
through it. Numbers should be printed with all their digits (Python's ``repr``).
"""

from __future__ import annotations

import re
import shlex
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from urpt_gcs.errors import SettingsError
from urpt_gcs.problem.regions import RegionSet

__all__ = [
    "PLACEHOLDERS",
    "TOUCH_TOL",
    "PeerCommand",
    "PeerTour",
    "closed_length",
    "first_missed",
    "read_peer_output",
]

PLACEHOLDERS = ("instance", "name", "time_s", "seed")
# A disc counts as touched when a leg passes within r + TOUCH_TOL * (1 + the largest
# coordinate magnitude of the instance) of its centre: room for the last printed digit.
TOUCH_TOL = 1e-7
_FIELD = re.compile(r"\{([^{}]*)\}")
# Discs checked against every leg at once, to bound the arrays' size.
_DISC_BLOCK = 256


@dataclass(frozen=True, slots=True)
class PeerCommand:
    """A peer's command line, split into words, each with placeholders still to fill."""

    words: tuple[str, ...]

    @classmethod
    def parse(cls, text: str) -> PeerCommand:
        """The command of ``--peer``, checked: it splits like a shell line, names only the
        placeholders of :data:`PLACEHOLDERS`, holds ``{instance}``, and its program can be
        started.

        Raises
        ------
        SettingsError
            Naming what is wrong with the command and the fix.
        """
        try:
            words = tuple(shlex.split(text))
        except ValueError as exc:
            raise SettingsError(
                f"--peer {text!r}: cannot be split ({exc}); check the quotes"
            ) from None
        if not words:
            raise SettingsError("--peer is empty: give a command, e.g. 'peer.py {instance}'")
        fields = {field for word in words for field in _FIELD.findall(word)}
        unknown = sorted(fields - set(PLACEHOLDERS))
        if unknown:
            known = ", ".join(f"{{{p}}}" for p in PLACEHOLDERS)
            raise SettingsError(
                f"--peer: unknown placeholder {{{unknown[0]}}}; the placeholders are {known}"
            )
        if "instance" not in fields:
            raise SettingsError(
                f"--peer {text!r} has no {{instance}}: the peer must be given the instance file"
            )
        program = words[0]
        if not _FIELD.search(program):
            found = shutil.which(program)
            if found is None:
                why = "is not executable" if Path(program).exists() else "is not found"
                raise SettingsError(
                    f"--peer: cannot start {program!r}: it {why}; give the path of a program "
                    "(e.g. 'python3 peer.py {instance}')"
                )
        return cls(words)

    def argv(self, instance: Path, time_s: float, seed: int) -> list[str]:
        """The command line for one instance."""
        values = {
            "instance": str(instance.resolve()),
            "name": instance.stem,
            "time_s": f"{time_s:g}",
            "seed": str(seed),
        }
        return [_FIELD.sub(lambda m: values[m.group(1)], word) for word in self.words]


@dataclass(frozen=True, slots=True)
class PeerTour:
    """What a peer printed: its turn points (``(m, 2)``) and the length it claims."""

    points: NDArray[np.float64]
    claimed_length: float | None


def read_peer_output(stdout: str) -> PeerTour | str:
    """The tour of a peer's stdout, or why there is none usable (a sentence)."""
    tour_line = None
    claimed: float | None = None
    for line in stdout.splitlines():
        words = line.split()
        if not words:
            continue
        if words[0] == "TOUR":
            tour_line = words[1:]
        elif words[0] == "LENGTH" and len(words) == 2:
            try:
                claimed = float(words[1])
            except ValueError:
                claimed = None
    if tour_line is None:
        return "printed no TOUR line"
    try:
        values = np.array([float(v) for v in tour_line], dtype=np.float64)
    except ValueError:
        return "its TOUR line holds something that is not a number"
    if values.size == 0 or values.size % 2:
        return f"its TOUR line holds {values.size} numbers, not x y pairs"
    if not np.all(np.isfinite(values)):
        return "its TOUR line holds a number that is not finite"
    return PeerTour(values.reshape(-1, 2), claimed)


def closed_length(points: NDArray[np.float64]) -> float:
    """The length of the closed tour through ``points`` in order."""
    legs = np.roll(points, -1, axis=0) - points
    return float(np.hypot(legs[:, 0], legs[:, 1]).sum())


def first_missed(points: NDArray[np.float64], regions: RegionSet) -> str | None:
    """The first disc (or the depot) the closed tour through ``points`` does not touch,
    described in a few words; None when it touches all."""
    discs = regions.discs
    if discs is None:
        raise SettingsError(f"{regions.name}: a CETSP instance holds discs, not polygons")
    scale = 1.0 + float(np.max(np.abs(discs[:, :2])))
    if regions.depot_xy is not None:
        scale = max(scale, 1.0 + max(abs(v) for v in regions.depot_xy))
    tol = TOUCH_TOL * scale
    starts = points
    legs = np.roll(points, -1, axis=0) - points
    lengths2 = np.einsum("ij,ij->i", legs, legs)
    safe2 = np.where(lengths2 > 0.0, lengths2, 1.0)

    def distances(centres: NDArray[np.float64]) -> NDArray[np.float64]:
        # Each centre's distance to its nearest leg (a leg of length 0 is its point).
        rel = centres[:, None, :] - starts[None, :, :]
        t = np.clip(np.einsum("kmj,mj->km", rel, legs) / safe2, 0.0, 1.0)
        near = rel - t[:, :, None] * legs[None, :, :]
        return np.asarray(np.sqrt(np.einsum("kmj,kmj->km", near, near)).min(axis=1))

    for lo in range(0, len(discs), _DISC_BLOCK):
        block = discs[lo : lo + _DISC_BLOCK]
        gaps = distances(block[:, :2]) - block[:, 2]
        missed = np.flatnonzero(gaps > tol)
        if missed.size:
            i = int(missed[0])
            x, y, r = (float(v) for v in block[i])
            return (
                f"misses disc {lo + i + 1} of {len(discs)} (centre {x:g}, {y:g}, radius "
                f"{r:g}) by {float(gaps[i]):.3g}"
            )
    if regions.depot_xy is not None:
        depot = np.array([regions.depot_xy], dtype=np.float64)
        away = float(distances(depot)[0])
        if away > tol:
            x, y = regions.depot_xy
            return f"does not pass through the depot ({x:g}, {y:g}): {away:.3g} away"
    return None
