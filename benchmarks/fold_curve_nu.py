"""The trefoil's opening critical twist as a curve phi*+(nu) (issue 17, item 5 / acceptance 6, in the
Poisson ratio), by two-parameter continuation of the located fold, against point studies.

The paper's rod (D, L) = (8, 292) mm, N = 121. The opening branch end (a fold) is located at nu = 0.5
by ``jaxrod.continuation.arclength.continuation`` on ``knot_problem``, then followed in nu by ``fold_curve``
with ``set_poisson_ratio`` (C = B/(1 + nu), B fixed) down to nu = 0: pseudo-arclength on the fold
system, with dphi*/dnu from the implicit function theorem at every point.

Point studies, independent of the curve: at 5 values of nu, a new scene ``jr.trefoil(..., nu=nu)``,
the stable-only engine from phi = 0 to 0.3 pi below the curve's phi*, then the pseudo-arclength
continuation through the fold, located on its own. The curve's value at exactly that nu is the fold
located again there from the nearest curve point (``fold_at``: Newton on the fold system at fixed
nu). Michell's ring, phi_M = 2 pi sqrt(3) (1 + nu), is drawn for comparison: a loose knot's opening
instability is Michell-like (the paper), here 1.2 to 1.3 times phi_M.

The same continuation in D/L (``set_diameter``) does not get far yet: at N = 121 it leaves the
shape fold for the sliding mode's singular set at D/L = 0.0248 and stalls near 0.0286 (see the
README, "still open").

Writes benchmarks/results/fold_curve_nu.{json,md,csv,png}.
Run: python benchmarks/fold_curve_nu.py   (~4 min on 2 cores)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import csv  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402
from jaxrod.continuation import ContinuationOptions  # noqa: E402
from jaxrod.continuation.arclength import PseudoArclength, continuation, fold_at, fold_curve  # noqa: E402
from jaxrod.continuation.arclength.rods import knot_problem, set_poisson_ratio  # noqa: E402

PI = math.pi
from _bench import SMOKE, markdown, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)

D, L = 8.0, 292.0
N = pick(121, 61)  # the small mode: the fewest nodes whose start at phi = 0 is a minimum
NU0 = 0.5
POINTS = pick((0.0, 0.1, 0.2, 0.3, 0.4), (0.4,))
CURVE_STEPS = pick(400, 4)  # the fold curve's steps in nu (the small mode: 5 points, one inside its slope check)
H_NU = 1e-3  # the central differences' step in nu (0.0 +- h: nu = -0.001 is a valid material)
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = results_dir()
ALG = PseudoArclength()
# The stable-only engine's largest step up to a point study's start: 3 pi takes 2-3 steps to ~6 pi,
# where 2 pi takes 6-14 (its steps refused and halved on the way). The start at NU0: 2 pi; the small
# mode's 3 pi relies on its first path step of 0.25 (PATH_DS): after one of 0.05, the path from that
# start meets a branch point just before the fold at N = 61.
STUDY_STEP = pick(2 * PI, 3 * PI)
START_STEP = pick(2 * PI, 3 * PI)
# The point studies' path: the fold comes at step ~24 of 40 (ds <= 0.25); the small mode takes
# longer steps, the first one too, and stops a few past the fold (it comes at step ~11), the path
# beyond it unused.
PATH_STEPS, PATH_DS, PATH_DS_MAX = pick((40, 0.05, 0.25), (14, 0.25, 1.0))


def _path_options(p_max, steps=PATH_STEPS):
    return ContinuationOptions(ds=PATH_DS, ds_min=1e-6, ds_max=PATH_DS_MAX, max_steps=steps, newton_tol=1e-10,
                               eig_rtol=1e-13, k=6, p_max=p_max)


def locate_opening_fold(nu, below, step=2 * PI):
    """A point study: the opening fold of the trefoil with Poisson ratio nu, from phi = 0."""
    scene = jr.trefoil(D=D, L=L, N=N, nu=nu)
    old = jr.follow_twist(scene, 0.0, below, jr.ContinuationOptions(step=step, max_switches=0))
    e = old.points[-1].equilibrium
    rod = knot_problem(scene, np.asarray(e.q), e.phi)
    br = continuation(rod.problem, ALG, _path_options(below + 1.0 * PI), throw=False)
    folds = [ev for ev in br.events if ev.kind == "fold"]
    return rod, (folds[0] if folds else None), br


def main():
    t0 = time.perf_counter()
    rod, fold, _ = locate_opening_fold(NU0, 6.3 * PI, START_STEP)
    located = time.perf_counter() - t0
    print(f"fold at nu = {NU0}: {fold.p / PI:.10f} pi ({located:.0f} s)", flush=True)
    t0 = time.perf_counter()
    opts = ContinuationOptions(ds=-0.5, ds_max=2.0, ds_min=1e-5, max_steps=CURVE_STEPS, newton_tol=1e-10, p_min=-0.005,
                               p_max=NU0 + 1e-9)
    curve = fold_curve(rod.problem, fold, set_poisson_ratio, NU0, ALG, opts)
    curve_seconds = time.perf_counter() - t0
    print(f"fold curve: {len(curve.mu)} points, nu {curve.mu[0]:.4f} -> {curve.mu[-1]:.4f}, {curve_seconds:.1f} s "
          f"({curve.result.value})", flush=True)
    rows = []
    for nu in POINTS:
        k = int(np.argmin(np.abs(curve.mu - nu)))
        near = type("Near", (), dict(u=curve.u[k], p=curve.p[k], v=curve.v[k]))
        on_curve = fold_at(rod.problem, near, set_poisson_ratio, curve.mu[k], nu, opts)
        t = time.perf_counter()
        _, study, br = locate_opening_fold(nu, on_curve.p - 0.3 * PI, STUDY_STEP)
        seconds = time.perf_counter() - t
        row = dict(nu=nu, curve_phi_over_pi=on_curve.p / PI, curve_dphi_dnu=on_curve.dp_dmu,
                   curve_residual=on_curve.residual, study_phi_over_pi=(study.p / PI if study else None),
                   difference_over_pi=(abs(study.p - on_curve.p) / PI if study else None),
                   study_critical_eigenvalue=(study.critical_eigenvalue if study else None),
                   study_seconds=seconds, michell_over_pi=2 * math.sqrt(3) * (1 + nu))
        if study is not None:
            # dphi*/dnu of the point studies: central differences of two more, at nu +- H_NU
            ends = [locate_opening_fold(nu + sgn * H_NU, on_curve.p - 0.3 * PI, STUDY_STEP)[1]
                    for sgn in (-1.0, 1.0)]
            if all(e is not None for e in ends):
                central = (ends[1].p - ends[0].p) / (2 * H_NU)
                row.update(central_dphi_dnu=central, derivative_rel_diff=abs(central - on_curve.dp_dmu) / abs(on_curve.dp_dmu))
        rows.append(row)
        print(f"nu = {nu}: curve {row['curve_phi_over_pi']:.10f} pi, point study "
              f"{row['study_phi_over_pi']} pi, difference {row['difference_over_pi']} pi ({seconds:.0f} s); dphi*/dnu "
              f"IFT {on_curve.dp_dmu:.8f}, central {row.get('central_dphi_dnu')}, rel {row.get('derivative_rel_diff')}",
              flush=True)
    # the IFT slope along the curve against the curve's own finite differences (a consistency check)
    order = np.argsort(curve.mu)
    mu, p, slope = curve.mu[order], curve.p[order], curve.dp_dmu[order]
    fd = np.gradient(p, mu)
    inner = slice(2, -2)
    slope_check = float(np.max(np.abs(fd[inner] - slope[inner]) / np.abs(slope[inner])))
    summary = dict(D=D, L=L, N=N, nu0=NU0, fold_phi_over_pi=fold.p / PI, locate_seconds=located,
                   curve_points=len(curve.mu), curve_seconds=curve_seconds, curve_result=curve.result.value,
                   nu_range=[float(mu[0]), float(mu[-1])], max_residual=float(np.max(curve.residual)),
                   slope_vs_curve_differences_max_rel=slope_check, point_studies=rows)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "fold_curve_nu.json"), "w") as f:
        json.dump(with_provenance(summary), f, indent=1)
    with open(os.path.join(OUT, "fold_curve_nu.csv"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["nu", "phi_star_over_pi", "dphi_star_dnu", "residual"])
        for a, b, c, r in zip(mu, p / PI, slope, curve.residual[order]):
            w.writerow([f"{a:.12g}", f"{b:.12g}", f"{c:.12g}", f"{r:.3g}"])
    write_md(summary)
    plot(mu, p, rows)


def write_md(s):
    lines = ["# The trefoil's opening critical twist phi*+(nu): fold curve against point studies", "",
             f"(D, L) = ({s['D']:g}, {s['L']:g}), N = {s['N']}; `benchmarks/fold_curve_nu.py`. The fold located at "
             f"nu = {s['nu0']} ({s['fold_phi_over_pi']:.10f} pi, {s['locate_seconds']:.0f} s), then `fold_curve` in nu: "
             f"{s['curve_points']} points over nu = {s['nu_range'][0]:.4f} ... {s['nu_range'][1]:.4f} in "
             f"{s['curve_seconds']:.1f} s ({s['curve_result']}), residual of the fold system <= {s['max_residual']:.1e}. "
             f"The IFT slope dphi*/dnu along the curve agrees with the curve's own finite differences to "
             f"{s['slope_vs_curve_differences_max_rel']:.1e} relative (second-order differences on uneven points).", "",
             f"Each point study's dphi*/dnu: central differences of two more point studies at nu +- {H_NU:g}, against "
             "the IFT on the fold system at the curve's point.", "",
             "| nu | curve phi* / pi | point study phi* / pi | difference / pi | dphi*/dnu (IFT) | central | rel. diff | "
             "Michell / pi | point study s |", "|---|---|---|---|---|---|---|---|---|"]
    for r in s["point_studies"]:
        diff = "--" if r["difference_over_pi"] is None else f"{r['difference_over_pi']:.1e}"
        study = "no fold" if r["study_phi_over_pi"] is None else f"{r['study_phi_over_pi']:.10f}"
        central = "--" if r.get("central_dphi_dnu") is None else f"{r['central_dphi_dnu']:.6f}"
        rel = "--" if r.get("derivative_rel_diff") is None else f"{r['derivative_rel_diff']:.1e}"
        lines.append(f"| {r['nu']:g} | {r['curve_phi_over_pi']:.10f} | {study} | {diff} | {r['curve_dphi_dnu']:.6f} | "
                     f"{central} | {rel} | {r['michell_over_pi']:.6f} | {r['study_seconds']:.0f} |")
    with open(os.path.join(OUT, "fold_curve_nu.md"), "w") as f:
        f.write(markdown(lines))


def plot(mu, p, rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4))
    ax.plot(mu, p / PI, "k-", label=f"trefoil (8, 292), N = {N}: fold curve")
    ax.plot([r["nu"] for r in rows if r["study_phi_over_pi"]], [r["study_phi_over_pi"] for r in rows
                                                               if r["study_phi_over_pi"]], "o", mfc="none",
            color="C3", label="point studies (fold located from phi = 0)")
    grid = np.linspace(0, 0.5, 50)
    ax.plot(grid, 2 * np.sqrt(3) * (1 + grid), "--", color="C0", label="Michell's ring: 2 sqrt(3) (1 + nu)")
    ax.set_xlabel("Poisson ratio nu (C = B / (1 + nu))")
    ax.set_ylabel("opening critical twist phi*+ / pi")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "fold_curve_nu.png"), dpi=120)


if __name__ == "__main__":
    main()
