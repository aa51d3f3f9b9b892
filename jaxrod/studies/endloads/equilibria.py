"""Equilibria of an end-loaded rod: Newton's method with a capped step and the exact Hessian
(``newton``), the equilibrium at an end rotation (``solve``, options in ``EndLoadOptions``), and
the equilibrium reached from NvdHT's analytic loop through stiffening stages
(``solve_from_helix``)."""
from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass

import jax
import numpy as np

from ...validation import check_finite, check_int_at_least, check_positive
from .compiled import rod_evaluate, rod_stability
from .resolution import check_rotation_resolution, gradient_tolerance
from .scene import check_q, check_scene, with_material
from .shapes import helical_start, restretched


def _capped_step(h, z, g, max_step):
    """Newton's step -H^-1 g (exact zero modes z lifted), its largest component capped; on the host
    (LAPACK: nothing to compile per shape)."""
    h, g = np.array(h, dtype=float), np.asarray(g, dtype=float)
    if z is not None:
        z = np.asarray(z, dtype=float)
        z = z / np.maximum(np.linalg.norm(z, axis=0, keepdims=True), 1e-300)
        h += (np.max(np.abs(np.diag(h))) + 1.0) * (z @ z.T)
    dy = -np.linalg.solve(h, g)
    big = np.max(np.abs(dy))
    return dy * min(1.0, max_step / max(big, 1e-300))


@functools.lru_cache(maxsize=None)
def _jitted_value_and_grad(fun):
    return jax.jit(jax.value_and_grad(fun))


@functools.lru_cache(maxsize=None)
def _jitted(fun):
    return jax.jit(fun)


def _compiled(fun):
    """fun itself if it is jitted or a host composition of jitted pieces (``fun.host``), else
    ``jax.jit(fun)`` (cached per function)."""
    if fun is None or hasattr(fun, "lower") or getattr(fun, "host", False):
        return fun
    return _jitted(fun)


def host(fun):
    """``fun`` marked as a host composition of jitted pieces: ``newton`` calls it as it is."""
    fun.host = True
    return fun


def newton(fun, hessian, y0, args, zero_modes=None, gtol=1e-9, max_step=0.5, max_steps=100, throw=True,
           value_and_grad=None, evaluate=None):
    """The stationary point of ``fun(y, args)`` nearest y0 (stable or not) by Newton's method with
    the exact ``hessian(y, args)`` (it may return (H, zero modes)), each step's largest component
    capped at ``max_step`` (scaled units: an edge length), exact symmetry directions
    ``zero_modes(y, args) -> (n, k)`` lifted out of the solve. No line search: on a stiff rod a
    good step often raises |grad| for one iteration. A Python loop over jitted pieces (jitted here
    unless already jitted or ``host``-marked); ``evaluate(y, args) -> (value, grad, H, zero modes)``,
    where given, replaces them. Returns a ``jaxrod.solve.solvers.Solution``."""
    from ...solve.solvers import ConvergenceError, Solution, StopReason  # noqa: PLC0415

    vg = None if evaluate is not None else (_jitted_value_and_grad(fun) if value_and_grad is None
                                            else _compiled(value_and_grad))
    hess, zm = _compiled(hessian), _compiled(zero_modes)
    max_steps = check_int_at_least("max_steps", max_steps, 0)
    y = np.asarray(y0, dtype=np.float64)
    cap = float(max_step)
    it = 0
    while True:
        if evaluate is not None:
            value, g, h, z = evaluate(y, args)
        else:
            value, g = vg(y, args)
        gnorm = float(np.max(np.abs(g)))
        if not np.isfinite(gnorm) or gnorm <= gtol or it >= max_steps:
            break
        if evaluate is None:
            h = hess(y, args)
            z = zm(y, args) if zm is not None else None
            if isinstance(h, tuple):
                h, z = h
        y = y + _capped_step(h, z, g, cap)
        it += 1
    ok = bool(np.isfinite(gnorm) and gnorm <= gtol)
    reason = StopReason.CONVERGED if ok else (StopReason.NONFINITE if not np.isfinite(gnorm) else StopReason.MAX_STEPS)
    sol = Solution(y=np.asarray(y), value=float(value), grad_norm=gnorm, iterations=it, converged=ok,
                   reason=reason, solver="capped_newton", gtol=float(gtol))
    if throw and not ok:
        raise ConvergenceError(f"capped Newton did not converge: {sol!r}", solution=sol)
    return sol


