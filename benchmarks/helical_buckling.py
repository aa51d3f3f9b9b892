"""Localized helical buckling (issue 19) against Neukirch, van der Heijden & Thompson 2002:
m = ML/B and t = TL^2/B of the discrete clamped rod at the analytic (d, R), for four (m, t, gamma)
sets and N = 120, 240, 480, with Richardson's extrapolation; theta_max; the L1 envelope error of
theta(s); Morse index; and the force-controlled rod with its end free in space.

Writes benchmarks/results/helical_buckling.json and helical_buckling.png.
Run: OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/helical_buckling.py
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
SETS = pick(((20.0, 300.0, 0.5), (30.0, 400.0, 0.3), (10.0, 300.0, 0.0), (15.0, 250.0, 0.5)), ((20.0, 300.0, 0.5),))
NS = pick((120, 240, 480), (91, 180))  # small mode: the N of helix_reference (180 and its coarse level 91), whose programs it shares
D = 2e-4  # D/L: stretch T/EA = t (D/L)^2/16 < 1e-6
HERE = os.path.dirname(os.path.abspath(__file__))


def main():
    rows = []
    states = {}
    for (m, t, nu) in SETS:
        ref = el.localized_helix(m, t, 1.0 / (1.0 + nu))
        for N in NS:
            rod = el.shortened_rod(N, 1.0, Material.from_ratio(B=1.0, nu=nu, D=D), shortening=ref.d)
            t0 = time.perf_counter()
            e = el.solve(rod, ref.R, el.helical_start(rod, m, t, ref.R), el.EndLoadOptions(k=4))
            loads = el.end_loads(rod, e.q, ref.R, e.neighbourhood)
            row = dict(m=m, t=t, nu=nu, gamma=ref.gamma, lam=ref.lam, d=ref.d, R=ref.R, N=N, M=loads.M, T=loads.T,
                       m_err=loads.M / m - 1, t_err=loads.T / t - 1,
                       theta_max=float(el.tangent_angles(e.x).max()), theta_max_exact=ref.theta_max,
                       envelope_L1=el.envelope_error(e.x, m, t), Wr=e.Wr, Tw=e.Tw, Lk_err=e.Lk - ref.R / (2 * math.pi),
                       morse=e.stability.n_negative, lowest=[float(v) for v in e.stability.eigenvalues[:3]],
                       grad_norm=e.solution.grad_norm, iterations=e.solution.iterations,
                       seconds=time.perf_counter() - t0)
            rows.append(row)
            states[(m, N)] = (rod, e, loads, ref)
            print(f"m={m:g} t={t:g} nu={nu:g} N={N}: m_err={row['m_err']:+.2e} t_err={row['t_err']:+.2e} "
                  f"theta_max err={row['theta_max'] - ref.theta_max:+.2e} L1={row['envelope_L1']:.2e} "
                  f"morse={row['morse']} ({row['seconds']:.1f} s)", flush=True)
    rich = []
    for (m, t, nu) in SETS:
        r = [x for x in rows if x["m"] == m]
        for a, b in zip(r[:-1], r[1:]):
            k = (b["N"] / a["N"]) ** 2
            ext = lambda key: (k * b[key] - a[key]) / (k - 1)  # noqa: E731
            rich.append(dict(m=m, t=t, nu=nu, N=(a["N"], b["N"]), m_err=ext("M") / m - 1, t_err=ext("T") / t - 1,
                             theta_max_err=ext("theta_max") - a["theta_max_exact"]))
            print(f"Richardson {a['N']}/{b['N']} m={m:g}: m_err={rich[-1]['m_err']:+.2e} "
                  f"t_err={rich[-1]['t_err']:+.2e} theta_max err={rich[-1]['theta_max_err']:+.2e}")
    # the end free in space, under the dead load T measured at fixed ends (first set, N = 120)
    m, t, nu = SETS[0]
    rod, e, loads, ref = states[(m, NS[0])]
    fr = el.ForceLoadedRod(rod, "free")
    f = fr.solve(loads.T, ref.R, fr.u_from(e.q, -ref.d * np.asarray(rod.axis)))
    rest = el.end_loads(el.with_end_offset(rod, f.end_offset), f.q, ref.R)
    free = dict(converged=f.converged, lateral_offset=[float(v) for v in f.end_offset[:2]],
                lateral_force_fixed_ends=[float(v) for v in loads.force[:2]],
                lateral_force_free=[float(v) for v in rest.force[:2]], extension=f.extension, d=ref.d,
                morse=f.morse, Lk_err=f.Lk - ref.R / (2 * math.pi))
    assert f.converged and max(abs(v) for v in free["lateral_force_free"]) < 1e-6 * loads.T
    assert abs(free["Lk_err"]) < 1e-10
    print("free end:", free)
    out = dict(sets=SETS, N=NS, D_over_L=D, rows=rows, richardson=rich, free_end=free)
    with open(os.path.join(results_dir(), "helical_buckling.json"), "w") as fh:
        json.dump(with_provenance(out), fh, indent=1)
    figure(rows, states)


def figure(rows, states):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(15, 4.5))
    ax = fig.add_subplot(1, 3, 1, projection="3d")
    rod, e, loads, ref = states[(SETS[0][0], NS[-1])]
    ax.plot(*e.x.T, lw=1)
    ax.set_title(f"N = {NS[-1]}, m = {ref.m:g}, t = {ref.t:g}")
    ax2 = fig.add_subplot(1, 3, 2)
    for N in NS:
        _, e, _, ref = states[(SETS[0][0], N)]
        th = el.tangent_angles(e.x)
        s = np.arange(th.size) / (th.size - 1) - 0.5
        ax2.plot(s, th, ".", ms=2, label=f"N = {N}")
    s = np.linspace(-0.5, 0.5, 2001)
    theta, _, _ = el.localized_helix_curve(ref.m, ref.t, s)
    ax2.plot(s, theta, "k-", lw=0.8, label="NvdHT 2002")
    ax2.set_xlabel("s / L from the midpoint")
    ax2.set_ylabel("tangent angle theta")
    ax2.legend()
    ax3 = fig.add_subplot(1, 3, 3)
    for (m, t, nu) in SETS:
        r = [x for x in rows if x["m"] == m]
        ax3.loglog([x["N"] for x in r], [abs(x["t_err"]) for x in r], "o-", label=f"|t err| m={m:g} t={t:g}")
        ax3.loglog([x["N"] for x in r], [x["envelope_L1"] for x in r], "s--", label=f"L1 envelope m={m:g}")
    ax3.set_xlabel("N")
    ax3.legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(os.path.join(results_dir(), "helical_buckling.png"), dpi=120)


if __name__ == "__main__":
    main()
