"""Michell's ring through jaxrod.continuation.arclength (issue 17, acceptance 4): the double branch point from
the extended system against ``critical_twist``, and the buckled branch switched onto from it and
continued, with its Morse index, until the rod touches itself (or 2 phi*).

Steps, in one process (times include JIT compilation, one per problem shape):
  1. ``critical_twist`` (tol 1e-10 pi) at the default gtol (1e-9) and at gtol = 3e-11: the reference.
  2. The trivial branch (planar circle, uniform twist) with the gauge pinned (7 DOFs,
     ``jaxrod.continuation.arclength.rods.pinned_problem``), phi = 0 .. 1.2 phi_Michell; the degenerate pair's
     crossing located by Brent on each eigenvalue and grouped into one double branch point.
  3. ``emanating_directions`` there: the reduced equations say whether the buckled solutions are
     isolated or a circle (the buckle slid along the ring), pitchfork or transcritical, and the
     sign of kappa (p - p* = -kappa r^2: kappa > 0 is subcritical).
  4. One more pin (``sliding_slice``) fixes the slide; ``switch_branches`` from the now simple
     branch point, r > 0 continued in chunks until the closest approach of two non-adjacent
     segments reaches the diameter D (then located by Brent along the branch), r < 0 a few steps
     (the same ring slid by a quarter turn: it must give the same E(phi)).

Writes benchmarks/results/bifurcation_michell.csv (the buckled branch point by point),
bifurcation_michell.png (phi/pi against Wr and against E - E_circle; stable solid, unstable dashed)
and bifurcation_michell.md. Run: python benchmarks/bifurcation_michell.py [N]   (N = 64: ~5 min)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import csv  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.optimize import brentq  # noqa: E402

import jaxrod as jr  # noqa: E402
from _bench import pick, provenance, provenance_line, results_dir  # noqa: E402  (benchmarks/ is on the path)
from jaxrod.continuation.arclength import (ArclengthOptions, PseudoArclength, Result, continuation,  # noqa: E402
                                emanating_directions, switch_branches)
from jaxrod.continuation.arclength.corrector import correct  # noqa: E402
from jaxrod.continuation.arclength.rods import pinned_problem, sliding_slice  # noqa: E402

NU = 0.5
N = int(sys.argv[1]) if len(sys.argv) > 1 else pick(64, 16)
PI = math.pi
PHI_M = jr.michell_critical_twist(NU)
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = results_dir()
ALG = PseudoArclength()
# newton_tol: the scaled gradient's roundoff floor is ~1e-11 (EA l^2 / B ~ 1e4 at D/R = 0.01);
# eig_rtol: ||J|| ~ 4e4, so the negative band is ~4e-9, above the eigenvalues' noise (~1e-11)
COMMON = dict(newton_tol=5e-11, eig_rtol=1e-13)
CHUNK = 10
PRECISION_NS = pick((24, 32, 48, 64), ())  # the branch point against critical_twist at each
R_MINUS_STEPS = pick(20, 2)  # points followed on r < 0, the mirror branch


def timed(fn, *a, **k):
    t = time.perf_counter()
    out = fn(*a, **k)
    return out, time.perf_counter() - t


def follow_to_contact(rod8, ev8, direction, sign, opts, D, max_points):
    """switch_branches along one sign, then chunks of CHUNK steps until the closest approach < D,
    p leaves [p_min, p_max] or max_points. Returns (points, events, stop reason)."""
    (br,) = [b for b in switch_branches(rod8.problem, ev8, ALG, opts_with(opts, max_steps=CHUNK), amplitude=1.0,
                                        directions=[direction]) if b.origin["sign"] == sign]
    points, events, checked = list(br.points), list(br.events), 0
    while True:
        if any(rod8.min_distance(q.u) < D for q in points[checked:]):
            return points, events, "contact"
        checked = len(points)
        if br.result is not Result.MAX_STEPS:
            return points, events, f"{br.result.name}: {br.message}"
        if len(points) >= max_points:
            return points, events, f"stopped after {len(points)} points"
        last = points[-1]
        br = continuation(rod8.problem, ALG, opts_with(opts, max_steps=CHUNK, ds=last.ds or opts.ds),
                          start=(last.u, last.p, last.tangent), throw=False)
        offset, s0 = len(points) - 1, last.arclength
        for e in br.events:
            e.step += offset
        for q in br.points:
            q.arclength += s0
        points += br.points[1:]  # its first point is the last one, corrected again
        events += br.events


def opts_with(opts, **kw):
    from dataclasses import replace

    kw = {k: v for k, v in kw.items() if v is not None}
    if "ds" in kw:
        kw["ds"] = math.copysign(min(max(abs(kw["ds"]), opts.ds_min), opts.ds_max), opts.ds)
    return replace(opts, **kw)


def locate_contact(rod8, a, b, D, opts):
    """The point between Points a and b where the closest approach equals D: Brent on s along
    <z - z_a, t_a> = s, each evaluation a corrector run on that hyperplane."""
    prob = rod8.problem
    za, zb, ta = a.z, b.z, a.tangent
    sb = float((zb - za) @ ta)

    def point(s):
        c = correct(prob.backend, lambda u, p: prob.linearise(u, p, prob.args), za + (s / sb) * (zb - za), ta,
                    opts.newton_tol, opts.newton_max_iter)
        if not c.converged:
            raise RuntimeError("corrector failed while locating the contact")
        return c.z

    s = brentq(lambda s: rod8.min_distance(point(s)[:-1]) - D, 0.0, sb, xtol=1e-12 * abs(sb))
    return point(s)


def exact_circle_roots(scene, phi_guess):
    """phi where each of the two lowest eigenvalues of the projected Hessian (``jaxrod.linalg.stability.
    spectrum``, critical_twist's matrix) vanishes on the exactly built twisted circle (nodes of the
    regular polygon, theta_i = i phi / N): Brent on each, a reference free of any equilibrium solve."""
    from jaxrod.linalg.stability import spectrum

    n = scene.n_nodes
    q0 = np.asarray(scene.q_init, dtype=float)

    def lam(phi, j):
        q = q0.copy()
        q[3 * n:] = np.arange(n) * phi / n
        return float(np.asarray(spectrum(scene, jnp.asarray(scene.to_scaled(q)), phi)[0])[j])

    a, b = phi_guess * (1 - 1e-6), phi_guess * (1 + 1e-6)
    return [brentq(lambda f: lam(f, j), a, b, xtol=1e-15, rtol=1e-15) for j in (0, 1)]


def branch_point_study(n):
    """critical_twist (two gtol), the trivial branch with its double branch point, the exact-circle
    roots, at N = n. -> dict."""
    scene = jr.michell_ring(n, nu=NU)
    times = {}
    cp_default, times["critical_twist (gtol 1e-9, first call)"] = timed(
        jr.critical_twist, scene, 0.0, 2 * PHI_M, jr.ContinuationOptions(tol=1e-10 * PI))
    cp, times["critical_twist (gtol 3e-11)"] = timed(jr.critical_twist, scene, 0.0, 2 * PHI_M,
                                                      jr.ContinuationOptions(tol=1e-10 * PI, gtol=3e-11))
    rod = pinned_problem(scene, np.asarray(scene.q_init), 0.0)
    trivial, times["trivial branch (7 pins)"] = timed(
        continuation, rod.problem, ALG, ArclengthOptions(ds=2.0, ds_max=8.0, p_max=1.2 * PHI_M, **COMMON))
    (ev,) = trivial.events
    exact, times["exact-circle roots"] = timed(exact_circle_roots, scene, ev.p)
    print(f"N = {n}: branch point {ev.p / PI:.12f} pi (multiplicity {ev.multiplicity}), critical_twist "
          f"{cp_default.phi / PI:.12f} pi (gtol 1e-9) {cp.phi / PI:.12f} pi (gtol 3e-11), exact circle "
          f"{exact[0] / PI:.12f} {exact[1] / PI:.12f} pi", flush=True)
    return dict(N=n, scene=scene, cp=cp, cp_default=cp_default, rod=rod, trivial=trivial, ev=ev, exact=exact,
                times=times)


def main():
    os.makedirs(OUT, exist_ok=True)
    study = branch_point_study(N)
    others = [branch_point_study(n) for n in PRECISION_NS if n != N]
    precision = sorted(others + [study], key=lambda d: d["N"])
    scene, cp, cp_default, rod, trivial, ev = (study[k] for k in ("scene", "cp", "cp_default", "rod", "trivial",
                                                                   "ev"))
    times = study["times"]
    D = float(scene.material.D)
    E_unit = float(scene.energy_scale)  # scaled energy -> B/R (B = R = 1)
    x0 = np.asarray(scene.positions(np.asarray(scene.q_init)))
    circle_dev = max(float(np.max(np.abs(np.asarray(scene.positions(rod.q(q.u))) - x0))) for q in trivial.points)
    twist_dev = max(float(np.max(np.abs(np.asarray(scene.vertex_twists(jnp.asarray(rod.q(q.u)), q.p)) - q.p / N)))
                    for q in trivial.points)
    triv_grad = max(rod.full_gradient(q.u, q.p) for q in trivial.points)

    # 3. reduced equations at the double branch point (7 pins: the slide is free)
    em7, times["emanating_directions (7 pins)"] = timed(emanating_directions, rod.problem, ev)

    # 4. the slide pinned: a simple branch point; switch and follow
    (rod8, ev8), times["sliding_slice"] = timed(sliding_slice, rod, ev)
    (direction,), times["emanating_directions (8 pins)"] = timed(emanating_directions, rod8.problem, ev8)
    print(f"8 pins: kappa = {direction.kappa:.6g}, order {direction.order}, predicted Morse "
          f"{direction.predicted_morse}", flush=True)
    opts = ArclengthOptions(ds=1.0, ds_max=2.0, p_min=0.0, p_max=2 * cp.phi, max_steps=CHUNK, **COMMON)
    (points, events, stop), times["buckled branch r > 0 (to contact)"] = timed(
        follow_to_contact, rod8, ev8, direction, 1, opts, D, 2000)
    print(f"buckled branch: {len(points)} points, stop: {stop}, events {[(e.kind, e.p / PI) for e in events]}",
          flush=True)
    (points_m, _, _), times["buckled branch r < 0 (20 steps)"] = timed(
        follow_to_contact, rod8, ev8, direction, -1, opts_with(opts), D, R_MINUS_STEPS)
    contact = None
    if stop == "contact":
        i = next(i for i, q in enumerate(points) if rod8.min_distance(q.u) < D)
        contact, times["contact located"] = timed(locate_contact, rod8, points[i - 1], points[i], D, opts)
        points = points[:i]
    extra_pin = int(sorted(set(rod8.pins.tolist()) - set(rod.pins.tolist()))[0])

    # trivial branch u(phi) is a straight line: E_circle(phi) from two of its points
    ta, tb = trivial.points[0], trivial.points[1]

    def u_circle(phi):
        return ta.u + (phi - ta.p) / (tb.p - ta.p) * (tb.u - ta.u)

    # the pinned problems' own arguments (the reference state and the scene's material), not the scene
    args7, args8 = rod.problem.args, rod8.problem.args
    energy = jax.jit(rod8.problem.energy)
    energy7 = jax.jit(rod.problem.energy)
    def row(j, u, p, arclength, morse, lam):
        e = float(energy(jnp.asarray(u), p, args8)) * E_unit
        e0 = float(energy7(jnp.asarray(u_circle(p)), p, args7)) * E_unit
        return dict(point=j, arclength=arclength, phi=p, phi_over_pi=p / PI, energy=e, energy_circle=e0,
                    energy_minus_circle=e - e0, Wr=rod8.writhe(u), morse_index=morse, lambda_0=lam[0],
                    lambda_1=lam[1], min_distance_over_D=rod8.min_distance(u) / D,
                    full_gradient=rod8.full_gradient(u, p))

    rows = [row(j, q.u, q.p, q.arclength, q.morse_index, q.eigenvalues) for j, q in enumerate(points)]
    if contact is not None:  # the located contact point ends the branch (arclength: nan, not on a step)
        J = rod8.problem.linearise(jnp.asarray(contact[:-1]), jnp.asarray(contact[-1]), args8)[1]
        lam, _, morse_c = rod8.problem.backend.spectrum(J, 4, 0, COMMON["eig_rtol"])
        rows.append(row(len(rows), contact[:-1], float(contact[-1]), math.nan, morse_c, lam))
    with open(os.path.join(OUT, "bifurcation_michell.csv"), "w", newline="") as f:
        f.write("# {commit}; {command}\n".format(**provenance()))  # read back with comment="#"
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.12g}" if isinstance(v, float) else v) for k, v in r.items()})

    # r < 0 against r > 0 at the same phi: each r < 0 point's phi corrected onto the r > 0 branch
    # (Newton on the hyperplane p = phi from the chord between the bracketing r > 0 points)
    sym = wr_sym = 0.0
    e_p = np.zeros(rod8.problem.n + 1)
    e_p[-1] = 1.0
    lin8 = lambda u, p: rod8.problem.linearise(u, p, args8)  # noqa: E731
    for q in points_m[1:]:
        i = next((i for i in range(1, len(points)) if points[i].p <= q.p <= points[i - 1].p), None)
        if i is None:
            continue
        a, b = points[i - 1], points[i]
        c = correct(rod8.problem.backend, lin8, a.z + (q.p - a.p) / (b.p - a.p) * (b.z - a.z), e_p,
                    COMMON["newton_tol"], 10)
        if c.converged:
            sym = max(sym, abs(float(energy(jnp.asarray(q.u), q.p, args8) - energy(jnp.asarray(c.z[:-1]), q.p, args8))
                               ) * E_unit)
            wr_sym = max(wr_sym, abs(rod8.writhe(q.u) - rod8.writhe(c.z[:-1])))
    # the slide is a zero mode of the 7-pin Hessian along the buckled branch
    slide = []
    for q in points[:: max(1, len(points) // 8)]:
        u7 = rod.restrict(np.asarray(rod8.embed(jnp.asarray(q.u))))
        lam = np.linalg.eigvalsh(np.asarray(rod.problem.linearise(jnp.asarray(u7), jnp.asarray(q.p), args7)[1]))
        k = int(np.argmin(np.abs(lam)))
        slide.append((q.p, lam[k], int(np.sum(lam < -1e-13 * np.max(np.abs(lam))))))

    plot(rows, trivial, ev, contact, rod8, D)
    write_md(locals())


def plot(rows, trivial, ev, contact, rod8, D):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    phi = np.array([r["phi_over_pi"] for r in rows])
    wr = np.array([r["Wr"] for r in rows])
    de = np.array([r["energy_minus_circle"] for r in rows])
    morse = np.array([r["morse_index"] for r in rows])
    p_star = ev.p / PI
    p_end = trivial.p[-1] / PI
    for ax, y, label in ((a1, wr, "Wr"), (a2, de, r"$E - E_\mathrm{circle}$  ($B/R$)")):
        ax.plot([0, p_star], [0, 0], "k-", lw=2, label="circle, Morse 0 (stable)")
        ax.plot([p_star, p_end], [0, 0], "k--", lw=1.5, label="circle, Morse 2")
        for m in sorted(set(morse)):
            sel = np.where(morse == m, y, np.nan)
            ax.plot(phi, sel, "-" if m == 0 else "--", color="C0" if m == 1 else "C3", lw=1.8,
                    label=f"buckled, Morse {m}" + (" (stable)" if m == 0 else ""))
        ax.plot([p_star], [0], "o", color="C1", ms=7, label=f"double branch point {p_star:.6f}$\\pi$")
        if contact is not None:
            yc = rod8.writhe(contact[:-1]) if y is wr else np.nan
            if y is wr:
                ax.plot([contact[-1] / PI], [yc], "x", color="C2", ms=9, mew=2, label=f"self-contact (d = D = {D:g})")
        ax.set_xlabel(r"$\phi/\pi$")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    a1.legend(fontsize=8, loc="upper right")
    a1.set_title(f"Michell's ring, N = {N}, nu = {NU}: Wr")
    a2.set_title("energy above the circle at the same twist")
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, "bifurcation_michell.png"), dpi=120)
    plt.close(fig)


def energy_text(rows):
    de = np.array([r["energy_minus_circle"] for r in rows])
    phi = np.array([r["phi_over_pi"] for r in rows])
    if np.all(de > 0):
        return (f"E - E_circle > 0 at every point, from {de[0]:.3g} B/R next to phi* to {de[-1]:.3g} B/R at "
                f"{phi[-1]:.4f} pi: at each twist below phi* this saddle sets an energy barrier the circle has to "
                f"cross to buckle, and the barrier vanishes at phi*.")
    i = int(np.where(np.diff(np.sign(de)) != 0)[0][0])
    p0 = phi[i] - de[i] * (phi[i + 1] - phi[i]) / (de[i + 1] - de[i])
    return f"E - E_circle goes from {de[0]:.3g} to {de[-1]:.3g} B/R and changes sign at {p0:.4f} pi."


def write_md(v):
    rows, ev, cp, em7, d8 = v["rows"], v["ev"], v["cp"], v["em7"], v["direction"]
    contact, D, times = v["contact"], v["D"], v["times"]
    last = rows[-1]
    morse = sorted({r["morse_index"] for r in rows})
    L = []
    L.append(f"# Michell's ring through jaxrod.continuation.arclength (issue 17, acceptance 4), N = {N}\n")
    L.append(f"nu = {NU} (C = B/(1 + nu)), D/R = {D:g}, B = R = 1; Michell's continuum phi* = "
             f"{PHI_M / PI:.10f} pi. Machine: {platform.machine()}, {os.cpu_count()} cores, jax {jax.__version__}. "
             f"{provenance_line()}\n")
    L.append("## The double branch point\n")
    L.append("phi* from the extended system (the trivial branch with 7 pins, Brent on each of the crossing pair's "
             "eigenvalues, grouped into one event) against ``critical_twist`` (tol 1e-10 pi) at its default gtol "
             "(1e-9) and at gtol = 3e-11, and against the roots of the two lowest eigenvalues of the projected "
             "Hessian on the exactly built twisted circle (no equilibrium solve: the floor set by roundoff).\n")
    L.append("| N | extended system phi*/pi | mult. | crit. eigenvalues | rel. to critical_twist (gtol 1e-9) | "
             "rel. to critical_twist (gtol 3e-11) | rel. to exact circle (each root) | critical_twist's eigenvalue "
             "at its phi* |\n|---|---|---|---|---|---|---|---|")
    for d in v["precision"]:
        e, c1, c2, ex = d["ev"], d["cp_default"], d["cp"], d["exact"]
        L.append(f"| {d['N']} | {e.p / PI:.12f} | {e.multiplicity} | "
                 f"{', '.join(f'{x:.1e}' for x in e.eigenvalues)} | {(e.p - c1.phi) / c1.phi:+.2e} | "
                 f"{(e.p - c2.phi) / c2.phi:+.2e} | {(e.p - ex[0]) / ex[0]:+.2e}, {(e.p - ex[1]) / ex[1]:+.2e} | "
                 f"{c1.eigenvalue:.1e} |")
    L.append("")
    L.append(f"- At N = {N}: corrector residual {ev.residual:.2e}; {ev.iterations} eigenvalue evaluations (Brent, "
             f"both eigenvalues); Morse index {ev.morse_before} -> {ev.morse_after}; critical_twist's multiplicity "
             f"{cp.multiplicity}.")
    L.append(f"- The trivial branch is the twisted circle: over its {len(v['trivial'].points)} points the nodes stay "
             f"within {v['circle_dev']:.1e} R of the regular polygon, every vertex twist equals phi/N to "
             f"{v['twist_dev']:.1e}, and the full gradient (pinned rows included) is <= {v['triv_grad']:.1e}.")
    L.append("- The floor: the eigenvalues carry roundoff ~1e-12 (||J|| ~ 4e4, the stretching stiffness at "
             "D/R = 0.01), while dlambda/dphi falls with N (eigenvalues ~ 1/N^2 in these units), so in float64 "
             "phi* is determined only to ~1e-12 / |dlambda/dphi|: ~1e-10 relative at N = 24, ~1e-9 at N = 64. The "
             "two exact-circle roots of the degenerate pair, equal in exact arithmetic, differ by that much, and "
             "any two determinations (critical_twist at two gtol, the extended system) differ by up to it. The "
             "extended system sits on the exact circle (the continuation's trivial branch is exact to "
             "roundoff) and is within the spread of the exact-circle roots at every N; against critical_twist "
             "the 1e-9 relative target holds up to N = 48 and is at the floor at N = 64.")
    L.append("- In the pinned gauge the pair is not degenerate away from phi* (the pins distort the metric), so its "
             "two roots differ by the eigenvalues' noise; they are grouped into one event of multiplicity 2 "
             "because both eigenvalues are below event_tol at the roots' mean.\n")
    L.append("## Emanating branches\n")
    L.append("7 pins (the slide free): " + "; ".join(
        f"eta = ({e.eta[0]:.3f}, {e.eta[1]:.3f}): order {e.order}, kappa = {e.kappa:.5g}, predicted Morse "
        f"{e.predicted_morse}, isolated = {e.isolated}" for e in em7) + ".")
    L.append("`isolated = False`: every direction of the 2-dimensional kernel solves the reduced equations, a "
             "circle of buckled rings (one buckle slid along the ring). kappa differs between the two basis "
             "directions only because the pinned metric is not isotropic.\n")
    k = v["extra_pin"]
    L.append(f"8 pins (slide pinned by ``sliding_slice``: q[{k}], coordinate {'xyz'[k % 3]} of node {k // 3}): "
             f"simple branch point, critical eigenvalue {v['ev8'].eigenvalues[0]:.1e}; order {d8.order} "
             f"(pitchfork: the cubic term vanishes by symmetry), kappa = {d8.kappa:.6g} > 0, so "
             f"phi - phi* = -kappa r^2 < 0; predicted Morse index {d8.predicted_morse}.\n")
    L.append("## The buckled branch\n")
    L.append("Point by point in bifurcation_michell.csv: arclength, phi, energy and the circle's at the same phi "
             "(B/R), Wr (exact polygon writhe), Morse index, the two lowest eigenvalues of the 8-pin Hessian "
             "(scaled), closest approach of non-adjacent segments / D, full gradient (scaled).\n")
    stop = "self-contact (closest approach of non-adjacent segments = D)" if contact is not None else v["stop"]
    L.append(f"Continued from the branch point (switch_branches, amplitude 1) for {len(rows)} points until {stop}.")
    if contact is not None:
        L.append(f"Contact located at phi = {contact[-1] / PI:.6f} pi, Wr = {v['rod8'].writhe(contact[:-1]):.5f}.")
    L.append(f"Events on the way: {[(e.kind, round(e.p / PI, 6)) for e in v['events']] or 'none'}; Morse index "
             f"along the branch: {morse}. Full gradient (all DOFs, the sliding pin's row included) <= "
             f"{max(r['full_gradient'] for r in rows[:len(v['points'])]):.1e} at every continuation point "
             f"({rows[-1]['full_gradient']:.1e} at the last row{' (the located contact)' if contact is not None else ''}): "
             f"the slide is an exact symmetry to roundoff, so these are equilibria of the free ring.\n")
    L.append("| | phi/pi | Wr | Morse | lambda_0 | lambda_1 | E - E_circle (B/R) | d_min/D |\n|---|---|---|---|---|---|---|---|")
    sel = sorted(set([0, 1, 2] + list(range(0, len(rows), max(1, len(rows) // 10))) + [len(rows) - 1]))
    for i in sel:
        r = rows[i]
        L.append(f"| {i} | {r['phi_over_pi']:.6f} | {r['Wr']:.5f} | {r['morse_index']} | {r['lambda_0']:.3e} | "
                 f"{r['lambda_1']:.3e} | {r['energy_minus_circle']:.5g} | {r['min_distance_over_D']:.2f} |")
    L.append("")
    L.append(f"- r < 0 (the same ring slid by a quarter turn): at the phi of each of its points, the r > 0 branch "
             f"has the same energy to {v['sym']:.1e} B/R and the same Wr to {v['wr_sym']:.1e}.")
    L.append("- The slide is a zero mode without the 8th pin: the 7-pin Hessian at points of the branch has "
             "its smallest |lambda| = " + ", ".join(f"{x[1]:.1e}" for x in v["slide"]) + " and negative count "
             + ", ".join(str(x[2]) for x in v["slide"]) + ".\n")
    L.append("## Sub- or supercritical\n")
    L.append(f"**Subcritical.** (1) The reduced equations give a pitchfork with kappa = {d8.kappa:.5g} > 0: the "
             f"buckled branch exists, near phi*, for phi < phi* only. (2) The continued branch goes backwards: from "
             f"{rows[0]['phi_over_pi']:.6f} pi (first point after the switch) down to {last['phi_over_pi']:.6f} pi "
             f"{'(self-contact)' if contact is not None else ''}, phi decreasing monotonically: "
             f"{bool(np.all(np.diff([r['phi'] for r in rows]) < 0))}, with no fold on the way. (3) It is unstable "
             f"near the branch point, where the circle is stable: Morse index {rows[0]['morse_index']} at the first "
             f"point, {morse} along the whole branch. {energy_text(rows)} Past phi* no nearby buckled equilibrium "
             f"exists, so a ring twisted through phi* jumps, and no post-buckled state is reached before the "
             f"rod touches itself -- the classic picture (REFERENCE.md section 3: the ring buckles out of plane "
             f"subcritically and the post-buckled ring touches itself).\n")
    L.append("## Timings (wall, one process, compilation included)\n")
    L.append("| step | s |\n|---|---|")
    for k, t in times.items():
        L.append(f"| {k} | {t:.1f} |")
    L.append("\n![branch](bifurcation_michell.png)\n")
    with open(os.path.join(OUT, "bifurcation_michell.md"), "w") as f:
        f.write("\n".join(L))
    print("\n".join(L))


if __name__ == "__main__":
    main()
