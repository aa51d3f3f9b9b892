"""MkDocs hook: the pages whose content the code and the benchmark results hold.

- ``cli.md``: each command's ``--help``, from the argparse parsers of ``jaxrod.cli.parser``;
- ``validation.md`` and ``performance.md``: tables read from ``benchmarks/results/*.json`` (and
  ``speed.csv``), each row with the command that reproduces it;
- the benchmarks' charts (``benchmarks/results/*.png``) are added to the site from where they live
  (the notebooks come in through the links in ``docs/examples/``, rendered by mkdocs-jupyter, not
  executed).

A page asks for a table with a marker line ``<!-- generated: NAME -->``. Nothing is typed twice,
so the pages cannot drift from the parsers or the results.
"""
from __future__ import annotations

import csv
import json
import math
import os
import pathlib

from mkdocs.structure.files import File

REPO = pathlib.Path(__file__).resolve().parent.parent
RESULTS = REPO / "benchmarks" / "results"
CHARTS = ("speed.png", "sparse_contact.png", "dynamics_accuracy.png", "michell.png", "helical_buckling.png",
          "peer_pyelastica.png", "tension_twist.png", "fold_curve_nu.png", "fold_curve_ratio.png",
          "hysteresis_trefoil.png", "bifurcation_trefoil.png", "plectoneme.png", "open_knot.png",
          "accuracy_trefoil.png", "trefoil_convergence.png", "shear_kirchhoff_limit.png",
          "shear_trefoil_limit.png", "loose_limit.png")
PI = math.pi


def on_files(files, config):
    for name in CHARTS:
        if (RESULTS / name).exists():
            files.append(File.generated(config, f"results/{name}", abs_src_path=str(RESULTS / name)))
    return files


def on_page_markdown(markdown, page, config, files):
    for name, make in GENERATORS.items():
        marker = f"<!-- generated: {name} -->"
        if marker in markdown:
            markdown = markdown.replace(marker, make())
    return markdown


# ---------------------------------------------------------------------------------------- CLI

def cli_reference():
    os.environ.setdefault("COLUMNS", "100")  # argparse wraps help at the terminal's width
    from jaxrod.cli import parser as cli_parser

    top = cli_parser.build_parser()
    sub = next(a for a in top._actions if a.dest == "command")
    parts = ["## jaxrod", "", "```text", top.format_help().rstrip(), "```", ""]
    for name, command in sub.choices.items():
        parts += [f"## jaxrod {name}", "", "```text", command.format_help().rstrip(), "```", ""]
    return "\n".join(parts)


# ---------------------------------------------------------------------------------- tables

def _load(name):
    path = RESULTS / name
    return json.loads(path.read_text()) if path.exists() else None


def _table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def _missing(name):
    return f"no result file (`benchmarks/results/{name}`)"


