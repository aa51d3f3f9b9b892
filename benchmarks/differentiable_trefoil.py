"""Derivatives of the trefoil's critical twists and of an equilibrium, by JAX through the implicit
function theorem, against differences of located values; and a design by Newton's method.

The trefoil (D, L) = (8, 292) mm, nu = 0.5, N = 61: both first ends (tightening and opening) are folds.
``critical_twist_function(knot, side, ("nu", "diameter", "contact_stiffness"))`` (diameter: the
rod's, B and C ~ D^4 and EA ~ D^2 at fixed E, as ``jaxrod critical-curve`` varies D/L) follows each
end, located once by ``critical_twists``, as the root of its fold system. For each side:

- ``jax.grad`` against differences of the ends located at p +- h (Newton on the fold system at
  each value): central in the diameter and the contact stiffness (relative steps 1e-5, and 1e-3 for
  the stiffness, on which phi* depends weakly); in nu, which
  sits at its bound 0.5, the one-sided second-order difference (3 f(0) - 4 f(-h) + f(-2h)) / 2h
  (h = 1e-5);
- second derivatives by forward-over-reverse (``jax.jacfwd(jax.grad(f))``) against the same
  differences of the exact gradient (relative steps 1e-4; 1e-2 for the stiffness).

An equilibrium at phi = 2 pi, ``equilibrium_function``: ``jax.jacfwd`` against fourth-order
differences (central in the diameter; in nu, one-sided: (25 f0 - 48 f-1 + 36 f-2 - 16 f-3 + 3 f-4) / 12h).

The design: the trefoil's diameter (at fixed E, nu, L: as ``jaxrod critical-curve`` varies D/L)
whose opening end is at ``TARGET`` = 8 pi, by ``match_critical_twist`` from D/L = 0.03, with the
critical-curve command's point study (``jaxrod.studies.critical_curve.first_instabilities``) at the
D/L found where it converges. The opening end at D/L = 0.03 (a fold at +6.525 pi at N = 61) moves
down as D/L grows (d phi*/d(D/L) = -31.8 pi there) and up as it shrinks, to about 6.8 pi for loose
knots (docs/guides/twist-study.md): followed continuously, it never reaches 8 pi, and the result
says so (not converged, with the reason). The opening ends near 8 pi (D/L ~ 0.045) belong to
another instability, which overtakes this one between D/L = 0.035 and 0.0425.

A calibration round trip: opening onsets at five D/L and tightening onsets at three of them (N = 61)
computed with (nu, contact stiffness) = (0.47, 120), with noise of 1e-6 pi, fitted back from
(0.5, 100) by ``fit_critical_twists`` (each onset the end located at nu = 0.5 and followed).

Writes benchmarks/results/differentiable_trefoil.{json,md}.
Run: python benchmarks/differentiable_trefoil.py   (about 17 minutes on 2 cores)
The small mode is the docs guide's knot (N = 41, nu = 0.48, the opening side, a simple branch
point) with the guide's parameters, so that its compiled programs are those of the guide's test;
it leaves out the design (``match_critical_twist`` is tested on Michell's ring) and the second
derivatives (their program alone takes about 30 s to trace and compile; the guide's test checks
them on this knot against differences of the gradient).
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxrod as jr  # noqa: E402
from jaxrod.studies.design import match_critical_twist  # noqa: E402
from jaxrod.studies.differentiable import critical_twist_function, equilibrium_function  # noqa: E402

from _bench import SMOKE, markdown, pick, results_dir, with_provenance  # noqa: E402

PI = math.pi
D, L = 8.0, 292.0
N, NU = pick((61, 0.5), (41, 0.48))
SIDES = pick(("plus", "minus"), ("plus",))
PARAMETERS = pick(("nu", "diameter", "contact_stiffness"), ("nu", "D", "contact_stiffness"))
TARGET = 8.0 * PI
DESIGN_START = 0.03  # D/L
ROUND_TRIP_RATIOS = (0.0225, 0.025, 0.0274, 0.03, 0.0325)  # D/L, N = 61 (edges shorter than D from 0.0165 on)
ROUND_TRIP_TRUTH = (0.47, 120.0)  # (nu, contact stiffness) of the synthetic measurements
# The tightening onsets too, where their fold can be followed from (0.5, 100) to the truth: they
# depend on the contact stiffness 30 - 600 times more than the opening ones (the knot tightens
# into contact), which alone leave it known to about 1e-3.
ROUND_TRIP_TIGHTENING = (0.025, 0.0274, 0.03)
OUT = results_dir()


def _difference(f, x, i, h, one_sided, order=2):
    """The derivative of f along x[i] by differences of step h: central, or one-sided backward
    (for a value at its upper bound); second or fourth order."""
    e = np.zeros_like(x)
    e[i] = h
    at = lambda s: np.asarray(f(jnp.asarray(x + s * e)))  # noqa: E731
    if one_sided:
        if order == 2:
            return (3.0 * at(0) - 4.0 * at(-1) + at(-2)) / (2.0 * h)
        return (25.0 * at(0) - 48.0 * at(-1) + 36.0 * at(-2) - 16.0 * at(-3) + 3.0 * at(-4)) / (12.0 * h)
    if order == 2:
        return (at(1) - at(-1)) / (2.0 * h)
    return (8.0 * (at(1) - at(-1)) - (at(2) - at(-2))) / (12.0 * h)


def _step(name, value, relative):
    # phi* depends weakly on the contact stiffness (d phi*/d k ~ 1e-6 rad per unit at k = 100): a
    # step 100 times longer keeps the located ends' ~1e-12 rad of noise below 1e-7 of the difference
    scale = 100.0 if name == "contact_stiffness" else 1.0
    return relative if name == "nu" else scale * relative * abs(value)


def critical_twist_rows(knot, ends):
    rows = []
    for side in SIDES:
        f = critical_twist_function(knot, side, PARAMETERS, end=ends[side])
        x = np.asarray(f.base)
        t = time.perf_counter()
        value_and_grad = jax.jit(jax.value_and_grad(f))
        phi, grad = value_and_grad(jnp.asarray(x))
        t_grad = time.perf_counter() - t
        t = time.perf_counter()
        hessian = np.full((len(x), len(x)), np.nan) if SMOKE else np.asarray(jax.jit(jax.jacfwd(jax.grad(f)))(jnp.asarray(x)))
        t_hess = time.perf_counter() - t
        gradient = lambda v: value_and_grad(v)[1]  # noqa: E731
        for i, name in enumerate(PARAMETERS):
            one_sided = name == "nu" and NU == 0.5
            diff = float(_difference(f, x, i, _step(name, x[i], 1e-5), one_sided))
            column = hessian[:, i] if SMOKE else _difference(gradient, x, i, _step(name, x[i], 1e-4), one_sided)
            rows.append(dict(side=side, kind=str(f.end.kind.value), phi_over_pi=float(phi) / PI, parameter=name,
                             value=float(x[i]), grad=float(grad[i]), difference=diff,
                             rel_grad=abs(float(grad[i]) - diff) / abs(diff),
                             hessian_column=hessian[:, i].tolist(), hessian_difference=column.tolist(),
                             rel_hessian=float(np.max(np.abs(hessian[:, i] - column)) / np.max(np.abs(hessian[:, i]))),
                             seconds_first_grad=t_grad, seconds_first_hessian=t_hess))
            print(f"{side} ({f.end.kind.value}, {float(phi) / PI:+.8f} pi) d/d{name}: grad {float(grad[i]):.10g}, "
                  f"differences {diff:.10g} (rel. {rows[-1]['rel_grad']:.1e}); second derivatives rel. "
                  f"{rows[-1]['rel_hessian']:.1e}", flush=True)
    return rows


def equilibrium_rows(knot):
    phi = 2.0 * PI
    names = PARAMETERS[:2]
    q = equilibrium_function(knot, phi, names, jr.relax_to_minimum(knot, phi))
    x = np.asarray(q.base)
    jac = np.asarray(jax.jit(jax.jacfwd(q))(jnp.asarray(x)))
    rows = []
    for i, name in enumerate(names):
        diff = _difference(q, x, i, _step(name, x[i], 1e-3 if name == "nu" else 1e-4), name == "nu" and NU == 0.5,
                           order=4)
        rel = float(np.max(np.abs(jac[:, i] - diff)) / np.max(np.abs(jac[:, i])))
        rows.append(dict(phi_over_pi=phi / PI, parameter=name, rel_jacobian=rel))
        print(f"equilibrium at {phi / PI:g} pi, dq/d{name}: rel. difference {rel:.1e}", flush=True)
    return rows


def design_row():
    from jaxrod.studies.critical_curve import CriticalCurveOptions, first_instabilities

    knot = jr.trefoil(D=DESIGN_START * L, L=L, N=N)
    t = time.perf_counter()
    result = match_critical_twist(knot, "plus", "diameter", TARGET, tol=1e-8 * PI, max_iterations=8,
                                  phi_min=-0.5 * PI, phi_max=10 * PI)
    seconds = time.perf_counter() - t
    ratio = result.value / L
    check = first_instabilities("3_1", N, ratio, CriticalCurveOptions(sides=("plus",), span=10 * PI)) \
        if result.converged else "not run (the design did not converge)"
    row = dict(start_ratio=DESIGN_START, target_over_pi=TARGET / PI, ratio=ratio, phi_over_pi=result.phi / PI,
               converged=result.converged, iterations=result.iterations, residual_over_pi=result.residual / PI,
               reason=result.reason, seconds=seconds, critical_curve=repr(check))
    print(f"design: D/L = {ratio:.10f} puts the opening end at {result.phi / PI:.10f} pi ({result.iterations} Newton "
          f"steps, {result.reason}); critical-curve there: {check}", flush=True)
    return row


def round_trip_row():
    """Opening onsets at ROUND_TRIP_RATIOS and tightening onsets at ROUND_TRIP_TIGHTENING computed with
    known (nu, contact stiffness), with noise of 1e-6 pi, fitted back from (0.5, 100) by
    ``fit_critical_twists``."""
    from jaxrod.studies.design import Measurement, fit_critical_twists

    rng = np.random.default_rng(7)
    sigma = 1e-6 * PI
    truth = np.array(ROUND_TRIP_TRUTH)
    cases = [(r, "plus") for r in ROUND_TRIP_RATIOS] + [(r, "minus") for r in ROUND_TRIP_TIGHTENING]
    knots = [jr.trefoil(D=r * L, L=L, N=N) for r, _ in cases]
    t = time.perf_counter()
    functions = [critical_twist_function(k, side, ("nu", "contact_stiffness"), -16 * PI, 10 * PI)
                 for k, (_, side) in zip(knots, cases)]
    onsets = [float(f(jnp.asarray(truth))) + sigma * rng.standard_normal() for f in functions]
    data = [Measurement(k, side, phi, sigma, end=f.end) for k, (_, side), f, phi in zip(knots, cases, functions, onsets)]
    fit = fit_critical_twists(data, ("nu", "contact_stiffness"), phi_min=-16 * PI, phi_max=10 * PI)
    errors = np.abs(fit.values - truth)
    row = dict(ratios=list(ROUND_TRIP_RATIOS), tightening_ratios=list(ROUND_TRIP_TIGHTENING), truth=truth.tolist(),
               sigma=sigma, values=fit.values.tolist(),
               standard_errors=fit.standard_errors.tolist(), relative_errors=(errors / truth).tolist(),
               in_standard_errors=(errors / fit.standard_errors).tolist(), chi2=fit.chi2, converged=fit.converged,
               reason=fit.reason, seconds=time.perf_counter() - t)
    print(f"round trip: (nu, k) = {fit.values} against {truth}; relative errors {row['relative_errors']}, "
          f"{row['in_standard_errors']} standard errors; chi2 = {fit.chi2:.2f}", flush=True)
    return row


def main():
    knot = jr.trefoil(D=D, L=L, N=N, nu=NU)
    t = time.perf_counter()
    if len(SIDES) == 2:
        found = jr.critical_twists(knot, -16.0 * PI, 16.0 * PI)
        ends = {"plus": found.plus, "minus": found.minus}
    else:
        from jaxrod.studies.critical_ends import knot_ends

        ends = knot_ends(knot, -0.5 * PI, 8.0 * PI, None)
    print(f"N = {N}: ends located in {time.perf_counter() - t:.0f} s", flush=True)
    data = dict(D=D, L=L, N=N, nu=NU, critical_twists=critical_twist_rows(knot, ends),
                equilibrium=equilibrium_rows(knot), design=None if SMOKE else design_row(),
                round_trip=None if SMOKE else round_trip_row())
    with open(os.path.join(OUT, "differentiable_trefoil.json"), "w") as f:
        json.dump(with_provenance(data), f, indent=1)
    with open(os.path.join(OUT, "differentiable_trefoil.md"), "w") as f:
        f.write(markdown(_table(data)))


def _table(data):
    lines = [f"# Derivatives of the trefoil's critical twists by JAX (N = {data['N']}, nu = {data['nu']:g})", "",
             "Gradients and second derivatives (forward-over-reverse) of phi* against differences of located ends "
             "(`benchmarks/differentiable_trefoil.py`, module docstring); relative differences.", "",
             "| side | kind | phi* / pi | parameter | value | d phi*/d p (JAX) | differences | rel. | second "
             "derivatives rel. |", "|---|---|---|---|---|---|---|---|---|"]
    for r in data["critical_twists"]:
        lines.append(f"| {r['side']} | {r['kind']} | {r['phi_over_pi']:+.10f} | {r['parameter']} | {r['value']:g} | "
                     f"{r['grad']:.10g} | {r['difference']:.10g} | {r['rel_grad']:.1e} | {r['rel_hessian']:.1e} |")
    lines += ["", "An equilibrium at phi = 2 pi, `jax.jacfwd` against fourth-order differences (largest difference over "
              "the column's largest entry):", "", "| parameter | rel. |", "|---|---|"]
    lines += [f"| {r['parameter']} | {r['rel_jacobian']:.1e} |" for r in data["equilibrium"]]
    d = data["design"]
    if d is not None:
        lines += ["", f"Design: from D/L = {d['start_ratio']:g}, D/L = {d['ratio']:.10f} puts the opening end at "
                  f"{d['phi_over_pi']:.10f} pi (target {d['target_over_pi']:g} pi, residual {d['residual_over_pi']:.1e} "
                  f"pi) in {d['iterations']} Newton steps ({d['seconds']:.0f} s); converged: {d['converged']}. "
                  f"The critical-curve point study at that D/L: {d['critical_curve']}."]
    t = data["round_trip"]
    if t is not None:
        lines += ["", f"Calibration round trip: opening onsets at D/L = {', '.join(f'{r:g}' for r in t['ratios'])} "
                  f"and tightening onsets at D/L = {', '.join(f'{r:g}' for r in t.get('tightening_ratios', []))} "
                  f"computed with (nu, contact stiffness) = ({t['truth'][0]:g}, {t['truth'][1]:g}) and noise "
                  f"{t['sigma'] / PI:.0e} pi, fitted from (0.5, 100): ({t['values'][0]:.8f}, {t['values'][1]:.6f}), "
                  f"relative errors {t['relative_errors'][0]:.1e}, {t['relative_errors'][1]:.1e}; "
                  f"{t['in_standard_errors'][0]:.2f} and {t['in_standard_errors'][1]:.2f} standard errors "
                  f"({t['standard_errors'][0]:.2e}, {t['standard_errors'][1]:.2e}); chi2 = {t['chi2']:.2f}; "
                  f"converged: {t['converged']} ({t['seconds']:.0f} s)."]
    return lines


if __name__ == "__main__":
    main()
