"""``bench cetsp --peer``: a second CETSP solver beside ours, on the same instances.

For each instance of a folder laid out like ``bench/cetsp``, ours (the solve of
:func:`urpt_gcs.bench.cetsp.instance_job`, one thread, in a spawned process) and the peer (a
command, :class:`urpt_gcs.bench.peer_tour.PeerCommand`, in a session of its own) start
together, each pinned to a CPU of its own, with the same time limit. The peer is killed,
its whole process group, when it runs ``grace_s`` past the limit; whatever it leaves
running when it ends is killed too. With fewer than two CPUs the two run one after the
other. The peer's tour is read by the protocol of :mod:`urpt_gcs.bench.peer_tour`; its
length is recomputed and its tour checked to touch every disc before it is tabulated.
"""

from __future__ import annotations

import contextlib
import csv
import io
import os
import signal
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Literal

from urpt_gcs.bench.cetsp import Published, Row, instance_job, instance_paths, read_instance
from urpt_gcs.bench.cetsp import read_published as read_best_known
from urpt_gcs.bench.peer_tour import PeerCommand, closed_length, first_missed, read_peer_output
from urpt_gcs.errors import SettingsError
from urpt_gcs.files.output import write_all
from urpt_gcs.processes import run_owned
from urpt_gcs.solvers.base import SolveSettings

__all__ = [
    "PEER_COLUMNS",
    "PEER_GRACE_S",
    "PEER_GRACE_SHARE",
    "PeerResult",
    "PeerRow",
    "format_peer_table",
    "peer_results_csv",
    "run_cetsp_peer",
]

# The peer is killed PEER_GRACE_S + PEER_GRACE_SHARE x the time limit after the limit.
PEER_GRACE_S = 2.0
PEER_GRACE_SHARE = 0.1
PEER_COLUMNS = (
    "instance",
    "n_discs",
    "best_known",
    "length",
    "above_pct",
    "lower_bound",
    "time_s",
    "peer_status",
    "peer_length",
    "peer_above_pct",
    "peer_claimed_length",
    "peer_time_s",
    "peer_note",
    "ours_cpus",
    "peer_cpus",
)
# A peer's ends: a valid tour, a tour that misses a disc, or no tour to judge.
PeerStatus = Literal["ok", "invalid", "timed out", "crashed", "no tour"]
# Two lengths within this relative difference are a tie.
_TIE = 1e-9


@dataclass(frozen=True, slots=True)
class PeerResult:
    """The peer's run on one instance; ``length`` is recomputed, and given only when the
    tour is valid (``status == "ok"``); ``note`` says what went wrong otherwise."""

    status: PeerStatus
    length: float | None
    claimed_length: float | None
    time_s: float
    note: str = ""

    def __post_init__(self) -> None:
        if (self.length is not None) != (self.status == "ok"):
            raise ValueError(f"a peer's length is given exactly when it is valid: {self}")


@dataclass(frozen=True, slots=True)
class PeerRow:
    """One instance: our row, the peer's result, and the CPUs each ran on (empty when not
    pinned)."""

    ours: Row
    peer: PeerResult
    ours_cpus: tuple[int, ...]
    peer_cpus: tuple[int, ...]

    @property
    def peer_above_best_pct(self) -> float | None:
        best = self.ours.best_known
        if self.peer.length is None or best is None or best <= 0.0:
            return None
        return 100.0 * (self.peer.length / best - 1.0)

    @property
    def lead(self) -> tuple[str, float] | None:
        """Who is ahead (``ours``, ``peer`` or ``tie``) and by how many percent of the
        shorter tour; None without a valid peer tour."""
        peer = self.peer.length
        if peer is None or peer <= 0.0 or self.ours.length <= 0.0:
            return None
        ours = self.ours.length
        if abs(peer - ours) <= _TIE * max(peer, ours):
            return "tie", 0.0
        if ours < peer:
            return "ours", 100.0 * (peer / ours - 1.0)
        return "peer", 100.0 * (ours / peer - 1.0)


def _pinned_job(
    job: tuple[tuple[Path, Published], SolveSettings, int | None],
) -> tuple[Row, tuple[int, ...]]:
    """Our solve of one instance on CPU ``cpu`` (any, when None), and the CPUs it ran on."""
    task, settings, cpu = job
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    row = instance_job(task, settings)
    return row, tuple(sorted(os.sched_getaffinity(0)))


class _PeerWatch(threading.Thread):
    """Waits for the peer; kills its process group when it runs past ``limit_s``."""

    def __init__(self, process: subprocess.Popen[bytes], limit_s: float) -> None:
        super().__init__(daemon=True)
        self.process = process
        self.limit_s = limit_s
        self.started = time.perf_counter()
        self.elapsed_s = 0.0
        self.timed_out = False

    def run(self) -> None:
        try:
            self.process.wait(timeout=self.limit_s)
        except subprocess.TimeoutExpired:
            self.timed_out = True
            _kill_group(self.process)
            self.process.wait()
        self.elapsed_s = time.perf_counter() - self.started