def validation_table():
    rows = []
    same = _load("redesign_same_answers.json")
    if same and "michell" in same["cases"]:
        case = same["cases"]["michell"]
        phi = next(h["new"] for h in case["headlines"] if h["key"] == "phi_star")
        n = case["args"][case["args"].index("--N") + 1]
        exact = 2 * PI * math.sqrt(3) * 1.5
        rows.append(["Michell's ring, ν = 0.5: φ* = 2π√3 (1 + ν)", f"{exact / PI:.7f} π",
                     f"{phi / PI:.7f} π (N = {n})", f"{(phi - exact) / exact:.1e} relative",
                     f"`jaxrod {' '.join(case['args'])}`"])
    else:
        rows.append(["Michell's ring", "", _missing("redesign_same_answers.json"), "", ""])
    ring = (_load("bifurcation_michell.json") or {}).get("zero_thickness")
    if ring:
        e, lim = ring["energy"], ring["limit"]["energy"]
        rows.append(["Michell's ring at first self-contact as D → 0: the figure-eight elastica, E = 32 K(m)² (m − ½) B/L",
                     f"{lim:.6f} B/R, φ = 2π, Wr = 1",
                     f"{e['value']:.6f} ± {e['error']:.0e} B/R (N = {', '.join(map(str, e['N']))} → ∞); "
                     f"φ/π = {ring['intercepts']['phi_over_pi']['value']:.6f}, Wr = {ring['intercepts']['Wr']['value']:.6f}",
                     f"{(e['value'] - lim) / lim:.1e} relative", "`python benchmarks/bifurcation_michell.py`"])
    tension = _load("tension_twist.json")
    if tension:
        finest = max(r["N"] for r in tension["onset"])
        onset = [r for r in tension["onset"] if r["N"] == finest]
        low = min(onset, key=lambda r: r["t"])
        worst = max(abs(r["rel_err"]) for r in onset)
        rows.append(["Greenhill: clamped rod under tension T and twist, onset moment M_c (→ 8.9868 B/L as T → 0)",
                     f"continuum clamped problem, M_c L/B = {low['M_c_continuum']:.4f} at TL²/B = {low['t']:g}",
                     f"{low['M_c']:.4f} (N = {finest})",
                     f"≤ {worst:.1e} relative over TL²/B = " + ", ".join(format(r["t"], "g") for r in onset),
                     "`python benchmarks/tension_twist.py`"])
    else:
        rows.append(["Greenhill", "", _missing("tension_twist.json"), "", ""])
    accuracy = _load("accuracy_trefoil.json")
    if accuracy:
        paper = {"plus": "8 π (simulation and experiment, ±2 π; opposite sign convention)",
                 "minus": "11.6 π (simulation; experiment ~10 π ± 2 π; opposite sign convention)"}
        for side in ("minus", "plus"):
            s = accuracy[side]
            rows.append([f"trefoil (D, L) = (8, 292) mm, {'tightening' if side == 'minus' else 'opening'} side",
                         paper[side], f"{s['phi_star_over_pi']:+.5f} π ± {s['error_over_pi']:.1e} π "
                         f"(N = {', '.join(str(n) for n in s['extrapolation']['N'])}, extrapolated)",
                         f"{abs(abs(s['phi_star_over_pi']) - (8.0 if side == 'plus' else 11.6)):.2f} π from the paper",
                         "`jaxrod trefoil --D 8 --L 292 --accuracy 0.01pi --out results/acc`"])
    else:
        rows.append(["trefoil against the paper", "", _missing("accuracy_trefoil.json"), "", ""])
    helix = _load("helix_reference.json")
    if helix:
        valid = [r for r in helix["rows"] if r.get("reference_valid")]
        m_err = max(abs(r["m_rel_error"]) for r in valid)
        t_err = max(abs(r["t_rel_error"]) for r in valid)
        m_x = max(abs(r["m_extrapolated_rel_error"]) for r in valid)
        t_x = max(abs(r["t_extrapolated_rel_error"]) for r in valid)
        rows.append(["localized helix of a clamped rod (Neukirch, van der Heijden & Thompson 2002, eqs. 14–15)",
                     "end moment m = ML/B and tension t = TL²/B at the analytic (d, R)",
                     f"{len(valid)} loops, N = {helix['N']}",
                     f"m ≤ {m_err:.1e}, t ≤ {t_err:.1e} relative; Richardson: {m_x:.1e}, {t_x:.1e}",
                     "`python benchmarks/helix_reference.py`"])
    else:
        rows.append(["helix against NvdHT", "", _missing("helix_reference.json"), "", ""])
    peer = _load("peer_pyelastica.json")
    if peer:
        best = peer["at_pyelastica_best"]
        rows.append(["localized helix against PyElastica (same rod, same ends; θ(s) envelope, L1 error)",
                     f"PyElastica {peer['pyelastica_version']}: {best['pyelastica_best_err']:.1e} "
                     f"in {best['pyelastica_s']:.0f} s (n = {best['pyelastica_n']})",
                     f"jaxrod N = {best['jaxrod_N']}: {best['jaxrod_err']:.1e} in {best['jaxrod_warm_s']:.1f} s warm",
                     "both against the analytic envelope", "`python benchmarks/peer_pyelastica.py`"])
    else:
        rows.append(["helix against PyElastica", "", _missing("peer_pyelastica.json"), "", ""])
    plectoneme = _load("plectoneme.json")
    if plectoneme:
        p = plectoneme
        rows.append(["plectoneme at constant tension: torque plateau (two-phase model with hard contact, "
                     "Clauvelin–Audoly–Neukirch superhelix form)",
                     f"M L/B = {p['two_phase_M_p']:.2f}, extension {p['two_phase_slope']:.4f} L per turn",
                     f"{p['plateau_M_mean']:.2f} ({p['plateau_M_min']:.2f} … {p['plateau_M_max']:.2f}), "
                     f"{p['slope_ext_per_turn']:.4f} L per turn (N = {p['N']})",
                     f"{abs(p['plateau_M_mean'] / p['two_phase_M_p'] - 1):.1e} relative (mean torque)",
                     "`python benchmarks/plectoneme.py`"])
    # CWF: no benchmark writes its result yet; the row says so until one does
    cwf = _load("cwf.json")
    rows.append(["CWF", "", "not yet reproduced: " + _missing("cwf.json") if cwf is None
                 else json.dumps(cwf)[:80], "", ""])
    rows += _differentiable_rows() + _shear_rows() + _figure_eight_rows()
    return _table(["reference", "reference value", "jaxrod", "error", "reproduce"], rows)


