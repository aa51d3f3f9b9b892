"""Issue 17, acceptance 1: command 1's located branch ends against the study's step.

``jaxrod trefoil --D 8 --L 292 --N 121 --phi-min -12pi --phi-max 14pi --step S`` for S = 0.25, 0.5
and 1 pi, one after another on one compile cache (XDG_CACHE_HOME in a fresh temporary folder).
Each study's last stable state before a branch end is the start of that end's pseudo-arclength
path (``jaxrod.studies.diagram``), so the step changes the start; the located end must not change (1e-8 pi).
Reports, per step and end: kind, located phi, within the study's bracket or not, and the spread
over the steps of each end located inside its bracket.

Writes benchmarks/results/diagram_steps.{md,json}. Run: python benchmarks/diagram_steps.py (~3 min)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import shutil  # noqa: E402
import tempfile  # noqa: E402

from cli_start import ARGS, run_cli  # noqa: E402  (benchmarks/ is on the path: this script's folder)

from _bench import SMOKE, markdown, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
STEPS = pick(("0.25pi", "0.5pi", "1pi"), ("0.5pi",))


def _over_pi(phi):
    return None if phi is None else phi / 3.141592653589793  # None: no critical twist in the range


def main():
    tmp = tempfile.mkdtemp(prefix="jaxrod-diagram-steps-")
    runs = {}
    try:
        for step in STEPS:
            out = os.path.join(tmp, step)
            seconds = run_cli([*ARGS, "--step", step, "--no-extrapolation", "--no-figures"], os.path.join(tmp, "cache"),
                              out)
            with open(os.path.join(out, "critical.json")) as f:
                crit = json.load(f)
            runs[step] = {"seconds": seconds, "phi_plus_over_pi": _over_pi(crit["phi_plus"]),
                          "phi_minus_over_pi": _over_pi(crit["phi_minus"]),
                          "ends": [{k: e.get(k) for k in ("direction", "from_branch", "kind", "phi_over_pi", "located",
                                                          "within_bracket", "critical_eigenvalue", "residual",
                                                          "iterations")} for e in crit.get("events", [])],
                          "brackets": [{k: c[k] for k in ("direction", "from_branch", "phi_over_pi")} |
                                       {"error_over_pi": c["phi_error"] / 3.141592653589793}
                                       for c in crit["instabilities"]]}
            print(step, json.dumps(runs[step]), flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    lines = ["# Command 1's located branch ends against the study's step (issue 17, acceptance 1)", "",
             f"`jaxrod {' '.join(ARGS)} --step S`, N = 121; `python benchmarks/diagram_steps.py`. phi in units of pi.", "",
             "| step | side | from branch | study's bracket | located | kind | in the bracket | critical eigenvalue | "
             "residual | Newton iterations |", "|---|---|---|---|---|---|---|---|---|---|"]
    spread = {}
    for step, r in runs.items():
        for c, e in zip(r["brackets"], r["ends"]):
            located = "not located" if not e["located"] else f"{e['phi_over_pi']:+.10f}"
            lines.append(f"| {step} | {e['direction']} | {e['from_branch']} | {c['phi_over_pi']:+.6f} +- "
                         f"{c['error_over_pi']:.1e} | {located} | {e.get('kind')} | {e.get('within_bracket')} | "
                         f"{e.get('critical_eigenvalue') or float('nan'):.1e} | {e.get('residual') or float('nan'):.1e} | "
                         f"{e.get('iterations')} |")
            if e["located"] and e["within_bracket"]:
                spread.setdefault((e["direction"], e["from_branch"]), []).append(e["phi_over_pi"])
    lines += ["", "Spread over the steps of each end located inside its bracket:", "",
              "| side | from branch | steps agreeing | spread /pi |", "|---|---|---|---|"]
    for (side, branch), values in spread.items():
        lines.append(f"| {side} | {branch} | {len(values)} of {len(STEPS)} | {max(values) - min(values):.1e} |")
    with open(os.path.join(results_dir(), "diagram_steps.md"), "w") as f:
        f.write(markdown(lines))
    with open(os.path.join(results_dir(), "diagram_steps.json"), "w") as f:
        json.dump(with_provenance(runs), f, indent=1)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
