"""Equilibria of a scene at a given imposed twist, each reported with its stability."""
from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .material import check_finite
from .solvers import LBFGS, ConvergenceError, DampedNewton, Newton, Solution, minimise
from .stability import DEFAULT_NEGATIVE_TOL, Stability, stability

__all__ = ["Equilibrium", "solve_equilibrium", "relax", "TopologyChangeError", "scaled_energy", "scaled_zero_modes"]


# Module-level functions of (u, (scene, phi)): the solvers' jitted loops take the function as a
# static argument and the scene as a pytree argument, so one compilation serves every scene of
# the same kind and size, whatever its material or twist.
def scaled_energy(u, args):
    scene, phi = args
    return scene.scaled_energy(u, phi)


def scaled_zero_modes(u, args):
    scene, phi = args
    return scene.scaled_zero_modes(u, phi)


def contact_list_stale(u, args):
    scene, phi = args
    return scene.contact_list_stale(scene.from_scaled(u), phi)


class TopologyChangeError(RuntimeError):
    """The rod passed through itself (its writhe jumped by ~2): the knot type changed."""


def relax(scene, phi=0.0, q0=None, gtol=1e-9, max_rounds=200, max_displacement=None, k=8,
          negative_tol=DEFAULT_NEGATIVE_TOL, previous=None, progress=None, with_stability=True):
    """Minimise the energy of a scene with self-contact from q0 (default scene.q_init) without
    letting the rod pass through itself.

    Damped Newton (exact Hessian, shifted positive definite) with every node's step capped at
    ``max_displacement`` (default D/4, so no strand can jump across another between two energy
    evaluations); the run pauses whenever a node has moved more than skin/2 since the contact
    candidate list was built, the list is rebuilt, and the run resumes. After every pause the
    writhe is compared with the last one: a jump of 1 or more (strand passage changes it by ~2)
    raises ``TopologyChangeError``. ``previous`` (an Equilibrium, e.g. the last continuation step)
    makes the first comparison against its writhe, so a step that jumped a strand across another
    before the solve even started is refused too.

    Returns (equilibrium, scene): the scene carries the contact list valid at the equilibrium.
    """
    phi = check_finite("phi", phi)
    q = np.asarray(scene.q_init if q0 is None else q0, dtype=float)
    has_contact = "contact" in scene.terms
    if has_contact:
        scene = scene.with_contacts(q)
        cap = 0.25 * float(scene.material.D) if max_displacement is None else float(max_displacement)
    else:
        cap = math.inf if max_displacement is None else float(max_displacement)
    say = progress or (lambda s: None)
    solver = DampedNewton(
        zero_modes=scaled_zero_modes if scene.n_zero_modes else None,
        max_step=cap / float(scene.length_scale),
        leave=contact_list_stale if has_contact else None,
    )
    wr_last = float(scene.writhe(jnp.asarray(q), phi)) if previous is None else float(previous.Wr)
    if abs(float(scene.writhe(jnp.asarray(q), phi)) - wr_last) >= 1.0:
        raise TopologyChangeError(
            f"the starting state's writhe differs from the previous equilibrium's ({wr_last:.4f}) by 1 or more: "
            "the step passed the rod through itself"
        )
    total = 0
    for round_ in range(max_rounds):
        u0 = scene.to_scaled(jnp.asarray(q))
        sol = minimise(scaled_energy, u0, (scene, jnp.asarray(phi)), solver, gtol, None, throw=False)
        total += sol.iterations
        q = np.asarray(scene.from_scaled(jnp.asarray(sol.y)))
        wr = float(scene.writhe(jnp.asarray(q), phi))
        say(f"relax round {round_}: {sol.reason}, {sol.iterations} steps, |g| = {sol.grad_norm:.2e}, Wr = {wr:.4f}")
        if abs(wr - wr_last) >= 1.0:
            raise TopologyChangeError(
                f"writhe jumped from {wr_last:.4f} to {wr:.4f}: the rod passed through itself"
            )
        wr_last = wr
        if sol.reason == "left_region":
            scene = scene.with_contacts(q)
            continue
        if not sol.converged:
            raise ConvergenceError(f"relaxation did not converge: {sol!r}")
        if has_contact:
            scene = scene.with_contacts(q)
        sol = Solution(y=sol.y, value=sol.value, grad_norm=sol.grad_norm, iterations=total,
                       converged=True, reason="converged", solver=f"damped_newton({round_ + 1} rounds)",
                       gtol=sol.gtol)
        return equilibrium_from_solution(scene, phi, sol, k=k, with_stability=with_stability,
                                         negative_tol=negative_tol), scene
    raise ConvergenceError(f"relaxation needed more than {max_rounds} contact-list rebuilds")


