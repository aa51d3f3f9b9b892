"""Plectoneme with self-contact at constant tension (issue 19, item 3 / acceptance 2).

A rod (B = 1, L = 1, nu = 0 so C = B, diameter D) clamped at s = 0, its far clamp pulled by a dead
load T along the axis and free to slide on it (``ForceLoadedRod(rod, "slide")``), soft self-contact
(``shortened_rod(..., contact_stiffness=1e4)``). The end rotation R is the continuation parameter.

* Straight branch: the straight state under T, twisted by R (stable up to the discrete buckling
  twist R_c from ``straight_buckling_moment``, Morse index 2 beyond it).
* Buckled branch, one pseudo-arclength continuation in (u, R) (secant predictor, bordered Newton
  corrector with the exact Hessian, the rigid rotation about the axis lifted out), started on the
  localized loop of NvdHT 2002 near the bifurcation (m = 0.9 * 2 sqrt t): the loop opens towards
  smaller R (subcritical), tightens until its strands touch, turns at a fold, and then, in contact,
  winds into a plectoneme that grows with R. The contact neighbourhood is rebuilt at every
  predictor and whenever a node has moved more than skin/2 during the corrector; after
  convergence it is rebuilt at the solution and the gradient checked there. A step is refused
  (halved) if the exact writhe jumps by more than 0.3 (a strand passage) or Lk != R / 2 pi.
  Each point: extension, M = dE/dR, T, Wr, Tw, Lk, contacting segment pairs, Morse index under the
  dead load (the axial rotation excluded).

Reference for the plateau: the two-phase model of a plectoneme with hard contact (superhelix
radius r = D/2 between strand axes and the plectoneme axis, helix angle a; straight tails under
T; the end loop neglected). Per unit rod length the plectoneme stores B sin^4 a / (2 r^2) of
bending and absorbs sin(2a) / (4 pi r) turns of writhe; coexistence with the straight phase at
torque M and tension T, minimised over a, gives
    M r / B = 2 sin^3 a cos a / cos 2a,    T r^2 / B = sin^4 a (1 + 2 cos^2 a) / (2 cos 2a),
(the form of Clauvelin, Audoly & Neukirch's superhelix equations without electrostatics; for
small a: M ~ 2 (2/3)^(3/4) B^(1/4) T^(3/4) r^(1/2)), and the hat curve's slope
d(extension)/d(turns) = -4 pi r / sin 2a.

Writes benchmarks/results/plectoneme.csv, plectoneme.json (the summary, with the commit and command)
and plectoneme.png; prints the summary numbers. Small mode (``--smoke``): T = 100, N = 40, a dozen points.
"""
import csv
import json
import math
import os
import sys
import time

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402

from jaxrod.studies import endloads as el  # noqa: E402
from jaxrod.model.contact import contact_count  # noqa: E402
from jaxrod.model.material import Material  # noqa: E402

from _bench import SMOKE, pick, provenance, provenance_line, results_dir, with_provenance  # noqa: E402,F401  (benchmarks/ is on the path)
HERE = os.path.dirname(os.path.abspath(__file__))
TWO_PI = 2.0 * math.pi


def two_phase_plateau(B, T, D):
    """(M_p, helix angle a, d extension / d turns) of the hard-contact two-phase plectoneme model."""
    p = el.plectoneme_plateau(B, T, D)
    return p.M, p.alpha, p.slope