def _figure_eight_rows():
    """The amphichiral figure-eight knot: its two converged ends against the mirror symmetry."""
    data = _load("figure_eight_accuracy.json")
    if not data:
        return [["figure-eight knot: mirror-image ends", "", _missing("figure_eight_accuracy.json"), "", ""]]
    rows = []
    for case in data["cases"]:
        plus, minus = case["sides"]["plus"], case["sides"]["minus"]
        if not (plus["reached"] and minus["reached"]):
            continue
        rows.append([f"figure-eight knot (amphichiral), D/L = {case['D_over_L']:g}, start's mirror distance "
                     f"{case['mirror_distance_start']:.1e}: φ*₊ = −φ*₋",
                     "mirror symmetry", f"{plus['phi_star_over_pi']:+.4f} π ± {plus['error_over_pi']:.3f} π, "
                     f"{minus['phi_star_over_pi']:+.4f} π ± {minus['error_over_pi']:.3f} π "
                     f"(N = {', '.join(map(str, plus['extrapolation']['N']))}, extrapolated)",
                     f"|φ*₊ + φ*₋| = {case['asymmetry_over_pi']:.1e} π, error bars {case['error_sum_over_pi']:.3f} π",
                     "`python benchmarks/figure_eight_accuracy.py`"])
    return rows


def _differentiable_rows():
    """The trefoil's derivatives by JAX against differences, and the calibration round trip."""
    data = _load("differentiable_trefoil.json")
    if not data:
        return [["derivatives of the trefoil's critical twists", "", _missing("differentiable_trefoil.json"), "", ""]]
    twists, command = data["critical_twists"], "`python benchmarks/differentiable_trefoil.py`"
    ends = sorted({f"{r['phi_over_pi']:+.4f} π ({r['kind']})" for r in twists})
    rows = [[f"trefoil (8, 292) mm, N = {data['N']}: φ* by `jax.grad` and forward-over-reverse, in "
             + ", ".join(dict.fromkeys(r["parameter"] for r in twists)),
             "differences of ends located at p ± h", ", ".join(ends),
             f"gradients ≤ {max(r['rel_grad'] for r in twists):.1e}, second derivatives ≤ "
             f"{max(r['rel_hessian'] for r in twists):.1e}, equilibrium Jacobian ≤ "
             f"{max(r['rel_jacobian'] for r in data['equilibrium']):.1e} relative", command]]
    trip = data.get("round_trip")
    if trip:
        both = f" and tightening onsets at {len(trip['tightening_ratios'])} of them" if trip.get("tightening_ratios") else ""
        rows.append([f"calibration round trip: (ν, k) from opening onsets at {len(trip['ratios'])} D/L{both}, noise "
                     f"{trip['sigma'] / PI:.0e} π", f"({trip['truth'][0]:g}, {trip['truth'][1]:g})",
                     f"({trip['values'][0]:.8f}, {trip['values'][1]:.4f})",
                     f"{trip['relative_errors'][0]:.1e}, {trip['relative_errors'][1]:.1e} relative; "
                     f"{trip['in_standard_errors'][0]:.2f}, {trip['in_standard_errors'][1]:.2f} standard errors",
                     command])
    return rows


