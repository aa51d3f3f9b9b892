"""Command 1 as a user runs it: ``jaxrod trefoil ...`` as two CLI processes, the second reusing the
first's compile cache, with the CLI's XLA flags (the default) and without them (XLA_FLAGS set to
XLA's defaults for the flags the CLI sets, which it then leaves alone), side by side on this machine.

    python benchmarks/cli_start.py              # 1 round
    python benchmarks/cli_start.py --rounds 2

Each round and setting starts from an empty cache (XDG_CACHE_HOME in a fresh temporary folder):
'cold' is the first process, 'warm' the second. Rounds alternate the settings. Wall times of the
whole process (interpreter start, import, tracing, cache loads, the study, figures). Writes
benchmarks/results/cli_start.md and cli_start.json.
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

from _bench import SMOKE, TINY_CLI_ARGS, fmt, markdown, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
# the small mode: the tiny study without its figures (~2 s of a process; cli_startup_breakdown.py's
# small run draws them)
ARGS = pick(["trefoil", "--D", "8", "--L", "292", "--N", "121", "--phi-min", "-12pi", "--phi-max", "14pi"],
            TINY_CLI_ARGS + ["--no-figures"])
SETTINGS = {"CLI flags (default)": None,
            "XLA defaults": "--xla_cpu_use_fusion_emitters=true --xla_backend_optimization_level=3"}
if SMOKE:  # one setting, and the compile cache and XLA flags of the caller (the test suite's)
    SETTINGS = {"CLI flags (default)": None}


def run_cli(args, cache, out, xla_flags=None):
    """Wall seconds of one ``jaxrod`` process (``args`` + --out out --quiet) on the compile cache
    under ``cache`` (XDG_CACHE_HOME), with ``xla_flags`` as XLA_FLAGS (None: the CLI's own)."""
    env = dict(os.environ, XDG_CACHE_HOME=cache)
    if not SMOKE:
        env.pop("JAX_COMPILATION_CACHE_DIR", None)
        env.pop("XLA_FLAGS", None)
    if xla_flags is not None:
        env["XLA_FLAGS"] = xla_flags
    jaxrod = os.path.join(os.path.dirname(sys.executable), "jaxrod")
    t = time.perf_counter()
    subprocess.run([jaxrod, *args, "--out", out, "--quiet"], env=env, check=True, capture_output=True)
    return time.perf_counter() - t


def run(xla_flags, cache, out):
    seconds = run_cli(ARGS, cache, out, xla_flags)
    with open(os.path.join(out, "critical.json")) as f:
        crit = json.load(f)
    return seconds, crit["phi_plus"], crit["phi_minus"]


def _diff(a, b):
    return None if a is None or b is None else abs(a - b)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--rounds", type=int, default=1)
    opts = parser.parse_args()
    rows = {name: [] for name in SETTINGS}
    for _ in range(opts.rounds):
        for name, flags in SETTINGS.items():
            tmp = tempfile.mkdtemp(prefix="jaxrod-cli-start-")
            try:
                cold = run(flags, os.path.join(tmp, "cache"), os.path.join(tmp, "cold"))
                # small mode: one process, on the caller's warm compile cache
                warm = cold if SMOKE else run(flags, os.path.join(tmp, "cache"), os.path.join(tmp, "warm"))
            finally:
                shutil.rmtree(tmp, ignore_errors=True)
            rows[name].append({"cold_s": cold[0], "warm_s": warm[0], "phi_plus": warm[1], "phi_minus": warm[2]})
            print(name, rows[name][-1], flush=True)
    cur = rows["CLI flags (default)"]
    base = rows.get("XLA defaults", cur)
    med = lambda rs, k: statistics.median(r[k] for r in rs)  # noqa: E731
    lines = ["# Command 1 as a user runs it: two CLI processes, the second with the first's compile cache", "",
             f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, BLAS threads 1, "
             f"{opts.rounds} round(s), medians; `python benchmarks/cli_start.py`.", "",
             "| setting | cold (empty cache) | warm (second process) | phi+ (rad) | phi- (rad) |", "|---|---|---|---|---|"]
    for name, rs in rows.items():
        lines.append(f"| {name} | {med(rs, 'cold_s'):.1f} s | {med(rs, 'warm_s'):.1f} s | {fmt(rs[-1]['phi_plus'], '.12f')} | "
                     f"{fmt(rs[-1]['phi_minus'], '.12f')} |")
    lines += ["", f"Ratio XLA defaults / CLI flags: cold {med(base, 'cold_s') / med(cur, 'cold_s'):.2f}x, "
              f"warm {med(base, 'warm_s') / med(cur, 'warm_s'):.2f}x. phi* differs by "
              f"{fmt(_diff(base[-1]['phi_plus'], cur[-1]['phi_plus']), '.1e')} / "
              f"{fmt(_diff(base[-1]['phi_minus'], cur[-1]['phi_minus']), '.1e')} rad."]
    with open(os.path.join(results_dir(), "cli_start.md"), "w") as f:
        f.write(markdown(lines))
    with open(os.path.join(results_dir(), "cli_start.json"), "w") as f:
        json.dump(with_provenance(rows), f, indent=1)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
