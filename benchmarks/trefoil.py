"""Critical twists of the twisted trefoil: convergence in N, dependence on D/L and on the contact
stiffness, compared with the paper and with the Michell estimates.

Each case follows the stable branch from the relaxed knot at phi = 0 in both directions
(``jaxrod.follow_twist``, no branch switching) to the first instability, located to ``tol``.
Results are appended to benchmarks/results/trefoil_critical.csv as each case finishes, so an
interrupted run resumes where it stopped (cases already in the file are skipped).

    python benchmarks/trefoil.py convergence   # N = 61, 121, 241 at (D, L) = (8, 292)
    python benchmarks/trefoil.py ratio         # D/L sweep at N = 61 (SWEEP_N)
    python benchmarks/trefoil.py stiffness     # kappa_c = 30, 300 at N = 61 (100: the convergence row)
    python benchmarks/trefoil.py stretch       # EA x 10 at N = 61
    python benchmarks/trefoil.py report        # table (trefoil_critical.md) and figures
    python benchmarks/trefoil.py --smoke       # small mode: N = 61, a quarter turn each way, then the report
"""
import csv
import math
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402

PI = math.pi
from _bench import SMOKE, pick, provenance_line, results_dir  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = results_dir()
CSV = os.path.join(RESULTS, "trefoil_critical.csv")
FIELDS = ["study", "N", "D", "L", "D_over_L", "contact_stiffness", "direction", "phi_star", "phi_star_over_pi",
          "phi_error", "kind", "multiplicity", "Wr_before", "Tw_before", "radius_of_gyration_change", "seconds"]
L = 292.0
NU = 0.5
MICHELL = jr.michell_critical_twist(NU)  # 5.196 pi
# The D/L and stiffness sweeps run at N = 61: loose knots relax slowly (D/L = 0.005 at N = 121 took
# 760 s for one side on this 2-core machine); the convergence study measures what N = 61 costs in
# accuracy (about 2% on phi*).
SWEEP_N = 61


def done(study, N, D, stiffness, direction):
    if not os.path.exists(CSV):
        return False
    with open(CSV, newline="") as f:
        for r in csv.DictReader(f):
            if (r["study"], int(r["N"]), float(r["D"]), float(r["contact_stiffness"]), r["direction"]) == (
                    study, N, D, stiffness, direction):
                return True
    return False


