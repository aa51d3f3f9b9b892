"""The trefoil's tightening end (phi < 0) located on the extended system with the O(n) host backend
(``SparseBackend``: SciPy's sparse factorisations) against the dense one, side by side in one
process per N (issue 18, acceptance 1: phi* equal to 1e-8 pi wherever both run, both sides; the
opening side is ``sparse_fold.py``).

For each N: the stable-only engine follows the symmetric branch to -10 pi in steps of 2 pi; from
there the pseudo-arclength continuation (ds_max = 1, newton_tol = 1e-10, eig_rtol = 1e-13,
resolve_crossings = 1e-5) runs towards -11.6 pi, once per backend, with the same pins (the gauge,
and the material slide where ``knot_problem`` finds it exact). The first event at which the Morse
index grows is the branch end; both backends' values are compared.

    python benchmarks/sparse_tightening_end.py          # N = 121 and 241, both backends
    python benchmarks/sparse_tightening_end.py --N 481  # add (or redo) N = 481, the other rows kept
    python benchmarks/sparse_tightening_end.py --report-only

Writes benchmarks/results/sparse_tightening_end.{json,md}.
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
CASES = pick((121, 241), (61,))  # the small mode: the fewest nodes whose start is a minimum
MAX_STEPS = pick(150, 4)  # the small mode: a few steps towards the end
START = pick(-10.0, -2.0)  # phi / pi where the continuation starts; the small mode: one step of the stable-only engine


def child(N):
    import numpy as np

    import jaxrod as jr
    from jaxrod.continuation import ContinuationOptions
    from jaxrod.continuation.arclength import PseudoArclength, continuation
    from jaxrod.linalg.bordered import DenseBackend, SparseBackend
    from jaxrod.continuation.arclength.rods import assemble_pinned_hessian, knot_problem

    scene = jr.trefoil(D=8.0, L=292.0, N=N)
    path = jr.follow_twist(scene, 0.0, (START - 0.3) * PI, jr.ContinuationOptions(step=2 * PI, max_switches=0))
    e = [p.equilibrium for p in path.points if abs(p.equilibrium.phi / PI - START) < 1e-9][0]
    rod0 = knot_problem(scene, np.asarray(e.q), e.phi, backend=SparseBackend(assemble_pinned_hessian))
    pins = np.asarray(rod0.pins)
    opts = ContinuationOptions(ds=-0.05, ds_min=1e-6, ds_max=1.0, max_steps=MAX_STEPS, newton_tol=1e-10, eig_rtol=1e-13,
                               k=6, p_min=-11.6 * PI, resolve_crossings=1e-5)
    for name in ("sparse", "dense"):
        backend = SparseBackend(assemble_pinned_hessian) if name == "sparse" else DenseBackend()
        t = time.perf_counter()
        rod = knot_problem(scene, np.asarray(e.q), e.phi, backend=backend, pins=pins)
        br = continuation(rod.problem, PseudoArclength(), opts, throw=False)
        seconds = time.perf_counter() - t
        end = next((ev for ev in br.events if ev.kind in ("fold", "branch_point") and ev.morse_after > ev.morse_before),
                   None)
        row = {"N": N, "backend": name, "seconds": seconds, "points": len(br.points), "result": br.result.value,
               "slide_pinned": rod0.slide_pin is not None,
               "kind": end.kind if end else None, "phi_over_pi": end.p / PI if end else None,
               "critical_eigenvalue": end.critical_eigenvalue if end else None,
               "residual": end.residual if end else None, "iterations": end.iterations if end else None,
               "morse": [end.morse_before, end.morse_after] if end else None,
               "located": bool(end.converged) if end else False,
               "full_gradient": rod.full_gradient(end.u, end.p) if end else None,
               "events": [(ev.kind, ev.p / PI, ev.morse_before, ev.morse_after) for ev in br.events]}
        print("ROW " + json.dumps(row), flush=True)


def child_output(N):
    """(stdout, stderr, returncode) of the child for N. The small mode's one N runs here instead: a
    child of its own would only import jaxrod and compile N = 61's programs a second time."""
    if SMOKE:
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            child(N)
        return buf.getvalue(), "", 0
    out = subprocess.run([sys.executable, __file__, "--child", str(N)], capture_output=True, text=True)
    return out.stdout, out.stderr, out.returncode


def main():
    if len(sys.argv) > 2 and sys.argv[1] == "--child":
        child(int(sys.argv[2]))
        return
    path = os.path.join(RESULTS, "sparse_tightening_end.json")
    old = []
    if os.path.exists(path):
        with open(path) as fh:
            old = json.load(fh)
    if sys.argv[1:] == ["--report-only"]:
        rows, todo = old, ()
    elif sys.argv[1:2] == ["--N"]:  # these N again, the other rows kept
        todo = tuple(int(a) for a in sys.argv[2:])
        rows = [r for r in old if r["N"] not in todo]
    else:
        rows, todo = [], CASES
    for N in todo:
        stdout, stderr, returncode = child_output(N)
        for line in stdout.splitlines():
            if line.startswith("ROW "):
                rows.append(json.loads(line[4:]))
                print(line, flush=True)
        if returncode != 0:
            print(stderr[-3000:], file=sys.stderr)
    os.makedirs(RESULTS, exist_ok=True)
    for r in rows:  # runs before the 'located' field: a located event has a finite residual <= 1e-10
        r.setdefault("located", r["residual"] is not None and math.isfinite(r["residual"]) and r["residual"] <= 1e-10)
    with open(os.path.join(RESULTS, "sparse_tightening_end.json"), "w") as fh:
        json.dump(with_provenance(rows), fh, indent=2)
    lines = ["# The trefoil's tightening end on the extended system: sparse (host) backend against dense", "",
             "Trefoil (8, 292), nu = 0.5; pseudo-arclength continuation from the symmetric branch at -10 pi towards "
             "-11.6 pi, the first event at which the Morse index grows (`python benchmarks/sparse_tightening_end.py`; "
             "time: the continuation, each backend's first call in its process, compilation included).", "",
             "| N | backend | kind | phi*/pi | located | Morse | critical eigenvalue | residual | Newton iterations | "
             "full gradient | time (s) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["phi_over_pi"] is None:
            lines.append(f"| {r['N']} | {r['backend']} | none ({r['result']}) | | | | | | | | {r['seconds']:.1f} |")
            continue
        lines.append(f"| {r['N']} | {r['backend']} | {r['kind']} | {r['phi_over_pi']:+.10f} | "
                     f"{'yes' if r['located'] else 'no: bracketed only'} | {r['morse'][0]} -> {r['morse'][1]} | {r['critical_eigenvalue']:.1e} | {r['residual']:.1e} | "
                     f"{r['iterations']} | {r['full_gradient']:.1e} | {r['seconds']:.1f} |")
    by = {(r["N"], r["backend"]): r for r in rows}
    lines.append("")
    for N in sorted({r["N"] for r in rows}):
        a, b = by.get((N, "sparse")), by.get((N, "dense"))
        if a and b and a["phi_over_pi"] is not None and b["phi_over_pi"] is not None:
            lines.append(f"- N = {N}: |sparse - dense| = {abs(a['phi_over_pi'] - b['phi_over_pi']):.1e} pi; time "
                         f"dense / sparse = {b['seconds'] / a['seconds']:.1f}x")
    with open(os.path.join(RESULTS, "sparse_tightening_end.md"), "w") as fh:
        fh.write(markdown(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
