"""The twisted trefoil's hysteresis loops (issue 17, item 4 / acceptance 5): from each buckled
branch, continued back (untwisting) by pseudo-arclength, the twist at which the buckled knot stops
being stable, i.e. where it snaps back.

The paper's rod (D, L) = (8, 292) mm, N = 121 (command 1). For each side: ``follow_twist`` (the
stable-only engine) from phi = 0 through the symmetric branch's end onto the buckled branch, to
7 pi (opening) or -12 pi (tightening); from that buckled state, ``jaxrod.continuation.arclength.continuation``
on ``knot_problem`` towards phi = 0, with two step limits, until the first event that costs the
buckled branch its stability (a fold or a branch point: the Morse index goes 0 -> 1). Soft folds
(the path turning back along the sliding mode, a saddle-node of the discretisation's tiny
sliding landscape) are crossed by a slide (``ContinuationOptions.soft_folds = "slide"``): the rod
relaxes to the neighbouring minimum, its strands slipping, and the path goes on.

The loop on each side is [buckled branch's end, symmetric branch's end]: twisting up, the
symmetric knot buckles at its end (from benchmarks/results/bifurcation_trefoil.json); untwisting,
the buckled knot stays stable down to the end found here.

Writes benchmarks/results/hysteresis_trefoil.{json,md,csv,png}.
Run: python benchmarks/hysteresis_trefoil.py   (~6 min on 2 cores)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import csv  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402
from jaxrod.continuation import ContinuationOptions  # noqa: E402
from jaxrod.continuation.arclength import PseudoArclength, continuation  # noqa: E402
from jaxrod.continuation.arclength.rods import knot_problem  # noqa: E402
from jaxrod.model.topology import writhe  # noqa: E402

PI = math.pi
from _bench import COMMITTED_RESULTS, SMOKE, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = results_dir()
N = pick(121, 61)  # the small mode: the fewest nodes whose start at phi = 0 is a minimum
# where the buckled branch is started (phi / pi); the small mode: the opening side, a few points
SIDES = pick({"plus": 7.0, "minus": -12.0}, {"plus": 7.0})
STEP_LIMITS = pick((0.5, 0.25), (0.5,))
MAX_STEPS = pick(320, 6)
CHUNK = pick(25, 3)  # continuation steps between the observer's looks
PAST_END = pick(6, 1)  # points followed past the buckled branch's end
# the stable-only engine's largest step to the buckled branch (the small mode: 15 steps to 7 pi, not 30)
FOLLOW_STEP = pick(0.5 * PI, 3 * PI)
# the corrector's residual: along a slide of eigenvalue ~3e-8 a residual r leaves the point uncertain
# by r / 3e-8; at 1e-10 that is 3e-3, enough for the path to turn in phi by noise (measured)
NEWTON_TOL = 1e-12


def symmetric_ends():
    """The symmetric branch's ends located by the fold system (benchmarks/bifurcation_trefoil.py)."""
    # the small mode's folder is empty: the committed results there
    with open(os.path.join(COMMITTED_RESULTS if SMOKE else OUT, "bifurcation_trefoil.json")) as f:
        summary = json.load(f)["summary"]
    return {side: summary[side]["phi_over_pi"] for side in ("plus", "minus")}


def buckled_state(scene, side):
    stop = SIDES[side] * PI
    t = time.perf_counter()
    path = jr.follow_twist(scene, 0.0, stop, jr.ContinuationOptions(step=FOLLOW_STEP, max_switches=1))
    seconds = time.perf_counter() - t
    buckled = [p for p in path.points if p.branch.startswith("buckled")]
    if not path.completed or not buckled:
        raise RuntimeError(f"{side}: follow_twist did not reach the buckled branch: {path.reason}")
    return buckled[-1].equilibrium, seconds


