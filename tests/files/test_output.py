"""--out holds one plan's files: swapped in as a set, undone on any failure or interrupt."""

from __future__ import annotations

import json
import os
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner
from conftest import DEMO

from urpt_gcs.cli import main
from urpt_gcs.errors import OutputError
from urpt_gcs.files.output import check_file, check_folder, commit
from urpt_gcs.files.products import check_extra, check_out, write_products
from urpt_gcs.pipeline.planner import plan
from urpt_gcs.pipeline.result import Plan
from urpt_gcs.pipeline.settings import PlanSettings
from urpt_gcs.solvers import SolveSettings

SITE = DEMO / "site.tif"
TARGETS = DEMO / "targets.kml"
FAST = SolveSettings(time_limit_s=0.5)
# Short enough that the demo flight is split into sorties, long enough for every stop.
SORTIE_ENDURANCE_MIN = 4.0

Tree = dict[str, bytes | str]


@pytest.fixture(scope="module")
def one_sortie() -> Plan:
    return plan(SITE, TARGETS, PlanSettings(solve=FAST))


@pytest.fixture(scope="module")
def sorties() -> Plan:
    result = plan(SITE, TARGETS, PlanSettings(solve=FAST, endurance_min=SORTIE_ENDURANCE_MIN))
    assert len(result.missions) > 1
    return result


def tree(root: Path) -> Tree:
    """Every entry under ``root``: a file's bytes, a link's target, ``<dir>`` for a folder."""
    found: Tree = {}
    for path in sorted(root.rglob("*")):
        key = str(path.relative_to(root))
        if path.is_symlink():
            found[key] = f"-> {os.readlink(path)}"
        elif path.is_dir():
            found[key] = "<dir>"
        else:
            found[key] = path.read_bytes()
    return found


def temporaries(root: Path) -> list[str]:
    return [str(p) for p in root.rglob(".urpt-*")]


def _cli(args: list[str]) -> tuple[int, str]:
    result = CliRunner().invoke(main, args)
    return result.exit_code, result.stderr


def _plan_args(out: Path, *extra: str) -> list[str]:
    return ["plan", "--dem", str(SITE), "--targets", str(TARGETS), "--out", str(out), *extra]


def test_sorties_after_one_sortie_leave_no_mission_plan(tmp_path: Path) -> None:
    out = tmp_path / "out"
    code, stderr = _cli(_plan_args(out, "--time-limit", "0.5", "--no-map"))
    assert code == 0, stderr
    assert (out / "mission.plan").is_file()
    endurance = str(SORTIE_ENDURANCE_MIN)
    code, stderr = _cli(
        _plan_args(out, "--time-limit", "0.5", "--no-map", "--endurance", endurance)
    )
    assert code == 0, stderr
    names = sorted(p.name for p in out.iterdir())
    assert "mission.plan" not in names and "mission.waypoints" not in names
    assert {"mission_1.plan", "mission_2.plan", "summary.json"} <= set(names)
    listed = json.loads((out / "summary.json").read_text())["files"]
    assert sorted(Path(f).name for f in listed) == names
    # The stale single-sortie mission is gone, so it cannot be uploaded by mistake.
    code, stderr = _cli(["upload", str(out / "mission.plan"), "--connect", "udpin://127.0.0.1:1"])
    assert code == 1 and "mission.plan" in stderr


def test_no_map_after_a_map_run_removes_map_png_and_map_html(tmp_path: Path) -> None:
    out = tmp_path / "out"
    code, stderr = _cli(_plan_args(out, "--time-limit", "0.5"))
    assert code == 0, stderr
    assert (out / "map.png").is_file() and (out / "map.html").is_file()
    code, stderr = _cli(_plan_args(out, "--time-limit", "0.5", "--no-map"))
    assert code == 0, stderr
    assert not (out / "map.png").exists() and not (out / "map.html").exists()
    assert temporaries(tmp_path) == []


