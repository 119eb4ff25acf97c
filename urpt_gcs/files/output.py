"""Writing outputs as one set: checked before the work, staged, then swapped in, or nothing.

:func:`check_folder` and :func:`check_file` refuse, before anything is computed, a destination
that cannot be written: a path through a file, a broken link, a name longer than the
filesystem allows, a folder that cannot be written to. They touch nothing but a probe folder
they remove at once. :func:`commit` then writes one set of files into one or more checked
destinations:

1. every file is staged in a hidden folder ``.urpt-new-*``: inside the destination when it
   exists, beside it when it does not (so always on the destination's filesystem);
2. the set is swapped in: a destination that did not exist is the staged folder renamed into
   place; in one that did, the earlier set (every name the destination *owns*, and every name
   written again) is moved aside into ``.urpt-old-*``, then the staged files are moved in;
3. the folders of step 1 and 2, with the earlier set, are removed.

A failure or an interruption (Ctrl-C, SIGTERM) before step 3 moves every file back where it
was, removes the temporaries and any folder the commit created, and is raised again, so the
destination holds the earlier set or the new one, never a mix. During step 2 the signals wait
until the swap can be undone. Files a destination does not own are never moved or removed.
A process killed outright (SIGKILL, power loss) in step 2 can leave ``.urpt-old-*`` holding
the earlier files.
"""

from __future__ import annotations

import contextlib
import os
import re
import secrets
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any

from urpt_gcs.errors import OutputError

__all__ = ["Destination", "check_file", "check_folder", "commit", "refuse_inputs", "write_all"]

NEW_PREFIX = ".urpt-new-"
OLD_PREFIX = ".urpt-old-"
# Room under a destination for a staging folder and the longest file name we write.
_PATH_ROOM = len(NEW_PREFIX) + 8 + 2 + 64

Content = str | bytes


@dataclass(frozen=True, slots=True)
class Destination:
    """A folder that passed :func:`check_folder`: where one set of files is committed.

    Attributes
    ----------
    folder
        The folder, as the operator named it.
    flag
        The option that named it, for messages (``--out``).
    owns
        Names of files an earlier set left here that a new set replaces, whether it writes
        them again or not; None: only the names written again are replaced.
    names
        File names known, when it was checked, to be written here.
    """

    folder: Path
    flag: str = "--out"
    owns: re.Pattern[str] | None = None
    names: tuple[str, ...] = ()

    def owned(self, name: str) -> bool:
        """Whether ``name`` in this folder belongs to the set a commit replaces."""
        return self.owns is not None and self.owns.fullmatch(name) is not None

    def replaced(self) -> list[Path]:
        """The files now here that a commit would replace or remove: every name known to be
        written and every name the folder owns."""
        if not os.path.isdir(self.folder):
            return []
        with os.scandir(self.folder) as entries:
            owned = [e.name for e in entries if self.owned(e.name)]
        names = dict.fromkeys([*self.names, *owned])
        return [self.folder / n for n in names if os.path.lexists(self.folder / n)]


def refuse_inputs(destinations: Sequence[Destination], inputs: Mapping[str, Path | str]) -> None:
    """Refuse, before any work, an output that would replace or remove one of the inputs.

    Files are compared as files (device and inode), not by name, so that a hard link, a link
    to the input's folder, ``..`` or a relative spelling of an input is caught as surely as
    its own name. A link among the outputs that points to an input is not refused: the commit
    replaces the link, and the input is untouched.

    Parameters
    ----------
    destinations
        Every checked destination the work will commit to.
    inputs
        What names each input (``--dem``, ``[[site]] 'quarry', targets``) -> its path.

    Raises
    ------
    OutputError
        One line naming the output, the input it would replace, and the fix.
    """
    # A commit replaces names, never writes through them: what an output endangers is the
    # entry it replaces (not what a link there points to), and an input read through a link
    # is lost with the file the link names or with the link itself.
    known: dict[tuple[int, int], tuple[str, str]] = {}
    for who, path in inputs.items():
        for look in (os.stat, os.lstat):
            try:
                st = look(path)
            except (OSError, ValueError):
                continue  # the input's own check names it
            known.setdefault((st.st_dev, st.st_ino), (who, os.fspath(path)))
    for dest in destinations:
        for out in dest.replaced():
            try:
                st = os.lstat(out)
            except (OSError, ValueError):
                continue
            hit = known.get((st.st_dev, st.st_ino))
            if hit is None:
                continue
            who, path = hit
            if dest.owns is None and dest.names == (out.name,):
                raise OutputError(
                    f"{dest.flag} '{out}' is the file of {who} ('{path}'), which writing it "
                    f"would destroy: choose another {dest.flag}"
                )
            raise OutputError(
                f"{dest.flag} '{dest.folder}' holds {who} ('{path}') as '{out.name}', which "
                f"is replaced by an output of the same name: move the input or choose "
                f"another {dest.flag}"
            )