def _kill_group(process: subprocess.Popen[bytes]) -> None:
    # The peer leads a session of its own: its group holds whatever it started.
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(process.pid, signal.SIGKILL)


def _start_peer(
    argv: list[str], cpu: int | None, limit_s: float, out: IO[bytes], err: IO[bytes]
) -> _PeerWatch:
    # A new process takes the affinity of the thread that starts it: pinning this thread for
    # the start pins the peer before its first instruction, and everything it starts.
    own = os.sched_getaffinity(0)
    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    try:
        process = subprocess.Popen(
            argv, stdin=subprocess.DEVNULL, stdout=out, stderr=err, start_new_session=True
        )
    except OSError as exc:
        raise SettingsError(
            f"--peer: cannot start {argv[0]!r} ({exc.strerror}); give the path of a program"
        ) from None
    finally:
        if cpu is not None:
            os.sched_setaffinity(0, own)
    return _PeerWatch(process, limit_s)


def _judge(
    watch: _PeerWatch, stdout: str, stderr: str, path: Path, time_limit_s: float
) -> PeerResult:
    """The peer's result from how it ended and what it printed."""
    elapsed = watch.elapsed_s
    code = watch.process.returncode
    if watch.timed_out:
        return PeerResult(
            "timed out",
            None,
            None,
            elapsed,
            f"killed {watch.limit_s - time_limit_s:.1f} s past the {time_limit_s:g} s limit",
        )
    if code != 0:
        how = f"killed by signal {-code}" if code < 0 else f"exit code {code}"
        last = next((line.strip() for line in reversed(stderr.splitlines()) if line.strip()), "")
        return PeerResult("crashed", None, None, elapsed, f"{how}: {last[:120]}" if last else how)
    tour = read_peer_output(stdout)
    if isinstance(tour, str):
        return PeerResult("no tour", None, None, elapsed, tour)
    missed = first_missed(tour.points, read_instance(path))
    if missed is not None:
        return PeerResult("invalid", None, tour.claimed_length, elapsed, f"the tour {missed}")
    return PeerResult("ok", closed_length(tour.points), tour.claimed_length, elapsed)


def _run_pair(
    task: tuple[Path, Published],
    settings: SolveSettings,
    command: PeerCommand,
    cpus: tuple[int, int] | None,
    grace_s: float,
) -> PeerRow:
    """Ours and the peer on one instance: started together on ``cpus`` (ours, the peer's),
    or one after the other when ``cpus`` is None."""
    path = task[0]
    argv = command.argv(path, settings.time_limit_s, settings.seed)
    ours_cpu, peer_cpu = cpus if cpus is not None else (None, None)
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        if cpus is None:
            row, ours_ran = run_owned(_pinned_job, [(task, settings, None)], workers=1)[0]
        watch = _start_peer(argv, peer_cpu, settings.time_limit_s + grace_s, out, err)
        watch.start()
        try:
            if cpus is not None:
                row, ours_ran = run_owned(_pinned_job, [(task, settings, ours_cpu)], workers=1)[0]
            watch.join()
        finally:
            _kill_group(watch.process)
            watch.join()
        out.seek(0)
        err.seek(0)
        stdout = out.read().decode("utf-8", errors="replace")
        stderr = err.read().decode("utf-8", errors="replace")
    peer = _judge(watch, stdout, stderr, path, settings.time_limit_s)
    if cpus is None:
        return PeerRow(row, peer, (), ())
    return PeerRow(row, peer, ours_ran, (cpus[1],))


def run_cetsp_peer(
    directory: Path,
    peer: str,
    time_limit_s: float = 60.0,
    only: Sequence[str] | None = None,
    out_dir: Path | None = None,
    progress: Callable[[str], None] | None = None,
    seed: int = 0,
    min_discs: int | None = None,
    max_discs: int | None = None,
    grace_s: float | None = None,
) -> list[PeerRow]:
    """Run ours and the ``peer`` command side by side on every instance of ``directory``
    (those named in ``only``, with ``min_discs`` to ``max_discs`` discs), one instance after
    another; write ``results.csv`` (:data:`PEER_COLUMNS`) to ``out_dir`` as each ends.

    Parameters
    ----------
    peer
        The peer's command line with the placeholders of
        :data:`urpt_gcs.bench.peer_tour.PLACEHOLDERS`.
    time_limit_s
        Seconds each gets per instance.
    grace_s
        Seconds past the limit the peer may run before it is killed [default:
        ``PEER_GRACE_S + PEER_GRACE_SHARE * time_limit_s``].

    Raises
    ------
    SettingsError
        The command has no ``{instance}``, names an unknown placeholder, or cannot be
        started; the folder or the instance selection cannot be used.
    """
    command = PeerCommand.parse(peer)
    if grace_s is None:
        grace_s = PEER_GRACE_S + PEER_GRACE_SHARE * time_limit_s
    if grace_s < 0.0:
        raise SettingsError(f"--peer-grace {grace_s:g} is below 0: give seconds, e.g. 5")
    settings = SolveSettings(time_limit_s=time_limit_s, seed=seed, threads=1)
    say = progress or (lambda _msg: None)
    published = read_best_known(directory)
    paths = instance_paths(directory, only, min_discs, max_discs)
    free = sorted(os.sched_getaffinity(0))
    cpus = (free[0], free[1]) if len(free) >= 2 else None
    if cpus is None:
        say("one CPU is free: ours and the peer run one after the other")
    rows: list[PeerRow] = []
    for path in paths:
        task = (path, published.get(path.stem, Published(None, False)))
        row = _run_pair(task, settings, command, cpus, grace_s)
        rows.append(row)
        peer_text = f"{row.peer.length:.4f}" if row.peer.length is not None else row.peer.status
        say(
            f"[{len(rows)}/{len(paths)}] {path.stem}: {row.ours.n_discs} discs, ours "
            f"{row.ours.length:.4f}, peer {peer_text}"
        )
        if out_dir is not None:
            write_all(out_dir, {"results.csv": peer_results_csv(rows)})
    return rows


