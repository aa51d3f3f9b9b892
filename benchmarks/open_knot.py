"""An open overhand knot pulled tight (issue 19, item 4): loop size against the tension T.

A trefoil-shaped open knot (``jaxrod.open_knot.open_overhand_knot``) in a rod of length L = 1,
B = 1, diameter D, clamped on the z axis with self-contact (kappa_c = 100), is pulled by moving
the far clamp away (displacement control: the excess length e = L - end distance decreases
geometrically), at end rotations phi = 0 and +-2 pi (Lk = 3 + phi/2pi conserved: no strand passage).
At each state: T (exact, dE/d(end distance)), the loop height (largest distance from the axis),
Wr, Tw, Lk, the Morse index under the rigid loading. Fits e = c_e sqrt(B/T) and
height = c_h sqrt(B/T) (and the free exponent) per phi; the planar elastica loop (outer solution
of a loose knot) has c_e = 4, c_h = 2.

    python benchmarks/open_knot.py            # ~10 min on 2 cores (the three phi in 2 processes)
writes benchmarks/results/open_knot.csv, open_knot.json, open_knot.png.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "results")
N, L, D, LOOP = 160, 1.0, 1.0 / 150, 0.012
PHIS = (0.0, 2 * math.pi, -2 * math.pi)
N_STEPS = 6


def one(phi, path):
    import numpy as np

    sys.path.insert(0, os.path.dirname(HERE))
    from jaxrod import open_knot as ok

    t0 = time.time()
    scene, q = ok.open_overhand_knot(N, L, D, LOOP, phi=phi)
    e0 = float(scene.shortening)
    excesses = np.geomspace(e0, 0.62 * e0, N_STEPS)
    states = []

    def save():
        dump(phi, path, states, t0)

    def say(s):
        print(f"[phi={phi:+.3f}] {s}", flush=True)

    scene_q = (scene, q)
    prev = None
    for v in excesses:  # one state at a time, the results saved after each (a long run can be cut)
        got = ok.pull(scene_q[0], scene_q[1], [v], phi=phi, progress=say, previous=prev)
        if not got:
            break
        states.append(got[0])
        prev = got[0]
        scene_q = (ok._moved(scene_q[0], got[0].q, v)[0], got[0].q)
        save()


def dump(phi, path, states, t0):
    rows = [dict(phi=s.phi, excess=s.excess, T=s.T, M=s.M, height=s.height, Wr=s.Wr, Tw=s.Tw, Lk=s.Lk,
                 morse=s.morse, lowest=float(s.lowest[0]), contacts=s.contacts, energy=s.energy) for s in states]
    with open(path, "w") as f:
        json.dump(dict(rows=rows, wall_s=time.time() - t0, x_last=states[-1].x.tolist() if states else None,
                       x_first=states[0].x.tolist() if states else None), f)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--one", type=float, default=None)
    ap.add_argument("--to", default=None)
    ap.add_argument("--combine", action="store_true", help="combine the per-phi files already written")
    ap.add_argument("--parallel", type=int, default=3)
    a = ap.parse_args()
    if a.one is not None:
        one(a.one, a.to)
        return
    import numpy as np

    sys.path.insert(0, os.path.dirname(HERE))
    from jaxrod.open_knot import ELASTICA_EXCESS, ELASTICA_HEIGHT, fit_prefactor

    os.makedirs(OUT, exist_ok=True)
    parts = {phi: os.path.join("/tmp", f"open_knot_{phi:+.4f}.json") for phi in PHIS}
    t0 = time.time()
    pending = list(PHIS)
    running = []
    if a.combine:  # only combine the parts already written
        pending = []
    while pending or running:
        while pending and len(running) < a.parallel:
            phi = pending.pop(0)
            running.append(subprocess.Popen([sys.executable, __file__, "--one", repr(phi), "--to", parts[phi]]))
        if a.combine:
            break
        running[0].wait()
        running = [p for p in running if p.poll() is None]
    results = {}
    for phi in PHIS:
        with open(parts[phi]) as f:
            results[phi] = json.load(f)
    wall = time.time() - t0
    fits = {}
    lines = ["phi,excess,T,M,height,Wr,Tw,Lk,morse,lowest,contacts,energy"]
    for phi in PHIS:
        rows = results[phi]["rows"]
        for r in rows:
            lines.append(",".join(f"{r[k]:.10g}" for k in ("phi", "excess", "T", "M", "height", "Wr", "Tw", "Lk",
                                                            "morse", "lowest", "contacts", "energy")))
        T = np.array([r["T"] for r in rows])
        ok = T > 0
        if np.sum(ok) >= 3:
            ce = fit_prefactor(T[ok], np.array([r["excess"] for r in rows])[ok])
            ch = fit_prefactor(T[ok], np.array([r["height"] for r in rows])[ok])
            fits[f"{phi:+.4f}"] = dict(c_excess=ce[0], c_excess_std=ce[1], p_excess=ce[2], p_excess_std=ce[3],
                                       c_height=ch[0], c_height_std=ch[1], p_height=ch[2], p_height_std=ch[3],
                                       T_range=[float(T[ok].min()), float(T[ok].max())],
                                       Lk_range=[min(r["Lk"] for r in rows), max(r["Lk"] for r in rows)],
                                       morse=[r["morse"] for r in rows], n_states=len(rows),
                                       wall_s=results[phi]["wall_s"])
    with open(os.path.join(OUT, "open_knot.csv"), "w") as f:
        f.write("\n".join(lines) + "\n")
    with open(os.path.join(OUT, "open_knot.json"), "w") as f:
        json.dump(dict(N=N, L=L, D=D, loop=LOOP, B=1.0, nu=0.5, contact_stiffness=100.0, fits=fits,
                       elastica=dict(c_excess=ELASTICA_EXCESS, c_height=ELASTICA_HEIGHT), wall_s=wall), f, indent=1)
    print(json.dumps(fits, indent=1))

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 3, figsize=(15, 4.6))
    colors = {0.0: "k", 2 * math.pi: "tab:red", -2 * math.pi: "tab:blue"}
    for phi in PHIS:
        rows = results[phi]["rows"]
        if not rows:
            continue
        T = np.array([r["T"] for r in rows])
        for ax, key in ((axs[0], "excess"), (axs[1], "height")):
            y = np.array([r[key] for r in rows])
            st = np.array([r["morse"] == 0 for r in rows])
            lab = f"phi = {phi / math.pi:+.0f} pi"
            ax.loglog(T[st], y[st], "o", color=colors[phi], label=lab + " (stable)")
            if np.any(~st):
                ax.loglog(T[~st], y[~st], "x", color=colors[phi], label=lab + " (Morse > 0)")
            f = fits.get(f"{phi:+.4f}")
            if f:
                c = f["c_excess" if key == "excess" else "c_height"]
                tt = np.geomspace(T.min(), T.max(), 20)
                ax.loglog(tt, c / np.sqrt(tt), "-", color=colors[phi], lw=0.8,
                          label=f"fit {c:.2f} sqrt(B/T)")
    tt = np.geomspace(min(min(r["T"] for r in results[p]["rows"]) for p in PHIS if results[p]["rows"]),
                      max(max(r["T"] for r in results[p]["rows"]) for p in PHIS if results[p]["rows"]), 20)
    axs[0].loglog(tt, ELASTICA_EXCESS / np.sqrt(tt), "--", color="gray", label="elastica loop 4 sqrt(B/T)")
    axs[1].loglog(tt, ELASTICA_HEIGHT / np.sqrt(tt), "--", color="gray", label="elastica loop 2 sqrt(B/T)")
    axs[0].set(xlabel="T L^2 / B", ylabel="excess length e / L", title="open overhand knot: excess length")
    axs[1].set(xlabel="T L^2 / B", ylabel="loop height / L", title="largest distance from the axis")
    for ax in axs[:2]:
        ax.legend(fontsize=7)
    x = np.array(results[0.0]["x_first"] or [[0, 0, 0]])
    xl = np.array(results[0.0]["x_last"] or [[0, 0, 0]])
    axs[2].plot(x[:, 2], x[:, 0], "-", color="0.6", label="loosest (phi = 0)")
    axs[2].plot(xl[:, 2], xl[:, 0], "-k", label="tightest (phi = 0)")
    axs[2].set(xlabel="z / L (axis)", ylabel="x / L", title="centreline, side view")
    axs[2].set_aspect("equal")
    axs[2].legend(fontsize=7)
    fig.suptitle(f"N = {N}, D/L = {D:.4g}, kappa_c = 100; T from end_loads, Morse index under fixed ends")
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "open_knot.png"), dpi=110)
    print(f"wall {wall:.0f} s")


if __name__ == "__main__":
    main()
