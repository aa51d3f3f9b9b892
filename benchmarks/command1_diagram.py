"""Command 1 with its whole bifurcation diagram (each branch end located on the extended system,
the unstable branch beyond it: ``jaxrod.studies.diagram``) against the stable-only study (``--stable-only``,
today's engine), as a user runs it: two CLI processes per setting, the second reusing the first's
compile cache (XDG_CACHE_HOME in a fresh temporary folder per setting and round), side by side.

    python benchmarks/command1_diagram.py              # 1 round
    python benchmarks/command1_diagram.py --rounds 2

Wall times of the whole process (interpreter start, import, tracing, cache loads, the study, the
diagram, the rough extrapolation, figures). Writes benchmarks/results/command1_diagram.{md,json}.
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402

from cli_start import ARGS, run_cli  # noqa: E402  (benchmarks/ is on the path: this script's folder)

from _bench import SMOKE, fmt, markdown, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
SETTINGS = {"stable only (--stable-only)": ["--stable-only"], "whole diagram (default)": []}
if SMOKE:  # one process: the tiny study (already --stable-only) stands for both settings
    SETTINGS = {"whole diagram (default)": []}


def run(extra, cache, out):
    seconds = run_cli([*ARGS, *extra], cache, out)
    with open(os.path.join(out, "summary.json")) as f:
        summary = json.load(f)
    with open(os.path.join(out, "critical.json")) as f:
        events = json.load(f).get("events", [])
    return seconds, summary, events


def _over_pi(phi):
    return None if phi is None else phi / 3.141592653589793


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--rounds", type=int, default=1)
    opts = parser.parse_args()
    rows = {name: [] for name in SETTINGS}
    for _ in range(opts.rounds):
        for name, extra in SETTINGS.items():
            tmp = tempfile.mkdtemp(prefix="jaxrod-command1-diagram-")
            try:
                cold = run(extra, os.path.join(tmp, "cache"), os.path.join(tmp, "cold"))
                warm = cold if SMOKE else run(extra, os.path.join(tmp, "cache"), os.path.join(tmp, "warm"))
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
            s = warm[1]
            rows[name].append({"cold_s": cold[0], "warm_s": warm[0], "phi_plus": s["phi_plus"],
                               "phi_minus": s["phi_minus"], "seconds_diagram": s.get("seconds_diagram"),
                               "events": [{k: e.get(k) for k in ("direction", "kind", "phi_over_pi", "critical_eigenvalue",
                                                                 "residual", "iterations")} for e in warm[2]]})
            print(name, json.dumps(rows[name][-1]), flush=True)
    med = lambda rs, k: statistics.median(r[k] for r in rs)  # noqa: E731
    cur = rows["whole diagram (default)"]
    base = rows.get("stable only (--stable-only)", cur)
    lines = ["# Command 1 with its whole bifurcation diagram against the stable-only study", "",
             f"`jaxrod {' '.join(ARGS)}`, two CLI processes per setting (cold: empty cache; warm: the second, "
             f"with the first's cache); {platform.processor() or platform.machine()}, {os.cpu_count()} cores, BLAS "
             f"threads 1, {opts.rounds} round(s), medians; `python benchmarks/command1_diagram.py`.", "",
             "| setting | cold | warm | diagram (warm) | phi+ / pi | phi- / pi |", "|---|---|---|---|---|---|"]
    for name, rs in rows.items():
        d = rs[-1]["seconds_diagram"]
        lines.append(f"| {name} | {med(rs, 'cold_s'):.1f} s | {med(rs, 'warm_s'):.1f} s | "
                     f"{'' if d is None else f'{d:.1f} s'} | {fmt(_over_pi(rs[-1]['phi_plus']), '+.10f')} | "
                     f"{fmt(_over_pi(rs[-1]['phi_minus']), '+.10f')} |")
    lines += ["", f"Ratio whole diagram / stable only: cold {med(cur, 'cold_s') / med(base, 'cold_s'):.2f}x, "
              f"warm {med(cur, 'warm_s') / med(base, 'warm_s'):.2f}x.", "",
              "Located branch ends (warm run of the whole diagram):", "",
              "| side | kind | phi / pi | critical eigenvalue | residual | Newton iterations |", "|---|---|---|---|---|---|"]
    for e in cur[-1]["events"]:
        lines.append(f"| {e['direction']} | {e['kind']} | {e['phi_over_pi']:+.10f} | {e['critical_eigenvalue']:.1e} | "
                     f"{e['residual']:.1e} | {e['iterations']} |")
    with open(os.path.join(results_dir(), "command1_diagram.md"), "w") as f:
        f.write(markdown(lines))
    with open(os.path.join(results_dir(), "command1_diagram.json"), "w") as f:
        json.dump(with_provenance(rows), f, indent=1)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
