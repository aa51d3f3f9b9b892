"""The trefoil's critical twists as curves phi*+-(D/L) (issue 17, item 5 / acceptance 6).

D is varied at fixed L = 292 mm and N = 128 (N >= L/D down to D/L = 0.0079), E and nu fixed, so
B, C ~ D^4, EA ~ D^2 and the contact distance is D (``jaxrod.continuation.arclength.rods.set_diameter``).
Each side's first instability is located at the paper's D/L = 8/292 (the symmetric branch from
phi = 0 by the stable-only engine, then pseudo-arclength continuation through the event), then
followed in D by ``jaxrod.continuation.arclength.event_curve``: natural-parameter continuation in D, whose
predictor is the implicit function theorem on the event's extended system and whose corrector is
the event located again on a short pseudo-arclength run in phi at the new D (the fold system
alone, Newton in (u, phi) at fixed D, drifts onto the knot's sliding mode: see the module
docstring). Every row carries the kind of the event, its critical eigenvalue and residual, and
dphi*/d(D/L) from the implicit function theorem.

Checks:
- point studies at the 7 values of CHECKS: a new scene at that D, the stable-only engine from
  phi = 0 to 0.1 pi before the curve's value, then the event located on its own;
- dphi*/d(D/L) of each point study (IFT) against central differences of two more point studies at
  D +- h, started from that point study's stable state before its event (h = 1e-3, 1e-4 and 1e-5 D:
  the differences converge as h^2 to the IFT where the curve bends sharply).

Writes benchmarks/results/fold_curve_ratio.{json,csv,md,png} (the JSON after every point, so an
interrupted run keeps what it did).
Run: python benchmarks/fold_curve_ratio.py   (~45 min on 2 cores; `... plus` or `... minus` for one side,
`... checks SIDE` for the point studies only, `... report` to rewrite the tables and figure)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import csv  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402
from jaxrod.continuation import ContinuationOptions  # noqa: E402
from jaxrod.continuation.arclength import PseudoArclength  # noqa: E402
from jaxrod.continuation.arclength.event_curve import EventCurveOptions, event_curve  # noqa: E402
from jaxrod.continuation.arclength.rods import knot_problem, set_diameter  # noqa: E402
from jaxrod.model.symmetry import two_fold_asymmetry  # noqa: E402

PI = math.pi
from _bench import SMOKE, markdown, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)

L, D0, NU = 292.0, 8.0, 0.5
N = pick(128, 61)  # the small mode: the fewest nodes whose start at phi = 0 is a minimum
# small mode: one grid point below D0/L = 0.0274 (the way up locates the event at D0 alone), one point
# study there, one central difference; its point study's first event is a fold, where one at 0.028 is a
# branch point, whose sensitivity alone compiles for longer than the rest of the small run
GRID = pick(np.round(np.arange(0.008, 0.0451, 0.001), 4), np.array([0.027]))  # D/L
CHECKS = pick((0.010, 0.015, 0.020, 0.025, 0.030, 0.035, 0.040), (0.027,))  # every 0.005 over the range
SIDES = {"plus": dict(sign=1.0, below=pick(6.35, 6.3), name="opening"),  # small mode: N = 61's fold found first try
         "minus": dict(sign=-1.0, below=-10.9, name="tightening")}
DELTA = 0.03 * PI
MAX_JUMP = 2.0  # scaled units (edge lengths): a start that relaxed further has left the branch
H_RELS = pick((1e-3, 1e-4, 1e-5), (1e-3,))  # central-difference steps h / D (the last one is the check)
# The curves from D0 end before the grid's ends (the opening fold at a cusp near D/L = 0.0425, the
# tightening event where its curve turns back in D/L near 0.039); past them the first instability is
# another event (point studies at 0.044: opening 7.818 pi, tightening -12.679 pi). That event is
# followed as a second segment, from a point study at HIGH_START down to HIGH_LOW (``... high SIDE``).
HIGH_START, HIGH_LOW = 0.045, 0.030
HIGH_BELOW = {"plus": 7.2, "minus": -12.0}
HIGH_JSON = "fold_curve_ratio_high.json"
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = results_dir()
ALG = PseudoArclength()
# The stable-only engine's largest step to a start state: in the small mode 3 pi reaches ~6.3 pi in 3
# steps, where 2 pi takes 5-6 (steps refused and halved on the way).
FOLLOW_STEP = pick(2 * PI, 3 * PI)


def options(sign, max_points=60):
    return EventCurveOptions(_path(sign), DELTA, ALG, max_jump=MAX_JUMP, max_points=max_points)


def _path(sign):
    return ContinuationOptions(ds=0.05 * sign, ds_min=1e-6, ds_max=0.5, newton_tol=1e-10, eig_rtol=1e-13, k=6,
                               p_min=-20 * PI, p_max=16 * PI)


def asymmetry(rod, u):
    """The state's distance from the nearest two-fold symmetry that maps the nodes onto each other
    (rms, in edge lengths): node i -> k - i, over every k (through a node for k even, an edge's
    midpoint for k odd). The symmetry through the joint is k = 0; the material slid by whole edges is
    the same state (an isotropic rod's energy does not depend on where its joint is), symmetric
    about another node."""
    x = rod.nodes(u)
    return float(min(two_fold_asymmetry(np.roll(x[::-1], k + 1, axis=0)).asymmetry for k in range(N)) / (L / N))


def row_of(side, r, stage, rod):
    return dict(side=side, stage=stage, D_over_L=r.mu / L, phi_star_over_pi=r.p / PI, kind=r.kind,
                morse_before=r.morse_before, morse_after=r.morse_after, critical_eigenvalue=r.critical_eigenvalue,
                residual=r.residual, dphi_dratio_over_pi=r.dp_dmu * L / PI,
                predicted_over_pi=(r.predicted / PI if np.isfinite(r.predicted) else None), seconds=r.seconds,
                back_offs=r.back_offs, points=r.points, symmetric=bool(r.symmetric), asymmetry=asymmetry(rod, r.u),
                anchor_asymmetry=asymmetry(rod, r.anchor_u))


def start_state(D, below):
    """A state on the symmetric branch at phi = below (rad), from phi = 0, at diameter D."""
    scene = jr.trefoil(D=D, L=L, N=N, nu=NU)
    old = jr.follow_twist(scene, 0.0, below, jr.ContinuationOptions(step=FOLLOW_STEP, max_switches=0))
    e = old.points[-1].equilibrium
    return knot_problem(scene, np.asarray(e.q), e.phi)


def run_side(side, summary, save):
    cfg = SIDES[side]
    sign = cfg["sign"]
    t0 = time.perf_counter()
    rod = start_state(D0, cfg["below"] * PI)
    summary["start_seconds"][side] = time.perf_counter() - t0

    def observer(stage):
        def obs(r):
            rows = summary["curve"]
            rows.append(row_of(side, r, stage, rod))
            print(f"[{side} {stage}] D/L {r.mu / L:.4f}: {r.kind} {r.p / PI:+.9f} pi, lambda {r.critical_eigenvalue:.1e}, "
                  f"residual {r.residual:.1e}, dphi*/d(D/L) {r.dp_dmu * L / PI:+.3f} pi, {r.seconds:.1f} s",
                  flush=True)
            save()
        return obs

    results = {}
    for stage, grid in (("up", [g for g in GRID if g > D0 / L]), ("down", [g for g in GRID[::-1] if g < D0 / L])):
        if SMOKE and not grid:  # the small grid lies below D0: the way up would only locate D0's event again
            continue
        problem = rod.problem
        problem.args = set_diameter(problem.args, D0)
        t = time.perf_counter()
        curve = event_curve(problem, (problem.u0, problem.p0), set_diameter, D0, [g * L for g in grid],
                            options(sign, pick(150, 20)), observer=observer(stage),
                            progress=lambda m: print(f"  [{side} {stage}] {m}", flush=True))
        summary["curve_seconds"][f"{side}_{stage}"] = time.perf_counter() - t
        summary["curve_result"][f"{side}_{stage}"] = [curve.result.value, curve.message]
        results[stage] = curve
        if stage == "up":  # the start state again at D0 for the way down (args back at D0)
            rod = start_state(D0, cfg["below"] * PI)


def run_high(side, high, save):
    """The second segment: the first event at D/L = HIGH_START (from a state on the symmetric branch
    at HIGH_BELOW) followed down the grid to HIGH_LOW; rows with stage "high"."""
    sign = SIDES[side]["sign"]
    D = HIGH_START * L
    t0 = time.perf_counter()
    rod = start_state(D, HIGH_BELOW[side] * PI)
    high["start_seconds"][side] = time.perf_counter() - t0

    def obs(r):
        high["curve"].append(row_of(side, r, "high", rod))
        print(f"[{side} high] D/L {r.mu / L:.4f}: {r.kind} {r.p / PI:+.9f} pi, lambda {r.critical_eigenvalue:.1e}, "
              f"residual {r.residual:.1e}, dphi*/d(D/L) {r.dp_dmu * L / PI:+.3f} pi, {r.seconds:.1f} s", flush=True)
        save()

    problem = rod.problem
    t = time.perf_counter()
    curve = event_curve(problem, (problem.u0, problem.p0), set_diameter, D,
                        [g * L for g in GRID[::-1] if HIGH_LOW - 1e-9 <= g < HIGH_START - 1e-9],
                        options(sign, 300), observer=obs, progress=lambda m: print(f"  [{side} high] {m}", flush=True))
    high["curve_seconds"][f"{side}_high"] = time.perf_counter() - t
    high["curve_result"][f"{side}_high"] = [curve.result.value, curve.message]
    save()


def checks(side, curve_rows, summary, save):
    """Point studies at CHECKS: a new scene at D from phi = 0, its event located on its own; then
    dphi*/d(D/L) of that point study (IFT) against central differences of two more point studies
    at D +- h, each started from the point study's own stable state before its event."""
    sign = SIDES[side]["sign"]
    for ratio in CHECKS:
        r = next((q for q in curve_rows if q["side"] == side and abs(q["D_over_L"] - ratio) < 1e-9), None)
        if r is None:  # past the end of the curve from D0: the second segment's point, if any
            r = next((q for q in _high_rows()["curve"] if q["side"] == side and abs(q["D_over_L"] - ratio) < 1e-9), None)
        if r is None:
            continue
        D = ratio * L
        t = time.perf_counter()
        rod = start_state(D, (r["phi_star_over_pi"] - sign * 0.1) * PI)
        study = event_curve(rod.problem, (rod.problem.u0, rod.problem.p0), set_diameter, D, [], options(sign, 300))
        seconds = time.perf_counter() - t
        if not study.points:
            print(f"[{side} check] D/L {ratio}: point study found no event ({study.message})", flush=True)
            summary["checks"].append(dict(side=side, D_over_L=ratio, curve_over_pi=r["phi_star_over_pi"],
                                          curve_kind=r["kind"], study_over_pi=None, message=study.message))
            save()
            continue
        q = study.points[0]
        centrals = []
        for h_rel in H_RELS:  # two steps: a difference that changes with h is truncation, not the IFT
            h = h_rel * D
            located = []
            for mu in (D - h, D + h):
                c = event_curve(rod.problem, (q.anchor_u, q.anchor_p), set_diameter, mu, [], options(sign, 300))
                located.append((c.points[0].p, c.points[0].kind) if c.points else (float("nan"), None))
            centrals.append(((located[1][0] - located[0][0]) / (2 * h), [k for _, k in located]))
        # the step whose difference is nearest the IFT: truncation (~h^2) shrinks with h, and the noise of
        # the located phi* (~1e-12 pi) over 2h grows; a difference that converges to the IFT as h falls
        # is the check (all three are kept)
        best = int(np.argmin([abs(c - q.dp_dmu) if np.isfinite(c) else np.inf for c, _ in centrals]))
        fd, kinds = centrals[best]
        row = dict(side=side, D_over_L=ratio, curve_over_pi=r["phi_star_over_pi"], curve_kind=r["kind"],
                   study_over_pi=q.p / PI, study_kind=q.kind, study_asymmetry=asymmetry(rod, q.u),
                   curve_asymmetry=r.get("asymmetry"),
                   difference_over_pi=abs(q.p / PI - r["phi_star_over_pi"]), study_seconds=seconds,
                   curve_ift_over_pi=r["dphi_dratio_over_pi"], study_ift_over_pi=q.dp_dmu * L / PI,
                   central_difference_over_pi=fd * L / PI, central_kinds=kinds,
                   derivative_rel_diff=abs(fd - q.dp_dmu) / abs(q.dp_dmu), h_over_D=H_RELS[best],
                   centrals=[dict(h_over_D=h_rel, central_over_pi=c * L / PI, kinds=k,
                                  rel_diff=abs(c - q.dp_dmu) / abs(q.dp_dmu)) for h_rel, (c, k) in zip(H_RELS, centrals)])
        summary["checks"].append(row)
        others = "; ".join(f"{c['rel_diff']:.1e} at h = {c['h_over_D']:g} D" for c in row["centrals"])
        print(f"[{side} check] D/L {ratio}: curve {r['phi_star_over_pi']:+.10f} pi ({r['kind']}), study "
              f"{q.p / PI:+.10f} pi ({q.kind}), difference {row['difference_over_pi']:.1e} pi; IFT "
              f"{row['study_ift_over_pi']:+.6f} pi, central {row['central_difference_over_pi']:+.6f} pi "
              f"({kinds[0]}, {kinds[1]}), rel {row['derivative_rel_diff']:.1e} at h = {H_RELS[best]:g} D ({others}); "
              f"asymmetry study {row['study_asymmetry']:.1e}, curve {row['curve_asymmetry']}", flush=True)
        save()


def _saver(path, data):
    """save() -> None: ``data`` written to ``path`` as JSON atomically (after every point)."""
    def save():
        tmp = path + ".tmp"
        with open(tmp, "w") as f:
            json.dump(with_provenance(data), f, indent=1)
        os.replace(tmp, path)
    return save


def main_high(sides):
    path = os.path.join(OUT, HIGH_JSON)
    high = dict(curve=[], start_seconds={}, curve_seconds={}, curve_result={})
    if os.path.exists(path):
        with open(path) as f:
            old = json.load(f)
        high["curve"] = [r for r in old["curve"] if r["side"] not in sides]
        for key in ("start_seconds", "curve_seconds", "curve_result"):
            high[key] = {k: v for k, v in old.get(key, {}).items() if not any(k.startswith(s) for s in sides)}

    save = _saver(path, high)

    for side in sides:
        run_high(side, high, save)
    with open(os.path.join(OUT, "fold_curve_ratio.json")) as f:
        report(json.load(f))


def main():
    os.makedirs(OUT, exist_ok=True)
    if sys.argv[1:2] == ["high"]:
        main_high(sys.argv[2:] or ["plus", "minus"])
        return
    only_checks = sys.argv[1:2] == ["checks"]
    sides = sys.argv[2:] if only_checks else (sys.argv[1:] or pick(["plus", "minus"], ["plus"]))
    path = os.path.join(OUT, "fold_curve_ratio.json")
    summary = dict(L=L, N=N, nu=NU, D0=D0, grid=GRID.tolist(), delta_over_pi=DELTA / PI, curve=[], checks=[],
                   start_seconds={}, curve_seconds={}, curve_result={})
    if os.path.exists(path) and len(sides) < 2:
        with open(path) as f:
            old = json.load(f)
        summary["curve"] = [r for r in old.get("curve", []) if only_checks or r["side"] not in sides]
        summary["checks"] = [r for r in old.get("checks", []) if r["side"] not in sides]
        for key in ("start_seconds", "curve_seconds", "curve_result"):
            summary[key] = {k: v for k, v in old.get(key, {}).items()
                            if only_checks or not any(k.startswith(s) for s in sides)}

    save = _saver(path, summary)

    for side in sides:
        if not only_checks:
            run_side(side, summary, save)
        summary["checks"] = [c for c in summary["checks"] if c["side"] != side]
        checks(side, summary["curve"], summary, save)
    save()  # also when no point was found (the small mode's few steps)
    report(summary)


def report(s):
    rows = sorted(s["curve"], key=lambda r: (r["side"], r["D_over_L"]))
    _write_csv("fold_curve_ratio.csv", rows)
    lines = ["# The trefoil's critical twists against D/L: event curves against point studies", "",
             f"L = {s['L']:g} mm, N = {s['N']}, nu = {s['nu']}, D varied at fixed E (B, C ~ D^4), contact at D; "
             f"`benchmarks/fold_curve_ratio.py`. Each side's first instability followed in D/L by "
             f"`jaxrod.continuation.arclength.event_curve` from D/L = {s['D0'] / s['L']:.4f} up and down.", ""]
    lines += _curve_lines(s, rows)
    lines += ["", "Point studies (a new scene at that D, followed from phi = 0 on the two-fold symmetry through the joint; "
              "its event located on its own) and, for each, dphi*/d(D/L) from the IFT against central differences of two "
              "more point studies at D +- h (each from the point study's stable state before its event; h = 1e-3, 1e-4 and "
              "1e-5 D, the one nearest the IFT shown, all in brackets: truncation falls as h^2, noise grows as 1/h). Asymmetry: the located states' rms distance from the symmetry, in "
              "edge lengths:", "",
              "| side | D/L | curve / pi | point study / pi | difference / pi | asymmetry curve / study | "
              "dphi*/d(D/L) IFT / pi | central / pi | rel. diff |", "|---|---|---|---|---|---|---|---|---|"]
    for c in s["checks"]:
        if c.get("study_over_pi") is None:
            lines.append(f"| {c['side']} | {c['D_over_L']:.3f} | {c['curve_over_pi']:+.10f} ({c['curve_kind']}) | "
                         f"no event: {c.get('message', '')} | | | | | |")
            continue
        centrals = c.get("centrals", [])
        others = ", ".join(f"{q['rel_diff']:.1e} at {q['h_over_D']:g} D" for q in centrals)
        deriv = (f"{c['study_ift_over_pi']:+.6f} | {c['central_difference_over_pi']:+.6f} (h = {c['h_over_D']:g} D) | "
                 f"{c['derivative_rel_diff']:.1e}" + (f" ({others})" if others else ""))
        asym = f"{_fmt(c.get('curve_asymmetry'))} / {_fmt(c.get('study_asymmetry'))}"
        lines.append(f"| {c['side']} | {c['D_over_L']:.3f} | {c['curve_over_pi']:+.10f} ({c['curve_kind']}) | "
                     f"{c['study_over_pi']:+.10f} ({c['study_kind']}) | {c['difference_over_pi']:.1e} | {asym} | {deriv} |")
    high = _high_rows()
    if high["curve"]:
        _write_csv("fold_curve_ratio_high.csv", sorted(high["curve"], key=lambda r: (r["side"], r["D_over_L"])))
        lines += ["", f"Second segment: the first event at D/L = {HIGH_START} (a point study, from a state on the symmetric "
                  f"branch at {HIGH_BELOW['plus']} pi / {HIGH_BELOW['minus']} pi) followed down to D/L = {HIGH_LOW} "
                  "(`python benchmarks/fold_curve_ratio.py high`). Where both segments exist, the first instability is the "
                  "event of smaller |phi*|.", ""]
        lines += _curve_lines(high, sorted(high["curve"], key=lambda r: (r["side"], r["D_over_L"])))
    with open(os.path.join(OUT, "fold_curve_ratio.md"), "w") as f:
        f.write(markdown(lines))
    plot(rows, s, sorted(high["curve"], key=lambda r: (r["side"], r["D_over_L"])))


def _fmt(x):
    return "--" if x is None else f"{x:.1e}"


CSV_KEYS = ["side", "D_over_L", "phi_star_over_pi", "kind", "morse_before", "morse_after", "critical_eigenvalue",
            "residual", "dphi_dratio_over_pi", "predicted_over_pi", "seconds", "asymmetry"]


def _write_csv(name, rows):
    with open(os.path.join(OUT, name), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(CSV_KEYS)
        for r in rows:
            w.writerow([r.get(k) if not isinstance(r.get(k), float) else f"{r[k]:.12g}" for k in CSV_KEYS])


def _curve_lines(run, rows):
    """Markdown: a line per leg of ``run`` (points, seconds, how it ended), then the table of ``rows``."""
    lines = []
    for key, seconds in run["curve_seconds"].items():
        res = run["curve_result"].get(key, ["", ""])
        n = len([r for r in run["curve"] if f"{r['side']}_{r['stage']}" == key])
        lines.append(f"- {key}: {n} points in {seconds:.0f} s ({res[0]}{': ' + res[1] if res[1] else ''})")
    lines += ["", "| side | D/L | phi* / pi | kind | Morse | critical eigenvalue | residual | dphi*/d(D/L) / pi |",
              "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['side']} | {r['D_over_L']:.4f} | {r['phi_star_over_pi']:+.9f} | {r['kind']} | "
                     f"{r['morse_before']} -> {r['morse_after']} | {r['critical_eigenvalue']:.1e} | {r['residual']:.1e} | "
                     f"{r['dphi_dratio_over_pi']:+.3f} |")
    return lines


def _high_rows():
    path = os.path.join(OUT, HIGH_JSON)
    if not os.path.exists(path):
        return dict(curve=[], curve_seconds={}, curve_result={})
    with open(path) as f:
        return json.load(f)


def plot(rows, s, high=()):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5))
    for side, colour in (("plus", "C0"), ("minus", "C3")):
        rr = [r for r in rows if r["side"] == side]
        if not rr:
            continue
        x = np.array([r["D_over_L"] for r in rr])
        y = np.array([r["phi_star_over_pi"] for r in rr])
        ax.plot(x, y, "-", color=colour, lw=1.2, label=f"{SIDES[side]['name']} side: first instability (event curve)")
        for kind, marker in (("fold", "o"), ("branch_point", "D")):
            m = np.array([r["kind"] == kind for r in rr])
            if m.any():
                ax.plot(x[m], y[m], marker, color=colour, ms=3.5, ls="none",
                        label=f"  {kind.replace('_', ' ')}s")
    for side, colour in (("plus", "C0"), ("minus", "C3")):
        rr = [r for r in high if r["side"] == side]
        if rr:
            ax.plot([r["D_over_L"] for r in rr], [r["phi_star_over_pi"] for r in rr], "-", color=colour, lw=1.2,
                    marker=".", ms=4, alpha=0.6, label=f"{SIDES[side]['name']} side: second segment (from D/L = {HIGH_START})")
    for c in s["checks"]:
        if c.get("study_over_pi") is not None:
            ax.plot(c["D_over_L"], c["study_over_pi"], "ks", mfc="none", ms=8)
    ax.plot([], [], "ks", mfc="none", ms=8, label="point studies (from phi = 0)")
    atlas = os.path.join(OUT, "atlas", "atlas.csv")
    if os.path.exists(atlas):
        with open(atlas) as f:
            pts = [r for r in csv.DictReader(f) if r["knot"] == "3_1"]
        ax.plot([float(r["D_over_L"]) for r in pts], [float(r["phi_star_over_pi"]) for r in pts], "x", color="0.4",
                label="knot atlas (N = 101 to 201, stable-only engine)")
    m = 2 * math.sqrt(3) * (1 + s["nu"])
    ax.axhline(m, color="C0", ls="--", lw=1, label=f"Michell's ring, +{m:.3f} pi")
    ax.axhline(-2 * m, color="C3", ls="--", lw=1, label=f"2 x Michell, -{2 * m:.3f} pi")
    ax.set_xlabel("D / L (-)")
    ax.set_ylabel("critical twist phi* / pi")
    ax.set_title(f"Trefoil, L = {s['L']:g} mm, N = {s['N']}: critical twists against D/L")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "fold_curve_ratio.png"), dpi=120)


if __name__ == "__main__":
    if sys.argv[1:2] == ["report"]:
        with open(os.path.join(OUT, "fold_curve_ratio.json")) as f:
            report(json.load(f))
    else:
        main()
