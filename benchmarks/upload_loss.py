"""Benchmark: upload the demo mission to the simulated ArduCopter over a lossy link.

    .venv/bin/python benchmarks/upload_loss.py [--runs N] [--loss 0 0.1 0.2] [--retries R]
        [--seed S [--same-seed]] [--items K] [--upload-timeout S] [--verbose]

Each run starts the in-process simulator (``urpt_gcs.sim``) on a free loopback UDP port with
``--loss P`` each way and seed = run number, uploads the demo mission (28 items) through
:func:`urpt_gcs.vehicle.link.upload` with the default settings, and checks what the simulator then
holds. Prints, per loss rate, the share of runs verified, the attempts used, the median and
maximum wall time of the upload call (connecting included) and of the upload and read-back
alone (verified runs, from the report), and any run that reported success
while the vehicle held something else (which must never happen).

The simulator's loss generator is seeded, but which packet meets which draw depends on
timing (heartbeats and telemetry share it), so figures vary a little from run to run.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

from urpt_gcs.errors import LinkError
from urpt_gcs.files.formats import read_plan
from urpt_gcs.flight.mission import Mission
from urpt_gcs.flight.wire import WireItem, wire_items
from urpt_gcs.replay.fly import free_udp_port
from urpt_gcs.sim import SitlServer, VehicleSettings
from urpt_gcs.vehicle import mavsdk_link
from urpt_gcs.vehicle.link import UploadSettings, upload
from urpt_gcs.vehicle.readback import compare

REPO = Path(__file__).resolve().parents[1]
DEMO_PLAN = REPO / "missions" / "demo" / "out" / "mission.plan"


@dataclass(frozen=True, slots=True)
class Run:
    verified: bool
    false_success: bool
    attempts: int
    wall_s: float
    upload_s: float
    error: str


def held(server: SitlServer) -> list[WireItem]:
    """The simulator's mission, as a download would return it."""
    return [
        WireItem(seq, i.frame, i.command, 0, i.autocontinue, *i.params, i.x, i.y, i.z)
        for seq, i in enumerate(server.vehicle.store.items())
    ]


def one_run(mission: Mission, loss: float, seed: int, retries: int) -> Run:
    port = free_udp_port()
    vehicle = replace(VehicleSettings(loss=loss, seed=seed), home=mission.home)
    with SitlServer(vehicle, f"udpout://127.0.0.1:{port}") as server:
        started = time.monotonic()
        try:
            report = upload(mission, f"udpin://127.0.0.1:{port}", retries=retries)
        except LinkError as exc:
            wall = time.monotonic() - started
            return Run(False, False, retries + 1, wall, float("nan"), str(exc))
        wall = time.monotonic() - started
        holds = compare(wire_items(mission), held(server), mission.firmware).equal
    return Run(holds, not holds, report.attempts, wall, report.elapsed_s, "")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--loss", type=float, nargs="+", default=[0.0, 0.1, 0.2])
    parser.add_argument("--retries", type=int, default=UploadSettings().retries)
    parser.add_argument("--seed", type=int, default=0, help="seed of the first run")
    parser.add_argument(
        "--same-seed", action="store_true", help="use --seed for every run (as a test does)"
    )
    parser.add_argument(
        "--items", type=int, help="upload only the first N items of the demo mission (and home)"
    )
    parser.add_argument("--verbose", action="store_true", help="print every run")
    parser.add_argument(
        "--upload-timeout",
        type=float,
        help="MAVSDK's answer timeout for uploads, in place of mavsdk_link.UPLOAD_TIMEOUT_S "
        "(to compare values)",
    )
    args = parser.parse_args()
    if args.upload_timeout is not None:
        mavsdk_link.UPLOAD_TIMEOUT_S = args.upload_timeout
    mission = read_plan(DEMO_PLAN.read_text(), str(DEMO_PLAN))
    if args.items is not None:
        mission = replace(mission, items=mission.items[: args.items])
    items = len(wire_items(mission))
    part = " (part)" if args.items is not None else ""
    print(
        f"demo mission{part}: {items} items; {args.runs} runs per loss rate; "
        f"retries {args.retries}; "
        f"MAVSDK upload timeout {mavsdk_link.UPLOAD_TIMEOUT_S:g} s"
    )
    false_successes = 0
    for loss in args.loss:
        runs = []
        for n in range(args.runs):
            seed = args.seed if args.same_seed else args.seed + n
            run = one_run(mission, loss, seed, args.retries)
            runs.append(run)
            if args.verbose:
                outcome = "verified" if run.verified else run.error or "FALSE SUCCESS"
                print(
                    f"  loss {loss:4.2f} seed {seed:3d}: {run.wall_s:6.2f} s "
                    f"(upload {run.upload_s:6.3f} s), {run.attempts} attempt(s), {outcome}",
                    flush=True,
                )
        ok = [r for r in runs if r.verified]
        walls = [r.wall_s for r in runs]
        false_successes += sum(r.false_success for r in runs)
        attempts = statistics.mean(r.attempts for r in ok) if ok else float("nan")
        uploads = [r.upload_s for r in ok] or [float("nan")]
        print(
            f"loss {loss:4.2f}: verified {len(ok):3d}/{len(runs)} "
            f"({100 * len(ok) / len(runs):5.1f} %), attempts {attempts:4.2f}; "
            f"wall median {statistics.median(walls):6.2f} s, max {max(walls):6.2f} s; "
            f"upload+verify (verified) median {statistics.median(uploads):6.3f} s, "
            f"max {max(uploads):6.3f} s; false successes {sum(r.false_success for r in runs)}",
            flush=True,
        )
        for error in sorted({r.error for r in runs if r.error}):
            print(f"    failed: {error}")
    return 1 if false_successes else 0


if __name__ == "__main__":
    sys.exit(main())
