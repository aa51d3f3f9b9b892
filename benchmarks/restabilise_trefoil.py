"""Where the trefoil's unstable branches lead (issue 17, item 3): each symmetric branch's end
located, then the unstable branch beyond it followed until it restabilises
(``jaxrod.studies.diagram.DiagramOptions(until_restable=True)``: a fold or branch point where the Morse
index comes back to 0) -- the stated alternative to the study's relaxation along the critical mode.
Where it restabilises at a branch point it crosses another branch: that branch is switched onto
(``jaxrod.continuation.arclength.switch_branches``) and both its halves followed for a few steps, with their
Morse index.

Trefoil (8, 292), N = 121, nu = 0.5. Each side starts on the symmetric branch (the stable-only
engine in steps of 2 pi, to 6.3 pi and -11 pi), then ``follow_branch_end``.

    python benchmarks/restabilise_trefoil.py
    python benchmarks/restabilise_trefoil.py --report-only   # the tables again from the JSON

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
from jaxrod.continuation import ContinuationOptions  # noqa: E402
from jaxrod.continuation.arclength import PseudoArclength, emanating_directions, switch_branches  # noqa: E402
from jaxrod.studies.diagram import DiagramOptions, follow_branch_end  # noqa: E402
from jaxrod.model.topology import writhe  # noqa: E402

PI = math.pi
from _bench import SMOKE, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = results_dir()
SIDES = pick({"opening": (1.0, 6.3), "tightening": (-1.0, -11.0)}, {"opening": (1.0, 6.3)})
N = pick(121, 61)  # the small mode: the fewest nodes whose start at phi = 0 is a minimum
MAX_UNSTABLE = pick(400, 4)


def event_row(e):
    return None if e is None else {"kind": e.kind, "phi_over_pi": float(e.p) / PI, "morse": [int(e.morse_before), int(e.morse_after)],
                                   "critical_eigenvalue": float(np.max(np.abs(e.critical_eigenvalue))),
                                   "residual": float(e.residual), "iterations": int(e.iterations)}


# The branch met at a restabilising branch point, each half followed for MET_STEPS steps.
MET_STEPS = pick(25, 2)
MET_OPTIONS = ContinuationOptions(ds=0.05, ds_min=1e-6, ds_max=0.5, max_steps=MET_STEPS, newton_tol=1e-11, eig_rtol=1e-13,
                                  k=6, resolve_crossings=1e-5)


def met_branch(end):
    """Where the unstable branch restabilises at a branch point it crosses another branch: that
    branch's two halves (``switch_branches`` from the reduced equations, |r| = 0.2), each
    followed for MET_STEPS steps, with the Morse index along it. [] at a fold."""
    ev = end.restabilised
    if ev is None or ev.kind != "branch_point":
        return []
    problem = end.rod.problem
    if problem.update_args is not None:  # the contact list around the branch point itself
        problem.args = problem.update_args(np.asarray(ev.u), float(ev.p), problem.args)
    t = time.perf_counter()
    directions = emanating_directions(problem, ev)
    halves = []
    for br in switch_branches(problem, ev, PseudoArclength(), MET_OPTIONS, amplitude=0.2, directions=directions,
                              throw=False):
        o = br.origin
        phis = [float(q.p) / PI for q in br.points]
        halves.append({"sign": o["sign"], "order": int(o["direction"].order), "kappa": float(o["direction"].kappa),
                       "predicted_morse": int(o["direction"].predicted_morse[0 if o["sign"] > 0 else 1]),
                       "morse": [int(q.morse_index) for q in br.points], "points": len(br.points),
                       "phi_first_over_pi": phis[0] if phis else None, "phi_last_over_pi": phis[-1] if phis else None,
                       "result": br.result.value, "message": br.message,
                       "events": [(x.kind, float(x.p) / PI, int(x.morse_before), int(x.morse_after)) for x in br.events]})
    for h in halves:
        h["seconds_all_halves"] = time.perf_counter() - t
    return halves


def main():
    import sys

    if sys.argv[1:] == ["--report-only"]:
        with open(os.path.join(RESULTS, "restabilise_trefoil.json")) as fh:
            data = json.load(fh)
        return report(data["rows"] if isinstance(data, dict) else data)  # committed files may hold the bare list
    scene = jr.trefoil(D=8.0, L=292.0, N=N)
    rows = []
    for side, (sign, start) in SIDES.items():
        path = jr.follow_twist(scene, 0.0, start * PI, jr.ContinuationOptions(step=2 * PI, max_switches=0))
        e = path.points[-1].equilibrium
        t = time.perf_counter()
        end = follow_branch_end(scene, np.asarray(e.q), e.phi, sign,
                                DiagramOptions(until_restable=True, max_unstable_points=MAX_UNSTABLE))
        seconds = time.perf_counter() - t
        pts = end.points
        wr = [float(writhe(np.asarray(scene.unpack(end.rod.q(q.u), q.p)[0]))) for q in (pts[0], pts[-1])]
        row = {"side": side, "start_over_pi": start, "end": event_row(end.event), "restabilised": event_row(end.restabilised),
               "points": len(pts), "arclength": float(pts[-1].arclength), "seconds": seconds, "message": end.message,
               "last_phi_over_pi": float(pts[-1].p) / PI, "last_morse": int(pts[-1].morse_index),
               "writhe_first_last": wr}
        row["met"] = met_branch(end)
        rows.append(row)
        print(json.dumps(row), flush=True)
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, "restabilise_trefoil.json"), "w") as fh:
        json.dump(with_provenance(rows), fh, indent=1)
    report(rows)


def report(rows):
    lines = ["# Where the trefoil's unstable branches lead", "", provenance_line(), "",
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
    lines += ["", "The branch met at each restabilising branch point (`switch_branches`: the reduced equations' "
              f"direction, |r| = 0.2, each half followed for {MET_STEPS} steps):", "",
              "| side | half (sign of r) | order / kappa | predicted Morse | Morse along it | as predicted | "
              "phi first / last (pi) | result |",
              "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        halves = r.get("met", [])
        # the two halves leave the point on opposite sides in phi (dp = -kappa r), each with its predicted index
        opposite = len(halves) == 2 and ((halves[0]["phi_first_over_pi"] - r["restabilised"]["phi_over_pi"])
                                         * (halves[1]["phi_first_over_pi"] - r["restabilised"]["phi_over_pi"]) < 0)
        for h in halves:
            morse = sorted(set(h["morse"]))
            ok = opposite and morse == [h["predicted_morse"]]
            lines.append(f"| {r['side']} | {h['sign']:+d} | {h['order']} / {h['kappa']:.3g} | {h['predicted_morse']} | "
                         f"{morse} | {'yes' if ok else 'NO'} | {h['phi_first_over_pi']:+.6f} / "
                         f"{h['phi_last_over_pi']:+.6f} | {h['result']} |")
    with open(os.path.join(RESULTS, "restabilise_trefoil.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