def check_folder(
    folder: Path,
    flag: str = "--out",
    owns: re.Pattern[str] | None = None,
    names: Sequence[str] = (),
) -> Destination:
    """Refuse a folder that a set of files cannot be committed to, before any work is done.

    Parameters
    ----------
    folder
        The folder; it and its parents may be missing, they are created by the commit.
    flag
        The option that named it, for messages.
    owns
        See :attr:`Destination.owns`.
    names
        File names known now to be written there.

    Returns
    -------
    Destination
        The checked folder.

    Raises
    ------
    OutputError
        One line naming the path, what is wrong and what to do.
    """
    _check(folder, flag, str(folder), owns, names)
    return Destination(folder, flag, owns, tuple(names))


def check_file(path: Path, flag: str) -> Destination:
    """Refuse a single output file that cannot be written, before any work is done.

    Parameters
    ----------
    path
        The file; its folder may be missing, it is created by the commit.
    flag
        The option that named it, for messages.

    Returns
    -------
    Destination
        Its folder, to commit ``{path.name: ...}`` to.

    Raises
    ------
    OutputError
        One line naming the path, what is wrong and what to do.
    """
    if path.name in ("", ".", ".."):
        raise _refused(flag, str(path), "names a folder, not a file")
    _check(path.parent, flag, str(path), None, [path.name])
    return Destination(path.parent, flag, names=(path.name,))


def commit(writes: Sequence[tuple[Destination, Mapping[str, Content]]]) -> list[Path]:
    """Write every ``(destination, {name: content})`` as one set, or change nothing.

    Parameters
    ----------
    writes
        Checked destinations and the files for each (text is written as UTF-8). Several
        entries for the same folder are merged.

    Returns
    -------
    list of Path
        The files written.

    Raises
    ------
    OutputError
        A file could not be written or moved in; every destination is as it was.
    """
    stages = [_Stage(dest, files) for dest, files in _merged(writes)]
    current = stages[0].dest if stages else Destination(Path("."))
    with _interrupts() as guard:
        try:
            for stage in stages:
                current = stage.dest
                stage.prepare(guard)
            with guard.held():
                for stage in stages:
                    current = stage.dest
                    stage.swap(guard)
        except BaseException as exc:
            with guard.held():
                restored = all([stage.undo() for stage in reversed(stages)])
                for stage in reversed(stages):
                    stage.remove_temporaries(keep_earlier=not restored)
            if isinstance(exc, OSError) and not isinstance(exc, OutputError):
                raise _commit_failed(current, exc, stages, restored) from exc
            raise
        with guard.held():
            for stage in reversed(stages):
                stage.remove_temporaries(keep_earlier=False)
    return [stage.dest.folder / name for stage in stages for name in stage.files]


def write_all(out_dir: Path, files: Mapping[str, Content], flag: str = "--out") -> list[Path]:
    """Check ``out_dir`` and commit ``files`` (name -> content) to it: all appear or none.

    Files already in ``out_dir`` under other names are left alone.
    """
    return commit([(check_folder(out_dir, flag, names=list(files)), files)])