def _shear_rows():
    """The Cosserat ring's Michell twist against the Kirchhoff limit."""
    data = _load("shear_kirchhoff_limit.json")
    if not data:
        return [["Cosserat ring: the Kirchhoff limit", "", _missing("shear_kirchhoff_limit.json"), "", ""]]
    finest = max(data["limit"], key=int)
    limit = data["limit"][finest]
    return [["Cosserat ring (shear): Michell's twist as kGA → ∞, first order in 1/kGA",
             f"slope −1; Michell {data['michell'] / PI:.7f} π",
             f"slope {data['slope']:.3f} (N = {data['N']}); limit {limit / PI:.7f} π (N = {finest})",
             f"{(limit - data['michell']) / data['michell']:+.1e} relative at N = {finest}",
             "`python benchmarks/shear_kirchhoff_limit.py`"]]


def _machine(text):
    return text or "x86_64, 2 cores"


REDESIGN_TASKS = {"command1": "command 1 (the whole trefoil study with its diagram)", "michell": "Michell's ring, N = 1024",
                  "michell_api": "Michell's ring, N = 1024, from Python", "helix": "the localized helix, N = 240",
                  "critical_curve": "critical curve, 8 ratios, N = 61", "accuracy": "the trefoil to 0.01 π (accuracy mode)"}


def _command(args):
    if args[0].isdigit():
        return f"`critical_twist(michell_ring(N={args[0]}), ...)`"
    return f"`jaxrod {' '.join(args)}`"


def performance_table():
    rows = []
    same = _load("redesign_same_answers.json")
    if same:
        for name, case in same["cases"].items():
            if "runs" in case:  # cold and second processes
                runs = case["runs"].get("new", [])
                cold = [r["seconds"] for r in runs if r.get("kind") == "cold"]
                warm = [r["seconds"] for r in runs if r.get("kind") == "warm"]
                time = f"{min(cold):.1f} s cold / {min(warm):.1f} s second process" if cold and warm else ""
            else:
                time = f"{case['seconds']['new']:.1f} s"
            rows.append([REDESIGN_TASKS.get(name, name), _command(case["args"]), time, same.get("machine", ""),
                         "`python benchmarks/redesign_same_answers.py`"])
    start = _load("cli_start.json")
    if start:
        for setting, runs in start.items():  # the CLI's XLA flags against XLA's defaults
            if setting == "provenance":
                continue
            run = runs[0]
            rows.append([f"command 1, {setting}", "`jaxrod trefoil --D 8 --L 292 --N 121 ...`",
                         f"{run['cold_s']:.1f} s cold / {run['warm_s']:.1f} s second process", "x86_64, 2 cores",
                         "`python benchmarks/cli_start.py`"])
    diagram = _load("command1_diagram.json")
    if diagram:
        for name, runs in diagram.items():
            if name == "provenance":
                continue
            run = runs[0]
            rows.append([f"command 1, {name}", "`jaxrod trefoil --D 8 --L 292 --N 121 ...`",
                         f"{run['cold_s']:.1f} s cold / {run['warm_s']:.1f} s second process", "x86_64, 2 cores",
                         "`python benchmarks/command1_diagram.py`"])
    for name, what in (("sparse_fold.json", "opening fold"), ("sparse_tightening_end.json", "tightening end")):
        for row in _load(name) or ():
            rows.append([f"trefoil {what} on the extended system, N = {row['N']}",
                         f"pseudo-arclength continuation, {row['backend']} backend", f"{row['seconds']:.1f} s",
                         "x86_64, 2 cores", f"`python benchmarks/{name[:-5]}.py`"])
    return _table(["task", "what runs", "time", "machine", "reproduce"], rows)


