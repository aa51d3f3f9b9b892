"""One side of the trefoil (8, 292) to its first branch end, O(n) sparse path against the dense path
(issue 18, item 1 / acceptance 1), side by side in one process per N.

For each N: the knot relaxed at phi = 0 by each engine, then ``follow_twist`` from there to the
first branch end (ContinuationOptions(tol=1e-3 pi, switch=False, linear_algebra=...)), each side
twice in a row: 'first' includes compiling that N's code in this process, 'warm' is the same
call again in the same process (everything compiled and loaded; this is not a user's second CLI
process, see cli_start.py for that). The dense path runs where it finishes in reasonable time
(N <= --dense-max, default 481). Each N runs in a fresh child process (memory and compiled code
of one N kept out of the next); rows are appended to the CSV as they arrive (resumable: done rows
are skipped).

    python benchmarks/sparse_contact.py                  # N = 61, 121, 241, 481, 961
    python benchmarks/sparse_contact.py --N 121 241
    python benchmarks/sparse_contact.py --report-only    # tables and charts from the CSV
    python benchmarks/sparse_contact.py --smoke          # small mode: N = 61, a quarter turn, one side

Writes benchmarks/results/sparse_contact.{csv,md,png} and sparse_contact_accuracy.png (accuracy
against time, issue 18 item 4).
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import csv  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from _bench import SMOKE, pick, provenance_line, results_dir  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = results_dir()
CSV = os.path.join(RESULTS, "sparse_contact.csv")
FIELDS = ["N", "n_dof", "engine", "side", "relax_s", "first_s", "warm_s", "phi_over_pi", "phi_error_over_pi",
          "bracket_lo_over_pi", "bracket_hi_over_pi", "kind", "points", "load_1min"]
# small mode: N = 61 (the fewest nodes whose relaxed knot is a minimum), one side, a quarter turn: both
# engines (in this process) and the report, no branch end reached
SIDES = pick({"opening": 7.5 * math.pi, "tightening": -12.0 * math.pi}, {"opening": 0.25 * math.pi})


def follow_twice(scene, start, stop, engine):
    """((first, warm) seconds, path): one side of ``scene`` from the relaxed ``start`` to phi_stop
    ``stop`` on the linear algebra ``engine``, twice in a row (jaxrod as imported)."""
    from jaxrod.continuation import ContinuationOptions, follow_twist

    opts = ContinuationOptions(tol=1e-3 * math.pi, switch=False, linear_algebra=engine)
    times = []
    for _ in range(2):
        t = time.perf_counter()
        path = follow_twist(scene, 0.0, stop, opts, start=start)
        times.append(time.perf_counter() - t)
    return times, path


def child(N, engines):
    import jaxrod as jr

    scene = jr.trefoil(D=8.0, L=292.0, N=N)
    for engine in engines:
        t = time.perf_counter()
        start = jr.relax(scene, 0.0, options=jr.RelaxOptions(linear_algebra=engine))
        relax_s = time.perf_counter() - t
        for side, stop in SIDES.items():
            times, path = follow_twice(scene, start, stop, engine)
            inst = path.instabilities[0] if path.instabilities else None
            row = {"N": N, "n_dof": int(scene.n_dof), "engine": engine, "side": side, "relax_s": relax_s,
                   "first_s": times[0], "warm_s": times[1],
                   "phi_over_pi": inst.phi / math.pi if inst else math.nan,
                   "phi_error_over_pi": inst.phi_error / math.pi if inst else math.nan,
                   "bracket_lo_over_pi": min(inst.bracket) / math.pi if inst else math.nan,
                   "bracket_hi_over_pi": max(inst.bracket) / math.pi if inst else math.nan,
                   "kind": inst.kind.value if inst else "none", "points": len(path.points),
                   "load_1min": os.getloadavg()[0]}
            print("ROW " + json.dumps(row), flush=True)


def read_rows():
    if not os.path.exists(CSV):
        return []
    with open(CSV) as f:
        return list(csv.DictReader(f))


def fit_exponent(ns, ts):
    import numpy as np

    return float(np.polyfit(np.log(ns), np.log(ts), 1)[0])


def accuracy_lines(rows, plt):
    """Accuracy against time (issue 18, item 4): each run's |phi*(N) - phi_inf|, phi_inf the
    Richardson extrapolation (order measured) of the sparse path's levels; a chart of it against
    the warm time."""
    from jaxrod.studies.accuracy import richardson

    out = ["## Accuracy against time", "",
           "|phi*(N) - phi_inf| with phi_inf extrapolated from the sparse path's levels (Richardson, order measured "
           "from the three finest; `jaxrod.studies.accuracy.richardson`). The branch ends here are located by failed "
           "corrector trials to tol = 1e-3 pi, so each phi*(N) carries up to ~5e-4 pi of bracket error too.", "",
           "| side | phi_inf / pi | error estimate / pi | order | levels |", "|---|---|---|---|---|"]
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    table = ["", "| N | side | engine | warm (s) | phi*/pi | abs(phi* - phi_inf)/pi |", "|---|---|---|---|---|---|"]
    for side, colour in (("opening", "C0"), ("tightening", "C3")):
        sparse = sorted((int(r["N"]), float(r["phi_over_pi"])) for r in rows
                        if r["engine"] == "sparse" and r["side"] == side and r["kind"] != "none")
        if len(sparse) < 2:
            continue
        ext = richardson([n for n, _ in sparse], [v for _, v in sparse])
        out.append(f"| {side} | {ext.value:+.6f} | {ext.error:.1e} | {ext.order:.2f} | "
                   f"{', '.join(str(n) for n, _ in sparse)} |")
        for engine, marker in (("sparse", "o-"), ("dense", "s--")):
            pts = sorted((int(r["N"]), float(r["warm_s"]), float(r["phi_over_pi"])) for r in rows
                         if r["engine"] == engine and r["side"] == side and r["kind"] != "none")
            if not pts:
                continue
            errs = [max(abs(v - ext.value), 1e-6) for _, _, v in pts]
            ax.loglog([t for _, t, _ in pts], errs, marker, color=colour, label=f"{engine}, {side}")
            for (n, t, v), e in zip(pts, errs):
                ax.annotate(str(n), (t, e), fontsize=7, xytext=(3, 3), textcoords="offset points")
                table.append(f"| {n} | {side} | {engine} | {t:.1f} | {v:+.6f} | {abs(v - ext.value):.1e} |")
    ax.set_xlabel("warm time to the branch end (s)")
    # plain seconds on the time axis: it spans little more than a decade, where matplotlib would
    # label the minor ticks in powers of ten, over one another
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    ax.xaxis.set_major_formatter(ScalarFormatter())
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xticks([1, 2, 5, 10, 20, 50, 100])
    ax.set_ylabel("|phi*(N) - phi_inf| / pi")
    ax.set_title("Trefoil (8, 292): accuracy against time")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(RESULTS, "sparse_contact_accuracy.png"), dpi=120)
    plt.close(fig)
    return out + table


def report(rows):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by = {(int(r["N"]), r["engine"], r["side"]): r for r in rows}
    Ns = sorted({int(r["N"]) for r in rows})
    lines = ["# One side of the trefoil to its first branch end: sparse (O(n)) against dense", "",
             f"Trefoil (8, 292) mm, nu = 0.5; `follow_twist(scene, 0, phi_stop, ContinuationOptions(tol=1e-3 pi, "
             f"switch=False, linear_algebra=...), start=relaxed)`, phi_stop = +7.5 pi (opening) / -12 pi "
             f"(tightening). 'first': the first call for that N in its process (compilation included); 'warm': the "
             f"same call again in the same process (compiled code in memory). {platform.machine()}, "
             f"{os.cpu_count()} cores, BLAS threads 1; one child process per N, both engines in it; "
             f"`python benchmarks/sparse_contact.py`.", "", provenance_line(), "",
             "| N | n | side | sparse first (s) | sparse warm (s) | dense first (s) | dense warm (s) | ratio warm | "
             "sparse phi*/pi (bracket) | dense phi*/pi (bracket) | brackets overlap | kind sparse / dense |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for N in Ns:
        for side in SIDES:
            s, d = by.get((N, "sparse", side)), by.get((N, "dense", side))
            if s is None:
                continue
            f = lambda r, k: float(r[k])  # noqa: E731
            br = lambda r: f"{f(r, 'phi_over_pi'):+.6f} [{f(r, 'bracket_lo_over_pi'):+.6f}, {f(r, 'bracket_hi_over_pi'):+.6f}]"  # noqa: E731,E501
            if d is not None:
                overlap = max(f(s, "bracket_lo_over_pi"), f(d, "bracket_lo_over_pi")) <= \
                    min(f(s, "bracket_hi_over_pi"), f(d, "bracket_hi_over_pi")) + 1e-12
                lines.append(f"| {N} | {s['n_dof']} | {side} | {f(s, 'first_s'):.1f} | {f(s, 'warm_s'):.1f} | "
                             f"{f(d, 'first_s'):.1f} | {f(d, 'warm_s'):.1f} | {f(d, 'warm_s') / f(s, 'warm_s'):.1f}x | "
                             f"{br(s)} | {br(d)} | {'yes' if overlap else 'NO'} | {s['kind']} / {d['kind']} |")
            else:
                lines.append(f"| {N} | {s['n_dof']} | {side} | {f(s, 'first_s'):.1f} | {f(s, 'warm_s'):.1f} | | | | "
                             f"{br(s)} | | | {s['kind']} / |")
    lines.append("")
    lines += accuracy_lines(rows, plt)
    lines.append("")
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for engine, style in (("sparse", "o-"), ("dense", "s--")):
        for side, colour in (("opening", "C0"), ("tightening", "C3")):
            pts = sorted((int(r["N"]), float(r["warm_s"])) for r in rows if r["engine"] == engine and r["side"] == side)
            if not pts:
                continue
            ns, ts = zip(*pts)
            ax.loglog(ns, ts, style, color=colour, label=f"{engine}, {side}")
            big = [(n, t) for n, t in pts if 241 <= n <= 961]
            if engine == "sparse" and len(big) >= 2:
                p = fit_exponent(*zip(*big))
                lines.append(f"- sparse, {side}: warm time ~ N^{p:.2f} over N = {', '.join(str(n) for n, _ in big)}")
            if engine == "dense" and len(pts) >= 2:
                p = fit_exponent(ns[-2:], ts[-2:])
                lines.append(f"- dense, {side}: local exponent {p:.2f} between N = {ns[-2]} and {ns[-1]}")
    n_ref = [241, 961]
    ax.loglog(n_ref, [2.0, 2.0 * 4**1.3], ":", color="grey", label="N^1.3")
    ax.set_xlabel("N (nodes)")
    ax.set_ylabel("warm time to the branch end (s)")
    ax.set_title("Trefoil (8, 292): one side, sparse vs dense")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(os.path.join(RESULTS, "sparse_contact.png"), dpi=120)
    with open(os.path.join(RESULTS, "sparse_contact.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))


def child_lines(N, engines):
    """(process, its output lines) of the child for N. The small mode's one N runs here instead
    (process None): a child of its own would only import jaxrod a second time."""
    if SMOKE:
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            child(N, engines)
        return None, out.getvalue().splitlines(keepends=True)
    proc = subprocess.Popen([sys.executable, __file__, "--child", str(N), "--engines", ",".join(engines)],
                            stdout=subprocess.PIPE, text=True)
    return proc, proc.stdout


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--N", type=int, nargs="*", default=pick([61, 121, 241, 481, 961], [61]))
    parser.add_argument("--report-only", action="store_true")
    parser.add_argument("--dense-max", type=int, default=481)
    parser.add_argument("--child", type=int, default=None)
    parser.add_argument("--engines", default="sparse,dense")
    opts = parser.parse_args()
    if opts.child is not None:
        child(opts.child, opts.engines.split(","))
        return
    if opts.report_only:
        report(read_rows())
        return
    os.makedirs(RESULTS, exist_ok=True)
    done = {(int(r["N"]), r["engine"]) for r in read_rows()}
    for N in opts.N:
        engines = [e for e in ("sparse", "dense") if (e == "sparse" or N <= opts.dense_max) and (N, e) not in done]
        if not engines:
            continue
        proc, lines = child_lines(N, engines)
        for line in lines:
            if line.startswith("ROW "):
                row = json.loads(line[4:])
                new = not os.path.exists(CSV)
                with open(CSV, "a", newline="") as f:
                    w = csv.DictWriter(f, fieldnames=FIELDS)
                    if new:
                        w.writeheader()
                    w.writerow(row)
                print(f"N = {N} {row['engine']} {row['side']}: first {row['first_s']:.1f} s, warm {row['warm_s']:.1f} s, "
                      f"phi* = {row['phi_over_pi']:+.6f} pi ({row['kind']})", flush=True)
        if proc is not None and proc.wait() != 0:
            raise SystemExit(f"child N = {N} failed")
    report(read_rows())


if __name__ == "__main__":
    main()