class Continuation:
    """Pseudo-arclength continuation in the end rotation of a ``ForceLoadedRod`` at fixed T."""

    def __init__(self, fr, T, r_weight=1.0):
        self.fr, self.T = fr, float(T)
        self.rod = fr.rod
        self.D = float(self.rod.material.D)
        self.w = r_weight  # weight of R (rad) against the scaled DOFs in the arclength

    def nbr(self, u, phi):
        return self.fr.neighbourhood(u, phi)

    def grad(self, u, phi, nbr):
        return self.fr.value_and_grad(u, (phi, self.T, nbr))[1]

    def corrector(self, u, phi, tu, tphi, u_pred, phi_pred, gtol=1e-8, max_it=25, diverge=None):
        """Bordered Newton on [grad(u, phi) = 0, tangent . ((u, phi) - predictor) = 0]."""
        nbr = self.nbr(u, phi)
        x_built = self._x(u)
        for it in range(max_it):
            if np.max(np.linalg.norm(self._x(u) - x_built, axis=1)) > 0.25 * self.D:
                nbr, x_built = self.nbr(u, phi), self._x(u)
            g = self.grad(u, phi, nbr)
            if it == 0:
                g0 = max(float(np.max(np.abs(g))), 1e-6)
            elif diverge is not None and not np.max(np.abs(g)) < diverge * g0:
                return None  # diverging: no solution near the predictor
            arc = float(tu @ (u - u_pred) + self.w ** 2 * tphi * (phi - phi_pred))
            if np.max(np.abs(g)) < gtol and abs(arc) < 1e-9:
                # check against a neighbourhood built at the solution itself
                nbr = self.nbr(u, phi)
                g = self.grad(u, phi, nbr)
                if np.max(np.abs(g)) < gtol:
                    return u, phi, it
                x_built = self._x(u)
            h, z = self.fr.hessian(u, (phi, self.T, nbr))
            z = z[:, 0] / max(np.linalg.norm(z), 1e-300)
            h = h + (np.max(np.abs(np.diag(h))) + 1.0) * np.outer(z, z)
            eps = 1e-6
            gphi = (self.grad(u, phi + eps, nbr) - self.grad(u, phi - eps, nbr)) / (2 * eps)
            n = u.size
            A = np.zeros((n + 1, n + 1))
            A[:n, :n], A[:n, n] = h, gphi
            A[n, :n], A[n, n] = tu, self.w ** 2 * tphi
            d = np.linalg.solve(A, -np.concatenate([g, [arc]]))
            big = np.max(np.abs(d[:n]))
            d *= min(1.0, 0.5 / max(big, 1e-300))  # capped as el.newton: half an edge length
            u, phi = u + d[:n], phi + d[n]
        return None

    def descend(self, u, phi, gtol=1e-8, max_it=300):
        """A local minimum at fixed phi from u: Newton steps on the Hessian shifted positive
        definite (the zero mode lifted), capped (no node moves more than D/4), energy decrease
        enforced by halving; the neighbourhood rebuilt when a node has moved D/4 from its build."""
        nbr, x_built = self.nbr(u, phi), self._x(u)
        for _ in range(max_it):
            if np.max(np.linalg.norm(self._x(u) - x_built, axis=1)) > 0.25 * self.D:
                nbr, x_built = self.nbr(u, phi), self._x(u)
            val, g = self.fr.value_and_grad(u, (phi, self.T, nbr))
            h, z = self.fr.hessian(u, (phi, self.T, nbr))
            z = z[:, 0] / max(np.linalg.norm(z), 1e-300)
            h = h + (np.max(np.abs(np.diag(h))) + 1.0) * np.outer(z, z)
            lam = float(np.linalg.eigvalsh(h)[0])
            if np.max(np.abs(g)) < gtol and lam > 0:
                nbr = self.nbr(u, phi)
                if np.max(np.abs(self.grad(u, phi, nbr))) < gtol:
                    return u
                x_built = self._x(u)
                continue
            mu = 0.0 if lam > 1e-6 else 1.5 * abs(lam) + 1e-4
            d = -np.linalg.solve(h + mu * np.eye(h.shape[0]), g)
            n_x = 3 * (self.rod.n_nodes - 4)
            cap = 0.25 * self.D / float(self.rod.length_scale)
            d *= min(1.0, 0.5 / max(np.max(np.abs(d)), 1e-300), cap / max(np.max(np.abs(d[:n_x])), 1e-300))
            for _ in range(30):
                v2, _ = self.fr.value_and_grad(u + d, (phi, self.T, nbr))
                if v2 <= val + 1e-14 * abs(val):
                    break
                d *= 0.5
            u = u + d
        return None

    def lowest_mode(self, u, phi):
        nbr = self.nbr(u, phi)
        h, z = self.fr.hessian(u, (phi, self.T, nbr))
        z = z[:, 0] / max(np.linalg.norm(z), 1e-300)
        h = h + (np.max(np.abs(np.diag(h))) + 1.0) * np.outer(z, z)
        lam, vec = np.linalg.eigh(h)
        return lam[0], vec[:, 0]

    def _x(self, u):
        rod, ur, _ = self.fr._state(u)
        return np.asarray(rod.positions(rod.from_scaled(ur)))

    def point(self, u, phi):
        e = self.fr.equilibrium(u, self.T, phi)
        rod, ur, _ = self.fr._state(u)
        nbr = rod.neighbourhood(np.asarray(rod.from_scaled(ur)), phi)
        nc = int(contact_count(e.x, nbr.pairs, nbr.mask, False, self.D))
        # smallest distance between non-neighbouring nodes (|i - j| > the contact exclusion), / D
        x = e.x
        dd = np.linalg.norm(x[:, None, :] - x[None, :, :], axis=-1)
        gap = int(math.ceil(math.pi * self.D / 2 / float(self.rod.length_scale))) + 1
        ii, jj = np.triu_indices(len(x), k=gap + 1)
        dmin = float(np.min(dd[ii, jj])) / self.D
        return e, nc, dmin