def _check(
    folder: Path, flag: str, subject: str, owns: re.Pattern[str] | None, names: Sequence[str]
) -> None:
    if "\0" in os.fspath(folder) or any("\0" in n for n in names):
        raise _refused(flag, subject.replace("\0", "\\0"), "contains a NUL character")
    # Walk the path as given, so that messages name what the operator typed.
    existing, missing = folder, []
    while not os.path.lexists(existing) and existing != existing.parent:
        missing.append(existing.name)
        existing = existing.parent
    if subject == str(existing):
        problem = "is"
    else:
        problem = f"cannot be {'created' if missing else 'written'}: '{existing}' is"
    if not os.path.isdir(existing):
        if os.path.lexists(existing) and not os.path.exists(existing):
            what = f"a link to '{os.readlink(existing)}', which does not exist"
            fix = f"remove the link or choose another {flag}"
        else:
            what, fix = "a file, not a folder", None
        raise _refused(flag, subject, f"{problem} {what}", fix)
    name_max = _pathconf(existing, "PC_NAME_MAX")
    for name in [*missing, *names]:
        size = len(os.fsencode(name))
        if name_max is not None and size > name_max:
            raise _refused(
                flag,
                subject,
                f"has a name of {size} bytes; this filesystem allows {name_max}",
                f"choose a shorter {flag}",
            )
    path_max = _pathconf(existing, "PC_PATH_MAX")
    size = len(os.fsencode(os.path.abspath(folder)))
    if path_max is not None and size + _PATH_ROOM > path_max:
        raise _refused(
            flag,
            subject,
            f"is {size} bytes long; this system allows {path_max} for a path and the files "
            "inside it",
            f"choose a shorter {flag}",
        )
    if not missing:
        for name in names:
            if os.path.isdir(folder / name) and not os.path.islink(folder / name):
                raise _refused(flag, subject, f"cannot be written: '{folder / name}' is a folder")
        if owns is not None:
            with os.scandir(folder) as entries:
                for entry in entries:
                    if owns.fullmatch(entry.name) and entry.is_dir(follow_symlinks=False):
                        raise _refused(
                            flag,
                            subject,
                            f"holds a folder '{entry.name}' where the plan writes a file",
                            f"move it or choose another {flag}",
                        )
    try:
        # Held, so that Ctrl-C cannot fall between making the probe and removing it.
        with _interrupts() as guard, guard.held():
            os.rmdir(tempfile.mkdtemp(prefix=".urpt-probe-", dir=existing))
    except OSError as exc:
        raise _refused(flag, subject, f"{problem} not writable ({exc.strerror or exc})") from exc


def _pathconf(path: Path, name: str) -> int | None:
    try:
        value = os.pathconf(path, name)
    except (OSError, ValueError, AttributeError):
        return None
    return value if value > 0 else None


def _refused(flag: str, subject: str, problem: str, fix: str | None = None) -> OutputError:
    return OutputError(f"{flag} '{subject}' {problem}: {fix or f'choose another {flag}'}")


def _commit_failed(
    dest: Destination, exc: OSError, stages: Sequence[_Stage], restored: bool
) -> OutputError:
    reason = exc.strerror or str(exc)
    if restored:
        return OutputError(
            f"{dest.flag} '{dest.folder}' could not be written ({reason}) and was left as it "
            f"was: free space or choose another {dest.flag}"
        )
    kept = ", ".join(f"'{s.earlier}'" for s in stages if s.earlier is not None)
    return OutputError(
        f"{dest.flag} '{dest.folder}' could not be written ({reason}) and the earlier files "
        f"could not all be put back; they are in {kept}: move them back by hand"
    )


def _merged(
    writes: Sequence[tuple[Destination, Mapping[str, Content]]],
) -> list[tuple[Destination, dict[str, Content]]]:
    """One entry per real folder, the deepest first so a nested one is staged before its parent."""
    merged: dict[str, tuple[Destination, dict[str, Content]]] = {}
    for dest, files in writes:
        for name in files:
            if not name or name in (".", "..") or os.sep in name or "/" in name:
                raise ValueError(f"output name {name!r} is not a plain file name")
        key = os.path.realpath(dest.folder)
        if key not in merged:
            merged[key] = (dest, dict(files))
            continue
        first, named = merged[key]
        if clash := named.keys() & files.keys():
            raise ValueError(f"'{sorted(clash)[0]}' is written twice into '{dest.folder}'")
        named.update(files)
        merged[key] = (first if first.owns is not None else dest, named)
    return [merged[k] for k in sorted(merged, key=lambda k: -len(Path(k).parts))]


