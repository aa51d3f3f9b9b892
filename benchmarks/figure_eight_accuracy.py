"""The figure-eight knot's critical twists with error bars: ``converged_critical_twists`` (each level
started from the previous one's state, resampled; Richardson with the order measured) to 0.05 pi at
D/L = 0.02 (N = 151, 201, 251) and 0.015 (N = 101 ... 251), both sides, nu = 0.5, contact stiffness
100 B/D^3. The knot is amphichiral: where the relaxed start is its own mirror image (to
``chirality.ACHIRAL_TOL``) the two sides must agree, phi*+ = -phi*-, within their error bars.
Writes figure_eight_accuracy.json / .md / .png.

    python benchmarks/figure_eight_accuracy.py
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
from jaxrod.io.plotting import plot_resolution_convergence  # noqa: E402
from jaxrod.measure.chirality import ACHIRAL_TOL, mirror_distance  # noqa: E402
from jaxrod.solve.equilibrium import relax_twist_free  # noqa: E402
from jaxrod.studies.accuracy import converged_critical_twists  # noqa: E402

from _bench import markdown, pick, results_dir, with_provenance  # noqa: E402  (benchmarks/ is on the path)

RESULTS = results_dir()
ACCURACY = pick(0.05, 1.0) * math.pi
# small mode: the stiffer knot at the fewest nodes its contact allows, three close levels, a coarse step
CASES = pick({0.02: (151, 201, 251), 0.015: (101, 151, 201, 251)}, {0.025: (41, 45, 49)})
STEP = pick(0.5, 1.0) * math.pi


def run_case(ratio, levels, t0):
    scene = jr.knot("4_1", D=ratio, L=1.0, N=levels[0], nu=0.5, contact_stiffness=100.0)
    scene, start = relax_twist_free(scene)
    say = lambda s: print(f"[{time.perf_counter() - t0:6.1f} s] D/L = {ratio:g}: {s}", file=sys.stderr, flush=True)  # noqa: E731
    result = converged_critical_twists(scene, ACCURACY, levels=levels, step=STEP, progress=say,
                                       out=tempfile.mkdtemp(prefix="jaxrod-figure-eight-"))
    distance = mirror_distance(start.x)
    case = {"D_over_L": ratio, "levels": list(levels), "Lk0": int(round(float(scene.Lk0))),
            "mirror_distance_start": distance, "start": "achiral" if distance <= ACHIRAL_TOL else "chiral",
            "Wr_start": float(start.Wr), "sides": {side: r.as_json() for side, r in result.items()}}
    plus, minus = result["plus"], result["minus"]
    if plus.phi_star is not None and minus.phi_star is not None:
        case["asymmetry"] = abs(plus.phi_star + minus.phi_star)
        case["asymmetry_over_pi"] = case["asymmetry"] / math.pi
        case["error_sum_over_pi"] = (plus.error + minus.error) / math.pi
        case["mirror_sides_within_error"] = bool(case["asymmetry"] <= plus.error + minus.error)
    return case, result


def table(cases):
    """The Markdown table: a row per (D/L, side)."""
    rows = ["| D/L | side | levels N: phi*/pi | extrapolated phi*/pi | error / pi | accuracy reached | "
            "start's mirror distance |", "|---|---|---|---|---|---|---|"]
    for c in cases:
        for side, s in c["sides"].items():
            levels = ", ".join(f"{lv['N']}: {lv['phi_star_over_pi']:+.4f}" for lv in s["levels"])
            value = "none" if s["phi_star_over_pi"] is None else f"{s['phi_star_over_pi']:+.4f}"
            rows.append(f"| {c['D_over_L']:g} | {side} | {levels} | {value} | {s['error_over_pi']:.3f} | "
                        f"{'yes' if s['reached'] else 'no'} | {c['mirror_distance_start']:.4f} ({c['start']}) |")
    return rows


def main():
    t0 = time.perf_counter()
    cases, results = [], {}
    for ratio, levels in CASES.items():
        case, results[ratio] = run_case(ratio, levels, t0)
        cases.append(case)
    seconds = time.perf_counter() - t0
    data = {"knot": "4_1", "accuracy_over_pi": ACCURACY / math.pi, "achiral_tol": ACHIRAL_TOL, "nu": 0.5,
            "contact_stiffness": 100.0, "cases": cases, "seconds": seconds}
    with open(os.path.join(RESULTS, "figure_eight_accuracy.json"), "w") as f:
        json.dump(with_provenance(data), f, indent=2)
    first = next(iter(CASES))
    plot_resolution_convergence(results[first], os.path.join(RESULTS, "figure_eight_accuracy.png"),
                                title=f"Figure-eight knot, D/L = {first:g}: critical twists converged in N")
    lines = ["# The figure-eight knot's critical twists with error bars", "", *table(cases), ""]
    for c in cases:
        if "asymmetry_over_pi" in c and all(side["reached"] for side in c["sides"].values()):
            lines.append(f"- D/L = {c['D_over_L']:g}: |phi*+ + phi*-| = {c['asymmetry_over_pi']:.5f} pi against the "
                         f"error bars' sum {c['error_sum_over_pi']:.4f} pi (start {c['start']})")
        for side, s in c["sides"].items():
            lines.append(f"- D/L = {c['D_over_L']:g}, {side}: {s['reason']}")
    lines.append(f"\n{seconds:.0f} s on this machine.")
    with open(os.path.join(RESULTS, "figure_eight_accuracy.md"), "w") as f:
        f.write(markdown(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
