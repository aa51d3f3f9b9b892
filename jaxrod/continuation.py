"""Twist continuation and critical twist.

``critical_twist`` follows an equilibrium branch in phi (tangent predictor, Newton corrector) and
watches the count of negative Hessian eigenvalues over the *whole* spectrum (zero modes removed),
so an unstable mode that comes down from high in the spectrum is caught. When the count changes
between two steps, the crossing eigenvalue (the one with ascending index = the count before) is
driven to zero by Newton's method in phi, using its derivative along the branch from forward-mode
autodiff (``stability.eigenvalue_phi_derivative``), safeguarded by the bracket. A handful of
Hessian evaluations reach 1e-10 rad, where bisection would need ~30.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .equilibrium import Equilibrium, solve_equilibrium
from .material import check_finite, check_positive
from .solvers import ConvergenceError
from .stability import DEFAULT_NEGATIVE_TOL, eigenvalue_phi_derivative

__all__ = ["CriticalPoint", "critical_twist", "NoCrossingError"]


class NoCrossingError(RuntimeError):
    """The negative-eigenvalue count did not change over the scanned range of phi."""


@dataclass(frozen=True)
class CriticalPoint:
    """A twist at which an eigenvalue of the equilibrium branch crosses zero.

    phi: critical twist (rad); eigenvalue: crossing eigenvalue there (~0, dimensionless);
    dlambda_dphi: its derivative along the branch; mode: (n,) critical eigenvector (scaled DOFs);
    equilibrium: the branch state at phi; multiplicity: change of the negative count (2 for a
    degenerate pair, as in the ring); bracket: (phi_a, phi_b) where the count changed;
    phi_error: size of the last Newton correction (an upper bound on the error once converged);
    hessian_evaluations: in the refinement; scan: list of (phi, n_negative, lowest eigenvalues).
    """

    phi: float
    eigenvalue: float
    dlambda_dphi: float
    mode: np.ndarray
    equilibrium: Equilibrium
    multiplicity: int
    bracket: tuple
    phi_error: float
    hessian_evaluations: int
    scan: list = field(repr=False)
    seconds: float = 0.0


def _corrector(scene, phi, q_pred, k, negative_tol):
    return solve_equilibrium(scene, phi, q_pred, method="newton", k=k, negative_tol=negative_tol)


def critical_twist(
    scene,
    phi_start=0.0,
    phi_stop=None,
    step=None,
    q0=None,
    tol=1e-6 * math.pi,
    k=8,
    negative_tol=DEFAULT_NEGATIVE_TOL,
    max_refine=30,
    progress=None,
):
    """First phi beyond ``phi_start`` (in the direction of ``phi_stop``) where the negative count
    of the equilibrium branch changes.

    scene: a scene; q0: initial guess at phi_start (default scene.q_init, relaxed first);
    step: scan step (default (phi_stop - phi_start)/40); tol: requested accuracy in phi.
    progress: optional callable(str) for progress lines. Returns a ``CriticalPoint``; raises
    ``NoCrossingError`` if the count never changes before phi_stop.
    """
    t0 = time.perf_counter()
    phi_start = check_finite("phi_start", phi_start)
    phi_stop = check_finite("phi_stop", 8.0 * math.pi if phi_stop is None else phi_stop)
    if phi_stop == phi_start:
        raise ValueError("phi_stop must differ from phi_start")
    tol = check_positive("tol", tol)
    direction = 1.0 if phi_stop > phi_start else -1.0
    step = abs(phi_stop - phi_start) / 40.0 if step is None else check_positive("step", abs(step))
    say = progress or (lambda s: None)

    eq = solve_equilibrium(scene, phi_start, q0, method="auto", k=k, negative_tol=negative_tol)
    count0 = eq.stability.n_negative
    scan = [(eq.phi, count0, eq.stability.eigenvalues.copy())]
    say(f"phi = {eq.phi / math.pi:+.4f} pi: {count0} negative, lowest {eq.stability.eigenvalues[0]:.3e}")

    # Scan with a tangent predictor until the count changes.
    prev = eq
    while True:
        phi_next = prev.phi + direction * step
        if direction * (phi_next - phi_stop) > 1e-12:
            raise NoCrossingError(
                f"negative count stayed {count0} from phi = {phi_start:.6g} to {phi_stop:.6g}"
            )
        _, _, _, dq = eigenvalue_phi_derivative(scene, prev.q, prev.phi, 0)
        cur = _corrector(scene, phi_next, prev.q + dq * (phi_next - prev.phi), k, negative_tol)
        scan.append((cur.phi, cur.stability.n_negative, cur.stability.eigenvalues.copy()))
        say(
            f"phi = {cur.phi / math.pi:+.4f} pi: {cur.stability.n_negative} negative, "
            f"lowest {cur.stability.eigenvalues[0]:.3e}"
        )
        if cur.stability.n_negative != count0:
            break
        prev = cur

    # Refine: the eigenvalue with ascending index `count0` changes sign inside [prev, cur].
    index = min(count0, cur.stability.n_negative)
    multiplicity = abs(cur.stability.n_negative - count0)
    evals = 0

    def evaluate(e):
        nonlocal evals
        evals += 1
        lam, dlam, v, dq = eigenvalue_phi_derivative(scene, e.q, e.phi, index)
        return lam, dlam, v, dq

    lo, hi = prev, cur
    f_lo, d_lo, _, dq_lo = evaluate(lo)
    f_hi, d_hi, _, _ = evaluate(hi)
    bracket = (lo.phi, hi.phi)
    # First guess: secant through the bracket ends.
    phi_c = lo.phi - f_lo * (hi.phi - lo.phi) / (f_hi - f_lo)
    base, base_dq = lo, dq_lo
    phi_error = abs(hi.phi - lo.phi)
    for _ in range(max_refine):
        try:
            e = _corrector(scene, phi_c, base.q + base_dq * (phi_c - base.phi), k, negative_tol)
        except ConvergenceError:
            e = _corrector(scene, phi_c, base.q, k, negative_tol)
        f_c, d_c, v_c, dq_c = evaluate(e)
        if np.sign(f_c) == np.sign(f_lo):
            lo, f_lo = e, f_c
        else:
            hi, f_hi = e, f_c
        newton = phi_c - f_c / d_c if d_c != 0.0 else math.nan
        a, b = sorted((lo.phi, hi.phi))
        if not (math.isfinite(newton) and a <= newton <= b):
            newton = lo.phi - f_lo * (hi.phi - lo.phi) / (f_hi - f_lo)  # regula falsi fallback
            if not (a < newton < b):
                newton = 0.5 * (a + b)
        phi_error = abs(newton - phi_c)
        base, base_dq = e, dq_c
        say(f"refine: phi = {phi_c / math.pi:.12f} pi, eigenvalue {f_c:+.3e}, next step {phi_error:.2e}")
        if phi_error < tol or f_c == 0.0:
            break
        phi_c = newton
    else:
        raise ConvergenceError(f"critical twist refinement did not reach tol = {tol:.3g} in {max_refine} steps")

    return CriticalPoint(
        phi=float(phi_c),
        eigenvalue=float(f_c),
        dlambda_dphi=float(d_c),
        mode=v_c,
        equilibrium=e,
        multiplicity=multiplicity,
        bracket=bracket,
        phi_error=float(phi_error),
        hessian_evaluations=evals,
        scan=scan,
        seconds=time.perf_counter() - t0,
    )
