"""Which buckled shape does the seed paper's method select after the opening transition?

Two protocols on the trefoil (8, 292) mm at N nodes, each ending with a relaxation to a minimum.
Released: the last stable symmetric state, put at phi* + 0.1 pi (past the branch end, where it
is no longer an equilibrium), evolves under noisy damped dynamics (temperature T, several seeds)
at almost fixed twist: the shape dynamics picks among those available right after the
transition. Ramp (the paper's protocol): from the relaxed knot at one rate until the writhe has
left the symmetric branch (|Wr - Wr(0)| > 0.15), then 0.5 pi more: a fast ramp overshoots the
end by several pi and lands far from it. Its curvature profile kappa(s) L is counted: peaks
(``analysis.count_peaks``) and symmetry order (``analysis.symmetry_order``). The continuation's
branch switch at the branch end (``follow_twist``, one switch) gives the other answer. The paper
reports a 2-fold profile after the opening transition; the continuation's switch keeps 3 peaks.

Writes benchmarks/results/dynamics_shape.{csv,md,npz} (profiles in the npz for the notebook).

    python benchmarks/dynamics_shape.py [N] [rate] [T ...]     # default N = 121, rate 1e-2, T = 1e-8 1e-6
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
SEEDS = pick((1, 2), (1,))
# the twist ranges of the dynamics runs (release: its span and rate; ramp: its end, then the further
# span); the small mode runs a few chunks of each
RELEASE_SPAN, RELEASE_RATE = pick((0.02 * PI, 2e-5), (0.002 * PI, 1e-1))
RAMP_END, RAMP_MORE = pick((14.0 * PI, 0.5 * PI), (0.05 * PI, 0.05 * PI))
# the continuation with its branch switch: its largest step and where it stops (the small mode: steps
# of 2 pi, which pass the near-crossing at 5.6 pi that steps of 1 pi halve down to, and a stop just past
# the end at 6.6 pi)
SWITCH_STEP, SWITCH_STOP = pick(0.5, 2.0) * PI, pick(9.0, 7.0) * PI


def main(argv):
    import jaxrod as jr
    from jaxrod.measure.analysis import count_peaks, symmetry_order
    from jaxrod.io.records import step_record

    N = int(argv[0]) if argv else pick(121, 61)
    rate = float(argv[1]) if len(argv) > 1 else pick(1e-2, 1e-1)
    temperatures = [float(a) for a in argv[2:]] or pick([1e-8, 1e-6], [1e-6])
    knot = jr.trefoil(D=8.0, L=292.0, N=N)
    start = jr.relax_to_minimum(knot, 0.0)
    rows, profiles = [], {}
    t0 = time.perf_counter()
    path = jr.follow_twist(knot, 0.0, SWITCH_STOP, jr.ContinuationOptions(step=SWITCH_STEP, switch=True,
                                                                         max_switches=1), start=start)
    first = next(p for p in path.points if not p.branch.startswith("symmetric"))
    _, extra = step_record(knot, first.equilibrium)
    profiles["continuation"] = extra["kappa_L"]
    profiles["s_over_L"] = extra["s_over_L"]
    rows.append({"method": "continuation (branch switch)", "T": "", "seed": "", "phi_over_pi": first.equilibrium.phi / PI,
                 "Wr": first.equilibrium.Wr, "peaks": count_peaks(extra["kappa_L"]),
                 "symmetry_order": symmetry_order(extra["kappa_L"]), "seconds": time.perf_counter() - t0})
    print(rows[-1], flush=True)
    dt = jr.solve.dynamics.stable_time_step(knot, start.q, 0.0)
    end = path.instabilities[0]
    last = end.equilibrium  # the last stable symmetric state, just before the branch end

    def settled(label, T, seed, q, phi, t0):
        e = jr.relax_to_minimum(knot, phi, q)
        _, extra = step_record(knot, e)
        profiles[f"{label.split(',')[0].replace(' ', '_')}_T{T:g}_seed{seed}"] = extra["kappa_L"]
        rows.append({"method": label, "T": T, "seed": seed, "phi_over_pi": e.phi / PI, "Wr": e.Wr,
                     "peaks": count_peaks(extra["kappa_L"]), "symmetry_order": symmetry_order(extra["kappa_L"]),
                     "seconds": time.perf_counter() - t0})
        print(rows[-1], flush=True)

    # Released just past the end: the symmetric state at phi* + 0.1 pi (no longer an equilibrium)
    # under noisy damped dynamics at (almost) fixed twist, then relaxed: the shape that the
    # dynamics picks among those available right after the transition.
    for T in temperatures:
        for seed in SEEDS:
            t0 = time.perf_counter()
            phi0 = end.phi + 0.1 * PI
            r = jr.damped_dynamics(knot, phi0, phi0 + RELEASE_SPAN, RELEASE_RATE, last.q,
                                   jr.DynamicsOptions(temperature=T, dt=dt, stop_at_transition=False, seed=seed))
            settled("damped dynamics, released at phi* + 0.1 pi", T, seed, r.q, float(r.phi[-1]), t0)
    # A ramp (the paper's protocol) at the given rate: where it leaves the branch, 0.5 pi more.
    t0 = time.perf_counter()
    r = jr.damped_dynamics(knot, 0.0, RAMP_END, rate, start.q,
                           jr.DynamicsOptions(temperature=temperatures[-1], dt=dt, departure=0.15, seed=SEEDS[0]))
    phi = float(r.phi[-1])
    more = jr.damped_dynamics(knot, phi, phi + RAMP_MORE, rate, r.q,
                              jr.DynamicsOptions(temperature=temperatures[-1], dt=dt, stop_at_transition=False,
                                                 seed=SEEDS[0] + 100))
    settled(f"damped dynamics, ramp {rate:g}", temperatures[-1], SEEDS[0], more.q, float(more.phi[-1]), t0)
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, "dynamics_shape.csv"), "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    np.savez(os.path.join(RESULTS, "dynamics_shape.npz"), **profiles)
    lines = [f"# Shape after the opening transition, trefoil (8, 292) mm, N = {N}", "",
             "Generated by `python benchmarks/dynamics_shape.py` (see its docstring for the two dynamics protocols); "
             "each dynamics state relaxed to a minimum at its twist before its profile is counted.", "",
             "| method | T | seed | phi/pi | Wr | curvature peaks | symmetry order | time (s) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['method']} | {r['T']} | {r['seed']} | {r['phi_over_pi']:.3f} | {r['Wr']:.3f} | "
                     f"{r['peaks']} | {r['symmetry_order']} | {r['seconds']:.0f} |")
    with open(os.path.join(RESULTS, "dynamics_shape.md"), "w") as f:
        f.write(markdown(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main(sys.argv[1:])
