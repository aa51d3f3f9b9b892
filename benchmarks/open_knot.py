"""An open overhand knot pulled tight (issue 19, item 4): loop size against the tension T.

A trefoil-shaped open knot (``jaxrod.studies.open_knot.open_overhand_knot``, loop unit 0.012 L) in a rod of
length L = 1, B = 1, nu = 0.5, diameter D, clamped on the z axis with soft self-contact
(kappa_c = 100), is pulled by displacement control: the excess length e = L - end distance is set,
and each state is relaxed from the last (damped Newton, strand passage refused). At each state:
T (exact, dE/d(end distance)), the excess e, the loop span (the loop's diameter), Wr, Tw,
Lk = Lk0 + phi/2pi and the Morse index under fixed ends.

Scaling. For a rod much longer than the knot, dimensional analysis leaves e sqrt(T/B) and
span sqrt(T/B) functions of x = D sqrt(T/B) alone (at given nu, contact law and end moment
M/sqrt(BT)). Two diameters (L/150 at N = 160 and L/300 at N = 310) at phi = 0 test that: where
their x overlap the values must agree (finite-length effects would separate them), and the loose
limit (D << sqrt(B/T): the knot's size set by bending against tension alone, e and span
proportional to sqrt(B/T)) is the intercept at x = 0 (``open_knot.fit_loose_limit``).

Against the published asymptotics (Audoly, Clauvelin & Neukirch 2007; Clauvelin, Audoly & Neukirch
2009): the inextensible end-shortening (arc length - end distance, the axial stretch taken out)
and the loop's apex radius, times sqrt(T/B), are fitted in eps = sqrt(h/R) (h = D/2, R =
sqrt(B/2T)) and compared at eps = 0 with pi sqrt(2) and 1/sqrt(2) (``open_knot.LOOSE_LIMIT``); the
contact set's runs along the rod (``open_knot.contact_runs``) are listed at each case's loosest and
tightest states (published: an interval flanked by two isolated contact points). Twist:
phi = +-2 pi at D = L/150 (the end moment M/sqrt(BT) is reported). Edges are about D/2 and the
contact integral takes 3 Gauss points per segment (with 2, T(e) jumped by ~5 % as strands slid
past the nodes); N = 640 at D = L/150 checks the resolution.

From the relaxed drawn knot (e0 = 0.337) the rod is loosened in steps of 1.05 in e, then
tightened in steps of 0.95, each leg from the first state.

    python benchmarks/open_knot.py            # ~19 min on 2 cores (the five cases in 2 processes)
    python benchmarks/open_knot.py --combine  # table, fits and figure from the finished cases

Each case writes its states as they come (benchmarks/results/open_knot/<case>.json; a rerun skips
finished cases); the combination writes benchmarks/results/open_knot.csv, open_knot.json,
open_knot.png.
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

from _bench import SMOKE, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = results_dir()
PARTS = os.path.join(OUT, "open_knot")
L, LOOP, KAPPA = 1.0, 0.012, 100.0
# (name, D, N, phi): edges of about D/2 (N = 2 L/D + 20), and one case at D/4 for the resolution
CASES = (("D150_phi0", 1.0 / 150, 320, 0.0), ("D300_phi0", 1.0 / 300, 620, 0.0),
         ("D150_phi+2pi", 1.0 / 150, 320, 2 * math.pi), ("D150_phi-2pi", 1.0 / 150, 320, -2 * math.pi),
         ("D150_phi0_N640", 1.0 / 150, 640, 0.0))
if SMOKE:  # one case, one state each way
    CASES = CASES[:1]
LOOSEN = tuple(1.05 ** k for k in range(1, pick(10, 2)))  # up to 1.55 e0
TIGHTEN = tuple(0.95 ** k for k in range(1, pick(21, 2)))  # down to 0.36 e0
FIELDS = ("phi", "excess", "T", "M", "span", "height", "Wr", "Tw", "Lk", "morse", "lowest", "contacts", "energy")


def run_case(name, path):
    import numpy as np

    sys.path.insert(0, os.path.dirname(HERE))
    from jaxrod.studies import open_knot as ok

    (_, D, N, phi), = [c for c in CASES if c[0] == name]
    t0 = time.time()
    scene, q = ok.open_overhand_knot(N, L, D, LOOP, phi=phi, options=ok.OpenKnotOptions(contact_stiffness=KAPPA))
    e0 = float(scene.shortening)

    def say(s):
        print(f"[{name}] {s}", flush=True)

    first, st0 = ok.relax_knot(scene, phi, q)
    say(f"e0 = {e0:.4g}: T = {st0.T:.4g}, span = {st0.span:.4g}, Lk = {st0.Lk:.6f}, morse = {st0.morse}")
    states = [st0]
    legs = {}
    for leg, factors in (("loosen", LOOSEN), ("tighten", TIGHTEN)):
        got = []
        sc, qq, prev = scene, st0.q, first
        for f in factors:  # one state at a time, written after each (an interrupted run keeps them)
            step = ok.pull(sc, qq, [f * e0], phi=phi, progress=say, previous=prev)
            if not step:
                legs[leg] = "stopped"
                break
            got.append(step[0])
            sc, qq, prev = ok.moved_to_excess(sc, step[0].q, f * e0)[0], step[0].q, step[0]
            _dump(path, name, D, N, phi, states + got, t0, done=False)
        legs.setdefault(leg, "finished")
        states += got
    states.sort(key=lambda s: s.excess)
    _dump(path, name, D, N, phi, states, t0, done=True, legs=legs)
    say(f"done in {time.time() - t0:.0f} s")


def _dump(path, name, D, N, phi, states, t0, done, legs=None):
    import numpy as np

    rows = [{k: (float(getattr(s, k)[0]) if k == "lowest" else getattr(s, k)) for k in FIELDS} for s in states]
    tight = min(states, key=lambda s: s.excess) if states else None
    loose = max(states, key=lambda s: s.excess) if states else None
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        json.dump(dict(case=name, D=D, N=N, phi=phi, rows=rows, wall_s=time.time() - t0, done=done, legs=legs,
                       x_tight=tight.x.tolist() if tight else None, x_loose=loose.x.tolist() if loose else None,
                       x=[np.round(s.x, 12).tolist() for s in states]), f)
    os.replace(tmp, path)


def combine():
    import numpy as np

    sys.path.insert(0, os.path.dirname(HERE))
    from jaxrod.studies.open_knot import fit_loose_limit, fit_prefactor, mean_tension
    from jaxrod.studies import open_knot as ok

    results = {}
    for name, *_ in CASES:
        p = os.path.join(PARTS, name + ".json")
        if os.path.exists(p):
            with open(p) as f:
                results[name] = json.load(f)
    lines = ["case,D,N," + ",".join(FIELDS)]
    steps_lines = ["case,D,N,phi,e_mid,T_mean,T_states,span_mid,M_mid,x,e_sqrtT,span_sqrtT,m,stable"]
    table, steps = {}, {}
    for name, r in results.items():
        rows = sorted(r["rows"], key=lambda w: w["excess"])
        for w in rows:
            lines.append(f"{name},{r['D']:.10g},{r['N']}," + ",".join(f"{w[k]:.10g}" for k in FIELDS))
        # the scaling is read off the mean tension over each step (-dE/de), which the exact
        # tension at the states (end_loads) follows to within its ripple
        e = np.array([w["excess"] for w in rows])
        e_mid, T_mean = mean_tension(e, [w["energy"] for w in rows])
        pts = []
        for i in range(len(e_mid)):
            a, b = rows[i], rows[i + 1]
            T_states = 0.5 * (a["T"] + b["T"])
            span = 0.5 * (a["span"] + b["span"])
            M = 0.5 * (a["M"] + b["M"])
            sq = math.sqrt(T_mean[i]) if T_mean[i] > 0 else float("nan")
            pt = dict(e_mid=float(e_mid[i]), T_mean=float(T_mean[i]), T_states=T_states, span_mid=span, M_mid=M,
                      x=r["D"] * sq, e_sqrtT=float(e_mid[i]) * sq, span_sqrtT=span * sq, m=M / sq,
                      stable=a["morse"] == 0 and b["morse"] == 0)
            pts.append(pt)
            steps_lines.append(f"{name},{r['D']:.10g},{r['N']},{r['phi']:.10g}," + ",".join(
                f"{pt[k]:.10g}" for k in ("e_mid", "T_mean", "T_states", "span_mid", "M_mid", "x", "e_sqrtT",
                                          "span_sqrtT", "m")) + f",{int(pt['stable'])}")
        steps[name] = pts
        T = np.array([w["T"] for w in rows])
        ripple = np.array([p["T_states"] / p["T_mean"] - 1 for p in pts])
        pe = fit_prefactor([p["T_mean"] for p in pts], [p["e_mid"] for p in pts])
        table[name] = dict(D=r["D"], N=r["N"], phi=r["phi"], n_states=len(rows), done=r["done"], wall_s=r["wall_s"],
                           T_range=[float(T.min()), float(T.max())],
                           x_range=[min(p["x"] for p in pts), max(p["x"] for p in pts)],
                           m_range=[min(p["m"] for p in pts), max(p["m"] for p in pts)],
                           e_sqrtT_range=[min(p["e_sqrtT"] for p in pts), max(p["e_sqrtT"] for p in pts)],
                           tension_ripple_rms=float(np.sqrt(np.mean(ripple ** 2))),
                           tension_ripple_max=float(np.max(np.abs(ripple))),
                           exponent_e=pe[2], exponent_e_std=pe[3],
                           morse=sorted({w["morse"] for w in rows}),
                           Lk_error=max(abs(w["Lk"] - (3 + w["phi"] / (2 * math.pi))) for w in rows))
    fits = {}
    untwisted = [n for n in ("D150_phi0", "D300_phi0") if n in steps]  # the N = 640 case: resolution only
    pts = [p for n in untwisted for p in steps[n] if p["stable"] and p["T_mean"] > 0]
    if len(pts) >= 4:
        x = np.array([p["x"] for p in pts])
        for key in ("e_sqrtT", "span_sqrtT"):
            c = np.array([p[key] for p in pts])
            lin, lin_err, lin_res = fit_loose_limit(x, c, 1)
            quad, quad_err, quad_res = fit_loose_limit(x, c, 2)
            small = x <= 0.12  # the linear law over the loosest states only
            lin_s, lin_s_err, lin_s_res = fit_loose_limit(x[small], c[small], 1)
            # the loose limit depends on the form assumed for the correction: compare three
            forms = {}
            for form, cols in (("c0 + c1 x + c2 x^2", [x, x ** 2]), ("c0 + c1 sqrt(x) + c2 x", [np.sqrt(x), x]),
                               ("c0 + c1 x log x + c2 x", [x * np.log(x), x])):
                A = np.stack([np.ones_like(x)] + cols, axis=1)
                coef, *_ = np.linalg.lstsq(A, c, rcond=None)
                res = c - A @ coef
                cov = float(res @ res) / (len(c) - 3) * np.linalg.inv(A.T @ A)
                forms[form] = dict(c0=float(coef[0]), c0_std=float(math.sqrt(cov[0, 0])),
                                   rms_residual=float(np.sqrt(np.mean(res ** 2))), max_residual=float(np.max(np.abs(res))))
            fits[key] = dict(by_correction_form=forms, c0_quadratic=quad[0], c0_quadratic_std=quad_err[0], c1_quadratic=quad[1],
                             c2_quadratic=quad[2], max_residual_quadratic=quad_res,
                             c0_linear=lin[0], c0_linear_std=lin_err[0], c1_linear=lin[1], max_residual_linear=lin_res,
                             c0_linear_x_le_0p12=lin_s[0], c0_linear_x_le_0p12_std=lin_s_err[0],
                             x_range=[float(x.min()), float(x.max())], n_points=len(pts))
    # collapse: the D = L/300 values against the D = L/150 curve (linear interpolation in x) where both exist
    collapse = {}
    if len(untwisted) == 2:
        a = sorted(steps["D150_phi0"], key=lambda p: p["x"])
        xa = np.array([p["x"] for p in a])
        for key in ("e_sqrtT", "span_sqrtT"):
            ya = np.array([p[key] for p in a])
            d = [p[key] / np.interp(p["x"], xa, ya) - 1 for p in steps["D300_phi0"] if xa.min() <= p["x"] <= xa.max()]
            collapse[key] = dict(points=len(d), max_relative_difference=float(np.max(np.abs(d))) if d else None,
                                 mean_relative_difference=float(np.mean(d)) if d else None)
    # resolution: N = 640 against N = 320 at D = L/150 (the same excess steps)
    resolution = {}
    if "D150_phi0" in steps and "D150_phi0_N640" in steps:
        a = {round(p["e_mid"], 9): p for p in steps["D150_phi0"]}
        for key in ("T_mean", "span_mid"):
            d = [p[key] / a[round(p["e_mid"], 9)][key] - 1 for p in steps["D150_phi0_N640"] if round(p["e_mid"], 9) in a]
            resolution[key] = dict(points=len(d), max_relative_difference=float(np.max(np.abs(d))) if d else None,
                                   mean_relative_difference=float(np.mean(d)) if d else None)
    published, eps_points = _against_published(results, ok)
    os.makedirs(OUT, exist_ok=True)
    with open(os.path.join(OUT, "open_knot.csv"), "w") as f:
        f.write("\n".join(lines) + "\n")
    with open(os.path.join(OUT, "open_knot_steps.csv"), "w") as f:
        f.write("\n".join(steps_lines) + "\n")
    summary = dict(L=L, B=1.0, nu=0.5, loop_unit=LOOP, contact_stiffness=KAPPA, contact_quadrature=3, cases=table,
                   loose_limit=fits, collapse=collapse, resolution_N640_vs_N320=resolution,
                   published_loose_limit=published)
    with open(os.path.join(OUT, "open_knot.json"), "w") as f:
        json.dump(with_provenance(summary), f, indent=1)
    print(json.dumps(dict(cases=table, loose_limit=fits, collapse=collapse, resolution=resolution,
                          published_loose_limit=published), indent=1))
    _figure(results, steps, fits, eps_points, published)


# The fits in eps use the states with eps <= EPS_MAX (the loose regime: tighter, the loop reshapes
# and its apex radius jumps off the trend); the intercept's change with the cut moved by 0.05 is
# recorded beside it.
EPS_MAX = 0.35


def _sorted_states(r):
    order = sorted(range(len(r["rows"])), key=lambda i: r["rows"][i]["excess"])
    return [r["rows"][i] for i in order], [r["x"][i] for i in order]


def _eps_points(r, ok):
    """Per pulling step of one case: eps, the inextensible excess and the apex radius, both times
    sqrt(T/B), with T the step's mean tension (-dE/de) and the lengths at the step's geometric mean."""
    import numpy as np

    rows, xs = _sorted_states(r)
    e_mid, T = ok.mean_tension([w["excess"] for w in rows], [w["energy"] for w in rows])
    e_in = np.array([ok.inextensible_excess(x) for x in xs])
    radius = np.array([ok.apex_radius(x, 0.5 * math.sqrt(0.5 / max(w["T"], 1e-300))) for w, x in zip(rows, xs)])
    keep = T > 0
    sq = np.sqrt(np.where(keep, T, 1.0))
    return dict(eps=ok.loose_parameter(r["D"], np.where(keep, T, 1.0))[keep],
                excess=(np.sqrt(e_in[1:] * e_in[:-1]) * sq)[keep], loop_radius=(np.sqrt(radius[1:] * radius[:-1]) * sq)[keep])


def _against_published(results, ok):
    """The untwisted cases' fits in eps against the published leading order, and every case's contact
    runs (in units of D) at its loosest and tightest states."""
    import numpy as np

    untwisted = [n for n in ("D150_phi0", "D300_phi0") if n in results]
    points = {n: _eps_points(results[n], ok) for n in untwisted}
    out = dict(variable="eps = sqrt(h/R), h = D/2, R = sqrt(B/(2T))", cases=untwisted, fits={}, contact_runs={})
    eps = np.concatenate([p["eps"] for p in points.values()]) if points else np.zeros(0)
    loose = eps <= EPS_MAX
    if loose.sum() >= 4:
        for key in ("excess", "loop_radius"):
            y = np.concatenate([p[key] for p in points.values()])
            fit = {}
            for degree in (1, 2):
                coef, err, worst = ok.fit_loose_limit(eps[loose], y[loose], degree)
                fit[f"degree_{degree}"] = dict(c0=float(coef[0]), c0_std=float(err[0]), coefficients=coef.tolist(),
                                               max_residual=worst)
            # the quadratic's intercept with the fit range moved either way: its systematic error
            fit["degree_2_by_eps_max"] = {
                f"{cut:g}": dict(zip(("c0", "c0_std"), (float(v[0]), float(e[0]))))
                for cut in (EPS_MAX - 0.05, EPS_MAX + 0.05)
                for v, e, _ in [ok.fit_loose_limit(eps[eps <= cut], y[eps <= cut], 2)]}
            fit.update(published=ok.LOOSE_LIMIT[key], eps_max=EPS_MAX,
                       eps_range=[float(eps[loose].min()), float(eps[loose].max())], points=int(loose.sum()))
            out["fits"][key] = fit
    for name, r in results.items():
        rows, xs = _sorted_states(r)
        out["contact_runs"][name] = {
            label: dict(excess=rows[i]["excess"], runs_over_D=[[a / r["D"], b / r["D"]] for a, b in ok.contact_runs(xs[i], r["D"])])
            for label, i in (("loosest", -1), ("tightest", 0))}
    return out, points


def _published_panel(ax, eps_points, fits, style):
    """The inextensible excess and the apex radius (times sqrt(T/B)) against eps, their quadratic
    fits and the published leading order at eps = 0."""
    import numpy as np

    for key, colour, label in (("excess", "k", "(arc length - end distance) sqrt(T/B)"),
                               ("loop_radius", "tab:purple", "apex radius sqrt(T/B)")):
        for name, p in eps_points.items():
            ax.plot(p["eps"], p[key], style[name][1], color=colour, ms=4, mfc="none" if name == "D300_phi0" else colour,
                    label=f"{label}, D = L/{150 if name == 'D150_phi0' else 300}")
        f = fits.get(key)
        if f:
            c = f["degree_2"]["coefficients"]
            ee = np.linspace(0, f["eps_max"], 80)
            ax.plot(ee, c[0] + c[1] * ee + c[2] * ee ** 2, "--", color=colour, lw=1,
                    label=f"quadratic in eps: {c[0]:.3f} +- {f['degree_2']['c0_std']:.3f} at eps = 0")
            ax.plot([0], [f["published"]], "*", color=colour, ms=13, label=f"published leading order {f['published']:.4f}")
    ax.set(xlabel="eps = sqrt(h/R), h = D/2, R = sqrt(B/2T)", ylabel="scaled length",
           title="against the published loose limit (phi = 0)", xlim=(0, None), ylim=(0, None))
    ax.legend(fontsize=6)


def _figure(results, steps, fits, eps_points=None, published=None):
    import matplotlib
    import numpy as np

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    style = {"D150_phi0": ("k", "o"), "D300_phi0": ("tab:green", "s"), "D150_phi+2pi": ("tab:red", "^"),
             "D150_phi-2pi": ("tab:blue", "v"), "D150_phi0_N640": ("tab:orange", ".")}
    fig, axs = plt.subplots(1, 4, figsize=(21, 4.8))
    for name, r in results.items():
        pts = [p for p in steps[name] if p["T_mean"] > 0]
        col, mk = style[name]
        lab = f"D = L/{round(1 / r['D'])}, N = {r['N']}, phi = {r['phi'] / math.pi:+.0f} pi"
        T = np.array([p["T_mean"] for p in pts])
        st = np.array([p["stable"] for p in pts])
        for ax, key in ((axs[0], "e_mid"), (axs[1], "span_mid")):
            y = np.array([p[key] for p in pts])
            ax.loglog(T[st], y[st], mk, color=col, mfc="none" if r["phi"] else col, ms=4, label=lab)
            if np.any(~st):
                ax.loglog(T[~st], y[~st], "x", color=col, label=lab + " (Morse > 0)")
        if name == "D150_phi0":  # the tension at the states, with its ripple
            rows = r["rows"]
            axs[0].loglog([w["T"] for w in rows], [w["excess"] for w in rows], "+", color="0.6", ms=5,
                          label="D = L/150, phi = 0: T at the states (end_loads)")
        axs[2].plot([p["x"] for p in pts], [p["e_sqrtT"] for p in pts], mk + "-", color=col,
                    mfc="none" if r["phi"] else col, lw=0.7, ms=4, label=lab)
    f = fits.get("e_sqrtT")
    if f:
        xx = np.linspace(0, f["x_range"][1], 80)
        axs[2].plot(xx, f["c0_quadratic"] + f["c1_quadratic"] * xx + f["c2_quadratic"] * xx ** 2, "--", color="0.4",
                    lw=1, label=f"phi = 0, both D: quadratic fit in x, c0 = {f['c0_quadratic']:.3f}")
    axs[2].set(xlabel="x = D sqrt(T/B)", ylabel="e sqrt(T/B)", title="scaling: e sqrt(T/B) against D sqrt(T/B)",
               xlim=(0, None))
    axs[2].legend(fontsize=7)
    _published_panel(axs[3], eps_points or {}, (published or {}).get("fits", {}), style)
    tt = np.geomspace(60, 3000, 20)
    axs[0].loglog(tt, math.pi * np.sqrt(2.0 / tt), "--", color="0.4",
                  label="published loose limit: 2 pi R = pi sqrt(2B/T)")
    axs[1].loglog(tt, np.sqrt(2.0 / tt), "--", color="0.4", label="published loop diameter 2R = sqrt(2B/T)")
    axs[0].set(xlabel="T L^2 / B (mean over each step, -dE/de)", ylabel="excess length e / L",
               title="open overhand knot: excess length")
    axs[1].set(xlabel="T L^2 / B", ylabel="loop span / L", title="loop diameter")
    for ax in axs[:2]:
        ax.legend(fontsize=7)
    fig.suptitle("open overhand knot pulled by its ends: L = 1, B = 1, nu = 0.5, kappa_c = 100, 3 Gauss points; "
                 "filled: phi = 0, open: phi = +-2 pi; every state stable (Morse index 0 under fixed ends)")
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "open_knot.png"), dpi=100)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--case", default=None, help="run one case (a worker)")
    ap.add_argument("--combine", action="store_true", help="only combine the cases already written")
    ap.add_argument("--parallel", type=int, default=2)
    a = ap.parse_args()
    os.makedirs(PARTS, exist_ok=True)
    if a.case:
        run_case(a.case, os.path.join(PARTS, a.case + ".json"))
        return
    if not a.combine:
        t0 = time.time()
        pending = []
        for name, *_ in CASES:
            p = os.path.join(PARTS, name + ".json")
            if os.path.exists(p) and json.load(open(p)).get("done"):
                continue
            pending.append(name)
        if SMOKE:  # one case: run here, not in a worker process of its own
            for name in pending:
                run_case(name, os.path.join(PARTS, name + ".json"))
            pending = []
        running = []
        while pending or running:
            while pending and len(running) < a.parallel:
                running.append(subprocess.Popen([sys.executable, __file__, "--case", pending.pop(0)]))
            time.sleep(2)
            running = [p for p in running if p.poll() is None]
        print(f"cases ran in {time.time() - t0:.0f} s")
    combine()


if __name__ == "__main__":
    main()
