"""The twisted trefoil's branch ends through jaxrod.continuation.arclength (issue 17, acceptance 1 in part):
the symmetric branch followed by pseudo-arclength continuation through each branch end onto the
unstable branch, each end located by Newton on the minimally augmented fold system, from several
starts and step limits.

The paper's rod (D, L) = (8, 292) mm, N = 121 (command 1). For each side (opening phi > 0,
tightening phi < 0): states on the symmetric branch from the stable-only engine (``follow_twist``,
big steps), then ``jaxrod.continuation.arclength.continuation`` on ``knot_problem`` (gauge pinned, contact and
writhe through a neighbourhood, sliding modes split off by their shape) from two starts and with
three step limits, until the path is well past the fold. The located folds are compared with one
another (step and start independence) and with the README's values of today's engine.

Writes benchmarks/results/bifurcation_trefoil.csv (every point of every path: side, run, phi,
Morse index, lowest non-sliding eigenvalue, sliding eigenvalue), bifurcation_trefoil.json (the
events) and bifurcation_trefoil.md, and bifurcation_trefoil.png (phi against the lowest eigenvalue;
stable solid, unstable dashed, folds marked).
Run: python benchmarks/bifurcation_trefoil.py   (~3 min on 2 cores)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import csv  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402
from jaxrod.continuation import ContinuationOptions  # noqa: E402
from jaxrod.continuation.arclength import PseudoArclength, Result, continuation  # noqa: E402
from jaxrod.continuation.arclength.rods import knot_problem  # noqa: E402

from _bench import SMOKE, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)

PI = math.pi
N = pick(121, 61)
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = results_dir()
# README (today's engine, command 1): phi+ = 6.46490 pi +- 5e-5 pi, phi- = -11.18429 pi +- 9e-5 pi
TODAY = {"plus": (6.46490, 5e-5), "minus": (-11.18429, 9e-5)}
SIDES = {"plus": dict(stop=6.3, starts=pick((6.0, 6.3), (6.3,))), "minus": dict(stop=-11.0, starts=pick((-10.0, -11.0), (-11.0,)))}
if SMOKE:  # the small mode: the opening side only (the tightening side is the same code, 11 pi of twist from phi = 0)
    del SIDES["minus"]
STEP_LIMITS = pick((0.25, 0.5, 1.0), (1.0,))
PAST_FOLD = pick(8, 1)  # points followed on the unstable branch after the fold
CHUNK, MAX_POINTS = 20, 300


def run_side(scene, side):
    cfg = SIDES[side]
    sign = 1.0 if side == "plus" else -1.0
    t0 = time.perf_counter()
    old = jr.follow_twist(scene, 0.0, cfg["stop"] * PI, jr.ContinuationOptions(step=2 * PI, max_switches=0))
    t_old = time.perf_counter() - t0
    states = {round(p.equilibrium.phi / PI, 6): p.equilibrium for p in old.points}
    runs = []
    for start in cfg["starts"]:
        for ds_max in STEP_LIMITS:
            e = states[start]
            rod = knot_problem(scene, np.asarray(e.q), e.phi)
            opts = ContinuationOptions(ds=0.05 * sign, ds_min=1e-6, ds_max=ds_max, max_steps=CHUNK, newton_tol=1e-10,
                                       eig_rtol=1e-13, k=6, p_min=-13 * PI, p_max=14 * PI)
            t = time.perf_counter()
            points, evs, start_at, result = [], [], None, None
            while len(points) < MAX_POINTS:
                br = continuation(rod.problem, PseudoArclength(), opts, start=start_at, throw=False)
                offset = len(points) - (1 if points else 0)
                points += br.points[1:] if points else br.points
                evs += [replace(e, step=e.step + offset) for e in br.events]
                result = br.result
                fold = next((e for e in evs if e.kind == "fold"), None)
                if br.result is not Result.MAX_STEPS or (fold is not None and len(points) >= fold.step + PAST_FOLD):
                    break
                last = points[-1]
                start_at = (last.u, last.p, last.tangent)
            runs.append(dict(start=start, ds_max=ds_max, points=points, events=evs, result=result, rod=rod,
                             seconds=time.perf_counter() - t))
            print(f"{side} start {start:+.1f} pi, ds_max {ds_max}: {len(points)} points, {result.name}, "
                  f"{runs[-1]['seconds']:.1f} s; events " + ", ".join(
                      f"{e.kind} {e.p / PI:+.10f} pi ({e.morse_before}->{e.morse_after}, lambda {e.critical_eigenvalue:.1e})"
                      for e in evs) + "; phi range " + f"{min(q.p for q in points) / PI:+.4f} .. {max(q.p for q in points) / PI:+.4f} pi", flush=True)
    return old, t_old, runs


def lowest(q):
    shape = q.eigenvalues[~q.soft] if q.soft is not None else q.eigenvalues
    slide = q.eigenvalues[q.soft] if q.soft is not None and q.soft.any() else np.array([np.nan])
    return float(shape[0]), float(slide[0])


def main():
    os.makedirs(OUT, exist_ok=True)
    scene = jr.trefoil(D=8.0, L=292.0, N=N)
    rows, events, summary = [], [], {}
    for side in SIDES:
        old, t_old, runs = run_side(scene, side)
        folds, odd = [], []
        for k, r in enumerate(runs):
            fold = next((e for e in r["events"] if e.kind == "fold"), None)
            for q in r["points"]:
                shape, slide = lowest(q)
                rows.append(dict(side=side, run=k, start_over_pi=r["start"], ds_max=r["ds_max"], phi_over_pi=q.p / PI,
                                 morse_index=q.morse_index, lowest_shape_eigenvalue=shape,
                                 sliding_eigenvalue=slide))
            for e in r["events"][:3]:
                events.append(dict(side=side, run=k, start_over_pi=r["start"], ds_max=r["ds_max"], kind=e.kind,
                                   phi=e.p, phi_over_pi=e.p / PI, critical_eigenvalue=e.critical_eigenvalue,
                                   residual=e.residual, newton_iterations=e.iterations, converged=e.converged,
                                   morse_before=e.morse_before, morse_after=e.morse_after,
                                   full_gradient=r["rod"].full_gradient(e.u, e.p), seconds_run=r["seconds"],
                                   path_result=r["result"].name))
            if r["events"] and r["events"][0].kind == "fold":  # the branch end is the path's first event
                folds.append(fold)
            else:
                odd.append(dict(start_over_pi=r["start"], ds_max=r["ds_max"],
                                events=[(e.kind, e.p / PI, e.morse_before, e.morse_after) for e in r["events"][:3]]))
        # nan where no run's first event is a fold (at small N the tightening end can be a branch point)
        phis = np.array([f.p for f in folds] or [math.nan]) / PI
        summary[side] = dict(folds_found=len(folds), runs=len(runs), other_first_events=odd,
                             phi_over_pi=float(np.mean(phis)),
                             spread_over_pi=float(np.ptp(phis)), today=TODAY[side],
                             difference_from_today_over_pi=float(np.mean(phis) - TODAY[side][0]),
                             max_critical_eigenvalue=max((f.critical_eigenvalue for f in folds), default=math.nan),
                             max_residual=max((f.residual for f in folds), default=math.nan),
                             max_newton_iterations=max((f.iterations for f in folds), default=0),
                             seconds_follow_twist=t_old,
                             seconds_per_run=[round(r["seconds"], 1) for r in runs])
        print(side, json.dumps(summary[side]), flush=True)
    with open(os.path.join(OUT, "bifurcation_trefoil.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with open(os.path.join(OUT, "bifurcation_trefoil.json"), "w") as f:
        json.dump(with_provenance(dict(N=N, summary=summary, events=events,
                                       machine=platform.processor() or platform.machine())), f, indent=1)
    plot(rows, summary)
    write_md(summary, events)


def plot(rows, summary):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, side in zip(axes, [side for side in ("minus", "plus") if side in summary]):
        sel = [r for r in rows if r["side"] == side and r["run"] == 0]
        phi = np.array([r["phi_over_pi"] for r in sel])
        lam = np.array([r["lowest_shape_eigenvalue"] for r in sel])
        morse = np.array([r["morse_index"] for r in sel])
        for m, style in ((0, "-"), (1, "--"), (2, ":")):
            mask = morse == m
            if mask.any():
                ax.plot(phi[mask], lam[mask], style, marker=".", ms=3, label=f"Morse index {m}")
        ax.axvline(summary[side]["phi_over_pi"], color="k", lw=0.8)
        ax.axhline(0.0, color="0.6", lw=0.6)
        ax.set_xlabel("phi / pi")
        ax.set_ylabel("lowest shape eigenvalue (scaled)")
        ax.set_title(f"{'tightening' if side == 'minus' else 'opening'} end: fold at "
                     f"{summary[side]['phi_over_pi']:+.7f} pi")
        ax.legend(fontsize=8)
    fig.suptitle(f"Trefoil (8, 292) mm, N = {N}: the symmetric branch through its folds (jaxrod.continuation.arclength)")
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "bifurcation_trefoil.png"), dpi=120)


def write_md(summary, events):
    lines = [f"# Trefoil (8, 292) mm, N = {N}: branch ends as folds of the extended system", "",
             provenance_line(), "",
             "Written by `benchmarks/bifurcation_trefoil.py`. Each side: 2 starts x 3 step limits "
             f"(ds_max {STEP_LIMITS}).", "",
             "A run counts when its first event is a fold (the branch end); runs whose first event is "
             "something else are listed below the table.", "",
             "| side | runs ending at a fold | phi*/pi (mean) | spread over runs /pi | today (README) | difference /pi | "
             "max critical eigenvalue | max residual | max Newton iterations |", "|---|---|---|---|---|---|---|---|---|"]
    for side, s in summary.items():
        lines.append(f"| {side} | {s['folds_found']}/{s['runs']} | {s['phi_over_pi']:+.10f} | {s['spread_over_pi']:.1e} | "
                     f"{s['today'][0]:+.5f} +- {s['today'][1]:g} | {s['difference_from_today_over_pi']:+.1e} | "
                     f"{s['max_critical_eigenvalue']:.1e} | {s['max_residual']:.1e} | {s['max_newton_iterations']} |")
    for side, s in summary.items():
        for o in s["other_first_events"]:
            lines.append(f"\n{side}, start {o['start_over_pi']:+.1f} pi, ds_max {o['ds_max']}: first events " + ", ".join(
                f"{k} at {p:+.10f} pi (Morse {a} -> {b})" for k, p, a, b in o["events"]))
    lines += ["", "Events on each path (the first three):", "",
              "| side | start/pi | ds_max | kind | phi/pi | critical eigenvalue | residual | Morse before -> after | "
              "located |", "|---|---|---|---|---|---|---|---|---|"]
    for e in events:
        lines.append(f"| {e['side']} | {e['start_over_pi']:+.1f} | {e['ds_max']} | {e['kind']} | {e['phi_over_pi']:+.10f} | "
                     f"{e['critical_eigenvalue']:.1e} | {e['residual']:.1e} | {e['morse_before']} -> {e['morse_after']} | "
                     f"{e['converged']} |")
    with open(os.path.join(OUT, "bifurcation_trefoil.md"), "w") as f:
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
