"""``jaxrod critical-curve --ratios 0.018:0.032:0.002 --N 61`` (the trefoil, default start) against
the point study ``jaxrod trefoil --D r L --L 292 --N 61`` at every ratio r, and each side's first
instability against a fine-step reference.

1. The curve, run as a user runs it (the CLI, both sides, default start ratio).
2. At each ratio, the point study as a user runs it (``--phi-min=-16pi --phi-max 16pi``, the curve's
   span; ``--no-extrapolation``, which does not change phi_plus / phi_minus): its phi_plus /
   phi_minus against the curve's row, which should agree to 1e-8 pi.
3. The reference: from the point study's own state at phi = 0 (its first step file), the branch
   followed by pseudo-arclength continuation in small steps (``ds_max`` 0.05, scaled arclength:
   under 0.016 pi of twist per step), the Morse index of the shape modes (sliding modes split off by
   their shape) watched at every point, and the first fold or branch point at which it grows located
   on its extended system (``jaxrod.studies.diagram.follow_branch_end``). Newton keeps that path on the one
   branch of equilibria through the start; the stable-only study can leave it (a jump) or pass an
   event between two of its steps. Where the two differ, the reference's value is the first
   instability of the equilibrium branch through the study's start.

Writes benchmarks/results/critical_curve_vs_study.json (after every step: a rerun goes on from it,
while the runs' folders are still in the temporary directory) and critical_curve_vs_study.md.
Run: python benchmarks/critical_curve_vs_study.py [--no-reference]   (~25 min on one core)
Small mode (``--smoke``): one ratio (0.0274, the D/L of accuracy_trefoil's and atlas_parallel's trefoil) at N = 41, the opening side, three reference points; the
two commands run in this process (``jaxrod.cli.main``), so that the programs compiled for the curve
serve the study and the reference.
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

from _bench import SMOKE, pick, provenance_line, results_dir, run_cli, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = results_dir()
# the runs' own folders (step files the reference starts from): scratch space, not results
WORK = pick(os.path.join(tempfile.gettempdir(), "jaxrod_critical_curve_vs_study"), os.path.join(RESULTS, "runs"))
JSON = os.path.join(RESULTS, "critical_curve_vs_study.json")
MD = os.path.join(RESULTS, "critical_curve_vs_study.md")
# small mode: one ratio at N = 41, D/L = 0.0274 (D = 8: the trefoil of accuracy_trefoil and atlas_parallel,
# whose compiled programs it shares; another D compiles its own), the opening side only (its first instability near
# +7 pi), a point study over a quarter turn (no event: nothing to compare, the same code), and the
# reference's first few arclength points
RATIOS = pick("0.018:0.032:0.002", "0.0274")
N, L = pick(61, 41), 292.0  # small mode: the N of the other small trefoil runs (accuracy, atlas, batch), whose programs it shares
SIDES = pick(("plus", "minus"), ("plus",))
PHI_RANGE = pick(("-16pi", "16pi"), ("-0.25pi", "0.25pi"))
REFERENCE_POINTS = pick(4000, 3)
PI = math.pi
AGREE = 1e-8  # pi


def _load():
    if os.path.exists(JSON):
        with open(JSON) as f:
            return json.load(f)
    return {"curve": None, "studies": {}, "references": {}}


def _save(data):
    tmp = JSON + ".tmp"
    with open(tmp, "w") as f:
        json.dump(with_provenance(data), f, indent=1, sort_keys=True)
    os.replace(tmp, JSON)


def run_curve():
    t = time.perf_counter()
    out = os.path.join(WORK, "curve")
    run = run_cli(["critical-curve", "--ratios", RATIOS, "--N", str(N), "--sides", ",".join(SIDES),
                  "--out", out, "--fresh", "--json", "--quiet"], in_process=SMOKE)
    if run.returncode != 0:
        raise RuntimeError(run.stderr)
    result = json.loads(run.stdout)
    result["wall_seconds"] = time.perf_counter() - t
    result["warnings"] = [line for line in run.stderr.splitlines() if "warning" in line]
    return result


def run_study(ratio):
    t = time.perf_counter()
    out = os.path.join(WORK, f"study_{ratio:.4f}")
    run = run_cli(["trefoil", "--D", repr(ratio * L), "--L", repr(L), "--N", str(N), f"--phi-min={PHI_RANGE[0]}",
                  "--phi-max", PHI_RANGE[1], "--out", out, "--json", "--no-figures", "--quiet", "--no-extrapolation",
                  "--fresh"], in_process=SMOKE)
    if run.returncode != 0:
        raise RuntimeError(run.stderr)
    summary = json.loads(run.stdout)
    keep = {k: v for k, v in summary.items() if k.startswith(("phi_plus", "phi_minus"))}
    keep["wall_seconds"] = time.perf_counter() - t
    keep["out"] = out
    return keep


def run_reference(ratio, side, study_out):
    """The first fold or branch point on the branch through the point study's state at phi = 0,
    followed in small pseudo-arclength steps (see the module docstring)."""
    from jaxrod.studies.diagram import DiagramOptions, follow_branch_end
    from jaxrod.model.scenes import trefoil

    t = time.perf_counter()
    with np.load(os.path.join(study_out, "steps", f"{side}_0000.npz")) as f:
        q0, phi0 = np.asarray(f["q"]), float(f["phi"])
    assert phi0 == 0.0
    scene = trefoil(D=ratio * L, L=L, N=N)
    sign = 1.0 if side == "plus" else -1.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        end = follow_branch_end(scene, q0, 0.0, sign, DiagramOptions(ds_max=0.05, max_points=REFERENCE_POINTS,
                                                                           unstable_points=1),
                                p_min=-16.5 * PI, p_max=16.5 * PI)
    ev = end.event
    return {"phi_over_pi": None if ev is None else float(ev.p) / PI, "kind": None if ev is None else ev.kind,
            "converged": bool(ev is not None and ev.converged), "points": len(end.points), "message": end.message,
            "morse": None if ev is None else [int(ev.morse_before), int(ev.morse_after)],
            "seconds": time.perf_counter() - t}


def _f(v, fmt):
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, fmt)


def report(data):
    curve = data["curve"]
    lines = ["# `jaxrod critical-curve` against point studies, N = 61 (trefoil)", "", provenance_line(), "",
             f"`jaxrod critical-curve --ratios {RATIOS} --N {N}` (default start ratio, both sides): "
             f"{curve['wall_seconds']:.0f} s wall. Point studies: `jaxrod trefoil --D r*292 --L 292 --N 61 "
             "--phi-min=-16pi --phi-max 16pi --no-extrapolation`. Reference: the branch through the point "
             "study's state at phi = 0 followed by pseudo-arclength continuation (ds_max 0.05), its first "
             "fold or branch point located on the extended system (`follow_branch_end`).", "",
             "| side | D/L | curve phi*/pi | kind | switched | IFT slope/pi | secant/pi | slope disagr. | "
             "study phi*/pi | curve - study (pi) | reference phi*/pi | ref. kind | reference - study (pi) |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    worst, n_rows = 0.0, 0
    for q in curve["rows"]:
        r, side = q["D_over_L"], q["side"]
        study = data["studies"].get(f"{r:.4f}", {})
        phi_s = study.get(f"phi_{side}")
        diff = None if phi_s is None else (q["phi_star"] - phi_s) / PI
        if diff is not None:
            worst, n_rows = max(worst, abs(diff)), n_rows + 1
        ref = data["references"].get(f"{r:.4f}_{side}", {})
        ref_phi = ref.get("phi_over_pi")
        ref_diff = None if ref_phi is None or phi_s is None else ref_phi - phi_s / PI
        kind = q["kind"] if q["located"] else "bracketed"
        lines.append(f"| {side} | {r:.3f} | {q['phi_star_over_pi']:+.10f} | {kind} | "
                     f"{'yes (' + q['previous_kind'] + ')' if q['switched'] else ''} | "
                     f"{_f(q['dphi_dratio'] and q['dphi_dratio'] / PI, '+.3f')} | "
                     f"{_f(q['secant_slope'] and q['secant_slope'] / PI, '+.3f')} | "
                     f"{_f(q['slope_disagreement'], '.3f')} | {_f(phi_s and phi_s / PI, '+.10f')} | "
                     f"{_f(diff, '+.1e')} | {_f(ref_phi, '+.10f')} | {ref.get('kind') or '-'} | "
                     f"{_f(ref_diff, '+.1e')} |")
    lines += ["", f"Rows compared with their point study: {n_rows} of {len(curve['rows'])}; largest |curve - study| = "
              f"{worst:.1e} pi (asked: {AGREE:g} pi)."]
    slopes = [q["slope_disagreement"] for q in curve["rows"] if q["slope_disagreement"] is not None]
    if slopes:
        lines.append(f"Slope check (IFT against the secant of neighbours of the same kind, {len(slopes)} rows): "
                     f"median {np.median(slopes):.3f}, largest {max(slopes):.3f}; "
                     f"{sum(v > 0.5 for v in slopes)} above 0.5.")
    refs = [(q, data["references"].get(f"{q['D_over_L']:.4f}_{q['side']}", {})) for q in curve["rows"]]
    refs = [(q, ref) for q, ref in refs if ref.get("phi_over_pi") is not None]
    if refs:
        same = sum(abs(ref["phi_over_pi"] - q["phi_star_over_pi"]) < 1e-8 for q, ref in refs)
        earlier = sum(abs(ref["phi_over_pi"]) < abs(q["phi_star_over_pi"]) - 1e-8 for q, ref in refs)
        lines.append(f"Reference from the study's state at phi = 0: the same event (to 1e-8 pi) at {same} of "
                     f"{len(refs)} rows; earlier at {earlier}, later at {len(refs) - same - earlier}. Where they differ, the "
                     "pseudo-arclength path and the stable-only study have parted on the way (the path stays on the "
                     "one equilibrium branch through the start, through the slide's soft folds; the study can pass "
                     "an event between two steps or move into another placement of the nodes).")
    lines.append("")
    if curve.get("warnings"):
        lines += ["The curve's warnings:", ""] + [f"- {w}" for w in curve["warnings"]] + [""]
    return "\n".join(lines)


def main(with_reference=True):
    os.makedirs(WORK, exist_ok=True)
    data = _load()
    if data["curve"] is None:
        print("critical curve ...", flush=True)
        data["curve"] = run_curve()
        _save(data)
    ratios = sorted({q["D_over_L"] for q in data["curve"]["rows"]})
    for r in ratios:
        key = f"{r:.4f}"
        if key not in data["studies"]:
            print(f"point study at D/L = {r} ...", flush=True)
            data["studies"][key] = run_study(r)
            _save(data)
    if with_reference:
        for r in ratios:
            for side in SIDES:
                key = f"{r:.4f}_{side}"
                if key not in data["references"]:
                    print(f"reference at D/L = {r}, {side} ...", flush=True)
                    data["references"][key] = run_reference(r, side, data["studies"][f"{r:.4f}"]["out"])
                    _save(data)
    text = report(data)
    with open(MD, "w") as f:
        f.write(text + "\n")
    print(text)


if __name__ == "__main__":
    main(with_reference="--no-reference" not in sys.argv[1:])
