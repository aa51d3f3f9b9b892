"""The Kirchhoff limit of the Cosserat ring: Michell's critical twist as the shear stiffness grows.

A ``CosseratRing`` (B = 1, C = B / 1.5, R = 1, EA = 1e6) at N = 32; its planar twisted branch is
followed in phi to the first branch point (``jaxrod.studies.shear.ring_critical_twist``, a double
branch point located by the pseudo-arclength engine) for kGA from 10^1.5 to 10^5, and at kGA = 10^9
(the Kirchhoff limit of this discretisation). The shear enters the second variation through the
compliance 1 / kGA, so phi*(kGA) - phi*(oo) is first order in it: slope -1 on the log-log chart.
The limit itself against Michell's continuum value 2 pi sqrt(3) B / C at N = 32, 48, 64.

Writes benchmarks/results/shear_kirchhoff_limit.{json,md,png} (the docs show the chart from there).
Run: python benchmarks/shear_kirchhoff_limit.py   (about 4 minutes on 2 cores; the small mode: N = 16, two stiffnesses)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from jaxrod.model.cosserat import cosserat_ring  # noqa: E402
from jaxrod.studies.shear import ring_critical_twist  # noqa: E402

from _bench import markdown, pick, results_dir, with_provenance  # noqa: E402

B, C, EA, LIMIT = 1.0, 1.0 / 1.5, 1e6, 1e9
MICHELL = 2.0 * math.pi * math.sqrt(3.0) * B / C
N = pick(32, 16)
STIFFNESSES = pick(tuple(10.0 ** np.arange(1.5, 5.01, 0.5)), (1e2, 1e3))
LIMIT_N = pick((32, 48, 64), (16,))
OUT = results_dir()


def critical(N, GA):
    t = time.perf_counter()
    event = ring_critical_twist(cosserat_ring(N=N, length=2.0 * math.pi, B=B, C=C, EA=EA, GA=GA))
    return float(event.p), int(event.multiplicity), time.perf_counter() - t


def main():
    limit = {n: critical(n, LIMIT)[0] for n in LIMIT_N}
    rows = []
    for GA in STIFFNESSES:
        phi, multiplicity, seconds = critical(N, GA)
        rows.append(dict(GA=GA, phi=phi, difference=limit[N] - phi, multiplicity=multiplicity, seconds=seconds))
        print(f"kGA = {GA:9.3g}: phi* = {phi:.10f} ({multiplicity}-fold), phi*(oo) - phi* = {limit[N] - phi:.4e}",
              flush=True)
    g = np.log([r["GA"] for r in rows])
    d = np.log([r["difference"] for r in rows])
    slope = float(np.polyfit(g, d, 1)[0])
    coefficient = float(np.median([r["difference"] * r["GA"] for r in rows]))
    data = dict(N=N, B=B, C=C, EA=EA, michell=MICHELL, limit={str(k): v for k, v in limit.items()}, rows=rows,
                slope=slope, coefficient=coefficient)
    with open(os.path.join(OUT, "shear_kirchhoff_limit.json"), "w") as f:
        json.dump(with_provenance(data), f, indent=1)
    lines = ["# The Kirchhoff limit of the Cosserat ring (Michell's instability with shear)", "",
             f"N = {N}, B = 1, C = B/1.5, R = 1, EA = 1e6; `benchmarks/shear_kirchhoff_limit.py`. phi*(oo): kGA = 1e9.", "",
             "| kGA | phi* (rad) | phi*(oo) - phi* | (phi*(oo) - phi*) kGA |", "|---|---|---|---|"]
    lines += [f"| {r['GA']:.4g} | {r['phi']:.10f} | {r['difference']:.4e} | {r['difference'] * r['GA']:.4f} |"
              for r in rows]
    lines += ["", f"Log-log slope {slope:.4f} (first order in 1/kGA: -1 expected, the sign of the decrease aside); "
              f"phi*(oo) - phi* ~ {coefficient:.3f} B / (kGA R^2) rad.", "",
              "The limit against Michell's continuum value 2 pi sqrt(3) B / C = " f"{MICHELL:.10f}:", "",
              "| N | phi*(kGA = 1e9) | relative difference |", "|---|---|---|"]
    lines += [f"| {n} | {v:.10f} | {(v - MICHELL) / MICHELL:+.2e} |" for n, v in limit.items()]
    with open(os.path.join(OUT, "shear_kirchhoff_limit.md"), "w") as f:
        f.write(markdown(lines))
    figure(rows, slope)


def figure(rows, slope):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    GA = np.array([r["GA"] for r in rows])
    diff = np.array([r["difference"] for r in rows])
    fig, ax = plt.subplots(figsize=(5.2, 3.6))
    ax.loglog(GA, diff, "o-", label=f"Cosserat ring, N = {N} (slope {slope:.3f})")
    ax.loglog(GA, diff[0] * GA[0] / GA, "k--", lw=1, label="slope −1")
    ax.set_xlabel("shear stiffness kGA (units of B / R²)")
    ax.set_ylabel("φ*(kGA → ∞) − φ*(kGA) (rad)")
    ax.set_title("Michell's critical twist: the Kirchhoff limit")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "shear_kirchhoff_limit.png"), dpi=120)


if __name__ == "__main__":
    main()
