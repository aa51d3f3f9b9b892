"""One side of the trefoil (8, 292) at large N on the O(N) path: a previous release against the
working tree, side by side on this machine, in one script.

    python benchmarks/large_n_sides.py                               # N = 241, 481, 961; baseline ed030e8
    python benchmarks/large_n_sides.py --baseline 2d5c222 --N 961

For each N, side and version (the baseline first), a fresh process relaxes the knot at phi = 0 on
the sparse path and follows the side to its first branch end twice, as
``benchmarks/sparse_contact.py`` does (``follow_twist(scene, 0, phi_stop,
ContinuationOptions(tol=1e-3 pi, switch=False, linear_algebra="sparse"), start=relaxed)``,
phi_stop = +7.5 pi or -12 pi): 'first' compiles, 'warm' is the second call in the same process.
The baseline's ``jaxrod/`` comes from ``git archive``. Writes large_n_sides.md and .json: both
versions' warm times and their ratio, each version's end (the same bracket to 1e-8 pi is expected), and the
growth exponent of the current warm time over the node counts given (a least-squares slope of
log time against log N).
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402

import numpy as np  # noqa: E402

from _bench import REPO, SMOKE, pick, provenance_line, results_dir, with_provenance  # noqa: E402  (benchmarks/ is on the path)
from command1 import extract  # noqa: E402
from sparse_contact import follow_twice  # noqa: E402

NODES = pick([241, 481, 961], [61])
# the small mode: a quarter turn of the opening side (no end), the current version only
SIDES = pick({"opening": 7.5 * math.pi, "tightening": -12.0 * math.pi}, {"opening": 0.25 * math.pi})
MARK = "@@SIDE "


def follow_side(N, stop):
    """One side at N: {first_s, warm_s, points, phi_over_pi, bracket_over_pi} (jaxrod as imported)."""
    import jaxrod as jr

    scene = jr.trefoil(D=8.0, L=292.0, N=N)
    start = jr.relax(scene, 0.0, options=jr.RelaxOptions(linear_algebra="sparse"))
    times, path = follow_twice(scene, start, stop, "sparse")
    end = path.instabilities[0] if path.instabilities else None
    return {"first_s": times[0], "warm_s": times[1], "points": len(path.points),
            "phi_over_pi": end.phi / math.pi if end else None,
            "bracket_over_pi": [b / math.pi for b in end.bracket] if end else None}


def run_side(path, N, stop):
    """``follow_side`` in a fresh process importing jaxrod from ``path`` (in this one in the small mode,
    where the other small scripts' compiled programs serve)."""
    if SMOKE:
        return follow_side(N, stop)
    res = subprocess.run([sys.executable, __file__, "--child", path, str(N), repr(stop)], capture_output=True, text=True)
    for line in res.stdout.splitlines():
        if line.startswith(MARK):
            return json.loads(line[len(MARK):])
    raise RuntimeError(f"child N = {N} failed ({res.returncode}):\n{res.stderr[-3000:]}")


def growth_exponent(rows, side):
    """The slope of log(warm time) against log N over the current version's rows of one side."""
    pts = [(r["N"], r["current"]["warm_s"]) for r in rows if r["side"] == side]
    if len(pts) < 2:
        return None
    n, t = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(n, t, 1)[0])


def same_bracket(a, b, tol=1e-8):
    """Both versions bracketed the end at the same twists (to ``tol`` pi: roundoff apart)."""
    if a["bracket_over_pi"] is None or b["bracket_over_pi"] is None:
        return a["bracket_over_pi"] == b["bracket_over_pi"]
    return bool(np.max(np.abs(np.subtract(a["bracket_over_pi"], b["bracket_over_pi"]))) <= tol)


def table(rows, baseline):
    def end(v):
        return "none" if v["phi_over_pi"] is None else f"{v['phi_over_pi']:+.6f}"

    lines = [f"| N | side | {baseline} warm (s) | current warm (s) | ratio | current first (s) | end / pi "
             f"({baseline}) | end / pi (current) | same bracket |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b, c = r["baseline"], r["current"]
        lines.append(f"| {r['N']} | {r['side']} | {b['warm_s']:.1f} | {c['warm_s']:.1f} | "
                     f"{b['warm_s'] / c['warm_s']:.2f}x | {c['first_s']:.1f} | {end(b)} | {end(c)} | "
                     f"{same_bracket(b, c)} |")
    return lines


def main():
    if sys.argv[1:2] == ["--child"]:  # a version's process: its jaxrod first on the path
        sys.path.insert(0, sys.argv[2])
        print(MARK + json.dumps(follow_side(int(sys.argv[3]), float(sys.argv[4]))), flush=True)
        return
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--baseline", default="ed030e8", help="the previous release to compare with (a commit)")
    p.add_argument("--N", type=int, nargs="*", default=NODES)
    args = p.parse_args()
    out = results_dir()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = REPO if SMOKE else extract(args.baseline, os.path.join(tmp, "baseline"))
        for N in args.N:
            for side, stop in SIDES.items():
                row = {"N": N, "side": side}
                for name, path in (("baseline", base), ("current", REPO)):
                    if not (SMOKE and name == "baseline"):  # the small mode shows the current version twice
                        row[name] = run_side(path, N, stop)
                if SMOKE:
                    row["baseline"] = row["current"]
                rows.append(row)
                print(f"N = {N} {side}: warm {row['baseline']['warm_s']:.1f} s -> {row['current']['warm_s']:.1f} s",
                      flush=True)
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    exponents = {side: growth_exponent(rows, side) for side in SIDES}
    for r in rows:
        r["same_bracket"] = same_bracket(r["baseline"], r["current"])
    with open(os.path.join(out, "large_n_sides.json"), "w") as f:
        json.dump(with_provenance({"baseline": args.baseline, "machine": machine, "rows": rows,
                                   "growth_exponent": exponents}), f, indent=2)
    growth = ", ".join(f"{side} N^{e:.2f}" for side, e in exponents.items() if e is not None)
    text = "\n".join(["# One side of the trefoil at large N on the O(N) path, previous release against current", "",
                      provenance_line(), "",
                      f"Trefoil (8, 292) mm; each version and side in a fresh process: relaxed at phi = 0, then "
                      f"`follow_twist(..., ContinuationOptions(tol=1e-3 pi, switch=False, linear_algebra=\"sparse\"))` "
                      f"to the first branch end twice (warm: the second call); {machine}, BLAS threads "
                      f"{os.environ.get('OPENBLAS_NUM_THREADS')}. Growth of the current warm time over "
                      f"N = {', '.join(map(str, args.N))}: {growth or 'one N only'}.", "",
                      *table(rows, args.baseline), ""])
    with open(os.path.join(out, "large_n_sides.md"), "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
