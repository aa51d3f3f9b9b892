"""The point studies of ``fold_curve_ratio.py`` again, from the same knot with its material slid along
the centreline by a fraction of an edge (issue 17, acceptance 6).

A discrete knot's slide along its own centreline is a symmetry of the continuum rod that the
discretisation breaks into a landscape of wells (barriers ~3e-7 B/l at N = 121), periodic with one
edge: sliding the material by a whole edge relabels the nodes and changes nothing. Within that period
the knot has a few distinct equilibria, and each has its own critical twist, 1e-5 to 1e-3 pi apart at
N = 128. A point study lands in whichever well its path from phi = 0 reaches; the event curve stays in
the well it started in. Here each point study is repeated from the trefoil drawn with its material
origin moved by delta = 1/4, 1/2 and 3/4 of an edge (the same parametrised curve, its nodes placed
delta edges further along it), so that the paths from phi = 0 reach other wells. A curve point is
then compared with every well's event at its D/L: it agrees with the point study of its own well.

Writes benchmarks/results/fold_curve_wells_{plus,minus}.json and fold_curve_wells.md (the JSON after every run: an interrupted run
keeps what it did, and is resumed).
Run: python benchmarks/fold_curve_wells.py [plus|minus]   (~25 min per side on one core; `... report` for
the table alone)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402
from jaxrod.continuation.arclength.event_curve import event_curve  # noqa: E402
from jaxrod.continuation.arclength.rods import knot_problem, set_diameter  # noqa: E402
from jaxrod.model.material import Material  # noqa: E402
from jaxrod.model.scenes import DEFAULT_CONTACT_STIFFNESS, PAPER_YOUNG_MODULUS, trefoil_points  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _bench import COMMITTED_RESULTS, SMOKE, markdown, pick, with_provenance  # noqa: E402
from fold_curve_ratio import CHECKS, FOLLOW_STEP, L, N, NU, OUT, SIDES, options  # noqa: E402

PI = math.pi
SHIFTS = pick((0.25, 0.5, 0.75), (0.5,))  # edges
# the curve and the point studies it is compared with: fold_curve_ratio.py's results (the committed
# ones in the small mode, whose own folder is empty)
BASE = os.path.join(COMMITTED_RESULTS if SMOKE else OUT, "fold_curve_ratio.json")
AGREE = 1e-6  # pi: issue 17's acceptance 6


def shifted_trefoil(D, shift):
    """``jr.trefoil(N=N, D=D, L=L)`` with its nodes placed ``shift`` edges further along the same curve."""
    M = max(4 * N, 400)
    pts = trefoil_points(M)
    loop = np.vstack([pts, pts[:1]])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(loop, axis=0), axis=1))])
    targets = (s[:-1] + shift * s[-1] / N) % s[-1]  # each point moved shift edges along the polyline
    moved = np.stack([np.interp(targets, s, loop[:, k]) for k in range(3)], axis=1)
    return jr.closed_curve(moved, material=Material.from_engineering(PAPER_YOUNG_MODULUS, NU, D), N=N, length=L,
                           name="right-handed trefoil", contact_stiffness=DEFAULT_CONTACT_STIFFNESS)


def point_study(D, shift, below, sign):
    scene = shifted_trefoil(D, shift)
    old = jr.follow_twist(scene, 0.0, below, jr.ContinuationOptions(step=FOLLOW_STEP, max_switches=0))
    e = old.points[-1].equilibrium
    rod = knot_problem(scene, np.asarray(e.q), e.phi)
    study = event_curve(rod.problem, (rod.problem.u0, rod.problem.p0), set_diameter, D, [], options(sign, 300))
    return (study.points[0] if study.points else None), study.message


def main():
    sides = sys.argv[1:] or pick(["plus", "minus"], ["plus"])
    with open(BASE) as f:
        base = json.load(f)
    # one file per side, so that the two sides can run in two processes at once
    paths = {side: os.path.join(OUT, f"fold_curve_wells_{side}.json") for side in sides}
    done = {side: json.load(open(p)) if os.path.exists(p) else {"runs": []} for side, p in paths.items()}

    def save(side):
        tmp = paths[side] + ".tmp"
        with open(tmp, "w") as f:
            json.dump(with_provenance(done[side]), f, indent=1)
        os.replace(tmp, paths[side])

    # the construction reproduces the trefoil at shift 0
    assert np.array_equal(np.asarray(shifted_trefoil(8.0, 0.0).q_init), np.asarray(jr.trefoil(D=8.0, L=L, N=N).q_init))
    for side in sides:
        sign = SIDES[side]["sign"]
        for ratio in CHECKS:
            r = next(q for q in base["curve"] if q["side"] == side and abs(q["D_over_L"] - ratio) < 1e-9)
            for shift in SHIFTS:
                if any(x["D_over_L"] == ratio and x["shift"] == shift for x in done[side]["runs"]):
                    continue
                t = time.perf_counter()
                q, message = point_study(ratio * L, shift, (r["phi_star_over_pi"] - sign * 0.1) * PI, sign)
                row = dict(side=side, D_over_L=ratio, shift=shift, seconds=time.perf_counter() - t,
                           phi_star_over_pi=None if q is None else q.p / PI, kind=None if q is None else q.kind,
                           critical_eigenvalue=None if q is None else q.critical_eigenvalue,
                           residual=None if q is None else q.residual, message=message)
                done[side]["runs"].append(row)
                save(side)
                print(f"[{side}] D/L {ratio} shift {shift}: {row['phi_star_over_pi']} ({row['kind']}), "
                      f"{row['seconds']:.0f} s", flush=True)
    report(base, _all_runs())


def _all_runs():
    runs = []
    for side in SIDES:
        p = os.path.join(OUT, f"fold_curve_wells_{side}.json")
        if os.path.exists(p):
            with open(p) as f:
                runs += json.load(f)["runs"]
    return runs


def report(base, runs):
    lines = ["# The fold curve's point studies in every sliding well (`python benchmarks/fold_curve_wells.py`)", "",
             f"Trefoil, L = {L:g} mm, N = {N}, nu = {NU}. For each D/L: the event curve's value "
             "(`fold_curve_ratio.py`), the point study from the trefoil as drawn (shift 0, from "
             "`fold_curve_ratio.json`), and point studies from the trefoil with its nodes placed 1/4, 1/2 and "
             "3/4 of an edge further along the same curve. phi / pi; the closest: the point study nearest to the "
             "curve.", "",
             "| side | D/L | curve | shift 0 | shift 1/4 | shift 1/2 | shift 3/4 | closest (shift) | difference |",
             "|---|---|---|---|---|---|---|---|---|"]
    agree = 0
    total = 0
    for c in base["checks"]:
        side, ratio = c["side"], c["D_over_L"]
        cells = {0.0: (c.get("study_over_pi"), c.get("study_kind"))}
        for x in runs:
            if x["side"] == side and x["D_over_L"] == ratio:
                cells[x["shift"]] = (x["phi_star_over_pi"], x["kind"])
        if len(cells) < 1 + len(SHIFTS):
            continue
        total += 1
        curve = c["curve_over_pi"]
        found = {s: v for s, (v, _) in cells.items() if v is not None}
        best = min(found, key=lambda s: abs(found[s] - curve))
        diff = abs(found[best] - curve)
        agree += diff <= AGREE

        def cell(s):
            v, k = cells[s]
            return "none" if v is None else f"{v:+.10f} ({'bp' if k == 'branch_point' else k})"

        curve_kind = "bp" if c["curve_kind"] == "branch_point" else c["curve_kind"]
        lines.append(f"| {SIDES[side]['name']} | {ratio:.3f} | {curve:+.10f} ({curve_kind}) | "
                     + " | ".join(cell(s) for s in (0.0,) + SHIFTS) + f" | {best:g} | {diff:.1e} |")
    lines += ["", f"The curve equals a point study to {AGREE:g} pi at {agree} of {total} ratios."]
    with open(os.path.join(OUT, "fold_curve_wells.md"), "w") as f:
        f.write(markdown(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    if sys.argv[1:2] == ["report"]:
        with open(BASE) as f:
            report(json.load(f), _all_runs())
    else:
        main()