def _cell(value: float | None, digits: int) -> str:
    return "" if value is None else f"{value:.{digits}f}"


def peer_results_csv(rows: Sequence[PeerRow]) -> str:
    """``results.csv`` of a run with a peer: one line per instance, :data:`PEER_COLUMNS`."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(PEER_COLUMNS)
    for r in rows:
        w.writerow(
            [
                r.ours.instance,
                r.ours.n_discs,
                _cell(r.ours.best_known, 6),
                f"{r.ours.length:.6f}",
                _cell(r.ours.above_best_pct, 4),
                f"{r.ours.lower_bound:.6f}",
                f"{r.ours.time_s:.2f}",
                r.peer.status,
                _cell(r.peer.length, 6),
                _cell(r.peer_above_best_pct, 4),
                _cell(r.peer.claimed_length, 6),
                f"{r.peer.time_s:.2f}",
                r.peer.note,
                " ".join(map(str, r.ours_cpus)),
                " ".join(map(str, r.peer_cpus)),
            ]
        )
    return buf.getvalue()


def _mean(values: Sequence[float]) -> str:
    return f"{sum(values) / len(values):.3f} %" if values else "-"


def format_peer_table(rows: Sequence[PeerRow]) -> str:
    """A table: per instance the best known, ours (length, % above the best known, our
    lower bound), the peer's (length, % above, whether valid) and who is ahead by how much;
    the means; each peer failure's reason."""

    def num(value: float | None, digits: int = 3) -> str:
        return "-" if value is None else f"{value:.{digits}f}"

    head = (
        f"{'instance':<28} {'discs':>5} {'best known':>11} {'ours':>11} {'above %':>8} "
        f"{'bound':>11} {'peer':>11} {'above %':>8} {'peer tour':<10} {'ahead':<16}"
    )
    lines = [head, "-" * len(head)]
    notes = []
    for r in rows:
        lead = r.lead
        ahead = "-" if lead is None else lead[0]
        if lead is not None and lead[0] != "tie":
            ahead = f"{lead[0]} {lead[1]:.3f} %"
        valid = "valid" if r.peer.status == "ok" else r.peer.status
        lines.append(
            f"{r.ours.instance:<28} {r.ours.n_discs:>5} {num(r.ours.best_known):>11} "
            f"{r.ours.length:>11.3f} {num(r.ours.above_best_pct):>8} "
            f"{r.ours.lower_bound:>11.3f} {num(r.peer.length):>11} "
            f"{num(r.peer_above_best_pct):>8} {valid:<10} {ahead:<16}"
        )
        if r.peer.note:
            notes.append(f"peer on {r.ours.instance}: {r.peer.note}")
    ours = [r.ours.above_best_pct for r in rows if r.ours.above_best_pct is not None]
    peer = [r.peer_above_best_pct for r in rows if r.peer_above_best_pct is not None]
    both = [r for r in rows if r.peer_above_best_pct is not None]
    lines.append(
        f"mean above best known: ours {_mean(ours)} over {len(ours)}; peer {_mean(peer)} over "
        f"{len(peer)} valid tours of {len(rows)}"
    )
    if len(both) < len(ours) and both:
        lines.append(
            f"on the {len(both)} with a valid peer tour: ours "
            f"{_mean([r.ours.above_best_pct for r in both if r.ours.above_best_pct is not None])}"
            f", peer {_mean(peer)}"
        )
    wins = {side: sum(1 for r in rows if r.lead and r.lead[0] == side) for side in ("ours", "peer")}
    lines.append(f"ahead: ours on {wins['ours']}, the peer on {wins['peer']}")
    pinned = [r for r in rows if r.ours_cpus and r.peer_cpus]
    if pinned:
        first = pinned[0]
        lines.append(
            f"side by side: ours on CPU {','.join(map(str, first.ours_cpus))}, the peer on "
            f"CPU {','.join(map(str, first.peer_cpus))}"
        )
    else:
        lines.append("one after the other (one CPU free)")
    return "\n".join(line.rstrip() for line in lines + notes)