def _accept(res, record, prev_wr, verbose, need_contact=False, max_jump=0.3):
    """The recorded row of a corrector's result, or None (popped) when there is none, the writhe
    jumped by more than 0.3 (strand passage), Lk != R / 2 pi, or contact was lost when needed."""
    if res is None:
        return None
    u, p, _ = res
    row = record("buckled", u, p)
    bad = abs(row["Wr"] - prev_wr) > max_jump or abs(row["Lk_minus_turns"]) > 1e-6
    if need_contact and row["contacts"] == 0:
        bad = True
    if row["min_gap_over_D"] < 0.5:  # strands half through each other: the soft contact gave way
        bad = True
    if bad:
        row["refused"] = True
        if verbose:
            print("  refused: writhe jump, Lk != R/2pi or contact lost", flush=True)
        return None
    return row


def run(T=400.0, D=0.015, N=160, nu=0.0, kappa_c=1e4, R_stop=None, max_points=400, time_budget=420.0,
        max_move=0.25, verbose=True):
    t0 = time.perf_counter()
    mat = Material.from_ratio(B=1.0, nu=nu, D=D)
    rod = el.shortened_rod(N, 1.0, mat, contact_stiffness=kappa_c)
    fr = el.ForceLoadedRod(rod, "slide")
    B, C = float(mat.B), float(mat.C)
    gamma = C / B
    t = T  # L = B = 1
    phi_c, M_c = el.straight_buckling_moment(rod, T)
    if R_stop is None:
        R_stop = 1.12 * phi_c
    cont = Continuation(fr, T, r_weight=1.0)
    rows = []

    def record(branch, u, phi):
        e, nc, dmin = cont.point(u, phi)
        row = dict(branch=branch, R=phi, turns=phi / TWO_PI, extension=e.extension, M=e.M, T=e.T, Wr=e.Wr,
                   Tw=e.Tw, Lk=e.Lk, Lk_minus_turns=e.Lk - phi / TWO_PI, contacts=nc, min_gap_over_D=dmin,
                   morse=e.morse, lowest_eig=float(e.eigenvalues[0]), grad_norm=e.grad_norm)
        rows.append(row)
        if verbose:
            print(f"{branch:9s} R={phi:8.4f} n={phi / TWO_PI:6.3f} ext={e.extension:+.5f} M={e.M:8.4f} "
                  f"Wr={e.Wr:+.4f} Tw={e.Tw:+.4f} dLk={row['Lk_minus_turns']:+.1e} contacts={nc:3d} "
                  f"gap/D={dmin:.3f} morse={e.morse} t={time.perf_counter() - t0:.0f}s", flush=True)
        return row

    # straight branch
    for phi in np.linspace(0.0, 1.4 * phi_c, 8):
        record("straight", fr.straight(T, phi), float(phi))
    # two points on the localized loop near the bifurcation: the secant's start
    pts = []
    for m in (0.9 * 2 * math.sqrt(t), 0.86 * 2 * math.sqrt(t)):
        ref = el.localized_helix(m, t, gamma)
        shaped = el.with_shortening(rod, ref.d)
        q0 = el.helical_start(shaped, m, t, ref.R)
        f = fr.solve(T, ref.R, fr.u_from(q0, -ref.d * np.asarray(rod.axis)))
        pts.append((f.u, f.phi))
        record("buckled", f.u, f.phi)
    (u0, p0), (u1, p1) = pts
    ds = math.sqrt(np.sum((u1 - u0) ** 2) + (p1 - p0) ** 2)
    ds_max, ds_min = 4.0 * ds, 1e-3 * ds
    prev_wr = rows[-1]["Wr"]
    # phase 1: pseudo-arclength along the loop branch until the strands touch
    in_contact = False
    while len(rows) < max_points and time.perf_counter() - t0 < time_budget and not in_contact:
        du, dp = u1 - u0, p1 - p0
        nrm = math.sqrt(np.sum(du ** 2) + dp ** 2)
        tu, tp = du / nrm, dp / nrm
        # no node moves by more than max_move * D in one predictor step (soft contact: no strand
        # passage, and the neighbourhood's skin D/2 is not outrun)
        n_x = 3 * (N - 4)
        ds = min(ds, max_move * D / float(rod.length_scale) / max(float(np.max(np.abs(tu[:n_x]))), 1e-12))
        u_pred, p_pred = u1 + ds * tu, p1 + ds * tp
        res = cont.corrector(u_pred.copy(), p_pred, tu, tp, u_pred, p_pred)
        row = _accept(res, record, prev_wr, verbose)
        if row is None:
            ds *= 0.5
            if ds < ds_min:
                print("step too small: stop", flush=True)
                break
            continue
        u2, p2, its = res
        prev_wr = row["Wr"]
        u0, p0, u1, p1 = u1, p1, u2, p2
        in_contact = row["contacts"] > 0
        if its <= 4:
            ds = min(1.5 * ds, ds_max)
    # phase 2: in contact, natural continuation in R upwards (the contact branch turns at the
    # touching point, a near-corner that a secant cannot follow): secant predictor in R, a state
    # that has lost contact (jumped back to the loop branch) is refused like a writhe jump
    dR, dR_max, dR_min = 0.05, 0.5, 5e-3
    if in_contact:
        # the first touching state is at the corner where the loop branch (a saddle) and the
        # contact branch (stable) meet; step past it on the loop branch and leave the saddle
        # along its unstable mode, descending to the stable state in contact
        p_s = p1 + 0.3
        res = cont.corrector(u1.copy(), p_s, np.zeros_like(u1), 1.0, u1, p_s)
        found = None
        if res is not None:
            lam, v = cont.lowest_mode(res[0], p_s)
            for sign in (1.0, -1.0):
                n_x = 3 * (N - 4)
                kick = sign * v * (0.2 * D / float(rod.length_scale)) / max(np.max(np.abs(v[:n_x])), 1e-300)
                ud = cont.descend(res[0] + kick, p_s)
                if ud is None:
                    continue
                row = _accept((ud, p_s, 0), record, prev_wr, verbose, need_contact=True)
                if row is not None:
                    found = ud
                    prev_wr = row["Wr"]
                    break
        if found is None:
            print("no stable contact state found past the loop", flush=True)
            in_contact = False
        else:
            u1, p1 = found, p_s
    up, pp = u1, p1
    while in_contact and len(rows) < max_points and time.perf_counter() - t0 < time_budget and p1 < R_stop:
        slope = (u1 - up) / (p1 - pp) if p1 > pp else np.zeros_like(u1)
        n_x = 3 * (N - 4)
        mv = float(np.max(np.abs(slope[:n_x]))) * float(rod.length_scale)
        if mv > 0:
            dR = min(dR, max_move * D / mv)
        u_pred, p_pred = u1 + dR * slope, p1 + dR
        res = cont.corrector(u_pred.copy(), p_pred, np.zeros_like(u1), 1.0, u_pred, p_pred, max_it=15, diverge=1e3)
        row = _accept(res, record, prev_wr, verbose, need_contact=True)
        if row is None:
            dR *= 0.5
            if dR < dR_min:
                # a fold of the contact branch: the state snaps; descend at R a little further
                # from the last state (nudged along its lowest mode) to the next stable state
                p_s = p1 + 0.1
                lam, v = cont.lowest_mode(u1, p1)
                n_x = 3 * (N - 4)
                found = None
                for sign in (1.0, -1.0):
                    kick = sign * v * (0.1 * D / float(rod.length_scale)) / max(np.max(np.abs(v[:n_x])), 1e-300)
                    ud = cont.descend(u1 + kick, p_s)
                    if ud is None:
                        continue
                    # a snap may change the writhe a lot, but not through a strand passage: Lk checked
                    row = _accept((ud, p_s, 0), record, prev_wr, verbose, need_contact=True, max_jump=1.5)
                    if row is not None:
                        found = ud
                        break
                if found is None:
                    print("R step too small and no snap found: stop", flush=True)
                    break
                print(f"  snap at R = {p1:.4f}: Wr {prev_wr:+.4f} -> {row['Wr']:+.4f}", flush=True)
                row["snap"] = True
                prev_wr = row["Wr"]
                up, pp, u1, p1 = found, p_s, found, p_s
                dR = 0.05
            continue
        u2, p2, its = res
        prev_wr = row["Wr"]
        up, pp, u1, p1 = u1, p1, u2, p2
        if its <= 4:
            dR = min(1.5 * dR, dR_max)
    rows = [r for r in rows if not r.get("refused")]
    return dict(T=T, D=D, N=N, nu=nu, kappa_c=kappa_c, phi_c=phi_c, M_c=M_c, rows=rows, seconds=time.perf_counter() - t0,
                last_u=u1, last_phi=p1)


