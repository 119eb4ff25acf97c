"""Fleet plan folders for tests, laid out as ``plan --vehicles K --out OUT`` writes them.

Each vehicle is the demo planned by the single-vehicle ``plan`` on a subset of its targets,
at its own altitude and home, into ``OUT/vehicle_k``; ``OUT/summary.json`` gets the ``fleet``
block of the folder contract.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path

from click.testing import CliRunner
from conftest import DEMO

from urpt_gcs.cli import main
from urpt_gcs.site.targets import Target, read_targets

SITE, TARGETS = DEMO / "site.tif", DEMO / "targets.kml"
HOME = (47.688761595, 9.423090709)
# 20 m east of the demo's home.
HOME_EAST = (HOME[0], HOME[1] + 20.0 / (111_320.0 * math.cos(math.radians(HOME[0]))))


@dataclass(frozen=True)
class Vehicle:
    targets: tuple[str, ...]  # name prefixes, e.g. "T01"
    altitude_m: float
    home: tuple[float, float] = HOME
    args: tuple[str, ...] = ()  # more flags of its plan (``--endurance 4``: two sorties)


def build_fleet(
    out: Path, vehicles: list[Vehicle], mode: str = "altitude", min_m: float = 10.0
) -> Path:
    """Plan each vehicle into ``out/vehicle_k`` and write the fleet summary, and every
    vehicle's targets together in ``out/targets.csv``."""
    every = read_targets(TARGETS).targets
    rows = []
    planned: list[Target] = []
    for number, vehicle in enumerate(vehicles, start=1):
        chosen = [t for t in every if t.name.split()[0] in vehicle.targets]
        assert len(chosen) == len(vehicle.targets)
        planned += chosen
        subset = out / f"targets_{number}.csv"
        out.mkdir(parents=True, exist_ok=True)
        _write_targets(subset, chosen)
        folder = f"vehicle_{number}"
        args = [
            "plan", "--dem", str(SITE), "--targets", str(subset), "--out", str(out / folder),
            "--altitude", f"{vehicle.altitude_m:g}",
            "--home", f"{vehicle.home[0]},{vehicle.home[1]}",
            "--time-limit", "1", "--no-map", "--quiet", *vehicle.args,
        ]  # fmt: skip
        result = CliRunner().invoke(main, args)
        assert result.exit_code == 0, result.output
        summary = json.loads((out / folder / "summary.json").read_text())
        rows.append(
            {
                "vehicle": number,
                "dir": folder,
                "altitude_m": vehicle.altitude_m,
                "home_lat": vehicle.home[0],
                "home_lon": vehicle.home[1],
                "speed_m_s": summary["cruise_speed_m_s"],
                "flight_time_s": summary["flight_time_s"],
                "length_m": summary["tour_length_m"],
                "sorties": len(summary["sorties"]) if summary.get("sorties") else 1,
                "targets": [t.name for t in chosen],
            }
        )
    spacing = min_m if mode == "altitude" else 0.0
    block = {
        "vehicles": rows,
        "makespan_s": max(r["flight_time_s"] for r in rows),
        "makespan_bound_s": None,
        "makespan_gap_pct": None,
        "separation": {
            "mode": mode,
            "layer_spacing_m": spacing,
            "min_m": min_m,
            "closest_approach_m": None,
        },
    }
    (out / "summary.json").write_text(json.dumps({"fleet": block}, indent=2))
    _write_targets(out / "targets.csv", planned)
    return out


def _write_targets(path: Path, targets: list[Target]) -> None:
    with path.open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["name", "lat", "lon"])
        writer.writerows([t.name, f"{t.lat_deg:.9f}", f"{t.lon_deg:.9f}"] for t in targets)


def plan_fleet_of_two(out: Path) -> Path:
    """The planner's own fleet of two for the demo, written to ``out``: one home, layers
    10 m apart (its summary.json as plan writes it)."""
    args = ["plan", "--dem", str(SITE), "--targets", str(TARGETS), "--out", str(out)]
    result = CliRunner().invoke(main, [*args, "--vehicles", "2", "--time-limit", "2", "--no-map"])
    assert result.exit_code == 0, result.output
    return out
