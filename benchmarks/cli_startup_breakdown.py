"""Where the time of a warm CLI run goes (issue 18, item 3): command 1 run twice as separate CLI-like
processes on one compile cache; the second (warm: what a user's second run is) is timed by phase.

    python benchmarks/cli_startup_breakdown.py

Each process: ``import jaxrod`` (timed), then ``jaxrod.cli.main(ARGS)`` with JAX's monitoring
listeners summing the time spent tracing to jaxprs, lowering to MLIR, compiling, and retrieving
executables from the persistent cache. The remainder of main() is running the study (the two
directions in two threads, so phases overlap a little), writing records and figures. The figure
share is measured by a third process with --no-figures. Writes benchmarks/results/cli_startup_breakdown.md.
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import shutil  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402

from _bench import SMOKE, TINY_CLI_ARGS, markdown, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
ARGS = pick(["trefoil", "--D", "8", "--L", "292", "--N", "121", "--phi-min", "-12pi", "--phi-max", "14pi"],
            TINY_CLI_ARGS) + ["--quiet"]
MARK = "@@PHASES "

CHILD = r"""
import time, sys, json, os
t0 = time.perf_counter()
import jaxrod.cli as cli
t_import = time.perf_counter() - t0
import jax.monitoring as mon
sums, programs = {}, {}
def listen(event, seconds, **kw):
    sums[event] = sums.get(event, 0.0) + seconds
    name = kw.get("fun_name")
    if name:  # "jit(f)" for lowering and compilation, "f" for tracing: one program, f
        name = name[4:-1] if name.startswith("jit(") and name.endswith(")") else name
        per = programs.setdefault(name, {})
        per[event] = per.get(event, 0.0) + seconds
mon.register_event_duration_secs_listener(listen)
cli.add_cli_xla_flags()
t1 = time.perf_counter()
code = cli.main(json.loads(sys.argv[1]))
t_main = time.perf_counter() - t1
assert code == 0, code
print(MARK + json.dumps({"import_s": t_import, "main_s": t_main, "events": sums, "programs": programs}))
""".replace("MARK", repr(MARK))


def child(args, cache):
    env = dict(os.environ, XDG_CACHE_HOME=cache)
    if not SMOKE:  # the small mode keeps the caller's compile cache and XLA flags (the test suite's)
        env.pop("JAX_COMPILATION_CACHE_DIR", None)
        env.pop("XLA_FLAGS", None)
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(args)], env=env, capture_output=True, text=True,
                         check=True).stdout
    return json.loads(next(line for line in out.splitlines() if line.startswith(MARK))[len(MARK):])


def main():
    tmp = tempfile.mkdtemp(prefix="jaxrod-breakdown-")
    try:
        cache = os.path.join(tmp, "cache")
        cold = child(ARGS + ["--out", os.path.join(tmp, "a")], cache)
        # the small mode runs one process and shows it in all three columns
        warm = cold if SMOKE else child(ARGS + ["--out", os.path.join(tmp, "b")], cache)
        nofig = cold if SMOKE else child(ARGS + ["--out", os.path.join(tmp, "c"), "--no-figures"], cache)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    names = {"/jax/core/compile/jaxpr_trace_duration": "tracing to jaxprs",
             "/jax/core/compile/jaxpr_to_mlir_module_duration": "lowering to MLIR",
             "/jax/core/compile/backend_compile_duration": "XLA compilation",
             "/jax/compilation_cache/cache_retrieval_time_sec": "loading cached executables"}
    lines = ["# Command 1, where the time goes (`python benchmarks/cli_startup_breakdown.py`)", "",
             "Three processes on one compile cache: cold (empty cache), warm (the user's second run), warm "
             "with --no-figures. Seconds; the phases are sums over all jitted functions (the two study "
             "directions run in two threads, so the sum of phases can overlap the study).", "",
             "| phase | cold | warm | warm, --no-figures |", "|---|---|---|---|"]
    lines.append(f"| import jaxrod (interpreter already up) | {cold['import_s']:.1f} | {warm['import_s']:.1f} | "
                 f"{nofig['import_s']:.1f} |")
    # JAX's backend-compile event wraps compile_or_get_cached, i.e. the cache retrieval too
    # (counted as compilation, a warm run's loads would count twice and its arithmetic short): the
    # compilation proper is that event minus the retrievals.
    backend, load = "/jax/core/compile/backend_compile_duration", "/jax/compilation_cache/cache_retrieval_time_sec"
    for r in (cold, warm, nofig):
        ev = r["events"]
        r["phase"] = {k: ev.get(k, 0.0) for k in names}
        r["phase"][backend] = ev.get(backend, 0.0) - ev.get(load, 0.0)
        r["rest"] = r["main_s"] - sum(r["phase"].values())
    for key, label in names.items():
        lines.append(f"| {label} | " + " | ".join(f"{r['phase'][key]:.1f}" for r in (cold, warm, nofig)) + " |")
    lines.append("| the rest of main(): the study's arithmetic, records, figures | " +
                 " | ".join(f"{r['rest']:.1f}" for r in (cold, warm, nofig)) + " |")
    lines.append("| main() in all | " + " | ".join(f"{r['main_s']:.1f}" for r in (cold, warm, nofig)) + " |")
    lines += ["", f"Figures: {warm['main_s'] - nofig['main_s']:.1f} s of the warm run (warm minus --no-figures)."]
    table = program_table(cold["programs"])
    lines += ["", f"The cold run's costliest programs ({len(cold['programs'])} compiled in all), seconds:", "",
              "| program | tracing | lowering | XLA compilation | in all |", "|---|---|---|---|---|"]
    lines += [f"| `{r['program']}` | {r['trace_s']:.2f} | {r['lower_s']:.2f} | {r['compile_s']:.2f} | {r['total_s']:.2f} |"
              for r in table[:PROGRAMS_SHOWN]]
    out = results_dir()
    with open(os.path.join(out, "cli_startup_breakdown.md"), "w") as f:
        f.write(markdown(lines))
    record = {"args": ARGS, "runs": {name: {"import_s": r["import_s"], "main_s": r["main_s"], "phases": {
        names[k]: v for k, v in r["phase"].items()}, "rest_s": r["rest"]} for name, r in
        (("cold", cold), ("warm", warm), ("warm_no_figures", nofig))}, "programs_cold": table}
    with open(os.path.join(out, "cli_startup_breakdown.json"), "w") as f:
        json.dump(with_provenance(record), f, indent=1)
    print("\n".join(lines))


# Rows of the costliest-programs table in the .md (the .json keeps them all).
PROGRAMS_SHOWN = 12


def program_table(programs):
    """[{program, trace_s, lower_s, compile_s, total_s}], costliest first, from the per-program
    sums of JAX's monitoring events."""
    keys = {"trace_s": "/jax/core/compile/jaxpr_trace_duration",
            "lower_s": "/jax/core/compile/jaxpr_to_mlir_module_duration",
            "compile_s": "/jax/core/compile/backend_compile_duration"}
    rows = []
    for name, events in programs.items():
        row = {"program": name, **{k: events.get(e, 0.0) for k, e in keys.items()}}
        row["total_s"] = row["trace_s"] + row["lower_s"] + row["compile_s"]
        rows.append(row)
    return sorted(rows, key=lambda r: -r["total_s"])


if __name__ == "__main__":
    main()