@dataclass(frozen=True)
class EndLoadOptions:
    """How ``solve`` and ``solve_from_helix`` run (every field checked on construction; a
    ValueError names the wrong one).

    gtol: Newton's tolerance on the max |gradient| of the scaled energy (None:
      ``gradient_tolerance(scene)``, the same relative accuracy at every stretch stiffness).
    max_step: the cap on each Newton step's largest component (scaled units: an edge length).
    max_steps: Newton iterations allowed.
    k: eigenpairs kept in the result's stability.
    with_stability: compute the result's stability.
    """

    gtol: float | None = None
    max_step: float = 0.5
    max_steps: int = 200
    k: int = 8
    with_stability: bool = True

    def __post_init__(self):
        if self.gtol is not None:
            check_positive("gtol", self.gtol)
        check_positive("max_step", self.max_step)
        check_int_at_least("max_steps", self.max_steps, 0)


def solve(scene, phi, q0, options=None, throw=True):
    """Equilibrium (``jaxrod.Equilibrium``, with its stability unless ``options.with_stability`` is
    False) of an ``EndLoadedRod`` at end rotation phi nearest q0 (physical DOFs), by ``newton`` on
    the scaled energy (the axial rotation lifted out) to max |gradient| <= ``options.gtol``
    (``EndLoadOptions``; None: the defaults). Without contact only. Refused: a scene too coarse
    for its end rotation (more than ``MAX_TWIST_PER_EDGE`` rad per edge: N named), non-finite phi or q0."""
    from ...solve.equilibrium import equilibrium_from_solution  # noqa: PLC0415

    options = EndLoadOptions() if options is None else options
    check_scene(scene)
    phi = check_finite("phi", phi)
    gtol = gradient_tolerance(scene) if options.gtol is None else float(options.gtol)
    check_rotation_resolution(scene.n_nodes, phi)
    q0 = check_q(scene, "q0", q0)
    nbr = scene.neighbourhood(q0, phi)
    sol = newton(None, None, scene.to_scaled(q0), (scene, phi, nbr), gtol=gtol, max_step=options.max_step,
                 max_steps=options.max_steps, throw=throw, evaluate=rod_evaluate)
    q = scene.from_scaled(np.asarray(sol.y))
    nbr = scene.neighbourhood(q, phi)
    e = equilibrium_from_solution(scene, phi, sol, nbr, k=options.k, with_stability=False)
    if options.with_stability:
        e = dataclasses.replace(e, stability=rod_stability(scene, sol.y, phi, nbr, options.k))
    return e


# On a stiff rod Newton from the analytic loop wanders (a step's second-order stretch dwarfs the
# loads), so ``solve_from_helix`` solves at EA_0 = STIFFEN_FROM max(t, 4 pi^2) B/L^2 first, then
# stiffens by at most STIFFEN_FACTOR per stage, each started ``restretched`` from the last.
STIFFEN_FROM = 1e3
STIFFEN_FACTOR = 100.0


def stiffening_stages(scene, t):
    """The stretch stiffnesses EA (ascending, the last the scene's own) at which
    ``solve_from_helix`` solves a rod carrying t = TL^2/B."""
    check_scene(scene)
    B, EA, L = float(scene.material.B), float(scene.material.EA), float(scene.clamp_length)
    ea0 = STIFFEN_FROM * max(float(t), 4.0 * math.pi ** 2) * B / L ** 2
    if EA <= ea0:
        return [EA]
    n = math.ceil(math.log(EA / ea0) / math.log(STIFFEN_FACTOR) - 1e-12)
    return [ea0 * (EA / ea0) ** (j / n) for j in range(n)] + [EA]


def solve_from_helix(scene, m, t, phi, options=None, throw=True):
    """Equilibrium of ``scene`` (an ``EndLoadedRod``) at end rotation phi, from NvdHT's loop (m, t)
    (``helical_start``; either sign of m), by ``solve``: through ``stiffening_stages`` (the same
    rod at increasing EA, each stage started from the last's state restretched to its EA; the
    compiled programs shared), the last with ``options`` (``EndLoadOptions``), the others to
    their own ``gradient_tolerance`` without stability. Refused: as ``helical_start`` and ``solve``.
    Raises ``jaxrod.solve.solvers.ConvergenceError`` (with ``throw``) where a stage does not converge."""
    options = EndLoadOptions() if options is None else options
    check_scene(scene)
    q = helical_start(scene, m, t, phi)
    stages = stiffening_stages(scene, t)
    staged = dataclasses.replace(options, gtol=None, with_stability=False)
    for EA, stiffer in zip(stages[:-1], stages[1:]):
        soft = with_material(scene, dataclasses.replace(scene.material, EA=EA))
        q = solve(soft, phi, q, staged, throw=throw).q
        q = restretched(scene, q, EA / stiffer)
    return solve(scene, phi, q, options, throw=throw)
