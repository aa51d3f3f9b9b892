"""Accuracy asked for (issue 18, item 2): both critical twists of the trefoil (8, 292) to 0.01 pi by
``jaxrod.studies.accuracy.converged_critical_twists`` (levels N = 61, 121, 241, ...; Richardson with the
order measured), in one process, compiled as it runs (a cold start). Writes
benchmarks/results/accuracy_trefoil.json (levels, extrapolations, seconds) and .png.

    python benchmarks/accuracy_trefoil.py
"""
import json
import math
import os
import sys
import tempfile
import time

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import jaxrod as jr  # noqa: E402
from jaxrod.studies.accuracy import converged_critical_twists  # noqa: E402
from jaxrod.io.plotting import plot_resolution_convergence  # noqa: E402

from _bench import SMOKE, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
RESULTS = results_dir()


def main():
    t0 = time.perf_counter()
    scratch = tempfile.mkdtemp(prefix="jaxrod-accuracy-")
    # small mode: the fewest nodes the knot's contact allows, the three levels an order needs, close
    # together (the dense linear algebra grows as N^3), one side, a coarser step and bracket (each
    # level compiles its own programs, which is most of the time: fewer points are what is left)
    result = converged_critical_twists(jr.trefoil(D=8.0, L=292.0, N=pick(61, 41)), pick(0.01, 1.0) * math.pi,
                                       sides=pick(("plus", "minus"), ("plus",)), N_max=pick(481, 161), out=scratch,
                                       levels=pick(None, (41, 45, 49)), step=pick(0.5, 1.0) * math.pi,
                                       progress=lambda s: print(f"[{time.perf_counter() - t0:6.1f} s] {s}",
                                                                 file=sys.stderr, flush=True))
    seconds = time.perf_counter() - t0
    summary = {side: r.as_json() for side, r in result.items()}
    summary.update({"D": 8.0, "L": 292.0, "accuracy_over_pi": 0.01, "seconds": seconds,
                    "note": "one process, every level compiled as it ran (cold); two threads, one per side"})
    with open(os.path.join(RESULTS, "accuracy_trefoil.json"), "w") as f:
        json.dump(with_provenance(summary), f, indent=2)
    plot_resolution_convergence(result, os.path.join(RESULTS, "accuracy_trefoil.png"),
                                title="Trefoil (8, 292): critical twists converged in N")
    for side, r in result.items():
        print(f"{side}: {r.phi_star / math.pi:+.6f} pi +- {r.error / math.pi:.1e} pi ({r.reason})")
    print(f"{seconds:.1f} s")


if __name__ == "__main__":
    main()
