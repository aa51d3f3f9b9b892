"""Tension and twist (issue 19, item 3), without self-contact.

1. The straight clamped rod under tension T buckles at M_c; M_c / 2 sqrt(BT) against
   L sqrt(T/B): discrete (N = 120, 240) and the continuum clamped problem
   (``clamped_tension_twist_threshold``), tending to 1 (the infinite rod).
2. At constant T (t = T L^2/B = 300), the end rotation R against the extension ("hat curve") and
   the torque: the straight branch (stable below M_c) and the localized-loop branch, each loop
   solved under the dead load T (end sliding on the axis) by Newton from the analytic loop of
   NvdHT 2002 at the same (R, t), with its Morse index under force control. No contact: the
   plectoneme (loops touching, the torque plateau) is not modelled here.

Writes benchmarks/results/tension_twist.json and tension_twist.png.
"""
import json
import math
import os
import time

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

from jaxrod.studies import endloads as el  # noqa: E402
from jaxrod.model.material import Material  # noqa: E402

from _bench import SMOKE, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
NU = 0.5
D = 2e-4


def onset():
    rows = []
    for N in pick((120, 240), (91,)):  # small mode: an N of helical_buckling and helix_reference
        rod = el.shortened_rod(N, 1.0, Material.from_ratio(B=1.0, nu=NU, D=D))
        for root_t in pick((1.0, 2.0, 4.0, 8.0, 16.0, 24.0), (1.0, 8.0)):
            t = root_t ** 2
            t0 = time.perf_counter()
            _, Mc = el.straight_buckling_moment(rod, t)
            exact = el.clamped_tension_twist_threshold(1.0, t, 1.0)
            rows.append(dict(N=N, L_sqrt_T_over_B=root_t, t=t, M_c=Mc, M_c_continuum=exact,
                             ratio=Mc / (2 * root_t), ratio_continuum=exact / (2 * root_t),
                             rel_err=Mc / exact - 1, seconds=time.perf_counter() - t0))
            print(rows[-1], flush=True)
    return rows


def hat(N=pick(240, 91), t=300.0):
    gamma = 1.0 / (1.0 + NU)
    rod = el.shortened_rod(N, 1.0, Material.from_ratio(B=1.0, nu=NU, D=D))
    fr = el.ForceLoadedRod(rod, "slide")
    _, Mc = el.straight_buckling_moment(rod, t)
    rows = []
    for m in np.linspace(2.0, 32.0, pick(16, 3)):
        ref = el.localized_helix(m, t, gamma)
        if N < el.EDGES_PER_CORE * ref.lam + 2:
            continue
        shaped = el.with_shortening(rod, ref.d)
        q0 = el.helical_start(shaped, m, t, ref.R)
        u0 = fr.u_from(q0, -ref.d * np.asarray(rod.axis))
        try:
            f = fr.solve(t, ref.R, u0)
        except Exception as exc:  # noqa: BLE001 -- report, keep going
            print(f"m = {m:.2f}: {type(exc).__name__}: {exc}")
            continue
        rows.append(dict(branch="loop", m_analytic=m, R=ref.R, extension=f.extension, extension_analytic=-ref.d,
                         M=f.M, morse=f.morse, Lk=f.Lk, Wr=f.Wr, converged=f.converged))
        print(rows[-1], flush=True)
    C = float(rod.material.C)
    for R in np.linspace(0.0, 1.3 * Mc / C, pick(14, 3)):
        rows.append(dict(branch="straight", R=float(R), extension=t / float(rod.material.EA), M=C * R,
                         morse=0 if C * R < Mc else 2))
    return dict(t=t, N=N, M_c=Mc, rows=rows)


def figure(on, ht):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.2))
    for N in sorted({r["N"] for r in on}):
        rr = [r for r in on if r["N"] == N]
        ax[0].plot([r["L_sqrt_T_over_B"] for r in rr], [r["ratio"] for r in rr], "o", label=f"discrete N = {N}")
    rr = [r for r in on if r["N"] == 120]
    ax[0].plot([r["L_sqrt_T_over_B"] for r in rr], [r["ratio_continuum"] for r in rr], "k-", label="continuum, clamped")
    ax[0].axhline(1.0, color="gray", ls=":")
    ax[0].set_xlabel("L sqrt(T/B)")
    ax[0].set_ylabel("M_c / 2 sqrt(BT)")
    ax[0].legend()
    for k, (key, label) in enumerate((("extension", "end extension / L"), ("M", "torque M L / B"))):
        a = ax[k + 1]
        for br, mk in (("straight", "-"), ("loop", "o")):
            rr = [r for r in ht["rows"] if r["branch"] == br]
            for stable in (True, False):
                sel = [r for r in rr if (r["morse"] == 0) == stable]
                if sel:
                    a.plot([r["R"] / (2 * math.pi) for r in sel], [r[key] for r in sel], mk,
                           color="C0" if stable else "C3", label=f"{br}, {'stable' if stable else 'unstable'}")
        if key == "extension":
            rr = [r for r in ht["rows"] if r["branch"] == "loop"]
            a.plot([r["R"] / (2 * math.pi) for r in rr], [r["extension_analytic"] for r in rr], "k+",
                   label="NvdHT 2002 (infinite rod)")
        a.set_xlabel("end rotation R / 2 pi (turns)")
        a.set_ylabel(label)
        a.set_title(f"t = {ht['t']:g}, N = {ht['N']}, no contact")
        a.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(results_dir(), "tension_twist.png"), dpi=120)


def main():
    on = onset()
    ht = hat()
    with open(os.path.join(results_dir(), "tension_twist.json"), "w") as fh:
        json.dump(with_provenance(dict(onset=on, hat=ht)), fh, indent=1, default=float)
    figure(on, ht)


if __name__ == "__main__":
    main()
