"""The trefoil's critical twists as the knot loosens, against the limits derived from the doubly
covered twisted ring.

As D/L -> 0 the elastic trefoil tends to the circle of radius R = L / (4 pi) traversed twice
(Gerlach, Reiter & von der Mosel, ARMA 2017). Michell's criterion for a twisted ring, C w R / B =
sqrt(m^2 - 1) for a perturbation of m waves per turn (Goriely, J. Elasticity 2006), admits
half-integer m on a doubly covered circle (k = 2m waves along the whole rod). With the whole
twist phi = w L = 4 pi R w:

    k = 3 (the trefoil's own three lobes):  phi = 2 pi sqrt(5) B / C = 2 pi sqrt(5) (1 + nu)
    k = 4:                                  phi = 4 pi sqrt(3) B / C = 2 x Michell's 2 pi sqrt(3) (1 + nu)

(6.7082 pi and 10.3923 pi at nu = 0.5). Each D/L below is converged in N by the accuracy mode
(``jaxrod.studies.accuracy.converged_critical_twists``: Richardson with the order measured from
three levels, edges from about 0.85 D down to 0.4 D), with its error estimate.

Writes benchmarks/results/loose_limit.{json,md,png} (loose_limit_nu<nu>.* for another --nu); each
D/L's levels are kept in
benchmarks/results/loose_limit_levels/ as they finish (a rerun reuses them; not committed: the states).
Run: python benchmarks/loose_limit.py [--nu 0.5] [--min-ratio 0.002]   (about 10 minutes on 2 cores)
The small mode: the paper's rod (D/L = 0.0274) at N = 41, 45, 49, the opening side, to 1 pi.
"""
import json
import math
import os
import sys
import time

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import jaxrod as jr  # noqa: E402
from jaxrod.studies.accuracy import converged_critical_twists  # noqa: E402

from _bench import markdown, pick, results_dir, with_provenance  # noqa: E402  (benchmarks/ is on the path)

PI, L = math.pi, 292.0


def _nu(argv):
    import argparse

    ap = argparse.ArgumentParser(description="the loose trefoil's critical twists against the doubly covered ring")
    ap.add_argument("--nu", type=float, default=0.5, help="Poisson ratio (default 0.5)")
    ap.add_argument("--min-ratio", type=float, default=0.002, help="the smallest D/L (default 0.002)")
    args = ap.parse_args(argv)
    return args.nu, args.min_ratio


NU, MIN_RATIO = _nu(sys.argv[1:])
STEM = "loose_limit" if NU == 0.5 else f"loose_limit_nu{NU:g}"
# D/L and its levels N (edges L / N about 0.85 D, 0.6 D and 0.4 D; more where three do not reach the accuracy)
LEVELS = pick({0.035: (41, 57, 81, 115, 161), 0.0274: (41, 57, 81, 115, 161, 241, 337),
               0.02: (61, 85, 121, 171, 241), 0.015: (81, 113, 161, 227), 0.01: (121, 161, 241, 337),
               0.0075: (161, 227, 321), 0.005: (241, 337, 481), 0.0035: (337, 481, 685), 0.0025: (481, 673, 961), 0.002: (601, 841, 1201)},
             {0.0274: (41, 45, 49)})
SIDES = pick(("plus", "minus"), ("plus",))
FIT_MAX = pick(0.02, 0.03)  # the approach law is fitted to the loose knots only (D/L <= 0.02): it is asymptotic
ACCURACY = pick(0.02, 1.0) * PI
STEP = pick(0.5, 1.0) * PI
OUT = results_dir()


def limits(nu):
    """The doubly covered ring's first two instabilities (rad): k = 3 and k = 4 waves along the rod."""
    return {"k3": 2.0 * PI * math.sqrt(5.0) * (1.0 + nu), "k4": 4.0 * PI * math.sqrt(3.0) * (1.0 + nu)}


def run_ratio(ratio, levels):
    knot = jr.trefoil(D=ratio * L, L=L, N=levels[0], nu=NU)
    t = time.perf_counter()
    result = converged_critical_twists(knot, ACCURACY, sides=SIDES, levels=levels, step=STEP,
                                       out=os.path.join(OUT, "loose_limit_levels", f"nu_{NU:g}_ratio_{ratio:g}"),
                                       progress=lambda s: print(f"  {s}", file=sys.stderr, flush=True))
    rows = []
    for side, r in result.items():
        row = dict(D_over_L=ratio, **r.as_json())
        rows.append(row)
        print(f"D/L = {ratio:g}, {side}: {r.phi_star / PI:+.5f} pi +- {r.error / PI:.1e} pi ({r.reason}); "
              f"{time.perf_counter() - t:.0f} s", flush=True)
    return rows


