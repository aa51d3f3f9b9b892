"""Michell's ring: accuracy against time for phi*(N), N = 32, 64, 128, 256, and Richardson.

Side by side in one process, for every N and the same tolerance (1e-6 pi):
  * jaxrod.critical_twist: scan on the negative count, then Newton on the crossing eigenvalue with
    its autodiff derivative along the branch;
  * baseline: the same scan, then bisection on the negative count (one equilibrium + one full
    spectrum per halving), the usual way to locate a threshold without eigenvalue derivatives.
Each is run once to compile and once timed; the table gives the timed run (compile apart).

Writes benchmarks/results/michell.md (table) and benchmarks/results/michell.png (chart).
Run: python benchmarks/michell.py   (about 5 minutes on 2 cores)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import math  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402

import jaxrod  # noqa: E402
from jaxrod import EquilibriumOptions, critical_twist, michell_critical_twist, michell_ring, solve_equilibrium  # noqa: E402,E501

from _bench import SMOKE, markdown, pick, provenance_line, results_dir  # noqa: E402,F401  (benchmarks/ is on the path)
NEWTON_EXACT_COUNT = EquilibriumOptions(method="newton", negative_tol=0.0)
from jaxrod.io.plotting import plot_convergence  # noqa: E402

NU = 0.5
TOL = 1e-6 * math.pi
NS = pick((32, 64, 128, 256), (8, 16, 32))
N1, N2, N3 = NS[-3:]  # Richardson from the last three
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = results_dir()


def ours(scene, analytic):
    cp = critical_twist(scene, 0.0, 2 * analytic, jaxrod.ContinuationOptions(step=analytic / 8, tol=TOL))
    return cp.phi, len(cp.scan) + cp.hessian_evaluations


def bisection(scene, analytic):
    """Scan like critical_twist, then halve the bracket on the negative count until < TOL.

    An eigenvalue counts as negative below 0 exactly (any threshold -t would bias the result by
    t / |d lambda / d phi|: with jaxrod's default t = 1e-10 that is 1e-5 pi at N = 128)."""
    step = analytic / 8
    eq = solve_equilibrium(scene, 0.0, options=EquilibriumOptions(negative_tol=0.0))
    count0, evals = eq.stability.n_negative, 1
    lo = eq
    while True:
        hi = solve_equilibrium(scene, lo.phi + step, lo.q, NEWTON_EXACT_COUNT)
        evals += 1
        if hi.stability.n_negative != count0:
            break
        lo = hi
    while hi.phi - lo.phi > TOL:
        mid = solve_equilibrium(scene, 0.5 * (lo.phi + hi.phi), lo.q, NEWTON_EXACT_COUNT)
        evals += 1
        if mid.stability.n_negative == count0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo.phi + hi.phi), evals


def timed(fn, scene, analytic):
    t = time.perf_counter()
    fn(scene, analytic)  # compile + run
    first = time.perf_counter() - t
    t = time.perf_counter()
    phi, evals = fn(scene, analytic)
    return phi, evals, time.perf_counter() - t, first


def main():
    os.makedirs(OUT, exist_ok=True)
    analytic = michell_critical_twist(NU)
    rows = []
    for N in NS:
        scene = michell_ring(N=N, nu=NU)
        for label, fn in (("jaxrod (Newton on eigenvalue)", ours), ("baseline (bisection on count)", bisection)):
            phi, evals, secs, first = timed(fn, scene, analytic)
            rel = (phi - analytic) / analytic
            rows.append(dict(label=label, N=N, phi=phi, rel_error=rel, seconds=secs, first=first, evals=evals))
            print(f"{label:32s} N={N:4d} phi*={phi / math.pi:.10f} pi rel={rel:.3e} "
                  f"time={secs:.2f}s (first call {first:.1f}s) evaluations={evals}", flush=True)

    ours_rows = {r["N"]: r for r in rows if r["label"].startswith("jaxrod")}
    base_rows = {r["N"]: r for r in rows if r["label"].startswith("baseline")}
    orders = [math.log2(ours_rows[a]["rel_error"] / ours_rows[b]["rel_error"]) for a, b in zip(NS[:-1], NS[1:])]
    rich = (4 * ours_rows[N3]["phi"] - ours_rows[N2]["phi"]) / 3
    # Order estimated from phi*(N1), phi*(N2), phi*(N3) alone (no analytic value used).
    f64, f128, f256 = (ours_rows[n]["phi"] for n in (N1, N2, N3))
    p = math.log2((f64 - f128) / (f128 - f256))
    rich_p = f256 + (f256 - f128) / (2**p - 1)
    rich_rel = (rich - analytic) / analytic
    rich_p_rel = (rich_p - analytic) / analytic
    rich_secs = ours_rows[N2]["seconds"] + ours_rows[N3]["seconds"]

    lines = [
        "# Michell's ring: critical twist against resolution",
        "",
        f"nu = {NU}, analytic phi* = 2 pi sqrt(3) (1 + nu) = {analytic / math.pi:.10f} pi; slenderness D/R = 0.01; "
        f"tolerance {TOL / math.pi:.0e} pi. Machine: {platform.machine()}, {os.cpu_count()} cores, "
        f"jax {jaxrod.jax.__version__}, BLAS threads 1. Times are the second (compiled) run; "
        "'first call' includes JIT compilation.",
        "",
        "| N | phi*/pi | rel. error | observed order | time (s) | first call (s) | evals | baseline time (s) | baseline evals | speed-up |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for i, N in enumerate(NS):
        o, b = ours_rows[N], base_rows[N]
        order = f"{orders[i - 1]:.3f}" if i > 0 else ""
        lines.append(
            f"| {N} | {o['phi'] / math.pi:.10f} | {o['rel_error']:.3e} | {order} | {o['seconds']:.2f} | "
            f"{o['first']:.1f} | {o['evals']} | {b['seconds']:.2f} | {b['evals']} | {b['seconds'] / o['seconds']:.2f}x |"
        )
    lines += [
        "",
        f"Richardson (N = {N2}, {N3}, order 2): phi* = {rich / math.pi:.10f} pi, rel. error {rich_rel:.2e} "
        f"(cost {rich_secs:.2f} s).",
        f"Richardson with the order estimated from N = {N1}, {N2}, {N3} without the analytic value "
        f"(p = {p:.4f}): rel. error {rich_p_rel:.2e}.",
        "",
        "Both methods agree on phi*(N) to within the tolerance. 'evals' counts equilibrium solves with a full "
        "spectrum: for both, the scan steps; then the bisection's halvings, or our refinement's "
        "eigenvalue-and-derivative evaluations.",
        "",
        "![accuracy against time](michell.png)",
    ]
    with open(os.path.join(OUT, "michell.md"), "w") as f:
        f.write(markdown(lines))
    chart_rows = [dict(r) for r in rows]
    chart_rows.append(dict(label=f"jaxrod + Richardson ({N2}, {N3})", N=N3, rel_error=rich_rel, seconds=rich_secs))
    plot_convergence(chart_rows, os.path.join(OUT, "michell.png"),
                     title="Michell ring: |relative error of phi*| against time")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
