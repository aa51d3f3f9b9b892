"""Peer benchmark: PyElastica's localized helical buckling against jaxrod's static solve.

PyElastica (``pip install pyelastica``; a benchmark-only environment, never a jaxrod dependency)
reaches the localized helical state of a clamped, twisted rod with end shortening by explicit,
damped Cosserat dynamics. This script drives its public API with the physical set-up of its
``examples/HelicalBucklingCase`` (read, not copied): L = 100, B = 1.345, C = 0.789, shear and
stretch stiffness 1e5, mass 1 per unit length, slack 3 (d = 0.03), 27 turns (R = 54 pi) applied
over t = 500 by ``HelicalBucklingBC``, then held; linear damping 0.01; position Verlet with
dt = 1e-3 L/n. The example runs to t = 10500 (10.5 million steps at n = 100).

The analytic reference (Neukirch, van der Heijden & Thompson 2002, eqs. 14-15; PyElastica's
post-processing does the same): (m, t) solved from the *imposed* (d, R, gamma),

    R = m/gamma + 4 arccos(m / (2 sqrt t)),   d = sqrt((16/t)(1 - m^2/(4t))),

and the tangent's angle theta to the clamp axis along the rod, s from the loop centre,

    1 - cos theta(s) = (2 lambda^2 / t) sech^2(lambda s / L),   lambda = sqrt(t - m^2/4).

Envelope error (the number charted): with sigma = s/L in [0, 1] (arc length along the deformed
rod from the first clamp, sampled at the edge midpoints) and theta_h the angle of each edge's
tangent to the clamp axis,

    E_L1 = int_0^1 | theta_h(sigma) - theta_an(sigma - sigma_c) | d sigma     (radians)

by the trapezoid rule on the edge samples, where sigma_c is the loop centre of the computed shape
(the centroid of 1 - cos theta_h). E_L1 = 0.0012 rad is the error of a shape whose angle is
1 % off the analytic one everywhere (int theta_an d sigma = 0.118 rad for this case).

PyElastica runs: several resolutions n, each recording E_L1 at checkpoints of simulated time, so
one run gives error against wall time as the damped dynamics settle (the example's t = 10500 is
far past settling: 2000 is the default here). The time step is the example's; it is at the
stability limit (n = 50 diverges after the twist at dt = 2e-3 and also at 1e-3), so larger steps
are not an option and smaller ones only cost. jaxrod: the static solve of the same (d, R, gamma)
case (``jaxrod_worker``), each N in a fresh process, cold (first solve in the process: JIT
compilation included) and warm (the same solve again in the same process). ``--path-only N``
times jaxrod without the analytic start instead (``jaxrod_path_worker``: from the straight rod
along a load path, as PyElastica's boundary condition does in time).

Run:  python3 -m venv benchmarks/.venv-peer && benchmarks/.venv-peer/bin/pip install pyelastica
      benchmarks/.venv-peer/bin/pip install -e .
      OPENBLAS_NUM_THREADS=1 benchmarks/.venv-peer/bin/python benchmarks/peer_pyelastica.py
      (about 20 min on 2 idle cores); then, optionally, ... --path-only 342 and ... --rederive
Writes benchmarks/results/peer_pyelastica.{csv,png,json} (peer_pyelastica_path.json).
"""
from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse
import csv
import json
import math
import sys
import time
from pathlib import Path

import numpy as np
from scipy.optimize import brentq, fsolve

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results"

# The case (PyElastica's example).
L = 100.0
B = 1.345
C = 0.789
GAMMA = C / B
SLACK = 3.0
D_SHORT = SLACK / L
TURNS = 27
R_ROT = TURNS * 2.0 * math.pi
STIFF = 1e5  # PyElastica's shear and stretch stiffness (diagonal of shear_matrix)
TWIST_TIME = 500.0
DAMPING = 0.01
DT_FACTOR = 1e-3  # dt = DT_FACTOR * L / n, as in the example