def test_foreign_files_survive_and_only_plan_outputs_are_replaced(
    tmp_path: Path, one_sortie: Plan, sorties: Plan
) -> None:
    out = tmp_path / "out"
    write_products(one_sortie, out, with_map=False)
    (out / "notes.txt").write_text("the operator's\n")
    (out / "mission-edited.plan").write_text("{}\n")
    (out / "photos").mkdir()
    (out / "photos" / "mission.plan").write_text("not ours: inside a subfolder\n")
    foreign = {k: v for k, v in tree(out).items() if k.startswith(("notes", "mission-", "photos"))}
    (out / "flown.json").write_text("{}\n")
    write_products(sorties, out, with_map=False)
    after = tree(out)
    assert {k: after[k] for k in foreign} == foreign
    assert "mission.plan" not in after
    # The earlier plan's flight report is not this plan's.
    assert "flown.json" not in after
    assert temporaries(tmp_path) == []


def _failing_on(
    call: int, raise_: Callable[[], BaseException | None], counter: list[int]
) -> Callable[..., None]:
    real = os.replace

    def replace(src: object, dst: object, *args: object, **kwargs: object) -> None:
        counter[0] += 1
        if counter[0] == call:
            exc = raise_()
            if exc is not None:
                raise exc
        real(src, dst, *args, **kwargs)  # type: ignore[arg-type]

    return replace


def _interruptions() -> Iterator[tuple[str, Callable[[], BaseException | None]]]:
    yield "OSError", lambda: OSError(28, "No space left on device")
    yield "KeyboardInterrupt", KeyboardInterrupt

    def sigterm() -> None:
        os.kill(os.getpid(), signal.SIGTERM)

    yield "SIGTERM", sigterm


RAISED: dict[str, type[BaseException]] = {
    "OSError": OutputError,
    "KeyboardInterrupt": KeyboardInterrupt,
    "SIGTERM": SystemExit,
}


@pytest.mark.parametrize("kind", list(RAISED))
def test_a_failure_at_any_step_of_the_swap_leaves_the_previous_set(
    kind: str, tmp_path: Path, one_sortie: Plan, sorties: Plan, monkeypatch: pytest.MonkeyPatch
) -> None:
    make = dict(_interruptions())[kind]

    def previous(root: Path) -> tuple[Path, Path]:
        write_products(one_sortie, root / "out", with_map=False)
        (root / "out" / "notes.txt").write_text("the operator's\n")
        (root / "gtsp").mkdir()
        (root / "gtsp" / "demo.gtsp").write_text("an earlier export\n")
        return root / "out", root / "gtsp" / "demo.gtsp"

    def second(out: Path, gtsp: Path) -> None:
        export = check_file(gtsp, "--export-gtsp")
        write_products(sorties, out, with_map=False, also=[(export, {gtsp.name: "new\n"})])

    counter = [0]
    earlier = previous(tmp_path / "count")
    with monkeypatch.context() as m:
        m.setattr(os, "replace", _failing_on(0, lambda: None, counter))
        second(*earlier)
    calls = counter[0]
    # --out: the earlier set's 5 files aside, the new set in; the export: aside, in.
    assert calls == 5 + (2 * len(sorties.missions) + 3) + 2
    root = tmp_path / "run"
    out, gtsp = previous(root)
    before = tree(root)
    for call in range(1, calls + 1):
        counter = [0]
        with monkeypatch.context() as m:
            m.setattr(os, "replace", _failing_on(call, make, counter))
            with pytest.raises(RAISED[kind]) as info:
                second(out, gtsp)
        if kind == "SIGTERM":
            assert info.value.args == (128 + signal.SIGTERM,)
        if kind == "OSError":
            message = str(info.value)
            assert "\n" not in message and "left as it was" in message, message
        assert tree(root) == before, f"failure at rename {call} of {calls}"
        assert temporaries(root) == []
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_DFL
    second(out, gtsp)
    assert gtsp.read_text() == "new\n" and not (out / "mission.plan").exists()


