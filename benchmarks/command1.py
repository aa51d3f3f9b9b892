"""Command 1 of the README (the whole trefoil study) side by side: a previous release against the
working tree, on this machine, in one script.

    python benchmarks/command1.py                     # baseline 7b060a4 (before the layered redesign), 2 rounds
    python benchmarks/command1.py --baseline 84b372f --rounds 3

Each round runs, in a fresh process per version (baseline first, then current):
``jaxrod.cli.main(["trefoil", "--D", "8", "--L", "292", "--N", "121", "--phi-min", "-12pi",
"--phi-max", "14pi", "--no-cache", ...])`` twice: the first call compiles everything (cold), the
second reuses the compiled code (warm, figures included). The baseline's ``jaxrod/`` comes from
``git archive``. Rounds alternate the versions so that drift of the machine hits both alike; the
table gives the best and the median of the rounds, the critical twists of each version and its
peak resident memory. Writes benchmarks/results/command1.md and command1.json.
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

from _bench import SMOKE, TINY_CLI_ARGS, fmt, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
# the small mode: the tiny study without its figures (~2 s of a process; cli_startup_breakdown.py's
# small run draws them)
ARGS = pick(["trefoil", "--D", "8", "--L", "292", "--N", "121", "--phi-min", "-12pi", "--phi-max", "14pi"],
            TINY_CLI_ARGS + ["--no-figures"]) + ["--no-cache", "--quiet", "--json"]
MARK = "@@COMMAND1 "
# cli.main calls per process: cold, then warm; the small mode's one call stands for both
CALLS = pick(2, 1)

CHILD = r"""
import io, json, os, resource, sys, time, contextlib
sys.path.insert(0, sys.argv[1])
import jaxrod.cli as cli
out = sys.argv[2]
times, summaries = [], []
for k in range(CALLS):
    buf = io.StringIO()
    t = time.perf_counter()
    with contextlib.redirect_stdout(buf):
        code = cli.main(ARGS + ["--out", os.path.join(out, f"run{k}")])
    times.append(time.perf_counter() - t)
    assert code == 0, code
    summaries.append(json.loads(buf.getvalue().strip().splitlines()[-1]))
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print(MARK + json.dumps({"cold_s": times[0], "warm_s": times[-1], "peak_rss_mb": rss,
                         "phi_plus_over_pi": summaries[-1]["phi_plus_over_pi"],
                         "phi_minus_over_pi": summaries[-1]["phi_minus_over_pi"],
                         "same_answer_twice": summaries[0]["phi_plus"] == summaries[-1]["phi_plus"]
                         and summaries[0]["phi_minus"] == summaries[-1]["phi_minus"]}))
"""


def extract(commit, into):
    """The ``jaxrod/`` folder of ``commit`` under ``into`` (git archive)."""
    os.makedirs(into, exist_ok=True)
    archive = subprocess.run(["git", "-C", REPO, "archive", commit, "jaxrod"], check=True, capture_output=True)
    subprocess.run(["tar", "-x", "-C", into], input=archive.stdout, check=True)
    return into


def run_version(path, scratch):
    code = f"ARGS = {ARGS!r}\nMARK = {MARK!r}\nCALLS = {CALLS!r}\n" + CHILD
    res = subprocess.run([sys.executable, "-c", code, path, scratch], capture_output=True, text=True)
    for line in res.stdout.splitlines():
        if line.startswith(MARK):
            return json.loads(line[len(MARK):])
    raise RuntimeError(f"child failed ({res.returncode}):\n{res.stderr[-3000:]}")


def git_rev(ref="HEAD"):
    return subprocess.run(["git", "-C", REPO, "rev-parse", "--short", ref], capture_output=True, text=True,
                          check=True).stdout.strip()


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--baseline", default="7b060a4", help="the previous release to compare with (a commit; default: the last one before the layered redesign)")
    p.add_argument("--rounds", type=int, default=pick(2, 1), help="rounds (each: baseline then current)")
    p.add_argument("--out", default=results_dir(), help="folder for command1.md/.json")
    args = p.parse_args(argv)
    os.makedirs(args.out, exist_ok=True)
    runs = {"baseline": [], "current": []}
    with tempfile.TemporaryDirectory() as tmp:
        base = extract(args.baseline, os.path.join(tmp, "baseline"))
        # the small mode runs the current version once and shows it in both columns: the baseline's
        # code would be compiled from scratch, for nothing
        versions = (("current", REPO),) if SMOKE else (("baseline", base), ("current", REPO))
        for r in range(args.rounds):
            for name, path in versions:
                t = time.perf_counter()
                row = run_version(path, tempfile.mkdtemp(dir=tmp))
                runs[name].append(row)
                print(f"round {r + 1}/{args.rounds} {name:8s}: cold {row['cold_s']:.1f} s, warm {row['warm_s']:.1f} s, "
                      f"phi* = {fmt(row['phi_plus_over_pi'], '+.6f')} pi, {fmt(row['phi_minus_over_pi'], '+.6f')} pi "
                      f"({time.perf_counter() - t:.0f} s)", flush=True)
    if SMOKE:
        runs["baseline"] = runs["current"]
    summary = {"baseline_commit": args.baseline, "current_commit": git_rev(), "rounds": args.rounds,
               "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}",
               "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"), "runs": runs,
               "timestamp": time.strftime("%Y-%m-%d %H:%M:%S")}
    with open(os.path.join(args.out, "command1.json"), "w") as f:
        json.dump(with_provenance(summary), f, indent=2)

    def stat(name, key, fn):
        return fn([r[key] for r in runs[name]])

    lines = [
        "# Command 1: the whole trefoil study, previous release against current",
        "",
        provenance_line(),
        "",
        f"`jaxrod trefoil --D 8 --L 292 --N 121 --phi-min -12pi --phi-max 14pi` (`benchmarks/command1.py`, "
        f"{summary['timestamp']}): each version in a fresh process, `cli.main` twice with `--no-cache` "
        f"(cold: everything compiled; warm: the second call, figures included), {args.rounds} rounds "
        f"alternating the versions; {summary['machine']}, BLAS threads {summary['blas_threads']}. "
        f"Previous release {args.baseline}, current {summary['current_commit']}.",
        "",
        "| | previous (best / median) | current (best / median) | ratio (best) |",
        "|---|---|---|---|",
    ]
    for key, label in (("cold_s", "first call, cold (s)"), ("warm_s", "second call, warm (s)")):
        b, c = stat("baseline", key, min), stat("current", key, min)
        lines.append(f"| {label} | {b:.1f} / {stat('baseline', key, statistics.median):.1f} | "
                     f"{c:.1f} / {stat('current', key, statistics.median):.1f} | {b / c:.2f}x |")
    lines.append(f"| peak resident memory (MB) | {stat('baseline', 'peak_rss_mb', max):.0f} | "
                 f"{stat('current', 'peak_rss_mb', max):.0f} | |")
    for key, label in (("phi_plus_over_pi", "phi*(opening) / pi"), ("phi_minus_over_pi", "phi*(tightening) / pi")):
        b, c = runs['baseline'][-1][key], runs['current'][-1][key]
        diff = None if b is None or c is None else abs(c - b)
        lines.append(f"| {label} | {fmt(b, '+.6f')} | {fmt(c, '+.6f')} | diff {fmt(diff, '.1e')} |")
    same = all(r["same_answer_twice"] for v in runs.values() for r in v)
    lines += ["", f"Both calls of each process gave the same critical twists: {same}.", ""]
    with open(os.path.join(args.out, "command1.md"), "w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