def summarise(res):
    T, D = res["T"], res["D"]
    B = 1.0
    rows = [r for r in res["rows"] if r["branch"] == "buckled"]
    Mp_th, a_th, slope_th = two_phase_plateau(B, T, D)
    # the plectoneme: in contact, R increasing; the plateau: the points past the contact fold with R >= R_c
    plect = [r for r in rows if r["contacts"] > 0]
    fold = None
    for i in range(1, len(rows) - 1):
        if rows[i]["R"] < rows[i - 1]["R"] and rows[i]["R"] <= rows[i + 1]["R"]:
            fold = rows[i]
    # the plateau: the plectoneme proper, past the snap of the clasped loop into a two-strand
    # superhelix (contact, writhe beyond 2 turns)
    tail = [r for r in plect if r["Wr"] > 2.0]
    out = dict(T=T, D=D, N=res["N"], sqrtBT=math.sqrt(B * T), L_sqrt_T_over_B=math.sqrt(T),
               R_c=res["phi_c"], turns_c=res["phi_c"] / TWO_PI, M_c=res["M_c"],
               M_c_over_2sqrtBT=res["M_c"] / (2 * math.sqrt(B * T)),
               M_c_continuum_over_2sqrtBT=el.clamped_tension_twist_threshold(B, T, 1.0) / (2 * math.sqrt(B * T)),
               two_phase_M_p=Mp_th, two_phase_M_p_over_sqrtBT=Mp_th / math.sqrt(B * T),
               two_phase_helix_angle_deg=math.degrees(a_th), two_phase_slope=slope_th,
               fold_R=None if fold is None else fold["R"], fold_M=None if fold is None else fold["M"],
               max_abs_Lk_error=max(abs(r["Lk_minus_turns"]) for r in res["rows"]), seconds=res["seconds"])
    if len(tail) >= 3:
        n = np.array([r["turns"] for r in tail])
        ext = np.array([r["extension"] for r in tail])
        M = np.array([r["M"] for r in tail])
        out.update(plateau_turns=[float(n.min()), float(n.max())], plateau_M_mean=float(M.mean()),
                   plateau_M_min=float(M.min()), plateau_M_max=float(M.max()),
                   plateau_M_over_sqrtBT=float(M.mean()) / math.sqrt(B * T),
                   plateau_M_over_Mc=float(M.mean()) / res["M_c"],
                   slope_ext_per_turn=float(np.polyfit(n, ext, 1)[0]),
                   plateau_morse=sorted({r["morse"] for r in tail}),
                   plateau_contacts=[min(r["contacts"] for r in tail), max(r["contacts"] for r in tail)],
                   plateau_min_gap_over_D=float(min(r["min_gap_over_D"] for r in tail)))
    return out


