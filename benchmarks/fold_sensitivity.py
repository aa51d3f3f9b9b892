"""Derivatives of a knot's critical twist (issue 17, acceptance 6: dphi*/dnu and dphi*/d(D/L) from the
implicit function theorem against central differences of point studies).

The twisted trefoil (D, L) = (8, 292) mm, the paper's rod. Each side's branch end is a fold, located
by ``jaxrod.continuation.arclength.continuation`` on ``knot_problem`` (the minimally augmented fold system,
Newton to roundoff). At the fold:

- IFT: ``fold_sensitivity`` -- one bordered solve with the fold system's Jacobian, dphi*/dmu for
  mu = nu (``set_poisson_ratio``: C = B/(1 + nu)) and mu = D (``set_diameter``: B, C ~ D^4, EA ~ D^2,
  contact at D; L fixed, so dphi*/d(D/L) = L dphi*/dD).
- Point studies: ``fold_at`` -- the fold located again at mu +- h (Newton on its system at fixed mu,
  to roundoff), central differences at h and h/2 (the truncation error falls 4x: second order).

What it replaces: ``critical_twist_derivative`` differentiated the lowest eigenvalue on a fixed
branch, which at a fold is the wrong formula (the branch itself turns there): at N = 61 it gave
-0.057 or -0.105 (tol 1e-3 pi or 1e-4 pi), i.e. dphi*/dnu of 5 to 11, against 13.47 from finite
differences of two whole studies (issue 17). It now refuses knots.

Writes benchmarks/results/fold_sensitivity.{json,md}.
Run: python benchmarks/fold_sensitivity.py   (~4 min on 2 cores)
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
from jaxrod.continuation.arclength import PseudoArclength, continuation, fold_at, fold_sensitivity  # noqa: E402
from jaxrod.continuation.arclength.rods import knot_problem, set_diameter, set_poisson_ratio  # noqa: E402

PI = math.pi
D, L = 8.0, 292.0
from _bench import SMOKE, markdown, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = results_dir()
# (N, side, start of the pseudo-arclength path (from follow_twist), p bound, steps)
CASES = pick(((61, "opening", 6.3, 7.0, 40), (121, "opening", 6.3, 7.0, 30), (121, "tightening", -11.0, -12.0, 80)),
             ((61, "opening", 6.3, 7.0, 13),))  # the small mode: the fold comes at step 11, the path after it unused
# the stable-only engine's largest step to the path's start, and the path's first and largest steps;
# the small mode: 3 pi reaches 6.3 pi in 3 steps (2 pi: 5-6), and longer path steps
FOLLOW_STEP, DS, DS_MAX = pick((2 * PI, 0.05, 0.25), (3 * PI, 0.25, 1.0))
PARAMETERS = pick((("nu", set_poisson_ratio, 0.5, 1e-3), ("D", set_diameter, D, 8e-4)),
                  (("nu", set_poisson_ratio, 0.5, 1e-3),))


def _options(sign, bound, steps):
    kw = dict(p_max=bound * PI) if sign > 0 else dict(p_min=bound * PI)
    return ContinuationOptions(ds=DS * sign, ds_min=1e-6, ds_max=DS_MAX, max_steps=steps, newton_tol=1e-10,
                               eig_rtol=1e-13, k=6, **kw)


def main():
    rows = []
    for N, side, start, bound, steps in CASES:
        sign = 1 if start > 0 else -1
        scene = jr.trefoil(D=D, L=L, N=N)
        t0 = time.perf_counter()
        old = jr.follow_twist(scene, 0.0, start * PI, jr.ContinuationOptions(step=FOLLOW_STEP * sign, max_switches=0))
        e = old.points[-1].equilibrium
        rod = knot_problem(scene, np.asarray(e.q), e.phi)
        opts = _options(sign, bound, steps)
        br = continuation(rod.problem, PseudoArclength(), opts, throw=False)
        folds = [ev for ev in br.events if ev.kind == "fold"]
        if not folds:
            print(f"N = {N} {side}: no fold ({[ev.kind for ev in br.events]}, {br.message}, "
                  f"p from {br.p[0] / PI:.4f} pi to {br.p[-1] / PI:.4f} pi)")
            continue
        fold = folds[0]
        located = time.perf_counter() - t0
        print(f"N = {N} {side}: fold at {fold.p / PI:.10f} pi ({located:.0f} s)", flush=True)
        for name, set_mu, mu0, h in PARAMETERS:
            t = time.perf_counter()
            fold_sensitivity(rod.problem, fold, set_mu, mu0)  # compiles
            t_compile = time.perf_counter() - t
            t = time.perf_counter()
            slope = fold_sensitivity(rod.problem, fold, set_mu, mu0)
            t_ift = time.perf_counter() - t
            central, moved = [], []
            for step in (h, h / 2):
                t = time.perf_counter()
                # from the unmoved fold where Newton converges from there (a point study independent of
                # the IFT), else from the IFT's first-order prediction
                for predict in (False, True):
                    up, down = (fold_at(rod.problem, fold, set_mu, mu0, mu0 + s * step, opts, predict=predict)
                                for s in (1, -1))
                    if up.converged and down.converged:
                        break
                moved.append(((time.perf_counter() - t) / 2, max(up.iterations, down.iterations),
                              up.converged and down.converged, "predicted" if predict else "unmoved fold"))
                central.append((up.p - down.p) / (2 * step))
            scale = L if name == "D" else 1.0  # dphi*/d(D/L) = L dphi*/dD at fixed L
            row = dict(N=N, side=side, phi_star_over_pi=fold.p / PI, parameter=name, mu0=mu0, h=h,
                       ift=slope, central_h=central[0], central_h2=central[1],
                       rel_diff_h=abs(slope - central[0]) / abs(central[0]),
                       rel_diff_h2=abs(slope - central[1]) / abs(central[1]),
                       truncation_ratio=abs(slope - central[0]) / max(abs(slope - central[1]), 1e-300),
                       per_unit=("d(D/L)" if name == "D" else "dnu"), ift_per_unit_over_pi=slope * scale / PI,
                       seconds_ift=t_ift, seconds_first_call=t_compile, seconds_point_study=moved[0][0], point_study_iterations=moved[0][1],
                       point_study_start=" / ".join(m[3] for m in moved),
                       converged=all(m[2] for m in moved))
            rows.append(row)
            print(f"  dphi*/d{name}: IFT {slope:.10g}, central {central[0]:.10g} (h) {central[1]:.10g} (h/2), "
                  f"rel. diff {row['rel_diff_h']:.1e} / {row['rel_diff_h2']:.1e}; IFT {t_ift:.2f} s "
                  f"(first call {t_compile:.1f} s), "
                  f"a point study {moved[0][0]:.2f} s ({moved[0][1]} Newton iterations, from {row['point_study_start']})",
                  flush=True)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "fold_sensitivity.json"), "w") as f:
        json.dump(with_provenance(dict(D=D, L=L, rows=rows)), f, indent=1)
    write_md(rows)


def write_md(rows):
    lines = ["# Derivatives of the trefoil's critical twist at its folds (IFT against point studies)", "",
             f"The trefoil (D, L) = ({D:g}, {L:g}); `benchmarks/fold_sensitivity.py`. IFT: `fold_sensitivity`, one "
             "bordered solve at the located fold. Central: the fold located again (`fold_at`, Newton on the fold "
             "system at fixed mu) at mu +- h and mu +- h/2. Seconds: a second call in the same process (the first "
             "call compiles the fold system's derivatives for that parameter: the first-call column).", "",
             "| N | side | phi* / pi | mu | h | dphi*/dmu (IFT) | central (h) | central (h/2) | rel. diff (h) | "
             "rel. diff (h/2) | per unit, / pi | IFT s | first call s | point study s (iterations) | "
             "point studies start from (h / h/2) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['N']} | {r['side']} | {r['phi_star_over_pi']:.10f} | {r['parameter']} | {r['h']:g} | "
                     f"{r['ift']:.10g} | {r['central_h']:.10g} | {r['central_h2']:.10g} | {r['rel_diff_h']:.1e} | "
                     f"{r['rel_diff_h2']:.1e} | {r['ift_per_unit_over_pi']:.6g} per {r['per_unit']} | "
                     f"{r['seconds_ift']:.2f} | {r['seconds_first_call']:.1f} | {r['seconds_point_study']:.2f} ({r['point_study_iterations']}) | {r['point_study_start']} |")
    lines += ["", "A point study starts from the unmoved fold, so that it owes nothing to the derivative it checks, "
              "where Newton converges from there; else from the IFT's first-order prediction (a converged root "
              "either way: residual of the fold system <= 1e-13). From the unmoved fold, the tightening fold's "
              "Newton diverges at nu - h/2: a second shape eigenvalue ~1e-7 next to the critical one amplifies "
              "the O(h) residual of the first step.", "", "The central differences converge to the IFT value at second order (the difference falls ~4x from "
              "h to h/2) down to the noise of the located folds (~5e-9 rad in phi* at N = 61, where a sliding mode is "
              "nearly null: for D it limits the difference to ~1e-5 relative there); the acceptance asks 1e-4. For nu at N = 61 the IFT "
              "gives the 13.47 that issue 17 measured by finite differences of two whole studies, where the "
              "fixed-branch formula gave 5 to 11."]
    with open(os.path.join(OUT, "fold_sensitivity.md"), "w") as f:
        f.write(markdown(lines))


if __name__ == "__main__":
    main()