def speed_table():
    path = RESULTS / "speed.csv"
    if not path.exists():
        return _missing("speed.csv")
    rows = []
    with path.open() as f:
        for r in csv.DictReader(f):
            if r["engine"] != "current" or r["status"] != "ok":
                continue
            warm = f"{float(r['warm_s']):.2f} s" if r["warm_s"] else ""
            rows.append([r["case"], r["N"], r["side"], f"{float(r['first_s']):.1f} s", warm,
                         f"{float(r['phi_star_over_pi']):+.6f} π", f"{r['cpu_count']} cores, jax {r['jax_version']}"])
    return _table(["problem", "N", "side", "first call (compilation included)", "warm", "φ*", "machine"], rows)


def per_step_table():
    data = _load("per_step.json")
    if data is None:
        return _missing("per_step.json")
    out = []
    for r in data["results"]:
        for name, t in r["backends"].items():
            out.append([r["scene"], r["N"], r["n_dof"], name, f"{t['gradient']:.2f}", f"{t['factorise']:.2f}",
                        f"{t['solve']:.2f}", f"{t['inertia']:.2f}", f"{t['eig4']:.2f}", f"{t['newton_iteration']:.2f}",
                        f"{t['stability']:.2f}"])
    return _table(["scene", "N", "DOFs", "backend", "gradient", "factorise", "solve", "inertia", "lowest 4",
                   "Newton iteration", "stability analysis"], out)


def compile_table():
    data = _load("cli_startup_breakdown.json")
    if data is None:
        return _missing("cli_startup_breakdown.json")
    rows = [[f"`{r['program']}`", f"{r['trace_s']:.2f}", f"{r['lower_s']:.2f}", f"{r['compile_s']:.2f}",
             f"{r['total_s']:.2f}"] for r in data["programs_cold"][:12]]
    total = sum(r["total_s"] for r in data["programs_cold"])
    rows.append([f"all {len(data['programs_cold'])} programs", "", "", "", f"{total:.1f}"])
    return _table(["program", "tracing (s)", "lowering (s)", "XLA compilation (s)", "in all (s)"], rows)


def _csv_rows(name):
    path = RESULTS / name
    if not path.exists():
        return None
    with path.open() as f:
        return list(csv.DictReader(f))


def sparse_contact_table():
    rows = _csv_rows("sparse_contact.csv")
    if rows is None:
        return _missing("sparse_contact.csv")
    out = [[r["N"], r["n_dof"], r["side"], r["engine"], f"{float(r['first_s']):.1f} s", f"{float(r['warm_s']):.1f} s",
            f"{float(r['phi_over_pi']):+.6f} π ± {float(r['phi_error_over_pi']):.0e} π"] for r in rows]
    return _table(["N", "DOFs", "side", "backend", "first call", "warm", "φ*"], out)


def dynamics_table():
    rows = _csv_rows("dynamics_accuracy.csv")
    if rows is None:
        return _missing("dynamics_accuracy.csv")
    out = []
    for r in rows:
        how = f"continuation, tol {r['tol']} π" if r["method"] == "continuation" else f"damped dynamics, ramp {r['rate']}"
        phi = f"{float(r['phi_over_pi']):+.4f} π" if r["phi_over_pi"] else "beyond the range"
        error = f"{float(r['error_over_pi']):.4f} π" if r["error_over_pi"] else ""
        out.append([r["N"], r["side"], how, phi, error, f"{float(r['seconds']):.1f} s"])
    return _table(["N", "side", "method", "φ* read", "error", "wall time"], out)


