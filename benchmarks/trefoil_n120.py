"""The trefoil at N = 120, whose discretisation keeps the three-fold symmetry (issue 17, acceptance 3):
the first instability on each side, classified (fold or double branch point) and located, and its
distance from N = 121's fold.

The paper's rod (D, L) = (8, 292) mm. From the stable-only engine's state at 6.3 pi (opening) or
-11.0 pi (tightening), ``jaxrod.continuation.arclength.continuation`` on ``knot_problem`` with the step control
that watches the spectrum (``ContinuationOptions.resolve_crossings``: a step across which the Morse
index changes by more than 1 is retried at half the step, down to 1e-5). Without it, the opening
side's symmetry pair and the fold fall into one step (Morse 0 -> 3), and the fold system's Newton
converges onto the branch point, which also solves it.

Writes benchmarks/results/trefoil_n120.{json,md}.
Run: python benchmarks/trefoil_n120.py   (~3 min on 2 cores)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402
from jaxrod.continuation import ContinuationOptions  # noqa: E402
from jaxrod.continuation.arclength import PseudoArclength, continuation  # noqa: E402
from jaxrod.continuation.arclength.rods import knot_problem  # noqa: E402

PI = math.pi
from _bench import SMOKE, markdown, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = results_dir()
# N = 121's folds (benchmarks/results/bifurcation_trefoil.md)
FOLD_121 = {"opening": 6.4648752000 * PI, "tightening": -11.1843257630 * PI}
# the small mode: one side, from 0.3 pi past the stable-only engine's first step, a few steps
SIDES = pick((("opening", 6.3, 7.0, 100), ("tightening", -11.0, -12.0, 140)), (("opening", 2.3, 7.0, 4),))
# the small mode: the other trefoil scripts' N, whose compiled programs it shares when run after them
# in one process (the three-fold symmetry of N = 120 is not what the small mode checks)
N = pick(120, 61)


def main():
    scene = jr.trefoil(D=8.0, L=292.0, N=N)
    rows = []
    for side, start, bound, steps in SIDES:
        sign = 1 if start > 0 else -1
        t0 = time.perf_counter()
        old = jr.follow_twist(scene, 0.0, start * PI, jr.ContinuationOptions(step=2 * PI * sign, max_switches=0))
        e = old.points[-1].equilibrium
        rod = knot_problem(scene, np.asarray(e.q), e.phi)
        kw = dict(p_max=bound * PI) if sign > 0 else dict(p_min=bound * PI)
        opts = ContinuationOptions(ds=0.05 * sign, ds_min=1e-6, ds_max=0.25, max_steps=steps, newton_tol=1e-10,
                                   eig_rtol=1e-13, k=6, resolve_crossings=1e-5, **kw)
        br = continuation(rod.problem, PseudoArclength(), opts, throw=False)
        seconds = time.perf_counter() - t0
        events = [dict(kind=ev.kind, phi_over_pi=ev.p / PI, multiplicity=ev.multiplicity,
                       critical_eigenvalue=float(ev.critical_eigenvalue), residual=float(ev.residual),
                       iterations=int(ev.iterations), morse_before=int(ev.morse_before),
                       morse_after=int(ev.morse_after)) for ev in br.events]
        print(f"{side}: {br.result.value} ({br.message}), {seconds:.0f} s", flush=True)
        for ev in events:
            print(f"  {ev['kind']} at {ev['phi_over_pi']:.10f} pi, Morse {ev['morse_before']} -> {ev['morse_after']}, "
                  f"lambda {ev['critical_eigenvalue']:.1e}, residual {ev['residual']:.1e}", flush=True)
        first = next((ev for ev in events if ev["kind"] in ("fold", "branch_point")), None)
        rows.append(dict(side=side, events=events, seconds=seconds, result=br.result.value, message=br.message,
                         distance_from_121_over_pi=(first["phi_over_pi"] - FOLD_121[side] / PI) if first else None))
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "trefoil_n120.json"), "w") as f:
        json.dump(with_provenance(rows), f, indent=1)
    lines = ["# The trefoil at N = 120 (three-fold symmetric): first instabilities", "",
             "(D, L) = (8, 292); `benchmarks/trefoil_n120.py`; pseudo-arclength on `knot_problem` with "
             "`resolve_crossings = 1e-5` (a step that changes the Morse index by more than 1 is halved).", "",
             "| side | events (phi / pi, kind, Morse) | first event - N = 121's fold | seconds |", "|---|---|---|---|"]
    for r in rows:
        evs = "; ".join(f"{e['phi_over_pi']:.10f} {e['kind']} {e['morse_before']}->{e['morse_after']} "
                        f"(lambda {e['critical_eigenvalue']:.0e}, res {e['residual']:.0e})" for e in r["events"])
        dist = "--" if r["distance_from_121_over_pi"] is None else f"{r['distance_from_121_over_pi']:+.2e} pi"
        lines.append(f"| {r['side']} | {evs or r['message']} | {dist} | {r['seconds']:.0f} |")
    with open(os.path.join(OUT, "trefoil_n120.md"), "w") as f:
        f.write(markdown(lines))


if __name__ == "__main__":
    main()