def test_ctrl_c_during_the_undo_waits_for_it(
    tmp_path: Path, one_sortie: Plan, sorties: Plan, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out"
    write_products(one_sortie, out, with_map=False)
    before = tree(tmp_path)
    real = os.replace
    calls = [0]

    def replace(src: str | Path, dst: str | Path) -> None:
        calls[0] += 1
        if calls[0] == 4:
            raise OSError(28, "No space left on device")
        if calls[0] == 5:  # the first move back
            os.kill(os.getpid(), signal.SIGINT)
        real(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    # Ctrl-C as at a terminal: a suite run as a shell's background job inherits SIGINT
    # ignored, and the writer leaves an ignored signal ignored.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            write_products(sorties, out, with_map=False)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert tree(tmp_path) == before
    assert temporaries(tmp_path) == []


def test_an_interrupt_while_staging_leaves_nothing(
    tmp_path: Path, one_sortie: Plan, monkeypatch: pytest.MonkeyPatch
) -> None:
    real = os.open
    written = [0]

    def open_(path: str | Path, flags: int, mode: int = 0o777, **kwargs: object) -> int:
        if ".urpt-new-" in str(path):
            written[0] += 1
            if written[0] == 3:
                raise KeyboardInterrupt
        return real(path, flags, mode)

    fresh = tmp_path / "a" / "b" / "out"
    monkeypatch.setattr(os, "open", open_)
    with pytest.raises(KeyboardInterrupt):
        write_products(one_sortie, fresh, with_map=False)
    assert tree(tmp_path) == {}, "the parents the commit made are removed too"


def test_a_new_folder_appears_whole_with_the_usual_modes(
    tmp_path: Path, one_sortie: Plan, monkeypatch: pytest.MonkeyPatch
) -> None:
    old = os.umask(0o027)
    try:
        write_products(one_sortie, tmp_path / "out", with_map=False)
    finally:
        os.umask(old)
    out = tmp_path / "out"
    assert out.stat().st_mode & 0o777 == 0o750
    assert {p.stat().st_mode & 0o777 for p in out.iterdir()} == {0o640}
    counter = [0]
    monkeypatch.setattr(os, "replace", _failing_on(1, lambda: OSError(5, "EIO"), counter))
    with pytest.raises(OutputError, match="left as it was"):
        write_products(one_sortie, tmp_path / "new" / "out", with_map=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_out_through_a_link_and_as_the_working_folder(
    tmp_path: Path, one_sortie: Plan, sorties: Plan, monkeypatch: pytest.MonkeyPatch
) -> None:
    real = tmp_path / "real"
    real.mkdir()
    link = tmp_path / "link"
    link.symlink_to(real, target_is_directory=True)
    write_products(one_sortie, link, with_map=False)
    assert link.is_symlink() and (real / "mission.plan").is_file()
    monkeypatch.chdir(real)
    (real / "notes.txt").write_text("kept\n")
    write_products(sorties, Path("."), with_map=False)
    assert link.is_symlink() and not (real / "mission.plan").exists()
    assert (real / "mission_1.plan").is_file() and (real / "notes.txt").read_text() == "kept\n"
    assert temporaries(tmp_path) == []


@pytest.mark.parametrize(
    ("make", "words"),
    [
        (lambda d: (d / "out").symlink_to(d / "nowhere"), ["is a link to", "remove the link"]),
        (lambda d: (d / "out" / "map.png").mkdir(parents=True), ["holds a folder 'map.png'"]),
    ],
)
def test_out_refused_before_planning(
    tmp_path: Path, make: Callable[[Path], object], words: list[str]
) -> None:
    make(tmp_path)
    before = tree(tmp_path)
    with pytest.raises(OutputError) as info:
        check_out(tmp_path / "out")
    for word in words:
        assert word in str(info.value), info.value
    assert tree(tmp_path) == before


def test_an_export_inside_out_is_one_commit_and_cannot_take_a_product_name(
    tmp_path: Path, one_sortie: Plan
) -> None:
    out = check_out(tmp_path / "out")
    with pytest.raises(OutputError, match="plan's own outputs"):
        check_extra(tmp_path / "out" / "summary.json", "--export-gtsp", out)
    export = check_extra(tmp_path / "out" / "demo.gtsp", "--export-gtsp", out)
    write_products(one_sortie, out, with_map=False, also=[(export, {"demo.gtsp": "x\n"})])
    assert (tmp_path / "out" / "demo.gtsp").read_text() == "x\n"
    assert (tmp_path / "out" / "mission.plan").is_file()


def test_write_all_replaces_only_what_it_writes(tmp_path: Path) -> None:
    folder = check_folder(tmp_path)
    (tmp_path / "other.csv").write_text("kept\n")
    commit([(folder, {"results.csv": "a\n"})])
    commit([(folder, {"results.csv": "b\n"})])
    assert tree(tmp_path) == {"other.csv": b"kept\n", "results.csv": b"b\n"}