def peer_table():
    peer = _load("peer_pyelastica.json")
    if peer is None:
        return _missing("peer_pyelastica.json")
    out = []
    best = dict(peer["at_pyelastica_best"], N=peer["at_pyelastica_best"]["jaxrod_N"])
    best["err_l1"] = f"{best['target_err']:.2e} (PyElastica's best, {best['pyelastica_best_err']:.2e}, + 2 %)"
    for r in peer["at_jaxrod_error"] + [best]:
        n, err = r["N"], r["err_l1"]
        err = err if isinstance(err, str) else f"{err:.2e}"
        jaxrod = f"N = {n}: {r['jaxrod_cold_s']:.1f} s cold, {r['jaxrod_warm_s']:.2f} s warm"
        if "pyelastica_s" not in r:  # PyElastica never reached this error in its runs
            out.append([err, jaxrod, "not reached", ""])
            continue
        out.append([err, jaxrod, f"n = {r['pyelastica_n']}: {r['pyelastica_s']:.0f} s",
                    f"{r['pyelastica_s'] / r['jaxrod_cold_s']:.0f}× / {r['pyelastica_s'] / r['jaxrod_warm_s']:.0f}×"])
    return _table(["envelope error E", "jaxrod", "PyElastica to reach it", "ratio, cold / warm"], out)


def shear_trefoil_table(stem="shear_trefoil"):
    """The trefoil's first ends as a Cosserat rod with shear, its Kirchhoff limit and the Kirchhoff scene."""
    data = _load(f"{stem}.json")
    if not data:
        return _missing(f"{stem}.json")
    fmt = lambda v: "" if v is None else f"{v:+.4f} π"  # noqa: E731
    rows = [[r["N"], r["side"], fmt(r.get("kirchhoff_over_pi")) or ("not located" if r.get("kirchhoff_failed") else ""),
             fmt(r.get("stiff_over_pi")),
             f"{fmt(r['shear_over_pi'])} ({r['shear_kind']})", fmt(r.get("shear_effect_over_pi"))] for r in data["rows"]]
    rows += [[f"N → ∞ ({e['from_N'][0]}, {e['from_N'][1]})", side, fmt(e.get("kirchhoff_over_pi")),
              fmt(e.get("stiff_over_pi")), fmt(e.get("shear_over_pi")), fmt(e.get("shear_effect_over_pi"))]
             for side, e in data.get("extrapolated", {}).items()]
    header = ["N", "side", "Kirchhoff scene", "Cosserat, kGA × 10⁴", "Cosserat with shear", "shear's effect"]
    return _table(header, rows) + f"\n\nFrom `{data['provenance']['command']}`."


def shear_trefoil_limit_table():
    """The trefoil's first ends as kGA grows: the distance from the Kirchhoff limit, times kGA."""
    data = _load("shear_trefoil.json")
    limit = (data or {}).get("kirchhoff_limit")
    if not limit:
        return _missing("shear_trefoil.json (its kirchhoff_limit)")
    rows = [[r["side"], f"{r['factor']:g}", f"{r['over_pi']:+.6f} π", f"{r['difference_over_pi']:.3e} π",
             f"{r['difference_over_pi'] * r['factor']:.4f} π"] if r["over_pi"] is not None else
            [r["side"], f"{r['factor']:g}", "not located", "", ""] for r in limit["rows"]]
    slopes = ", ".join(f"{side} {v:.3f}" for side, v in limit["slopes"].items() if v is not None)
    return (_table(["side", "kGA / kGA₀", "φ*", "|φ*(kGA₀ × 10⁴) − φ*|", "the same times kGA / kGA₀"], rows)
            + f"\n\nN = {limit['N']}; log–log slopes over kGA ≥ 4 kGA₀: {slopes}. From "
              f"`{limit['provenance']['command']}`.")


def loose_limit_table(stem="loose_limit"):
    """The trefoil's critical twists converged in N against D/L, with the doubly covered ring's limits."""
    data = _load(f"{stem}.json")
    if not data:
        return _missing(f"{stem}.json")
    k3, k4 = data["limits_over_pi"]["k3"], data["limits_over_pi"]["k4"]
    rows = []
    for r in sorted(data["rows"], key=lambda r: (r["side"], -r["D_over_L"])):
        limit = k3 if r["side"] == "plus" else -k4
        phi = r["phi_star"] / PI
        rows.append([f"{r['D_over_L']:g}", "opening" if r["side"] == "plus" else "tightening",
                     f"{phi:+.4f} π ± {r['error'] / PI:.1e} π", ", ".join(str(lv["N"]) for lv in r["levels"]),
                     f"{limit:+.4f} π", f"{phi - limit:+.4f} π"])
    laws = [f"{'opening' if side == 'plus' else 'tightening'}: |φ*| − limit = {law['coefficient_over_pi']:.3g} π "
            f"(D/L)^p with p = {law['exponent']:.2f} ± {law['exponent_error']:.2f} (over D/L = "
            f"{', '.join(f'{x:g}' for x in law['points'])})"
            for side, law in data.get("approach", {}).items() if law]
    return (_table(["D/L", "side", "φ* converged in N", "levels N", "limit (doubly covered ring)",
                    "φ* − limit"], rows) + f"\n\nFrom `{data['provenance']['command']}`."
            + ("" if not laws else " The approach, fitted where the gap is at least twice its error bar: "
               + "; ".join(laws) + "."))