def main():
    rows = [row for ratio, levels in LEVELS.items() if ratio >= MIN_RATIO for row in run_ratio(ratio, levels)]
    lim = limits(NU)
    data = dict(L=L, nu=NU, accuracy_over_pi=ACCURACY / PI, limits_over_pi={k: v / PI for k, v in lim.items()},
                michell_over_pi=2.0 * math.sqrt(3.0) * (1.0 + NU), rows=rows,
                approach={side: approach_law(rows, side, lim) for side in SIDES})
    with open(os.path.join(OUT, f"{STEM}.json"), "w") as f:
        json.dump(with_provenance(data), f, indent=1)
    lines = ["# The trefoil's critical twists as the knot loosens", "",
             f"L = {L:g} mm, nu = {NU}; converged in N to {ACCURACY / PI:g} pi (`benchmarks/loose_limit.py`). "
             f"Doubly covered ring: k = 3 at {lim['k3'] / PI:.4f} pi, k = 4 at {lim['k4'] / PI:.4f} pi "
             f"(2 x Michell); Michell's single ring {data['michell_over_pi']:.4f} pi.", "",
             "| D/L | side | phi*/pi | error/pi | levels N | order | distance to the limit/pi |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        target = lim["k3"] if r["side"] == "plus" else -lim["k4"]
        lines.append(f"| {r['D_over_L']:g} | {r['side']} | {r['phi_star'] / PI:+.5f} | {r['error'] / PI:.1e} | "
                     f"{', '.join(str(lv['N']) for lv in r['levels'])} | {_order(r)} | "
                     f"{(r['phi_star'] - target) / PI:+.4f} |")
    for side, law in data["approach"].items():
        if law:
            lines.append("")
            lines.append(f"{side}: |phi*| - limit = {law['coefficient_over_pi']:.4g} pi (D/L)^p, p = "
                         f"{law['exponent']:.2f} +- {law['exponent_error']:.2f} (weighted by the error bars; "
                         f"D/L = {', '.join(f'{x:g}' for x in law['points'])}: the gaps above twice their error)")
    with open(os.path.join(OUT, f"{STEM}.md"), "w") as f:
        f.write(markdown(lines))
    figure(rows, lim, data["michell_over_pi"])


def approach_law(rows, side, lim):
    """|phi*| - limit = c (D/L)^p fitted to the side's loose points (D/L <= FIT_MAX) whose gap is at
    least twice their error and whose levels were in their asymptotic range (weighted least squares in logs, each point's
    weight its gap over its error): {"exponent", "exponent_error", "coefficient_over_pi", "points"},
    or None with fewer than three such points."""
    import numpy as np

    limit = lim["k3"] if side == "plus" else lim["k4"]
    mine = [r for r in rows if r["side"] == side and r["D_over_L"] <= FIT_MAX and r["phi_star"] is not None
            and r["extrapolation"]
            and r["extrapolation"]["asymptotic"] and abs(abs(r["phi_star"]) - limit) >= 2.0 * r["error"]]
    if len(mine) < 3:
        return None
    x = np.log([r["D_over_L"] for r in mine])
    gap = np.array([abs(r["phi_star"]) - limit for r in mine])
    w = np.abs(gap) / np.maximum([r["error"] for r in mine], 1e-12)  # 1 / the error of log|gap|
    A = np.stack([np.ones_like(x), x], axis=1) * w[:, None]
    coef, *_ = np.linalg.lstsq(A, np.log(np.abs(gap)) * w, rcond=None)
    cov = np.linalg.inv(A.T @ A)
    return {"exponent": float(coef[1]), "exponent_error": float(math.sqrt(cov[1, 1])),
            "coefficient_over_pi": float(math.copysign(math.exp(coef[0]), gap[-1]) / PI),
            "points": [r["D_over_L"] for r in mine]}


def _order(row):
    ex = row.get("extrapolation")
    if not ex:
        return ""
    return f"{ex['order']:.2f}" + ("" if ex["order_measured"] else " (assumed)")


def figure(rows, lim, michell):
    import matplotlib.pyplot as plt
    import numpy as np

    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11.0, 4.2))
    for side, colour, target, name in (("plus", "C0", lim["k3"], "opening (φ > 0)"),
                                       ("minus", "C3", -lim["k4"], "tightening (φ < 0)")):
        mine = sorted((r for r in rows if r["side"] == side), key=lambda r: r["D_over_L"])
        if mine:
            ax.errorbar([r["D_over_L"] for r in mine], [abs(r["phi_star"]) / PI for r in mine],
                        yerr=[r["error"] / PI for r in mine], fmt="o-", color=colour, capsize=3,
                        label=f"{name}, converged in N")
        ax.axhline(abs(target) / PI, color=colour, ls="--", lw=1,
                   label=("doubly covered ring, k = 3: 2π√5(1+ν)" if side == "plus"
                          else "doubly covered ring, k = 4: 4π√3(1+ν) = 2 × Michell"))
    ax.axhline(michell, color="0.5", ls=":", lw=1, label="Michell's single ring 2π√3(1+ν)")
    ax.set_xlim(left=0.0)
    ax.set_xlabel("slenderness D/L")
    ax.set_ylabel("|φ*| / π")
    ax.set_title(f"Trefoil, ν = {NU}: the loose limit")
    ax.legend(fontsize=7, loc="center right")
    for side, colour, limit, name in (("plus", "C0", lim["k3"], "opening: 2π√5(1+ν) − φ*"),
                                      ("minus", "C3", lim["k4"], "tightening: |φ*| − 4π√3(1+ν)")):
        mine = sorted((r for r in rows if r["side"] == side), key=lambda r: r["D_over_L"])
        # gaps out of their error bars, where the bar is an error estimate (levels in their asymptotic range)
        shown = [r for r in mine if abs(abs(r["phi_star"]) - limit) > r["error"] and r["extrapolation"]["asymptotic"]]
        if shown:
            bx.errorbar([r["D_over_L"] for r in shown], [abs(abs(r["phi_star"]) - limit) / PI for r in shown],
                        yerr=[r["error"] / PI for r in shown], fmt="o", color=colour, capsize=3, label=name)
    x = np.array([0.002, 0.035])
    bx.loglog(x, 0.1 * (x / 0.02) ** 2, "k--", lw=1, label="slope 2")
    ticks = [0.002, 0.005, 0.01, 0.02, 0.035]
    bx.set_xticks(ticks, [f"{t:g}" for t in ticks])
    bx.minorticks_off()
    bx.set_xlabel("slenderness D/L")
    bx.set_ylabel("distance from the limit / π")
    bx.set_title("Approach to the limits (gaps larger than their error bars)")
    bx.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, f"{STEM}.png"), dpi=120)
    plt.close(fig)


if __name__ == "__main__":
    main()