def main():
    os.makedirs(OUT, exist_ok=True)
    scene = jr.trefoil(D=8.0, L=292.0, N=N)
    ends = symmetric_ends()
    rows, summary = [], {}
    for side in SIDES:
        e, t_follow = buckled_state(scene, side)
        wr0 = float(writhe(np.asarray(scene.positions(e.q)), closed=True))
        runs = []
        for ds_max in STEP_LIMITS:
            rod, br, seconds = run_with_points(scene, side, e, ds_max)
            end = next((ev for ev in br.events if ev.kind in ("fold", "branch_point") and ev.morse_after > ev.morse_before), None)
            for q in br.points:
                shape = q.eigenvalues[~q.soft] if q.soft is not None else q.eigenvalues
                rows.append(dict(side=side, ds_max=ds_max, phi_over_pi=q.p / PI, morse_index=q.morse_index,
                                 lowest_shape_eigenvalue=float(shape[0]),
                                 writhe=float(writhe(np.asarray(rod.nodes(q.u)), closed=True))))
            runs.append(dict(
                ds_max=ds_max, seconds=round(seconds, 1), points=len(br.points), result=br.result.name,
                events=[dict(kind=ev.kind, phi_over_pi=ev.p / PI, morse=(ev.morse_before, ev.morse_after),
                             critical_eigenvalue=ev.critical_eigenvalue, residual=ev.residual,
                             iterations=ev.iterations, converged=ev.converged) for ev in br.events],
                slides=[dict(phi_fold_over_pi=s.fold.p / PI, phi_over_pi=s.p / PI, distance=s.distance,
                             energy_drop=s.energy_drop, iterations=s.iterations) for s in br.slides],
                end=None if end is None else dict(kind=end.kind, phi_over_pi=end.p / PI,
                                                  critical_eigenvalue=end.critical_eigenvalue,
                                                  residual=end.residual, full_gradient=rod.full_gradient(end.u, end.p))))
            print(side, json.dumps(runs[-1]), flush=True)
        found = [r["end"]["phi_over_pi"] for r in runs if r["end"] is not None]
        summary[side] = dict(
            buckled_start_over_pi=e.phi / PI, buckled_start_writhe=wr0, seconds_follow_twist=round(t_follow, 1),
            symmetric_end_over_pi=ends[side], buckled_end_over_pi=float(np.mean(found)) if found else None,
            buckled_end_kind=runs[0]["end"]["kind"] if runs[0]["end"] else None,
            spread_over_pi=float(np.ptp(found)) if found else None, runs=runs)
        print(side, json.dumps({k: v for k, v in summary[side].items() if k != "runs"}), flush=True)
    with open(os.path.join(OUT, "hysteresis_trefoil.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(OUT, "hysteresis_trefoil.json"), "w") as f:
        json.dump(with_provenance(dict(N=N, D=8.0, L=292.0, summary=summary)), f, indent=1)
    plot(rows, summary)
    write_md(summary)


def run_with_points(scene, side, e, ds_max):
    """``run``, but keeping the branch when the observer stops it: continuation in chunks."""
    sign = -1.0 if side == "plus" else 1.0
    rod = knot_problem(scene, np.asarray(e.q), e.phi)
    t = time.perf_counter()
    points, events, slides, start, br = [], [], [], None, None
    chunk = CHUNK
    while len(points) < MAX_STEPS:
        opts = ContinuationOptions(ds=0.05 * sign, ds_min=1e-6, ds_max=ds_max, max_steps=chunk, newton_tol=NEWTON_TOL,
                                   eig_rtol=1e-13, k=6, p_min=-13 * PI, p_max=14 * PI)
        br = continuation(rod.problem, PseudoArclength(), opts, start=start, throw=False)
        points += br.points[1:] if points else br.points
        events += br.events
        slides += br.slides
        past = sum(q.morse_index > 0 for q in points)
        if br.result.name != "MAX_STEPS" or past >= PAST_END:
            break
        last = points[-1]
        start = (last.u, last.p, last.tangent)
    br.points, br.events, br.slides = points, events, slides
    return rod, br, time.perf_counter() - t


def plot(rows, summary):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, side in zip(axes, ("minus", "plus")):
        if side not in summary:  # the small mode runs one side
            continue
        s = summary[side]
        sel = [r for r in rows if r["side"] == side and r["ds_max"] == STEP_LIMITS[0]]
        phi = np.array([r["phi_over_pi"] for r in sel])
        wr = np.array([r["writhe"] for r in sel])
        morse = np.array([r["morse_index"] for r in sel])
        ax.plot(phi[morse == 0], wr[morse == 0], ".", ms=3, color="C1", label="buckled branch, stable")
        if (morse > 0).any():
            ax.plot(phi[morse > 0], wr[morse > 0], "x", ms=3, color="C3", label="buckled branch, unstable")
        ax.axvline(s["symmetric_end_over_pi"], color="C0", lw=1, label=f"symmetric end {s['symmetric_end_over_pi']:+.4f} pi")
        if s["buckled_end_over_pi"] is not None:
            ax.axvline(s["buckled_end_over_pi"], color="C3", lw=1, ls="--",
                       label=f"buckled end ({s['buckled_end_kind']}) {s['buckled_end_over_pi']:+.4f} pi")
        lo, hi = sorted((s["symmetric_end_over_pi"], s["buckled_end_over_pi"] or s["symmetric_end_over_pi"]))
        ax.axvspan(lo, hi, color="0.9", zorder=0)
        ax.set_xlabel("phi / pi")
        ax.set_ylabel("writhe")
        ax.set_title(f"{'tightening' if side == 'minus' else 'opening'} side: hysteresis {hi - lo:.3f} pi")
        ax.legend(fontsize=7)
    fig.suptitle(f"Trefoil (8, 292) mm, N = {N}: buckled branches continued back to their ends")
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "hysteresis_trefoil.png"), dpi=120)