def open_knot_table():
    """The open knot's inextensible end-shortening and apex radius at eps = 0 against the published
    leading order, with the intercept for the fit range moved either way."""
    data = _load("open_knot.json")
    fits = (data or {}).get("published_loose_limit", {}).get("fits")
    if not fits:
        return _missing("open_knot.json")
    cuts = sorted(next(iter(fits.values()))["degree_2_by_eps_max"], key=float)
    labels = {"excess": ("arc length − end distance", "π√2"), "loop_radius": ("loop radius at the apex", "1/√2")}
    rows = []
    for key, (label, exact) in labels.items():
        f = fits[key]
        fit = [f"{f['degree_2']['c0']:.4f} ± {f['degree_2']['c0_std']:.4f}"]
        fit += [f"{f['degree_2_by_eps_max'][c]['c0']:.4f} ± {f['degree_2_by_eps_max'][c]['c0_std']:.4f}" for c in cuts]
        rows.append([label, *fit, f"{exact} = {f['published']:.4f}",
                     f"{(f['degree_2']['c0'] - f['published']) / f['degree_2']['c0_std']:+.1f}"])
    first = next(iter(fits.values()))
    head = ["scaled by √(T/B)", f"ε ≤ {first['eps_max']:g}", *[f"ε ≤ {c}" for c in cuts], "published",
            "(fit − published) / error"]
    return (_table(head, rows) + f"\n\nQuadratic in ε over {first['points']} steps, ε = {first['eps_range'][0]:.2f} … "
            f"{first['eps_range'][1]:.2f}, from `{data['provenance']['command']}`.")


def large_n_sides_table():
    data = _load("large_n_sides.json")
    if data is None:
        return _missing("large_n_sides.json")
    base = data["baseline"]
    rows = [[r["N"], r["side"], f"{r['baseline']['warm_s']:.1f}", f"{r['current']['warm_s']:.1f}",
             f"{r['baseline']['warm_s'] / r['current']['warm_s']:.2f}x",
             "none" if r["current"]["phi_over_pi"] is None else f"{r['current']['phi_over_pi']:+.6f}",
             "yes" if r["same_bracket"] else "no"]
            for r in data["rows"]]
    growth = ", ".join(f"{side} N^{e:.2f}" for side, e in data["growth_exponent"].items() if e is not None)
    return (_table(["N", "side", f"{base} warm (s)", "current warm (s)", "ratio", "end / π", "same bracket"], rows)
            + f"\n\nGrowth of the current warm time: {growth}; {data['machine']}, from `{data['provenance']['command']}`.")


GENERATORS = {"cli": cli_reference, "loose_limit": loose_limit_table, "open_knot": open_knot_table,
              "loose_limit_nu_0_3": lambda: loose_limit_table("loose_limit_nu0.3"), "shear_trefoil": shear_trefoil_table, "shear_trefoil_limit": shear_trefoil_limit_table,
              "shear_trefoil_D4_L280": lambda: shear_trefoil_table("shear_trefoil_D4_L280"),
              "validation": validation_table, "performance": performance_table,
              "speed": speed_table, "sparse_contact": sparse_contact_table, "dynamics": dynamics_table,
              "peer": peer_table, "per_step": per_step_table, "large_n_sides": large_n_sides_table,
              "compile": compile_table}