def case(study, N, D, stiffness=100.0, step=PI, tol=1e-3 * PI, span=(-16.0 * PI, 16.0 * PI), ea_factor=1.0):
    scene = jr.trefoil(D=D, L=L, N=N, nu=NU, contact_stiffness=stiffness)
    if ea_factor != 1.0:  # stretching stiffness EA scaled (the rod closer to inextensible)
        from dataclasses import replace

        scene = replace(scene, material=replace(scene.material, EA=scene.material.EA * ea_factor))
    start = None
    for direction, stop in (("plus", span[1]), ("minus", span[0])):
        if done(study, N, D, stiffness, direction):
            continue
        t0 = time.perf_counter()
        if start is None:
            start = jr.relax(scene, 0.0, options=jr.RelaxOptions(with_stability=False))
        path = jr.follow_twist(scene, 0.0, stop, jr.ContinuationOptions(step=step, tol=tol, switch=False), start=start,
                               observer=jr.Observer(progress=lambda s: print("   ", s, flush=True)))
        seconds = time.perf_counter() - t0
        rg = [np.sqrt(np.mean(np.sum((p.equilibrium.x - p.equilibrium.x.mean(0)) ** 2, 1))) for p in path.points]
        row = {"study": study, "N": N, "D": D, "L": L, "D_over_L": D / L, "contact_stiffness": stiffness,
               "direction": direction, "radius_of_gyration_change": rg[-1] - rg[0], "seconds": seconds}
        if path.instabilities:
            inst = path.instabilities[0]
            row.update(phi_star=inst.phi, phi_star_over_pi=inst.phi / PI, phi_error=inst.phi_error, kind=inst.kind,
                       multiplicity=inst.multiplicity, Wr_before=inst.equilibrium.Wr, Tw_before=inst.equilibrium.Tw)
        else:
            row.update(phi_star="", phi_star_over_pi="", phi_error="", kind=path.reason)
        new = not os.path.exists(CSV)
        with open(CSV, "a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=FIELDS)
            if new:
                w.writeheader()
            w.writerow(row)
        print(f"{study} N={N} D/L={D / L:.4f} kc={stiffness} {direction}: phi* = {row['phi_star_over_pi']} pi "
              f"({seconds:.0f} s)", flush=True)


def read():
    with open(CSV, newline="") as f:
        return list(csv.DictReader(f))


def report():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = read()
    lines = ["# Twisted trefoil: critical twists", "",
             "jaxrod sign convention, right-handed trefoil (Lk = 3 + phi/2pi). The tightening side is "
             "phi < 0 here (radius of gyration shrinks), the paper's phi > 0. Generated by "
             "`python benchmarks/trefoil.py report` from trefoil_critical.csv.", "", provenance_line(), "",
             "| study | N | D/L | kappa_c | side | phi*/pi | +- (rad) | kind | Wr before | Tw before | time (s) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        side = "tightening (phi<0)" if r["direction"] == "minus" else "opening (phi>0)"
        val = f"{float(r['phi_star_over_pi']):+.4f}" if r["phi_star_over_pi"] else "none"
        err = f"{float(r['phi_error']):.1e}" if r["phi_error"] else ""
        wr = f"{float(r['Wr_before']):.4f}" if r.get("Wr_before") else ""
        tw = f"{float(r['Tw_before']):.4f}" if r.get("Tw_before") else ""
        lines.append(f"| {r['study']} | {r['N']} | {float(r['D_over_L']):.4f} | {float(r['contact_stiffness']):g} | "
                     f"{side} | {val} | {err} | {r['kind']} | {wr} | {tw} | {float(r['seconds']):.0f} |")
    conv = {(int(r["N"]), r["direction"]): float(r["phi_star_over_pi"]) for r in rows
            if r["study"] == "convergence" and r["phi_star_over_pi"]}
    if conv:
        lines += ["", "Convergence (D, L) = (8, 292) mm: change of phi*/pi between resolutions", ""]
        for direction in ("minus", "plus"):
            ns = sorted(n for n, d in conv if d == direction)
            for a, b in zip(ns, ns[1:]):
                lines.append(f"- {direction}: N = {a} -> {b}: {conv[(a, direction)]:+.4f} -> {conv[(b, direction)]:+.4f} pi "
                             f"(change {conv[(b, direction)] - conv[(a, direction)]:+.4f} pi)")
    conv_t = {(int(r["N"]), r["direction"]): (float(r["phi_star_over_pi"]), float(r["seconds"])) for r in rows
              if r["study"] == "convergence" and r["phi_star_over_pi"]}
    if all((n, d) in conv_t for n in (61, 121, 241) for d in ("plus", "minus")):
        # Accuracy against cost: error of each resolution against the Richardson extrapolation of
        # the two finest (second order: phi_241 + (phi_241 - phi_121) / 3).
        fig, ax = plt.subplots(figsize=(5.5, 4))
        lines += ["", "Accuracy against time (error vs Richardson extrapolation of N = 121, 241):", ""]
        for d, marker in (("minus", "o"), ("plus", "s")):
            p121, p241 = conv_t[(121, d)][0], conv_t[(241, d)][0]
            ref = p241 + (p241 - p121) / 3.0
            pts = [(conv_t[(n, d)][1], abs(conv_t[(n, d)][0] - ref)) for n in (61, 121, 241)]
            ax.loglog(*zip(*pts), marker + "-", label=f"{'tightening' if d == 'minus' else 'opening'} side")
            for n, (t_, e_) in zip((61, 121, 241), pts):
                ax.annotate(f"N={n}", (t_, e_), fontsize=7)
                lines.append(f"- {d}, N = {n}: |phi* - phi*_R| = {e_:.4f} pi in {t_:.0f} s "
                             f"(phi*_R = {ref:+.4f} pi)")
        ax.set_xlabel("time per critical twist, one side (s, 2-core CPU)")
        ax.set_ylabel("|phi* - Richardson| / pi")
        ax.set_title("Trefoil critical twists: accuracy against time")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(os.path.join(RESULTS, "trefoil_convergence.png"), dpi=130)
        plt.close(fig)
    lines += ["", f"Michell estimates (nu = {NU}): tightening 2 x Michell = {2 * MICHELL / PI:.3f} pi, "
              f"opening Michell = {MICHELL / PI:.3f} pi. Paper (D/L = 0.0274, N = 121): simulation 11.6 pi and "
              "-8 pi; experiment ~10 pi and ~-8 pi (+-2 pi)."]
    with open(os.path.join(RESULTS, "trefoil_critical.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    swept = [r for r in rows if (r["study"] == "ratio" or (r["study"] == "convergence" and int(r["N"]) == SWEEP_N))
             and float(r["contact_stiffness"]) == 100.0 and float(r["L"]) / int(r["N"]) <= float(r["D"])]
    ratio = [r for r in swept if r["phi_star_over_pi"]]
    # Ratios where the whole span was followed without an instability ("phi_stop"): marked at the
    # span's edge, "no buckling within 16 pi", rather than dropped.
    unbuckled = [r for r in swept if not r["phi_star_over_pi"] and r["kind"] == "phi_stop"]
    if ratio:
        fig, ax = plt.subplots(figsize=(8, 4))
        for direction, marker, label in (("minus", "o", "tightening |phi*| (phi < 0)"), ("plus", "s", "opening phi* (phi > 0)")):
            pts = sorted((float(r["D_over_L"]), abs(float(r["phi_star_over_pi"]))) for r in ratio if r["direction"] == direction)
            if pts:
                ax.plot(*zip(*pts), marker + "-", label=label)
        for direction, colour, nudge in (("minus", "C0", 0.9985), ("plus", "C1", 1.0015)):  # side by side
            none = sorted(nudge * float(r["D_over_L"]) for r in unbuckled if r["direction"] == direction)
            if none:
                side = "tightening" if direction == "minus" else "opening"
                ax.plot(none, [16.0] * len(none), "^", color=colour, ms=9, mfc="none",
                        label=f"{side}: no buckling within 16 pi")
        ax.axhline(2 * MICHELL / PI, color="C0", ls="--", lw=1, label="2 x Michell (10.39 pi)")
        ax.axhline(MICHELL / PI, color="C1", ls="--", lw=1, label="Michell (5.20 pi)")
        ax.errorbar([8 / 292], [11.6], fmt="C0x", ms=8, label="paper simulation 11.6 pi / 8 pi")
        ax.errorbar([8 / 292], [8.0], fmt="C1x", ms=8)
        ax.errorbar([8 / 292 * 1.03], [10.0], yerr=2.0, fmt="C0^", mfc="none", label="paper experiment (+-2 pi)")
        ax.errorbar([8 / 292 * 1.03], [8.0], yerr=2.0, fmt="C1^", mfc="none")
        ax.set_xlabel("slenderness D / L (-)")
        ax.set_ylabel("|critical twist| / pi (rad / pi)")
        ax.set_title(f"Twisted trefoil, nu = 0.5, N = max({SWEEP_N}, L/D)")
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
        fig.tight_layout()
        fig.savefig(os.path.join(RESULTS, "trefoil_critical_vs_ratio.png"), dpi=130)
        plt.close(fig)
    print("\n".join(lines))


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "report"
    if SMOKE:  # one case, N = 61 (the fewest nodes whose relaxed knot is a minimum), a quarter turn each way
        case("convergence", 61, 8.0, span=(-0.25 * PI, 0.25 * PI))
    elif what == "convergence":
        for n in [int(a) for a in sys.argv[2:]] or [61, 121, 241]:
            case("convergence", n, 8.0)
    elif what == "ratio":
        for ratio in [float(a) for a in sys.argv[2:]] or [0.01, 0.015, 0.02, 0.025, 0.035, 0.0425, 0.05]:
            D = round(ratio * L, 6)
            # Contact needs edges no longer than the diameter (l <= D): a coarser rod has a bumpy
            # contact landscape along which a loose knot snaps in small spurious jumps (seen at
            # D/L = 0.005, N = 61: l = 3.3 D).
            case("ratio", max(SWEEP_N, 2 * math.ceil(L / D / 2) + 1), D)
    elif what == "stretch":
        for factor in [float(a) for a in sys.argv[2:]] or [10.0]:
            case(f"stretch_EAx{factor:g}", SWEEP_N, 8.0, ea_factor=factor)
    elif what == "stiffness":
        for kc in [float(a) for a in sys.argv[2:]] or [30.0, 300.0]:
            case("stiffness", SWEEP_N, 8.0, stiffness=kc)
    report()
