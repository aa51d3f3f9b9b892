"""The trefoil's opening fold located on the extended system (``jaxrod.continuation.arclength``) with the O(n)
host backend (``SparseBackend``: SciPy's sparse factorisations) against the dense one, side by side
in one process per N (issue 18, acceptance 1: phi* equal to 1e-8 pi wherever both run).

For each N: the stable-only engine follows the symmetric branch to 6 pi; from there the
pseudo-arclength continuation (ds_max = 4, newton_tol = 1e-10, eig_rtol = 1e-13) runs up to the
fold and past it, once per backend, with the gauge pinned and, where ``knot_problem`` finds the
material slide to be a numerically exact symmetry (its eigenvalue ~1e-12 in scaled units at
N = 481, against ~1e-7 at N = 121; ``EXACT_SLIDE_TOL``), one extra pin on it, along which Newton's
corrector would otherwise step by edge lengths and stall (residual ~6e-8, with either backend).
``full_gradient`` at the fold measures the force that pin holds (~1e-12: none).

    python benchmarks/sparse_fold.py                 # N = 121, 481 (both backends), 961 (sparse)

Writes benchmarks/results/sparse_fold.{json,md}.
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import contextlib  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from _bench import SMOKE, markdown, pick, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = results_dir()
PI = math.pi
CASES = pick(((121, ("sparse", "dense")), (481, ("sparse", "dense")), (961, ("sparse",))),
             ((61, ("sparse", "dense")),))  # the small mode: the fewest nodes whose start is a minimum
MAX_STEPS = pick(120, 4)  # the small mode: a few steps towards the fold
# the stable-only engine's path to the start at 6 pi: largest step and end (the small mode: 0, 3, 6 pi)
FOLLOW_STEP, FOLLOW_STOP = pick((2 * PI, 6.3 * PI), (3 * PI, 6.0 * PI))


def child(N, backends):
    import numpy as np

    import jaxrod as jr
    from jaxrod.continuation import ContinuationOptions
    from jaxrod.continuation.arclength import PseudoArclength, continuation
    from jaxrod.linalg.bordered import DenseBackend, SparseBackend
    from jaxrod.continuation.arclength.rods import assemble_pinned_hessian, knot_problem

    scene = jr.trefoil(D=8.0, L=292.0, N=N)
    t = time.perf_counter()
    path = jr.follow_twist(scene, 0.0, FOLLOW_STOP, jr.ContinuationOptions(step=FOLLOW_STEP, max_switches=0))
    follow_s = time.perf_counter() - t
    e = [p.equilibrium for p in path.points if abs(p.equilibrium.phi / PI - 6.0) < 1e-9][0]
    # The gauge pins, and one more on the material slide where it is a numerically exact symmetry:
    # ``knot_problem`` decides (its eigenvalue below EXACT_SLIDE_TOL), once, with the sparse backend,
    # and both backends then get the same pins.
    rod0 = knot_problem(scene, np.asarray(e.q), e.phi, backend=SparseBackend(assemble_pinned_hessian))
    pins = np.asarray(rod0.pins) if rod0.slide_pin is not None else None
    print(f"N = {N}: slide pinned at DOF {rod0.slide_pin}" if pins is not None else f"N = {N}: no exact slide",
          file=sys.stderr, flush=True)
    # resolve_crossings: a step across which the Morse index jumps by more than 1 is halved, so that a
    # fold and a crossing next to it are located apart (N = 961: a branch point 2.4e-5 pi before the fold)
    opts = ContinuationOptions(ds=0.05, ds_min=1e-6, ds_max=4.0, max_steps=MAX_STEPS, newton_tol=1e-10, eig_rtol=1e-13,
                               k=6, p_max=7.0 * PI, resolve_crossings=1e-5)
    for name in backends:
        backend = SparseBackend(assemble_pinned_hessian) if name == "sparse" else DenseBackend()
        t = time.perf_counter()
        rod = knot_problem(scene, np.asarray(e.q), e.phi, backend=backend, pins=pins)
        br = continuation(rod.problem, PseudoArclength(), opts, throw=False)
        seconds = time.perf_counter() - t
        folds = [ev for ev in br.events if ev.kind == "fold"]
        f = folds[0] if folds else None
        row = {"N": N, "backend": name, "seconds": seconds, "follow_s": follow_s, "points": len(br.points),
               "result": br.result.value, "slide_pinned": pins is not None,
               "fold_over_pi": f.p / PI if f else None, "critical_eigenvalue": f.critical_eigenvalue if f else None,
               "residual": f.residual if f else None, "iterations": f.iterations if f else None,
               "full_gradient": rod.full_gradient(f.u, f.p) if f else None,
               "events": [(ev.kind, ev.p / PI) for ev in br.events]}
        print("ROW " + json.dumps(row), flush=True)


def child_output(N, backends):
    """(stdout, stderr, returncode) of the child for N. The small mode's one N runs here instead: a
    child of its own would only import jaxrod and compile N = 61's programs a second time."""
    if SMOKE:
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            child(N, backends)
        return buf.getvalue(), "", 0
    out = subprocess.run([sys.executable, __file__, "--child", str(N), ",".join(backends)], capture_output=True,
                         text=True)
    return out.stdout, out.stderr, out.returncode


def main():
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        child(int(sys.argv[2]), sys.argv[3].split(","))
        return
    rows = []
    for N, backends in CASES:
        stdout, stderr, returncode = child_output(N, backends)
        for line in stdout.splitlines():
            if line.startswith("ROW "):
                rows.append(json.loads(line[4:]))
                print(line, flush=True)
        if returncode != 0:
            print(stderr[-3000:], file=sys.stderr)
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, "sparse_fold.json"), "w") as fh:
        json.dump(with_provenance(rows), fh, indent=2)
    lines = ["# The trefoil's opening fold on the extended system: sparse (host) backend against dense", "",
             "Trefoil (8, 292), nu = 0.5; pseudo-arclength continuation from the symmetric branch at 6 pi to the fold "
             "(`python benchmarks/sparse_fold.py`; time: the continuation from 6 pi to 120 points past the start, "
             "each backend's first call in its process, compilation included).", "",
             "| N | backend | fold phi*/pi | critical eigenvalue | residual | Newton iterations | full gradient | "
             "slide pinned | time (s) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["fold_over_pi"] is None:
            lines.append(f"| {r['N']} | {r['backend']} | no fold ({r['result']}) | | | | | {r['slide_pinned']} | "
                         f"{r['seconds']:.1f} |")
            continue
        lines.append(f"| {r['N']} | {r['backend']} | {r['fold_over_pi']:+.10f} | {r['critical_eigenvalue']:.1e} | "
                     f"{r['residual']:.1e} | {r['iterations']} | {r['full_gradient']:.1e} | {r['slide_pinned']} | "
                     f"{r['seconds']:.1f} |")
    by = {(r["N"], r["backend"]): r for r in rows}
    lines.append("")
    for N, _ in CASES:
        a, b = by.get((N, "sparse")), by.get((N, "dense"))
        if a and b and a["fold_over_pi"] is not None and b["fold_over_pi"] is not None:
            lines.append(f"- N = {N}: |sparse - dense| = {abs(a['fold_over_pi'] - b['fold_over_pi']):.1e} pi; time "
                         f"dense / sparse = {b['seconds'] / a['seconds']:.1f}x")
    with open(os.path.join(RESULTS, "sparse_fold.md"), "w") as fh:
        fh.write(markdown(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