@dataclass(slots=True)
class _Stage:
    """One destination's part of a commit, with what it did so it can be undone."""

    dest: Destination
    files: dict[str, Content]
    staging: Path | None = None
    earlier: Path | None = None
    created: list[Path] = field(default_factory=list)
    moves: list[tuple[Path, Path]] = field(default_factory=list)

    @property
    def folder(self) -> Path:
        return Path(os.path.abspath(self.dest.folder))

    def prepare(self, guard: _Interrupts) -> None:
        folder = self.folder
        # Held: a folder made but not yet recorded could not be removed on an interrupt.
        with guard.held():
            if os.path.isdir(folder):
                self.staging = _new_folder(folder, NEW_PREFIX, 0o700)
                self.earlier = _new_folder(folder, OLD_PREFIX, 0o700)
            else:
                missing = []
                parent = folder.parent
                while not os.path.lexists(parent):
                    missing.append(parent)
                    parent = parent.parent
                for path in reversed(missing):
                    os.mkdir(path)
                    self.created.append(path)
                # Renamed into place as the destination itself: a new folder's mode.
                self.staging = _new_folder(folder.parent, NEW_PREFIX, 0o777)
        for name, content in self.files.items():
            data = content.encode("utf-8") if isinstance(content, str) else content
            # O_EXCL in a folder of our own; 0o666 less the umask, as for any new file.
            fd = os.open(self.staging / name, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
            with open(fd, "wb") as fh:
                fh.write(data)

    def swap(self, guard: _Interrupts) -> None:
        assert self.staging is not None
        folder = self.folder
        if self.earlier is None:
            guard.check()
            self._move(self.staging, folder)
            return
        with os.scandir(folder) as entries:
            earlier = [
                e.name
                for e in entries
                if (self.dest.owned(e.name) or e.name in self.files)
                and not e.is_dir(follow_symlinks=False)
            ]
        for name in sorted(earlier):
            guard.check()
            self._move(folder / name, self.earlier / name)
        for name in self.files:
            guard.check()
            self._move(self.staging / name, folder / name)

    def _move(self, source: Path, target: Path) -> None:
        os.replace(source, target)
        self.moves.append((source, target))

    def undo(self) -> bool:
        """Move everything back; False if something could not be."""
        restored = True
        for source, target in reversed(self.moves):
            try:
                os.replace(target, source)
            except OSError:
                restored = False
        self.moves.clear()
        return restored

    def remove_temporaries(self, keep_earlier: bool) -> None:
        for path in (self.staging, None if keep_earlier else self.earlier):
            # After a swap into a new folder the staging path no longer exists.
            if path is not None and os.path.isdir(path) and not os.path.islink(path):
                shutil.rmtree(path, ignore_errors=True)
        if not keep_earlier:
            self.earlier = None
        if not os.path.lexists(self.folder):
            for path in reversed(self.created):
                with contextlib.suppress(OSError):
                    os.rmdir(path)
        self.created.clear()


def _new_folder(parent: Path, prefix: str, mode: int) -> Path:
    for _ in range(100):
        path = parent / f"{prefix}{secrets.token_hex(4)}"
        try:
            os.mkdir(path, mode)
        except FileExistsError:
            continue
        return path
    raise FileExistsError(f"no free temporary name in '{parent}'")


class _Interrupts:
    """SIGINT and SIGTERM during a commit: raised at once, or held while a swap is under way."""

    __slots__ = ("holding", "pending")

    def __init__(self) -> None:
        self.holding = False
        self.pending: int | None = None

    def handle(self, signum: int, frame: FrameType | None) -> None:
        if not self.holding:
            raise _interruption(signum)
        if self.pending is None:
            self.pending = signum

    def check(self) -> None:
        """Raise a signal that arrived while held."""
        if self.pending is not None:
            signum, self.pending = self.pending, None
            raise _interruption(signum)

    @contextlib.contextmanager
    def held(self) -> Iterator[None]:
        was = self.holding
        self.holding = True
        try:
            yield
        finally:
            self.holding = was
        if not was:
            self.check()


def _interruption(signum: int) -> BaseException:
    if signum == signal.SIGINT:
        return KeyboardInterrupt()
    # The shell's status for a process ended by the signal.
    return SystemExit(128 + signum)


@contextlib.contextmanager
def _interrupts() -> Iterator[_Interrupts]:
    guard = _Interrupts()
    previous: dict[signal.Signals, Any] = {}
    # Python runs signal handlers in the main thread only; elsewhere the default stays.
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, signal.SIGTERM):
            handler = signal.getsignal(signum)
            if handler in (signal.SIG_IGN, None):
                continue
            previous[signum] = handler
            signal.signal(signum, guard.handle)
    try:
        yield guard
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
