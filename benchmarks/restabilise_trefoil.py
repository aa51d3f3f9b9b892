"""Where the trefoil's unstable branches lead (issue 17, item 3): each symmetric branch's end
located, then the unstable branch beyond it followed until it restabilises
(``jaxrod.diagram.DiagramOptions(until_restable=True)``: a fold or branch point where the Morse
index comes back to 0) -- the stated alternative to the study's relaxation along the critical mode.

Trefoil (8, 292), N = 121, nu = 0.5. Each side starts on the symmetric branch (the stable-only
engine in steps of 2 pi, to 6.3 pi and -11 pi), then ``follow_branch_end``.

    python benchmarks/restabilise_trefoil.py

Writes benchmarks/results/restabilise_trefoil.{json,md}.
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402
from jaxrod.diagram import DiagramOptions, follow_branch_end  # noqa: E402
from jaxrod.topology import writhe  # noqa: E402

PI = math.pi
HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = os.path.join(HERE, "results")
SIDES = {"opening": (1.0, 6.3), "tightening": (-1.0, -11.0)}


def event_row(e):
    return None if e is None else {"kind": e.kind, "phi_over_pi": float(e.p) / PI, "morse": [int(e.morse_before), int(e.morse_after)],
                                   "critical_eigenvalue": float(np.max(np.abs(e.critical_eigenvalue))),
                                   "residual": float(e.residual), "iterations": int(e.iterations)}


def main():
    scene = jr.trefoil(D=8.0, L=292.0, N=121)
    rows = []
    for side, (sign, start) in SIDES.items():
        path = jr.follow_twist(scene, 0.0, start * PI, jr.ContinuationOptions(step=2 * PI, max_switches=0))
        e = path.points[-1].equilibrium
        t = time.perf_counter()
        end = follow_branch_end(scene, np.asarray(e.q), e.phi, sign,
                                DiagramOptions(until_restable=True, max_unstable_points=400))
        seconds = time.perf_counter() - t
        pts = end.points
        wr = [float(writhe(np.asarray(scene.unpack(end.rod.q(q.u), q.p)[0]))) for q in (pts[0], pts[-1])]
        row = {"side": side, "start_over_pi": start, "end": event_row(end.event), "restabilised": event_row(end.restabilised),
               "points": len(pts), "arclength": float(pts[-1].arclength), "seconds": seconds, "message": end.message,
               "last_phi_over_pi": float(pts[-1].p) / PI, "last_morse": int(pts[-1].morse_index),
               "writhe_first_last": wr}
        rows.append(row)
        print(json.dumps(row), flush=True)
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, "restabilise_trefoil.json"), "w") as fh:
        json.dump(rows, fh, indent=1)
    lines = ["# Where the trefoil's unstable branches lead", "",
             "Trefoil (8, 292), N = 121: each symmetric branch's end located on the extended system, then the "
             "unstable branch beyond it followed by pseudo-arclength continuation until the Morse index comes back "
             "to 0 (`python benchmarks/restabilise_trefoil.py`; `DiagramOptions(until_restable=True)`).", "",
             "| side | end (kind, phi*/pi, Morse) | restabilised (kind, phi/pi, Morse) | critical eigenvalue / residual there "
             "| points | Wr at start / last | seconds |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        a, b = r["end"], r["restabilised"]
        ends = f"{a['kind']} {a['phi_over_pi']:+.10f} ({a['morse'][0]} -> {a['morse'][1]})" if a else "none"
        back = (f"{b['kind']} {b['phi_over_pi']:+.10f} ({b['morse'][0]} -> {b['morse'][1]})" if b else
                f"not within the points followed ({r['message']})")
        quality = f"{b['critical_eigenvalue']:.1e} / {b['residual']:.1e}" if b else ""
        lines.append(f"| {r['side']} | {ends} | {back} | {quality} | {r['points']} | "
                     f"{r['writhe_first_last'][0]:.3f} / {r['writhe_first_last'][1]:.3f} | {r['seconds']:.1f} |")
    with open(os.path.join(RESULTS, "restabilise_trefoil.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
