"""A trivial CETSP peer for ``urpt-gcs bench cetsp DIR --peer``: the disc centres (the depot
first, where there is one) in nearest-neighbour order, printed by the peer protocol.

    urpt-gcs bench cetsp ../shared/bench/cetsp --only bubbles1 --time-limit 2 \\
        --peer "python3 benchmarks/cetsp_nn_peer.py {instance}"

It is a template for wrapping a real solver: read the instance, solve, print
``TOUR x1 y1 x2 y2 ...`` (the turn points in order, the tour closing back to the first).
"""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path


def main(path: str) -> None:
    head, *lines = Path(path).read_text(encoding="utf-8").splitlines()
    points = [tuple(map(float, line.split()[:2])) for line in lines if line.strip()]
    depot = re.search(r"depot=(\S+)", head)
    if depot and depot.group(1) != "none":
        points.insert(0, tuple(map(float, depot.group(1).split(","))))
    tour = [points.pop(0)]
    while points:
        i = min(range(len(points)), key=lambda k: math.dist(points[k], tour[-1]))
        tour.append(points.pop(i))
    print("TOUR " + " ".join(f"{x!r} {y!r}" for x, y in tour))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("instance", help="a CETSP instance file (as in ../shared/bench/cetsp)")
    main(parser.parse_args().instance)
