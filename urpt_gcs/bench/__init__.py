"""Benchmarks: the solvers on published instance sets, measured and compared.

One module per study, each a library call the ``urpt-gcs bench`` command group wraps:

- :mod:`urpt_gcs.bench.gtsplib`: GTSPLIB instances against best-known values, GLNS's
  published figures and the OR-Tools baseline at equal time.
- :mod:`urpt_gcs.bench.pyvrp_sorties`: PyVRP beside our sortie planning at equal time, on
  the candidate viewpoints it can express (needs the ``bench`` extra).
- :mod:`urpt_gcs.bench.cetsp_peer`: another CETSP solver run beside ours, one CPU each, its
  tour checked by :mod:`urpt_gcs.bench.peer_tour` (every disc touched, length recomputed).
- :mod:`urpt_gcs.bench.paper`: the paper's simulation study (540 instances on random TIN
  terrains) with the analogues of its Tables I-III.
"""

from __future__ import annotations

__all__: list[str] = []