# ---------------------------------------------------------------------------- analytic solution
def solve_mt(d, R, gamma):
    """(m, t) of the localized helical solution for end shortening d and end rotation R."""

    def res(v):
        m, t = v
        return [m / gamma + 4.0 * math.acos(min(1.0, m / (2.0 * math.sqrt(t)))) - R,
                math.sqrt(max(0.0, 16.0 / t * (1.0 - m * m / (4.0 * t)))) - d]

    # Eliminate t with the d-equation, (d^2/16) t^2 - t + m^2/4 = 0. Its smaller root is the
    # branch PyElastica's post-processing uses (m = 98.54, t = 2901 for its example); the larger
    # root gives a second, tighter loop (m = 96.78, t = 15003 there), which the dynamics do not
    # reach (the measured m, t below say which one a run found).
    a = d * d / 16.0

    def t_of_m(m):
        return (1.0 - math.sqrt(max(0.0, 1.0 - a * m * m))) / (2.0 * a)

    def f(m):
        t = t_of_m(m)
        return m / gamma + 4.0 * math.acos(min(1.0, m / (2.0 * math.sqrt(t)))) - R

    m = brentq(f, 1.0, (4.0 / d) * (1.0 - 1e-12), xtol=1e-14, rtol=1e-15)
    m, t = fsolve(res, [m, t_of_m(m)], xtol=1e-15)
    return float(m), float(t)


def theta_analytic(sigma, m, t):
    """Angle of the tangent to the axis at sigma = s/L from the loop centre."""
    lam = math.sqrt(t - m * m / 4.0)
    one_minus_cos = 2.0 * lam * lam / t / np.cosh(lam * np.asarray(sigma)) ** 2
    return np.arccos(np.clip(1.0 - one_minus_cos, -1.0, 1.0))


def theta_max_analytic(m, t):
    return math.acos(m * m / (2.0 * t) - 1.0)


def tangent_angles(x, axis):
    """Edge-midpoint arc length sigma (from the first edge midpoint, over the rest length L) and
    the angle of each edge to ``axis`` (atan2 form: accurate for small angles)."""
    e = np.diff(x, axis=0)
    le = np.linalg.norm(e, axis=1)
    tt = e / le[:, None]
    c = tt @ axis
    s = np.linalg.norm(np.cross(tt, axis[None, :]), axis=1)
    theta = np.arctan2(s, c)
    smid = np.concatenate([[0.0], np.cumsum(0.5 * (le[1:] + le[:-1]))])
    return smid, theta


def envelope_error(x, axis, m, t, length=L):
    """E_L1 (centre-aligned), E_L1 with the centre at the midpoint, theta_max error, sigma_c."""
    s, th = tangent_angles(np.asarray(x, dtype=float), np.asarray(axis, dtype=float))
    sigma = s / length
    w = 1.0 - np.cos(th)
    sigma_c = float(np.sum(sigma * w) / np.sum(w)) if np.sum(w) > 0 else 0.5
    err = float(np.trapezoid(np.abs(th - theta_analytic(sigma - sigma_c, m, t)), sigma))
    err_mid = float(np.trapezoid(np.abs(th - theta_analytic(sigma - 0.5, m, t)), sigma))
    return {"err_l1": err, "err_l1_mid": err_mid,
            "theta_max": float(th.max()), "theta_max_err": float(th.max() - theta_max_analytic(m, t)),
            "sigma_c": sigma_c}


