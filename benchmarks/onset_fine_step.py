"""The twist study's located onsets against fine-step references (the trefoil, N = 61).

For each D/L and side: ``jaxrod trefoil`` (the study, then each end located on the extended
system), and an independent reference: from the study's last stable state before the end (where the
extended system starts too), Newton's method in steps of 2e-4 pi until the lowest eigenvalue changes
sign, then regula falsi on that mode (tracked by eigenvector overlap); where Newton finds no state
past a twist, the fold's twist. Writes benchmarks/results/onset_fine_step.md.

Run: python benchmarks/onset_fine_step.py
"""
import json
import math
import pathlib
import tempfile

import numpy as np

from jaxrod.solve.equilibrium import EquilibriumOptions, solve_equilibrium
from jaxrod.model.scenes import trefoil

from _bench import SMOKE, pick, provenance_line, results_dir, run_cli  # noqa: E402,F401  (benchmarks/ is on the path)
NEWTON = EquilibriumOptions(method="newton", gtol=1e-11, near_null_tol=1e-6)
L, N = 292.0, pick(61, 41)
CASES = pick(((0.020, "minus"), (0.024, "minus"), (0.028, "minus"), (0.024, "plus")), ((0.0274, "plus"),))
SMALL_STUDY = pick([], ["--stable-only", "--no-extrapolation"])  # small mode: the study's stable branches only
# small mode: the opening side ends at 6.83 pi, so the buckled branch after it is followed for less
PLUS_MAX = pick("7.5pi", "7pi")


def _study(D, out, side):
    span = ["--phi-min=-12pi", "--phi-max", "0.5pi"] if side == "minus" else ["--phi-min=-0.5pi", "--phi-max", PLUS_MAX]
    # small mode: in this process, so that the studies and the references share their programs
    run = run_cli(["trefoil", "--D", repr(D), "--L", repr(L), "--N", str(N), *span, "--out", out,
                   "--json", "--no-figures", "--quiet", *SMALL_STUDY], in_process=SMOKE)
    if run.returncode != 0:
        raise RuntimeError(run.stderr)
    return json.loads(run.stdout)


def _state_before(out, side):
    """(q, phi): the study's last stable state before its first end on this side (its mode file),
    where the extended system's path starts too."""
    crit = json.loads(pathlib.Path(out, "critical.json").read_text())
    first = next(c for c in crit["instabilities"] if c["direction"] == side)
    with np.load(pathlib.Path(out, first["mode_file"])) as f:
        return np.asarray(f["q"]), float(f["phi"])


def _tracked(e, v):
    j = int(np.argmax(np.abs(np.asarray(e.stability.eigenvectors).T @ v)))
    return float(e.stability.eigenvalues[j]), np.asarray(e.stability.eigenvectors[:, j])


def fine_step_zero(scene, q, phi, h):
    """(phi* / pi, kind): where the first of the lowest eigenvalues changes sign ('crossing', then
    regula falsi on that mode, tracked by eigenvector overlap), or, where Newton finds no equilibrium
    past a twist even in steps of 1e-7 pi, the fold's twist from lambda^2, linear in phi next to a
    fold, fitted through the last three states ('fold')."""
    from jaxrod.solve.solvers import ConvergenceError

    e = solve_equilibrium(scene, phi, q, NEWTON)
    assert e.stability.eigenvalues[0] > 0.0
    seen = [(e.phi, float(e.stability.eigenvalues[0]))]
    while abs(h) >= 1e-7 * math.pi:
        try:
            nxt = solve_equilibrium(scene, e.phi + h, e.q, NEWTON, nbr=e.neighbourhood)
        except ConvergenceError:
            h *= 0.5
            continue
        if nxt.stability.eigenvalues[0] < 0.0:
            v = np.asarray(nxt.stability.eigenvectors[:, 0])
            la, _ = _tracked(e, v)
            a, b, lb = e.phi, nxt.phi, float(nxt.stability.eigenvalues[0])
            for _ in range(4):
                p = a + (b - a) * la / (la - lb)
                lp, _ = _tracked(solve_equilibrium(scene, p, e.q, NEWTON, nbr=e.neighbourhood), v)
                a, la, b, lb = (p, lp, b, lb) if lp > 0.0 else (a, la, p, lp)
            return (a + (b - a) * la / (la - lb)) / math.pi, "crossing"
        e = nxt
        seen.append((e.phi, float(e.stability.eigenvalues[0])))
    (p1, l1), (p2, l2), (p3, l3) = seen[-3:]
    slope, intercept = np.polyfit([p1, p2, p3], [l1 ** 2, l2 ** 2, l3 ** 2], 1)
    return -intercept / slope / math.pi, "fold"


def main():
    rows = []
    for ratio, side in CASES:
        D = round(ratio * L, 6)
        with tempfile.TemporaryDirectory() as out:
            summary = _study(D, out, side)
            located = summary[f"phi_{side}_over_pi"]
            q, phi = _state_before(out, side)
            sign = 1.0 if side == "plus" else -1.0
            reference, how = fine_step_zero(trefoil(D=D, L=L, N=N), q, phi, sign * 0.0002 * math.pi)
        rows.append((ratio, side, summary[f"phi_{side}_kind"], located, reference, how, abs(located - reference)))
        print(rows[-1], flush=True)
    lines = ["| D/L | side | located kind | located (π) | fine-step reference (π) | reference from | difference (π) |",
             "|---|---|---|---|---|---|---|"]
    lines += [f"| {r:.3f} | {s} | {k} | {a:+.10f} | {b:+.10f} | {h} | {d:.1e} |" for r, s, k, a, b, h, d in rows]
    text = ("# Located onsets against fine-step references (trefoil, L = 292, N = 61)\n\n" + provenance_line() + "\n\n"
            "`python benchmarks/onset_fine_step.py`: the study's located onset, and the first zero of the "
            "lowest eigenvalues followed by Newton in steps of 2e-4 π from the study's last stable state "
            "(regula falsi at the end); where Newton finds no state past a twist even in steps of 1e-7 π, the "
            "fold's twist from λ², linear in φ next to a fold, through the last three states.\n\n" + "\n".join(lines) + "\n")
    path = pathlib.Path(results_dir()) / "onset_fine_step.md"
    path.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