def write_csv(rows, path):
    keys = ["branch", "R", "turns", "extension", "M", "T", "Wr", "Tw", "Lk", "Lk_minus_turns", "contacts",
            "min_gap_over_D", "morse", "lowest_eig", "grad_norm", "snap"]
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: int(bool(r.get(k))) if k == "snap" else r[k] for k in keys})


def figure(res, summ, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4.6))
    rows = res["rows"]
    for k, (key, label) in enumerate((("extension", "end extension / L"), ("M", "torque M L / B"))):
        a = ax[k]
        for br, col in (("straight", "C0"), ("buckled", "C1")):
            rr = [r for r in rows if r["branch"] == br]
            n = np.array([r["turns"] for r in rr])
            y = np.array([r[key] for r in rr])
            st = np.array([r["morse"] == 0 for r in rr])
            # runs of equal stability, in continuation order, broken at snaps (dotted: the jump)
            start = 0
            for i in range(1, len(rr) + 1):
                if i == len(rr) or st[i] != st[i - 1] or rr[i].get("snap"):
                    seg = slice(start, i + 1 if (i < len(rr) and not rr[i].get("snap")) else i)
                    a.plot(n[seg], y[seg], "-" if st[start] else "--", color=col, lw=1.6)
                    if i < len(rr) and rr[i].get("snap"):
                        a.plot(n[i - 1:i + 1], y[i - 1:i + 1], ":", color="gray", lw=1.0)
                    start = i
            c = np.array([r["contacts"] > 0 for r in rr])
            if np.any(c):
                a.plot(n[c], y[c], "o", ms=3, mfc="none", color="k")
        a.plot([], [], "-", color="C0", label="straight (solid: stable, dashed: unstable)")
        a.plot([], [], "-", color="C1", label="loop / plectoneme (solid: Morse 0, dashed: Morse >= 1)")
        a.plot([], [], "o", ms=3, mfc="none", color="k", label="self-contact")
        a.plot([], [], ":", color="gray", label="snap (fold of the contact branch)")
        if key == "M":
            a.axhline(2 * summ["sqrtBT"], color="gray", ls=":", label="2 sqrt(BT)")
            a.axhline(summ["two_phase_M_p"], color="C2", ls="-.", label="two-phase model, hard contact r = D/2")
            if "plateau_M_mean" in summ:
                a.axhline(summ["plateau_M_mean"], color="C3", ls=":", label=f"plateau {summ['plateau_M_mean']:.2f}")
        a.axvline(summ["turns_c"], color="gray", lw=0.5)
        a.set_xlabel("end rotation (turns) = Lk")
        a.set_ylabel(label)
        a.legend(fontsize=7)
    fig.suptitle(f"Plectoneme at constant tension: T L^2/B = {res['T']:g}, D/L = {res['D']:g}, N = {res['N']}, "
                 f"nu = {res['nu']:g}, sliding end, soft contact kappa_c = {res['kappa_c']:g}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def replot():
    """Redraw plectoneme.png from plectoneme.csv and plectoneme.json (no solving). Snaps missing
    from an older CSV are inferred: a writhe step above 0.01 between two touching states."""
    with open(os.path.join(results_dir(), "plectoneme.json")) as fh:
        summ = json.load(fh)
    rows = []
    with open(os.path.join(results_dir(), "plectoneme.csv")) as fh:
        for r in csv.DictReader(fh):
            row = {k: (v if k == "branch" else float(v)) for k, v in r.items() if v != ""}
            row["morse"], row["contacts"] = int(row["morse"]), int(row["contacts"])
            rows.append(row)
    for a, b in zip(rows[:-1], rows[1:]):
        if "snap" not in b and b["branch"] == a["branch"] == "buckled" and a["contacts"] > 0 and b["contacts"] > 0:
            b["snap"] = abs(b["Wr"] - a["Wr"]) > 0.01 and abs(b["R"] - a["R"]) < 0.2
    res = dict(rows=rows, T=summ["T"], D=summ["D"], N=summ["N"], nu=0.0, kappa_c=1e4)
    figure(res, summ, os.path.join(results_dir(), "plectoneme.png"))


def main():
    if "--replot" in sys.argv:
        return replot()
    quick = "--quick" in sys.argv
    D = float(sys.argv[sys.argv.index("--D") + 1]) if "--D" in sys.argv else 0.015
    # small mode: a coarse rod and the first points of the loop branch (the straight branch, the
    # secant's start, a few pseudo-arclength steps), no contact reached
    res = run(T=pick(400.0, 100.0), D=D, N=pick(160, 40), max_points=pick(60 if quick else 600, 12), time_budget=pick(120 if quick else 540, 60))
    summ = summarise(res)
    summ["provenance"] = provenance()
    print(json.dumps(summ, indent=1, default=float))
    tag = "" if "--D" not in sys.argv else f"_D{D:g}"  # another diameter: its own files
    write_csv(res["rows"], os.path.join(results_dir(), f"plectoneme{tag}.csv"))
    figure(res, summ, os.path.join(results_dir(), f"plectoneme{tag}.png"))
    with open(os.path.join(results_dir(), f"plectoneme{tag}.json"), "w") as fh:
        json.dump(with_provenance(summ), fh, indent=1, default=float)

if __name__ == "__main__":
    main()
