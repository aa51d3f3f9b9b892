"""The seed paper's method against the continuation, on the twisted trefoil's opening side.

Damped bead dynamics (``jaxrod.damped_dynamics``: the same energy, Langevin noise, the twist
ramped from the knot relaxed at phi = 0) at several ramp rates, each run to phi_stop; its writhe
trace against the twist, and where the writhe first leaves the symmetric branch, against the
continuation's branch end (``follow_twist``) at the same N. Writes
benchmarks/results/dynamics.{csv,md,png}.

    python benchmarks/dynamics.py [N] [rate ...]     # default N = 61, rates 1e-2 3e-3 1e-3
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import csv  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from _bench import SMOKE, markdown, pick, provenance_line, results_dir  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = results_dir()
PI = math.pi
D, L = 8.0, 292.0
PHI_STOP = pick(9.0 * PI, 0.05 * PI)  # small mode: a few chunks of the ramp
# The writhe of the symmetric branch grows by < 0.04 up to its end (3.055 -> 3.09 at N = 61);
# a state 0.15 above the start has left it.
LEFT_BRANCH = 0.15
# small mode: the continuation in whole turns of pi, its branch end located coarsely (None: the default)
CONT_STEP, CONT_TOL = pick(0.5 * PI, 1.0 * PI), pick(None, 1e-2 * PI)


def main(argv):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import jaxrod as jr

    N = int(argv[0]) if argv else pick(61, 41)
    rates = [float(a) for a in argv[1:]] or pick([1e-2, 3e-3, 1e-3], [1e-1])
    knot = jr.trefoil(D=D, L=L, N=N)
    # at N = 41 the relaxation without the stability check stops on a saddle: a minimum there
    start = (jr.relax_to_minimum(knot, 0.0) if SMOKE else
             jr.relax(knot, 0.0, options=jr.RelaxOptions(with_stability=False)))
    t0 = time.perf_counter()
    path = jr.follow_twist(knot, 0.0, 7.5 * PI, jr.ContinuationOptions(step=CONT_STEP, tol=CONT_TOL, switch=False),
                           start=start)
    t_cont = time.perf_counter() - t0
    phi_c, err_c = path.instabilities[0].phi, path.instabilities[0].phi_error
    print(f"continuation: branch end {phi_c / PI:.4f} pi +- {err_c / PI:.1e} in {t_cont:.1f} s (compilation included)")
    dt = jr.solve.dynamics.stable_time_step(knot, start.q, 0.0)
    rows, traces = [], []
    for rate in rates:
        r = jr.damped_dynamics(knot, 0.0, PHI_STOP, rate, start.q,
                               jr.DynamicsOptions(temperature=1e-8, dt=dt, chunk=pick(200, 20), stop_at_transition=False))
        left = np.flatnonzero(r.Wr - r.Wr[0] > LEFT_BRANCH)
        phi_left = float(r.phi[left[0] - 1]) if left.size else math.nan
        rows.append({"N": N, "rate": rate, "dt": r.dt, "steps": r.steps, "seconds": r.seconds,
                     "phi_left_branch_over_pi": phi_left / PI, "phi_writhe_jump_over_pi": r.transition_phi / PI,
                     "continuation_phi_over_pi": phi_c / PI, "continuation_seconds": t_cont,
                     "Wr_end": float(r.Wr[-1])})
        traces.append((rate, r.phi / PI, r.Wr))
        print(f"rate {rate:g}: {r.steps} steps in {r.seconds:.1f} s; leaves the branch after {phi_left / PI:.4f} pi; "
              f"writhe jump (> 0.3 within 0.1 pi) after {r.transition_phi / PI:.4f} pi; Wr end {r.Wr[-1]:.3f}")
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, "dynamics.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    fig, ax = plt.subplots(figsize=(8, 4.5))
    for rate, phi, wr in traces:
        ax.plot(phi, wr, lw=1.2, label=f"damped dynamics, ramp {rate:g} rad per unit time")
    ax.axvline(phi_c / PI, color="k", ls="--", lw=1, label=f"continuation: branch end {phi_c / PI:.3f} pi")
    ax.axvline(8.0, color="0.5", ls=":", lw=1, label="paper (opening): 8 pi")
    ax.set_xlabel("imposed twist phi / pi (rad / pi)")
    ax.set_ylabel("writhe Wr (turns)")
    ax.set_title(f"Trefoil (8, 292) mm, N = {N}: twist ramp against continuation", fontsize=10)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(os.path.join(RESULTS, "dynamics.png"), dpi=120)
    lines = [f"# Damped dynamics (the seed paper's method) against continuation, trefoil N = {N}, opening side", "",
             f"Continuation (`follow_twist`, step 0.5 pi, tol 2e-4 pi): branch end {phi_c / PI:.4f} pi in "
             f"{t_cont:.1f} s including compilation.", "",
             "| ramp rate | steps | wall time | leaves the symmetric branch after | overshoot | writhe jump (> 0.3 within 0.1 pi) after | Wr at 9 pi |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['rate']:g} | {r['steps']} | {r['seconds']:.1f} s | {r['phi_left_branch_over_pi']:.3f} pi | "
                     f"{r['phi_left_branch_over_pi'] - phi_c / PI:+.3f} pi | {r['phi_writhe_jump_over_pi']:.3f} pi | "
                     f"{r['Wr_end']:.3f} |")
    with open(os.path.join(RESULTS, "dynamics.md"), "w") as f:
        f.write(markdown(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1:])