def write_md(summary):
    lines = [f"# Trefoil (8, 292) mm, N = {N}: hysteresis loops", "",
             provenance_line(), "",
             "Written by `benchmarks/hysteresis_trefoil.py`. Twisting up, the symmetric knot buckles at the "
             "symmetric branch's end; untwisting, the buckled knot stays stable down to the buckled branch's end.", "",
             "| side | symmetric end /pi | buckled end /pi | kind | width /pi | spread over step limits /pi | slides |",
             "|---|---|---|---|---|---|---|"]
    for side, s in summary.items():
        nsl = [len(r["slides"]) for r in s["runs"]]
        if s["buckled_end_over_pi"] is None:
            lines.append(f"| {side} | {s['symmetric_end_over_pi']:+.10f} | not found | | | | {nsl} |")
            continue
        width = abs(s["symmetric_end_over_pi"] - s["buckled_end_over_pi"])
        lines.append(f"| {side} | {s['symmetric_end_over_pi']:+.10f} | {s['buckled_end_over_pi']:+.10f} | "
                     f"{s['buckled_end_kind']} | {width:.4f} | {s['spread_over_pi']:.1e} | {nsl} |")
    lines += ["", "| side | ds_max | points | seconds | events (kind phi/pi Morse) | slides (phi_fold/pi, distance, energy drop) |",
              "|---|---|---|---|---|---|"]
    for side, s in summary.items():
        for r in s["runs"]:
            ev = "; ".join(f"{e['kind']} {e['phi_over_pi']:+.10f} {e['morse'][0]}->{e['morse'][1]} "
                           f"(lambda {e['critical_eigenvalue']:.0e}, res {e['residual']:.0e})" for e in r["events"])
            sl = "; ".join(f"{x['phi_fold_over_pi']:+.7f}, {x['distance']:.2f}, {x['energy_drop']:.1e}" for x in r["slides"])
            lines.append(f"| {side} | {r['ds_max']} | {r['points']} | {r['seconds']} | {ev} | {sl} |")
    with open(os.path.join(OUT, "hysteresis_trefoil.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