@dataclass(frozen=True)
class Equilibrium:
    """A converged equilibrium.

    q: (n,) free DOFs (physical units); x: (N,3) nodes; theta: (M,) edge twist angles;
    phi: imposed twist; energy: total; energy_terms: dict per term; solution: the solver's
    ``Solution`` (iterations, gradient norm, stop reason); stability: ``Stability`` (or None when
    explicitly not computed); Wr, Tw, Lk: writhe, twist and linking number (open clamped rods:
    of the centreline extended along the clamp axis).
    """

    q: np.ndarray
    x: np.ndarray
    theta: np.ndarray
    phi: float
    energy: float
    energy_terms: dict
    solution: Solution
    stability: Stability | None
    Wr: float
    Tw: float
    Lk: float

    @property
    def stable(self):
        return None if self.stability is None else self.stability.stable

    def __repr__(self):
        return (
            f"Equilibrium(phi={self.phi:.6g}, energy={self.energy:.10g}, Wr={self.Wr:.6f}, "
            f"Tw={self.Tw:.6f}, Lk={self.Lk:.6f}, {self.solution!r}, {self.stability!r})"
        )


def solve_equilibrium(
    scene,
    phi=0.0,
    q0=None,
    method="auto",
    gtol=1e-9,
    max_steps=None,
    k=8,
    with_stability=True,
    negative_tol=DEFAULT_NEGATIVE_TOL,
    throw=True,
    near_null_tol=0.0,
):
    """Equilibrium of ``scene`` at imposed twist ``phi`` starting from ``q0`` (default scene.q_init).

    method: 'newton' (exact Hessian; converges to the nearest stationary point, stable or not:
    use it as a continuation corrector), 'lbfgs' (minimiser), or 'auto' (L-BFGS to 1e-5, then
    Newton to ``gtol``: global and fast). gtol bounds the max-abs gradient of the scaled energy.
    near_null_tol: Newton leaves eigen-directions with |lambda| below it alone (see ``Newton``).
    The result carries its stability (k lowest eigenvalues, negative count) unless
    ``with_stability`` is False. Raises ``ConvergenceError`` if the solver fails and ``throw``.
    """
    phi = check_finite("phi", phi)
    q0 = np.asarray(scene.q_init if q0 is None else q0, dtype=float)
    if q0.shape != (scene.n_dof,):
        raise ValueError(f"q0 must have shape ({scene.n_dof},), got {q0.shape}")
    if not np.all(np.isfinite(q0)):
        raise ValueError("q0 must be finite")
    u0 = scene.to_scaled(jnp.asarray(q0))
    newton = Newton(zero_modes=scaled_zero_modes if scene.n_zero_modes else None, near_null_tol=float(near_null_tol))
    args = (scene, jnp.asarray(phi))
    if method == "newton":
        sol = minimise(scaled_energy, u0, args, newton, gtol, max_steps, throw)
    elif method == "lbfgs":
        sol = minimise(scaled_energy, u0, args, LBFGS(), gtol, max_steps, throw)
    elif method == "auto":
        pre = minimise(scaled_energy, u0, args, LBFGS(), max(gtol, 1e-5), max_steps, throw=False)
        start = pre.y if np.all(np.isfinite(pre.y)) else np.asarray(u0)
        sol = minimise(scaled_energy, start, args, newton, gtol, None, throw)
        sol = Solution(
            y=sol.y, value=sol.value, grad_norm=sol.grad_norm,
            iterations=pre.iterations + sol.iterations, converged=sol.converged,
            reason=sol.reason, solver=f"lbfgs({pre.iterations})+newton({sol.iterations})", gtol=sol.gtol,
        )
    else:
        raise ValueError(f"method must be 'newton', 'lbfgs' or 'auto', got {method!r}")
    return equilibrium_from_solution(scene, phi, sol, k, with_stability, negative_tol)


@jax.jit
def _diagnostics(scene, u, phi):
    q = scene.from_scaled(u)
    x, theta = scene.unpack(q, phi)
    return q, x, theta, scene.energy_terms(q, phi), scene.writhe(q, phi), scene.twist(q, phi)


def equilibrium_from_solution(scene, phi, sol, k=8, with_stability=True, negative_tol=DEFAULT_NEGATIVE_TOL):
    """Wrap a solver ``Solution`` (scaled DOFs) into an ``Equilibrium`` with its diagnostics."""
    q, x, theta, terms, wr, tw = jax.device_get(_diagnostics(scene, jnp.asarray(sol.y), jnp.asarray(phi)))
    terms = {k_: float(v) for k_, v in terms.items()}
    wr, tw = float(wr), float(tw)
    stab = stability(scene, q, phi, k=k, tol=negative_tol) if with_stability else None
    return Equilibrium(
        q=q, x=np.asarray(x), theta=np.asarray(theta), phi=phi, energy=float(sum(terms.values())),
        energy_terms=terms, solution=sol, stability=stab, Wr=wr, Tw=tw, Lk=wr + tw,
    )