# ---------------------------------------------------------------------------- PyElastica
def pyelastica_run(n, final_time, checkpoint, dt_factor=DT_FACTOR, m_t=None, log=print):
    """One PyElastica run of the example's set-up at n elements. Returns one record per
    checkpoint of simulated time (every ``checkpoint`` after the twist is in): simulated time,
    steps, wall seconds so far (set-up and numba dispatch included, the checkpoint's own
    post-processing excluded), envelope error and the measured m, t."""
    import elastica as ea

    class Sim(ea.BaseSystemCollection, ea.Constraints, ea.Damping, ea.Forcing):
        pass

    m_an, t_an = m_t
    w0, c0 = time.perf_counter(), time.process_time()
    sim = Sim()
    radius = 0.35
    area = math.pi * radius**2
    density = 1.0 / area  # mass 1 per unit length
    rod = ea.CosseratRod.straight_rod(
        n, np.zeros(3), np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), L, radius, density,
        youngs_modulus=1e6, shear_modulus=STIFF)
    rod.shear_matrix[:] = STIFF * np.eye(3)[:, :, None]
    rod.bend_matrix[:] = np.diag([B, B, C])[:, :, None]
    sim.append(rod)
    dt = dt_factor * L / n
    sim.dampen(rod).using(ea.AnalyticalLinearDamper, damping_constant=DAMPING, time_step=dt)
    sim.constrain(rod).using(ea.HelicalBucklingBC, constrained_position_idx=(0, -1),
                             constrained_director_idx=(0, -1), twisting_time=TWIST_TIME,
                             slack=SLACK, number_of_rotations=TURNS)
    sim.finalize()
    rod.velocity_collection[..., n // 2] += np.array([0.0, 1e-6, 0.0])  # the example's kick
    stepper = ea.PositionVerlet()
    axis = np.array([0.0, 0.0, 1.0])
    setup = time.perf_counter() - w0
    setup_cpu = time.process_time() - c0

    records = []
    sim_time = np.float64(0.0)
    steps = 0
    wall, cpu = setup, setup_cpu
    targets = list(np.arange(TWIST_TIME + checkpoint, final_time + 0.5 * checkpoint, checkpoint))
    for target in targets:
        k = int(round(target / dt)) - steps
        w0, c0 = time.perf_counter(), time.process_time()
        for _ in range(k):
            sim_time = stepper.step(sim, sim_time, dt)
        wall += time.perf_counter() - w0
        cpu += time.process_time() - c0
        steps += k
        x = rod.position_collection.T.copy()
        if not np.all(np.isfinite(x)):
            log(f"  pyelastica n={n}: not finite at t={sim_time:.0f}")
            break
        rec = envelope_error(x, axis, m_an, t_an)
        Q = rod.director_collection  # (3, 3, n): rows are d1, d2, d3
        force = np.einsum("jik,jk->ik", Q, rod.internal_stress)  # lab frame, per element
        T = float(np.mean(force[2]))
        # M: the twisting moment C kappa_3 where the rod is straight (|s - s_c| > 0.35 L);
        # there the moment about the axis is all twist.
        sv = (np.arange(n - 1) + 1.0) / n
        far = np.abs(sv - rec["sigma_c"]) > 0.35
        M = float(np.mean(np.abs(rod.internal_couple[2, far]))) if np.any(far) else float("nan")
        rec.update(code="pyelastica", n=n, dt=float(dt), steps=steps, sim_time=float(sim_time),
                   wall_s=wall, cpu_s=cpu, setup_s=setup, m=M * L / B, t=T * L * L / B)
        records.append(rec)
        log(f"  pyelastica n={n:4d} t={sim_time:7.0f} steps={steps:9d} wall={wall:7.1f}s "
            f"E_L1={rec['err_l1']:.3e} theta_max={rec['theta_max']:.4f} m={rec['m']:.3f} t={rec['t']:.1f}")
    return records


# ---------------------------------------------------------------------------- jaxrod
def jaxrod_worker(N):
    """jaxrod's static solve of the case at N nodes, in a fresh process (so that 'cold' really
    includes JAX's start and every JIT compilation): returns a dict. The solve: the rod clamped
    at both ends with the far clamp SLACK closer (``jaxrod.studies.endloads.shortened_rod``), started on
    the analytic localized helix of the imposed (d, R, gamma) (``helical_start``) and solved by
    ``jaxrod.studies.endloads.solve`` (Newton with the exact Hessian, then the stability of the
    equilibrium: its lowest eigenvalues), the end loads T, M by autodiff (``end_loads``).
    cold = scene build + start + solve + end loads, first time in the process (JIT compile
    included; JAX and jaxrod already imported, their import time reported apart); warm = the
    same again in the same process (compiled code reused). A refusal (too few nodes for the loop)
    or any failure is reported by ``run_jaxrod`` and the point left out."""
    w0 = time.perf_counter()
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from jaxrod import Material
    from jaxrod.studies import endloads as el

    import_s = time.perf_counter() - w0
    m_an, t_an = solve_mt(D_SHORT, R_ROT, GAMMA)
    mat = Material(B=B, C=C, EA=STIFF)
    out = {"N": N, "import_s": import_s, "jaxrod_file": el.__file__}
    for label in ("cold", "warm"):
        w0, c0 = time.perf_counter(), time.process_time()
        scene = el.shortened_rod(N, L, mat, shortening=SLACK)
        q0 = el.helical_start(scene, m_an, t_an, R_ROT)
        eq = el.solve(scene, R_ROT, q0, throw=False)
        loads = el.end_loads(scene, eq.q, R_ROT)
        out[f"{label}_s"] = time.perf_counter() - w0
        out[f"{label}_cpu_s"] = time.process_time() - c0
    x = np.asarray(scene.nodes(jnp.asarray(eq.q)))
    out.update(envelope_error(x, np.array([0.0, 0.0, 1.0]), m_an, t_an))
    out.update(iterations=int(eq.solution.iterations), grad_norm=float(eq.solution.grad_norm),
               converged=bool(eq.solution.converged),
               stable=bool(eq.stable), Lk=float(eq.Lk), Wr=float(eq.Wr),
               m=loads.M * L / B, t=loads.T * L * L / B)
    return out


def _path_energy(u, args):
    scene, phi, shortening = args
    from jaxrod.studies import endloads as el

    return el.with_shortening(scene, shortening).scaled_energy(u, phi)


def _path_hessian(u, args):
    scene, phi, shortening = args
    from jaxrod.studies import endloads as el
    from jaxrod.model.hessian import scaled_hessian

    return scaled_hessian(el.with_shortening(scene, shortening), u, phi, None)


def jaxrod_path_worker(N, K):
    """jaxrod without the analytic start: from the straight, unshortened rod (a 1e-3 edge lateral
    kick), the shortening and the end rotation ramped together to (SLACK, R) in K equal load steps,
    like PyElastica's HelicalBucklingBC does in time; each step a minimiser (``DampedNewton``, exact
    structured Hessian) from the previous state; the last state then goes through
    ``endloads.solve`` (Newton, stability). One process, JIT compile included (cold only)."""
    w0, c0 = time.perf_counter(), time.process_time()
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from jaxrod import Material
    from jaxrod.studies import endloads as el
    from jaxrod.solve.solvers import DampedNewton, minimise

    m_an, t_an = solve_mt(D_SHORT, R_ROT, GAMMA)
    scene = el.shortened_rod(N, L, Material(B=B, C=C, EA=STIFF), shortening=0.0)
    u = np.asarray(scene.to_scaled(np.asarray(scene.q_init))).copy()
    n_free = N - 4
    u[0:3 * n_free:3] += 1e-3 * np.sin(np.pi * np.arange(1, n_free + 1) / (n_free + 1))
    iterations, unconverged = 0, 0
    for k in range(1, K + 1):
        f = k / K
        sol = minimise(_path_energy, u, (scene, jnp.asarray(f * R_ROT), jnp.asarray(f * SLACK)),
                       DampedNewton(hessian=_path_hessian), gtol=1e-8, max_steps=500, throw=False)
        u = sol.y
        iterations += sol.iterations
        unconverged += int(not sol.converged)
    final = el.shortened_rod(N, L, Material(B=B, C=C, EA=STIFF), shortening=SLACK)
    eq = el.solve(final, R_ROT, scene.from_scaled(u), throw=False)
    loads = el.end_loads(final, eq.q, R_ROT)
    out = {"N": N, "load_steps": K, "wall_s": time.perf_counter() - w0, "cpu_s": time.process_time() - c0,
           "damped_newton_iterations": iterations, "steps_not_converged_in_500": unconverged,
           "newton_iterations": int(eq.solution.iterations), "converged": bool(eq.solution.converged),
           "stable": bool(eq.stable), "Lk": float(eq.Lk), "Wr": float(eq.Wr),
           "m": loads.M * L / B, "t": loads.T * L * L / B, "jaxrod_file": el.__file__, "git": _git_state()}
    out.update(envelope_error(np.asarray(final.nodes(jnp.asarray(eq.q))), np.array([0.0, 0.0, 1.0]), m_an, t_an))
    return out


def run_jaxrod(N, log=print):
    cmd = [sys.executable, str(Path(__file__).resolve()), "--jaxrod-worker", str(N)]
    import subprocess

    p = subprocess.run(cmd, capture_output=True, text=True, check=False)
    line = [ln for ln in p.stdout.splitlines() if ln.startswith("{")]
    if p.returncode != 0 or not line:
        err = [ln for ln in p.stderr.splitlines() if ln.strip()]
        log(f"  jaxrod N={N:4d} failed: {err[-1] if err else p.returncode}")
        return None
    r = json.loads(line[-1])
    log(f"  jaxrod N={N:4d} cold={r['cold_s']:.2f}s warm={r['warm_s']:.3f}s (import {r['import_s']:.1f}s) "
        f"newton={r['iterations']} E_L1={r['err_l1']:.3e} theta_max={r['theta_max']:.4f} m={r['m']:.3f} "
        f"t={r['t']:.1f} stable={r['stable']} Lk={r['Lk']:.6f} converged={r['converged']}")
    return r


# ---------------------------------------------------------------------------- comparison
def time_to_error(records, target):
    """The first checkpoint from which the run's error stays <= target (None if never)."""
    errs = np.array([r["err_l1"] for r in records])
    ok = errs <= target
    if not ok[-1]:
        return None
    i = len(ok) - 1
    while i > 0 and ok[i - 1]:
        i -= 1
    return records[i]


def compare(pe_runs, jx):
    """For each jaxrod point: PyElastica's cheapest wall time to an error <= jaxrod's (over all
    runs and checkpoints), and the ratios (PyElastica / jaxrod, wall and CPU seconds). If no run
    gets there, compare at PyElastica's best settled error (the smallest final error of a run,
    with 2 % slack on its plateau) against the cheapest jaxrod point at or below it."""
    rows = []
    for j in jx:
        hits = [h for h in (time_to_error(recs, j["err_l1"]) for recs in pe_runs if recs) if h]
        best = min(hits, key=lambda h: h["wall_s"]) if hits else None
        row = {"N": j["N"], "err_l1": j["err_l1"], "jaxrod_cold_s": j["cold_s"], "jaxrod_warm_s": j["warm_s"],
               "jaxrod_cold_cpu_s": j["cold_cpu_s"], "jaxrod_warm_cpu_s": j["warm_cpu_s"]}
        if best is not None:
            row.update(pyelastica_s=best["wall_s"], pyelastica_cpu_s=best["cpu_s"], pyelastica_n=best["n"],
                       pyelastica_sim_time=best["sim_time"], pyelastica_err=best["err_l1"],
                       ratio_cold=best["wall_s"] / j["cold_s"], ratio_warm=best["wall_s"] / j["warm_s"],
                       ratio_cold_cpu=best["cpu_s"] / j["cold_cpu_s"], ratio_warm_cpu=best["cpu_s"] / j["warm_cpu_s"])
        rows.append(row)
    finals = [(recs[-1]["err_l1"], recs) for recs in pe_runs if recs]
    e_best, recs = min(finals, key=lambda v: v[0])
    target = 1.02 * e_best
    rec = time_to_error(recs, target)
    cands = [j for j in jx if j["err_l1"] <= target]
    at_best = {"pyelastica_best_err": e_best, "target_err": target, "pyelastica_n": rec["n"],
               "pyelastica_s": rec["wall_s"], "pyelastica_cpu_s": rec["cpu_s"], "pyelastica_sim_time": rec["sim_time"],
               "pyelastica_steps": rec["steps"]}
    if cands:
        j = min(cands, key=lambda v: v["warm_s"])
        at_best.update(jaxrod_N=j["N"], jaxrod_err=j["err_l1"], jaxrod_cold_s=j["cold_s"], jaxrod_warm_s=j["warm_s"],
                       jaxrod_cold_cpu_s=j["cold_cpu_s"], jaxrod_warm_cpu_s=j["warm_cpu_s"],
                       ratio_cold=rec["wall_s"] / j["cold_s"], ratio_warm=rec["wall_s"] / j["warm_s"],
                       ratio_cold_cpu=rec["cpu_s"] / j["cold_cpu_s"], ratio_warm_cpu=rec["cpu_s"] / j["warm_cpu_s"])
    return rows, at_best


def report(rows, at_best, log=print):
    log("\nAt jaxrod's error (PyElastica's cheapest wall time to reach it and stay), ratios PyElastica / jaxrod:")
    for r in rows:
        pe = "not reached" if "pyelastica_s" not in r else (
            f"PyElastica {r['pyelastica_s']:.1f}s wall, {r['pyelastica_cpu_s']:.1f}s CPU (n={r['pyelastica_n']}, "
            f"t={r['pyelastica_sim_time']:.0f}): ratio {r['ratio_cold']:.1f} cold / {r['ratio_warm']:.0f} warm "
            f"(CPU: {r['ratio_cold_cpu']:.1f} / {r['ratio_warm_cpu']:.0f})")
        log(f"  N={r['N']}: E={r['err_l1']:.3e}, jaxrod {r['jaxrod_cold_s']:.1f}s cold / {r['jaxrod_warm_s']:.2f}s warm; {pe}")
    log(f"At PyElastica's best error: {json.dumps(at_best)}")


# ---------------------------------------------------------------------------- output
CSV_FIELDS = ["code", "variant", "resolution", "dt", "steps", "sim_time", "wall_s", "cpu_s", "err_l1", "err_l1_mid",
              "theta_max", "theta_max_err", "m", "t"]


def write_outputs(pe_runs, jx, rows, at_best, meta, out_dir):
    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / "peer_pyelastica.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(CSV_FIELDS)
        for recs in pe_runs:
            for r in recs:
                w.writerow(["pyelastica", "checkpoint", r["n"], f"{r['dt']:.6g}", r["steps"], f"{r['sim_time']:.1f}",
                            f"{r['wall_s']:.3f}", f"{r['cpu_s']:.3f}", f"{r['err_l1']:.6e}", f"{r['err_l1_mid']:.6e}",
                            f"{r['theta_max']:.6f}", f"{r['theta_max_err']:.6f}", f"{r['m']:.4f}", f"{r['t']:.2f}"])
        for j in jx:
            for v in ("cold", "warm"):
                w.writerow(["jaxrod", v, j["N"], "", j["iterations"], "", f"{j[v + '_s']:.3f}", f"{j[v + '_cpu_s']:.3f}",
                            f"{j['err_l1']:.6e}", f"{j['err_l1_mid']:.6e}", f"{j['theta_max']:.6f}",
                            f"{j['theta_max_err']:.6f}", f"{j['m']:.4f}", f"{j['t']:.2f}"])
    with open(out_dir / "peer_pyelastica.json", "w") as f:
        json.dump({**meta, "jaxrod": jx, "at_jaxrod_error": rows, "at_pyelastica_best": at_best,
                   "pyelastica_final": [recs[-1] for recs in pe_runs if recs]}, f, indent=1)

    plot(pe_runs, jx, out_dir)


def plot(pe_runs, jx, out_dir, path=None):
    """The chart: PyElastica's error against wall time along each run, jaxrod's points (and the
    load-path run of ``--path-only``, where given)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11.0, 5.2))
    cmap = plt.get_cmap("viridis")
    for i, recs in enumerate(pe_runs):
        if not recs:
            continue
        col = cmap(i / max(1, len(pe_runs) - 1) * 0.85)
        ax.loglog([r["wall_s"] for r in recs], [r["err_l1"] for r in recs], "-o", ms=3, color=col,
                  label=f"PyElastica n={recs[0]['n']} (dt={recs[0]['dt']:.2g}; checkpoints t={recs[0]['sim_time']:.0f}"
                        f"..{recs[-1]['sim_time']:.0f})")
    for j in jx:
        ax.loglog([j["warm_s"]], [j["err_l1"]], "s", color="crimson", ms=7)
        ax.loglog([j["cold_s"]], [j["err_l1"]], "s", mfc="none", color="crimson", ms=7)
        ax.annotate(f"N={j['N']}", (j["warm_s"], j["err_l1"]), textcoords="offset points", xytext=(6, 3),
                    fontsize=8, color="crimson")
    if path is not None:
        ax.loglog([path["wall_s"]], [path["err_l1"]], "D", mfc="none", color="darkorange", ms=8,
                  label=f"jaxrod N={path['N']} from the straight rod, {path['load_steps']} load steps (cold; its own run)")
    ax.plot([], [], "s", color="crimson", label="jaxrod static solve, warm (second solve in process)")
    ax.plot([], [], "s", mfc="none", color="crimson", label="jaxrod, cold (JIT compile included)")
    ax.set_xlabel("wall time (s), this machine (2 cores, shared)")
    ax.set_ylabel(r"envelope error $\int_0^1|\theta_h-\theta_{an}|\,d(s/L)$ (rad)")
    ax.set_title(f"Localized helical buckling (d={D_SHORT:g}, R={TURNS}x2$\\pi$, $\\gamma$={GAMMA:.4f}): "
                 "error vs run time", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    fig.savefig(out_dir / "peer_pyelastica.png", dpi=130)
    plt.close(fig)


def read_results(out_dir):
    """pe_runs, jx and the path record back from the CSV and JSON (for ``--rederive``)."""
    d = json.loads((out_dir / "peer_pyelastica.json").read_text())
    runs = {}
    with open(out_dir / "peer_pyelastica.csv") as f:
        for r in csv.DictReader(f):
            if r["code"] != "pyelastica":
                continue
            n = int(r["resolution"])
            runs.setdefault(n, []).append({"n": n, "dt": float(r["dt"]), "sim_time": float(r["sim_time"]),
                                           "steps": int(r["steps"]), "wall_s": float(r["wall_s"]),
                                           "cpu_s": float(r["cpu_s"]), "err_l1": float(r["err_l1"])})
    p = out_dir / "peer_pyelastica_path.json"
    return [runs[n] for n in sorted(runs)], d["jaxrod"], (json.loads(p.read_text()) if p.exists() else None)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", default="100,150,200,300", help="PyElastica resolutions (elements)")
    ap.add_argument("--final-time", type=float, default=2000.0, help="simulated time of each PyElastica run "
                    "(the example's 10500; its error settles by ~1500 here)")
    ap.add_argument("--checkpoint", type=float, default=100.0, help="simulated time between error checkpoints")
    ap.add_argument("--N", default="342,402,502,602", help="jaxrod resolutions (nodes; jaxrod.studies.endloads "
                    "refuses fewer than 342 for this loop and turn count)")
    ap.add_argument("--out", default=str(RESULTS))
    ap.add_argument("--path-only", type=int, default=None, metavar="N",
                    help="instead: jaxrod from the straight rod along a load path (no analytic start) at N "
                         "nodes; writes peer_pyelastica_path.json")
    ap.add_argument("--path-steps", type=int, default=54, help="load steps of --path-only")
    ap.add_argument("--rederive", action="store_true", help="only recompute the comparison (JSON) and redraw the "
                    "chart from the written CSV and JSON (and peer_pyelastica_path.json, if there)")
    ap.add_argument("--jaxrod-worker", type=int, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.rederive:
        out = Path(a.out)
        pe_runs, jx, path = read_results(out)
        rows, at_best = compare(pe_runs, jx)
        report(rows, at_best)
        d = json.loads((out / "peer_pyelastica.json").read_text())
        d.update(at_jaxrod_error=rows, at_pyelastica_best=at_best)
        if path is not None:
            d["jaxrod_path"] = path
        (out / "peer_pyelastica.json").write_text(json.dumps(d, indent=1))
        plot(pe_runs, jx, out, path=path)
        return
    if a.jaxrod_worker is not None:
        print(json.dumps(jaxrod_worker(a.jaxrod_worker)))
        return
    if a.path_only is not None:
        r = jaxrod_path_worker(a.path_only, a.path_steps)
        r["loadavg_end"] = os.getloadavg()
        print(json.dumps(r, indent=1))
        Path(a.out).mkdir(parents=True, exist_ok=True)
        with open(Path(a.out) / "peer_pyelastica_path.json", "w") as f:
            json.dump(r, f, indent=1)
        return
    m_an, t_an = solve_mt(D_SHORT, R_ROT, GAMMA)
    import elastica

    meta = {"case": {"L": L, "B": B, "C": C, "gamma": GAMMA, "slack": SLACK, "d": D_SHORT, "turns": TURNS, "R": R_ROT,
                     "shear_stretch_stiffness": STIFF, "twist_time": TWIST_TIME, "damping": DAMPING,
                     "dt_factor": DT_FACTOR},
            "analytic": {"m": m_an, "t": t_an, "theta_max": theta_max_analytic(m_an, t_an),
                         "int_theta": float(np.trapezoid(theta_analytic(np.linspace(-0.5, 0.5, 200001), m_an, t_an),
                                                         np.linspace(-0.5, 0.5, 200001)))},
            "error": "E_L1 = int_0^1 |theta_h(sigma) - theta_an(sigma - sigma_c)| d sigma, sigma = s/L, edge "
                     "midpoints, trapezoid rule, sigma_c = centroid of 1 - cos theta_h (err_l1_mid: sigma_c = 1/2)",
            "pyelastica_version": getattr(elastica, "__version__", None) or _dist_version("pyelastica"),
            "final_time": a.final_time, "checkpoint": a.checkpoint,
            "loadavg_start": os.getloadavg(), "git": _git_state()}
    print(f"analytic: m = {m_an:.6f}, t = {t_an:.4f}, theta_max = {theta_max_analytic(m_an, t_an):.6f}")
    t_start = time.perf_counter()
    jx = [r for r in (run_jaxrod(int(n)) for n in a.N.split(",") if n) if r is not None]
    pe_runs = []
    for n in [int(v) for v in a.n.split(",") if v]:
        pe_runs.append(pyelastica_run(n, a.final_time, a.checkpoint, m_t=(m_an, t_an)))
    meta["loadavg_end"] = os.getloadavg()
    meta["total_s"] = time.perf_counter() - t_start
    rows, at_best = compare(pe_runs, jx)
    report(rows, at_best)
    write_outputs(pe_runs, jx, rows, at_best, meta, Path(a.out))
    print(f"total {meta['total_s']:.0f} s; wrote {a.out}/peer_pyelastica.{{csv,json,png}}")


def _git_state():
    """The repository's HEAD and whether jaxrod/ differs from it (the jaxrod actually imported is in
    each jaxrod record, ``jaxrod_file``)."""
    import subprocess

    def git(*args):
        p = subprocess.run(["git", *args], cwd=HERE.parent, capture_output=True, text=True, check=False)
        return p.stdout.strip()

    return {"head": git("rev-parse", "HEAD"), "jaxrod_changes": git("status", "--porcelain", "jaxrod")}


def _dist_version(name):
    try:
        from importlib.metadata import version

        return version(name)
    except Exception:  # noqa: BLE001
        return None


if __name__ == "__main__":
    main()
