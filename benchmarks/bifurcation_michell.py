"""Michell's ring through jaxrod.continuation.arclength: the double branch point from the extended system
against ``critical_twist``, and the buckled branch switched onto from it and continued, with its Morse
index, until the rod first touches itself, at D/R = 0.01, 0.005 and 0.0025 (EA = 16 B/D^2: the
stretching stiffness grows 16-fold over the range). No tolerance is set by hand: Newton's, the located
events' and the Morse count's follow from the problem's own scale
(``jaxrod.continuation.arclength.scales``), and the values used are tabulated.

Steps, in one process (times include JIT compilation, one per problem shape):
  1. At D/R = 0.01: ``critical_twist`` (tol 1e-10 pi) at the default gtol (1e-9) and at gtol =
     3e-11, the reference; at N = 24, 32, 48 and N.
  2. At each D/R: the trivial branch (planar circle, uniform twist) with the gauge pinned (7 DOFs,
     ``jaxrod.continuation.arclength.rods.pinned_problem``), phi = 0 .. 1.2 phi_Michell; the degenerate
     pair's crossing located by Brent on each eigenvalue and grouped into one double branch point.
  3. At D/R = 0.01: ``emanating_directions`` there (7 pins): the reduced equations say whether the
     buckled solutions are isolated or a circle (the buckle slid along the ring), pitchfork or
     transcritical, and the sign of kappa (p - p* = -kappa r^2: kappa > 0 is subcritical).
  4. At each D/R: one more pin (``sliding_slice``) fixes the slide; ``switch_branches`` from the now
     simple branch point, r > 0 continued in chunks (``continuation_until``) until the closest
     approach of two non-adjacent segments reaches the diameter D (then located by Brent along the
     branch), r < 0 one chunk (the same ring slid by a quarter turn: it must give the same E(phi)).
  5. At D/R = 0.0025: steps 2 and 4 at N = 16, 24, 32, 48: phi, Wr and the energy at first contact
     against N (``tests/test_michell_contact.py`` runs this case at small N).

Writes benchmarks/results/bifurcation_michell.csv (the buckled branch at D/R = 0.01 point by point),
bifurcation_michell.png (phi/pi against Wr and against E - E_circle; stable solid, unstable dashed),
bifurcation_michell.md and bifurcation_michell.json (the contact against D/R and against N, with the
tolerances used). Run: python benchmarks/bifurcation_michell.py [N]   (N = 64: ~3 min with the XLA
compile cache warm)
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import csv  # noqa: E402
import json  # noqa: E402
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
from jaxrod.continuation import ContinuationOptions  # noqa: E402
from jaxrod.continuation.arclength import (PseudoArclength, Result, continuation, continuation_until,  # noqa: E402
                                           emanating_directions, switch_branches)
from jaxrod.continuation.arclength.corrector import correct  # noqa: E402
from jaxrod.continuation.arclength.rods import pinned_problem, sliding_slice  # noqa: E402
from jaxrod.continuation.arclength.scales import residual_floor, scaled_options  # noqa: E402

NU = 0.5
N = int(sys.argv[1]) if len(sys.argv) > 1 else pick(64, 16)
PI = math.pi
PHI_M = jr.michell_critical_twist(NU)
OUT = results_dir()
ALG = PseudoArclength()
CHUNK = 10
SLENDERNESS = pick((0.01, 0.005, 0.0025), (0.01,))  # D/R; the first gets the detailed analysis
PRECISION_NS = pick((24, 32, 48, 64), ())  # the branch point against critical_twist at each (D/R = 0.01)
CONVERGENCE_NS = pick((16, 24, 32, 48), ())  # contact at D/R = 0.0025 against N (and N itself)
CONVERGENCE_SLENDERNESS = 0.0025
MAX_POINTS = pick(2000, 400)  # points on the buckled branch before giving up on contact
TRIVIAL = ContinuationOptions(ds=2.0, ds_max=8.0, p_max=1.2 * PHI_M)


def timed(fn, *a, **k):
    t = time.perf_counter()
    out = fn(*a, **k)
    return out, time.perf_counter() - t


def tolerances(opts, problem, u, p):
    """The resolved tolerances of a run and the residual floor estimate they come from."""
    floor, norm = residual_floor(problem, u, p)
    return dict(newton_tol=opts.newton_tol, event_tol=opts.event_tol, eig_rtol=opts.eig_rtol, floor=floor,
                norm_J=norm)


def trivial_branch(scene):
    """The 7-pin trivial branch with its double branch point. -> (rod, Branch, Event, tolerances)."""
    rod = pinned_problem(scene, np.asarray(scene.q_init), 0.0)
    opts = scaled_options(rod.problem, TRIVIAL, rod.problem.u0, rod.problem.p0)
    trivial = continuation(rod.problem, ALG, opts)
    (ev,) = trivial.events
    return rod, trivial, ev, tolerances(opts, rod.problem, rod.problem.u0, rod.problem.p0)


def contact_index(rod8, points, D, start=0):
    """Index of the first of points[start:] closer to itself than D, or None."""
    return next((i for i in range(start, len(points)) if rod8.min_distance(points[i].u) < D), None)


def buckled_to_contact(rod, ev, D, max_points=MAX_POINTS):
    """The slide pinned, the buckled branch r > 0 from the branch point until first self-contact
    (located by Brent), r < 0 one chunk. -> dict."""
    t0 = time.perf_counter()
    rod8, ev8 = sliding_slice(rod, ev)
    (direction,) = emanating_directions(rod8.problem, ev8)
    opts = scaled_options(rod8.problem, ContinuationOptions(ds=1.0, ds_max=2.0, p_min=0.0, p_max=2 * ev.p,
                                                            max_steps=CHUNK), ev8.u, ev8.p)
    plus, minus = sorted(switch_branches(rod8.problem, ev8, ALG, opts, amplitude=1.0, directions=[direction]),
                         key=lambda b: -b.origin["sign"])
    points, events, stop = list(plus.points), list(plus.events), plus.result.name
    checked = [0]

    def touched(pts, _events):
        i = contact_index(rod8, pts, D, checked[0])
        checked[0] = len(pts)
        if i is not None:
            return "contact"
        return f"stopped after {len(pts)} points" if len(pts) >= max_points else ""

    if touched(points, events) == "contact":
        stop = "contact"
    elif plus.result is Result.MAX_STEPS:
        last = points[-1]
        ds = min(max(abs(last.ds), opts.ds_min), opts.ds_max)
        rest = continuation_until(rod8.problem, ALG, opts.updated(ds=ds), lambda p, e: touched(points + p[1:], e),
                                  start=(last.u, last.p, last.tangent))
        offset, s0 = len(points) - 1, last.arclength
        for e in rest.events:
            e.step += offset
        for q in rest.points[1:]:
            q.arclength += s0
        points += rest.points[1:]
        events += rest.events
        stop = rest.message if rest.result is Result.STOPPED else f"{rest.result.name}: {rest.message}"
    # a chunk goes on past the contact to its end (the rod then passes through itself, where the
    # writhe, hence the energy, jumps): whatever the chunk reports there, contact is where it was
    i = contact_index(rod8, points, D)
    contact = None
    if i is not None:
        stop = "contact"
        contact = locate_contact(rod8, points[i - 1], points[i], D, opts)
        points, events = points[:i], [e for e in events if e.step < i]  # the rod passes through itself beyond
    return dict(rod8=rod8, ev8=ev8, direction=direction, opts=opts, points=points, events=events, stop=stop,
                contact=contact, minus=minus.points, seconds=time.perf_counter() - t0,
                tolerances=tolerances(opts, rod8.problem, ev8.u, ev8.p))


def locate_contact(rod8, a, b, D, opts):
    """The point between Points a and b where the closest approach equals D: Brent on s along
    <z - z_a, t_a> = s, each evaluation a corrector run on that hyperplane (to opts.newton_tol)."""
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


class Energies:
    """E (B/R) of a buckled state and E_circle at the same twist (the trivial branch u(phi) is a
    straight line in the pinned DOFs: from two of its points)."""

    def __init__(self, scene, rod, rod8, trivial):
        self.unit = float(scene.energy_scale)  # scaled energy -> B/R (B = R = 1)
        self.rod, self.rod8 = rod, rod8
        self.a, self.b = trivial.points[0], trivial.points[1]
        self.e8, self.e7 = jax.jit(rod8.problem.energy), jax.jit(rod.problem.energy)

    def circle(self, phi):
        a, b = self.a, self.b
        u = a.u + (phi - a.p) / (b.p - a.p) * (b.u - a.u)
        return float(self.e7(jnp.asarray(u), phi, self.rod.problem.args)) * self.unit

    def __call__(self, u8, phi):
        return float(self.e8(jnp.asarray(u8), phi, self.rod8.problem.args)) * self.unit


def contact_summary(slenderness, n, scene, rod, trivial, ev, tol7, branch):
    """One row of the contact tables (json-able)."""
    contact = branch["contact"]
    row = dict(slenderness=slenderness, N=n, phi_star_over_pi=ev.p / PI, multiplicity=ev.multiplicity,
               branch_point_residual=ev.residual, trivial_tolerances=tol7, buckled_tolerances=branch["tolerances"],
               kappa=branch["direction"].kappa, points=len(branch["points"]), stop=branch["stop"],
               morse=sorted({q.morse_index for q in branch["points"]}),
               events=[(e.kind.value, e.p / PI) for e in branch["events"]], seconds=branch["seconds"],
               stretch=float(scene.material.EA) * float(scene.length_scale) ** 2 / float(scene.material.B))
    if contact is not None:
        energies = Energies(scene, rod, branch["rod8"], trivial)
        u, p = contact[:-1], float(contact[-1])
        row.update(phi_over_pi=p / PI, Wr=branch["rod8"].writhe(u), energy=energies(u, p),
                   energy_circle=energies.circle(p), min_distance_over_D=branch["rod8"].min_distance(u) / float(
                       scene.material.D), full_gradient=branch["rod8"].full_gradient(u, p))
        row["energy_minus_circle"] = row["energy"] - row["energy_circle"]
    return row


def contact_at(slenderness, n):
    """The trivial branch, its branch point and the buckled branch to contact for one ring. -> row."""
    scene = jr.michell_ring(N=n, nu=NU, slenderness=slenderness)
    rod, trivial, ev, tol7 = trivial_branch(scene)
    branch = buckled_to_contact(rod, ev, float(scene.material.D))
    row = contact_summary(slenderness, n, scene, rod, trivial, ev, tol7, branch)
    print(f"N = {n}, D/R = {slenderness:g}: branch point {ev.p / PI:.10f} pi, {row['points']} points, "
          f"stop: {row['stop']}, contact phi {row.get('phi_over_pi', math.nan):.6f} pi, Wr "
          f"{row.get('Wr', math.nan):.5f}, newton_tol {branch['opts'].newton_tol:.2e}", flush=True)
    return row


def branch_point_study(n):
    """critical_twist (two gtol), the trivial branch with its double branch point, the exact-circle
    roots, at N = n and D/R = SLENDERNESS[0]. -> dict."""
    scene = jr.michell_ring(N=n, nu=NU, slenderness=SLENDERNESS[0])
    times = {}
    cp_default, times["critical_twist (gtol 1e-9, first call)"] = timed(
        jr.critical_twist, scene, 0.0, 2 * PHI_M, jr.ContinuationOptions(tol=1e-10 * PI))
    cp, times["critical_twist (gtol 3e-11)"] = timed(jr.critical_twist, scene, 0.0, 2 * PHI_M,
                                                      jr.ContinuationOptions(tol=1e-10 * PI, gtol=3e-11))
    (rod, trivial, ev, tol7), times["trivial branch (7 pins)"] = timed(trivial_branch, scene)
    exact, times["exact-circle roots"] = timed(exact_circle_roots, scene, ev.p)
    print(f"N = {n}: branch point {ev.p / PI:.12f} pi (multiplicity {ev.multiplicity}), critical_twist "
          f"{cp_default.phi / PI:.12f} pi (gtol 1e-9) {cp.phi / PI:.12f} pi (gtol 3e-11), exact circle "
          f"{exact[0] / PI:.12f} {exact[1] / PI:.12f} pi", flush=True)
    return dict(N=n, scene=scene, cp=cp, cp_default=cp_default, rod=rod, trivial=trivial, ev=ev, exact=exact,
                times=times, tol7=tol7)


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




def branch_rows(scene, rod, trivial, branch):
    """The buckled branch point by point (and the located contact last), for the csv and the tables."""
    rod8, opts, contact = branch["rod8"], branch["opts"], branch["contact"]
    energies = Energies(scene, rod, rod8, trivial)
    D = float(scene.material.D)

    def row(j, u, p, arclength, morse, lam):
        e, e0 = energies(u, p), energies.circle(p)
        return dict(point=j, arclength=arclength, phi=p, phi_over_pi=p / PI, energy=e, energy_circle=e0,
                    energy_minus_circle=e - e0, Wr=rod8.writhe(u), morse_index=morse, lambda_0=lam[0],
                    lambda_1=lam[1], min_distance_over_D=rod8.min_distance(u) / D,
                    full_gradient=rod8.full_gradient(u, p))

    rows = [row(j, q.u, q.p, q.arclength, q.morse_index, q.eigenvalues) for j, q in enumerate(branch["points"])]
    if contact is not None:  # the located contact point ends the branch (arclength: nan, not on a step)
        J = rod8.problem.linearise(jnp.asarray(contact[:-1]), jnp.asarray(contact[-1]), rod8.problem.args)[1]
        lam, _, morse_c = rod8.problem.backend.spectrum(J, 4, 0, opts.eig_rtol)
        rows.append(row(len(rows), contact[:-1], float(contact[-1]), math.nan, morse_c, lam))
    return rows


def mirror_check(rod8, branch, energies):
    """r < 0 against r > 0 at the same phi: each r < 0 point's phi corrected onto the r > 0 branch
    (Newton on the hyperplane p = phi from the chord between the bracketing r > 0 points).
    -> (max |dE| (B/R), max |dWr|)."""
    points, opts = branch["points"], branch["opts"]
    sym = wr_sym = 0.0
    e_p = np.zeros(rod8.problem.n + 1)
    e_p[-1] = 1.0
    lin8 = lambda u, p: rod8.problem.linearise(u, p, rod8.problem.args)  # noqa: E731
    for q in branch["minus"][1:]:
        i = next((i for i in range(1, len(points)) if points[i].p <= q.p <= points[i - 1].p), None)
        if i is None:
            continue
        a, b = points[i - 1], points[i]
        c = correct(rod8.problem.backend, lin8, a.z + (q.p - a.p) / (b.p - a.p) * (b.z - a.z), e_p, opts.newton_tol,
                    opts.newton_max_iter)
        if c.converged:
            sym = max(sym, abs(energies(q.u, q.p) - energies(c.z[:-1], q.p)))
            wr_sym = max(wr_sym, abs(rod8.writhe(q.u) - rod8.writhe(c.z[:-1])))
    return sym, wr_sym


def slide_check(rod, rod8, points, eig_rtol):
    """The slide is a zero mode of the 7-pin Hessian along the buckled branch: (phi, smallest
    |lambda|, negative count with the band eig_rtol ||J||) at a few points."""
    slide = []
    for q in points[:: max(1, len(points) // 8)]:
        u7 = rod.restrict(np.asarray(rod8.embed(jnp.asarray(q.u))))
        lam = np.linalg.eigvalsh(np.asarray(rod.problem.linearise(jnp.asarray(u7), jnp.asarray(q.p),
                                                                  rod.problem.args)[1]))
        k = int(np.argmin(np.abs(lam)))
        slide.append((q.p, lam[k], int(np.sum(lam < -eig_rtol * np.max(np.abs(lam))))))
    return slide


def write_csv(rows):
    with open(os.path.join(OUT, "bifurcation_michell.csv"), "w", newline="") as f:
        f.write("# {commit}; {command}\n".format(**provenance()))  # read back with comment="#"
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.12g}" if isinstance(v, float) else v) for k, v in r.items()})


def main():
    os.makedirs(OUT, exist_ok=True)
    study = branch_point_study(N)
    others = [branch_point_study(n) for n in PRECISION_NS if n != N]
    precision = sorted(others + [study], key=lambda d: d["N"])
    scene, cp, rod, trivial, ev = (study[k] for k in ("scene", "cp", "rod", "trivial", "ev"))
    times = study["times"]
    D = float(scene.material.D)
    x0 = np.asarray(scene.positions(np.asarray(scene.q_init)))
    circle_dev = max(float(np.max(np.abs(np.asarray(scene.positions(rod.q(q.u))) - x0))) for q in trivial.points)
    twist_dev = max(float(np.max(np.abs(np.asarray(scene.vertex_twists(jnp.asarray(rod.q(q.u)), q.p)) - q.p / N)))
                    for q in trivial.points)
    triv_grad = max(rod.full_gradient(q.u, q.p) for q in trivial.points)

    # reduced equations at the double branch point (7 pins: the slide is free)
    em7, times["emanating_directions (7 pins)"] = timed(emanating_directions, rod.problem, ev)
    # the slide pinned: a simple branch point; switch and follow to contact
    branch, times["buckled branch (8 pins: slice, reduced equations, r > 0 to contact, r < 0)"] = timed(
        buckled_to_contact, rod, ev, D)
    rod8, ev8, direction, points, events = (branch[k] for k in ("rod8", "ev8", "direction", "points", "events"))
    print(f"8 pins: kappa = {direction.kappa:.6g}, order {direction.order}; buckled branch: {len(points)} points, "
          f"stop: {branch['stop']}, events {[(e.kind, e.p / PI) for e in events]}", flush=True)
    rows = branch_rows(scene, rod, trivial, branch)
    write_csv(rows)
    sym, wr_sym = mirror_check(rod8, branch, Energies(scene, rod, rod8, trivial))
    slide = slide_check(rod, rod8, points, study["tol7"]["eig_rtol"])
    extra_pin = int(sorted(set(rod8.pins.tolist()) - set(rod.pins.tolist()))[0])
    contact = branch["contact"]
    plot(rows, trivial, ev, contact, rod8, D)

    sweep = [contact_summary(SLENDERNESS[0], N, scene, rod, trivial, ev, study["tol7"], branch)]
    for s in SLENDERNESS[1:]:
        row, times[f"D/R = {s:g}: trivial branch and buckled branch to contact"] = timed(contact_at, s, N)
        sweep.append(row)
    convergence = [r for r in sweep if r["slenderness"] == CONVERGENCE_SLENDERNESS]
    for n in CONVERGENCE_NS:
        if n != N:
            row, times[f"N = {n}, D/R = {CONVERGENCE_SLENDERNESS:g}: to contact"] = timed(
                contact_at, CONVERGENCE_SLENDERNESS, n)
            convergence.append(row)
    convergence.sort(key=lambda r: r["N"])
    with open(os.path.join(OUT, "bifurcation_michell.json"), "w") as f:
        json.dump(dict(provenance=provenance(), N=N, nu=NU, phi_michell_over_pi=PHI_M / PI, contact_against_D=sweep,
                       contact_against_N=convergence, zero_thickness=zero_thickness_limit(sweep, convergence)),
                  f, indent=1, default=float)
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
    L.append(f"# Michell's ring through jaxrod.continuation.arclength, N = {N}\n")
    L.append(f"nu = {NU} (C = B/(1 + nu)), D/R = {D:g} (other D/R in the last sections), B = R = 1; Michell's continuum phi* = "
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
    norms = ", ".join(f"{d['tol7']['norm_J']:.1e} at N = {d['N']}" for d in v["precision"])
    L.append(f"- The floor: the eigenvalues carry roundoff ~eps ||J|| (||J||_2, the stretching stiffness: {norms}), while dlambda/dphi falls with N (eigenvalues ~ 1/N^2 in these units), so in float64 "
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
    stop = "self-contact (closest approach of non-adjacent segments = D)" if contact is not None else v["branch"]["stop"]
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
    L.append(f"- r < 0 (the same ring slid by a quarter turn, {len(v['branch']['minus'])} points): at the phi of each of its points, the r > 0 branch "
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
    contact_tables(L, v)
    zero_thickness_text(L, zero_thickness_limit(v["sweep"], v["convergence"]))
    L.append("## Timings (wall, one process, compilation included)\n")
    L.append("| step | s |\n|---|---|")
    for k, t in times.items():
        L.append(f"| {k} | {t:.1f} |")
    L.append("\n![branch](bifurcation_michell.png)\n")
    with open(os.path.join(OUT, "bifurcation_michell.md"), "w") as f:
        f.write("\n".join(L))
    print("\n".join(L))


def zero_thickness_limit(sweep, convergence):
    """First contact against its zero-thickness limit, the figure-eight elastica (``jr.figure_eight_energy``:
    phi -> 2 pi, Wr -> 1, Tw -> 0). phi, Wr and Tw: straight lines in D/R over the sweep at N, their
    intercepts with the residual's standard error. E: at CONVERGENCE_SLENDERNESS, E_inf + c/N^2 + d/N^4
    through the three finest N (its error: the change from the two finest with c/N^2 alone), moved to
    D = 0 by the sweep (E = E_0 + c D^2 at N). Empty where fewer than three points reached contact."""
    by_d = [r for r in sweep if "phi_over_pi" in r]
    by_n = sorted((r for r in convergence if "phi_over_pi" in r), key=lambda r: r["N"])[-3:]
    if len(by_d) < 3 or len(by_n) < 3:
        return {}
    d = np.array([r["slenderness"] for r in by_d])
    out = dict(limit=dict(phi_over_pi=2.0, Wr=1.0, Tw=0.0, energy=jr.figure_eight_energy()), intercepts={})
    for key, y in (("phi_over_pi", [r["phi_over_pi"] for r in by_d]), ("Wr", [r["Wr"] for r in by_d]),
                   ("Tw", [r["phi_over_pi"] / 2 - r["Wr"] for r in by_d])):
        A = np.stack([np.ones_like(d), d], axis=1)
        coef, *_ = np.linalg.lstsq(A, np.array(y), rcond=None)
        res = np.array(y) - A @ coef
        err = math.sqrt(float(res @ res) / (len(y) - 2) * np.linalg.inv(A.T @ A)[0, 0])
        out["intercepts"][key] = dict(value=float(coef[0]), error=err, slope=float(coef[1]))
    n = np.array([r["N"] for r in by_n], dtype=float)
    e_n = np.linalg.solve(np.stack([np.ones(3), n ** -2.0, n ** -4.0], axis=1), [r["energy"] for r in by_n])[0]
    e_two = (n[2] ** 2 * by_n[2]["energy"] - n[1] ** 2 * by_n[1]["energy"]) / (n[2] ** 2 - n[1] ** 2)
    c = np.linalg.lstsq(np.stack([np.ones_like(d), d ** 2], axis=1), [r["energy"] for r in by_d], rcond=None)[0]
    at_n = float(c[1] * CONVERGENCE_SLENDERNESS ** 2)  # E(D/R = 0.0025) - E(0) at N
    out["energy"] = dict(value=float(e_n - at_n), error=float(abs(e_n - e_two)), thickness_correction=-at_n,
                         N=[int(v) for v in n], slenderness=CONVERGENCE_SLENDERNESS)
    return out


def zero_thickness_text(L, z):
    if not z:
        return
    L.append("## First contact against the zero-thickness limit\n")
    L.append("As D -> 0 the touching ring tends to the figure-eight elastica: Wr -> 1 (half of a strand passage's 2), "
             "Tw -> 0 (a planar closed curve other than the circle is in equilibrium only untwisted), so "
             f"phi -> 2 pi, and E -> 32 K(m)^2 (m - 1/2) B/L = {z['limit']['energy']:.7f} B/R (2E(m) = K(m)).\n")
    L.append("| quantity | extrapolated | limit | (extrapolated - limit) / error |\n|---|---|---|---|")
    for key, label in (("phi_over_pi", "phi/pi at contact"), ("Wr", "Wr"), ("Tw", "Tw = phi/2pi - Wr")):
        i = z["intercepts"][key]
        L.append(f"| {label} (linear in D/R, slope {i['slope']:.4g}) | {i['value']:.7f} +- {i['error']:.1e} | "
                 f"{z['limit'][key]:g} | {(i['value'] - z['limit'][key]) / max(i['error'], 1e-300):+.1f} |")
    e = z["energy"]
    L.append(f"| E (B/R): N = {', '.join(map(str, e['N']))} to infinity at D/R = {e['slenderness']:g}, "
             f"then D -> 0 ({e['thickness_correction']:+.1e}) | {e['value']:.6f} +- {e['error']:.1e} | "
             f"{z['limit']['energy']:.6f} | {(e['value'] - z['limit']['energy']) / e['error']:+.1f} |\n")


def contact_tables(L, v):
    """The tolerances used, and first self-contact against D/R and against N."""
    sweep, convergence = v["sweep"], v["convergence"]
    L.append("## Tolerances (none set by hand)\n")
    L.append("newton_tol, event_tol and eig_rtol as ``jaxrod.continuation.arclength.scales`` sets them from the "
             "problem at the start of each run: floor = eps ||J||_2 max(|u|, 1), newton_tol = max(1e-12, 0.5 floor), "
             "event_tol = max(1e-10, 4 floor), eig_rtol = max(100 eps, 1e-10 min(1, 1/||J||_2)). Trivial branch (7 "
             "pins, at phi = 0) / buckled branch (8 pins, at the branch point).\n")
    L.append("| D/R | N | EA l^2/B | ||J||_2 | floor | newton_tol | event_tol | eig_rtol | branch point residual |\n"
             "|---|---|---|---|---|---|---|---|---|")
    for r in sorted(sweep + [c for c in convergence if c not in sweep], key=lambda r: (-r["slenderness"], r["N"])):
        t7, t8 = r["trivial_tolerances"], r["buckled_tolerances"]
        L.append(f"| {r['slenderness']:g} | {r['N']} | {r['stretch']:.3g} | {t7['norm_J']:.3g} / {t8['norm_J']:.3g} | "
                 f"{t7['floor']:.2e} / {t8['floor']:.2e} | {t7['newton_tol']:.2e} / {t8['newton_tol']:.2e} | "
                 f"{t7['event_tol']:.2e} / {t8['event_tol']:.2e} | {t7['eig_rtol']:.2e} / {t8['eig_rtol']:.2e} | "
                 f"{r['branch_point_residual']:.2e} |")
    L.append("")
    L.append(f"## First self-contact against D/R (N = {N})\n")
    L.append("The buckled branch (r > 0, slide pinned) followed from the double branch point until the closest "
             "approach of two non-adjacent segments equals D, that point located by Brent along the branch. "
             "E in B/R; E_circle: the planar circle at the same twist.\n")
    contact_table(L, sweep, "D/R")
    L.append(f"## First self-contact against N (D/R = {CONVERGENCE_SLENDERNESS:g})\n")
    contact_table(L, convergence, "N")
    reached = [r for r in convergence if "phi_over_pi" in r]
    if len(reached) > 1:
        phis = [r["phi_over_pi"] for r in reached]
        L.append(f"phi at contact spans {min(phis):.5f} .. {max(phis):.5f} pi over N = "
                 f"{', '.join(str(r['N']) for r in reached)}; at N = {reached[-1]['N']} it is {phis[-1]:.5f} pi.\n")


def contact_table(L, rows, key):
    L.append(f"| {key} | phi*/pi (branch point) | kappa | points | Morse | events | phi/pi at contact | Wr | E | "
             "E - E_circle | full gradient | s |\n|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        first = f"{r['slenderness']:g}" if key == "D/R" else str(r["N"])
        if "phi_over_pi" not in r:
            L.append(f"| {first} | {r['phi_star_over_pi']:.10f} | {r['kappa']:.4g} | {r['points']} | {r['morse']} | "
                     f"{r['events'] or 'none'} | not reached ({r['stop']}) | | | | | {r['seconds']:.0f} |")
            continue
        L.append(f"| {first} | {r['phi_star_over_pi']:.10f} | {r['kappa']:.4g} | {r['points']} | {r['morse']} | "
                 f"{r['events'] or 'none'} | {r['phi_over_pi']:.6f} | {r['Wr']:.5f} | {r['energy']:.6g} | "
                 f"{r['energy_minus_circle']:.6g} | {r['full_gradient']:.1e} | {r['seconds']:.0f} |")
    L.append("")


if __name__ == "__main__":
    main()
