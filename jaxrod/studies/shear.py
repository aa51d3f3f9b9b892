"""Studies of Cosserat rods with shear (``jaxrod.model.cosserat``): a cantilever's tip deflection and
a column's buckling load, against Timoshenko's, Haringx's and Engesser's formulas.

- ``cantilever_tip_deflection(rod, force)``: the linear response to a small dead tip force,
  H^-1 f at the straight state (H = ``jax.hessian`` of the energy). Timoshenko: P L^3 / (3 B) + P L / (kGA).
- ``ring_critical_twist(ring)``: a ``CosseratRing``'s planar twisted branch followed in phi from 0
  to its first branch point (Michell's instability, with shear), located by the same engine.
- ``column_buckling_load(rod)``: the pinned column's trivial (straight, compressed) branch followed
  in the load by the pseudo-arclength engine (``jaxrod.continuation.arclength.continuation``) to its
  first branch point, located on the extended system. With the shear strain in the material frame
  the load solves  P (1 - P / EA) + P^2 / kGA = P_E  (Haringx's formula when EA -> oo; derivation in
  docs/guides/shear.md): ``haringx_load``; Engesser's P_E / (1 + P_E / kGA) is ``engesser_load``.
"""
from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["cantilever_tip_deflection", "timoshenko_deflection", "column_buckling_load", "euler_load", "haringx_load",
           "engesser_load", "ring_critical_twist"]


def timoshenko_deflection(force, length, B, GA):
    """A cantilever's tip deflection under a small tip force, bending and shear: F L^3 / (3 B) + F L / kGA."""
    return force * length ** 3 / (3.0 * B) + force * length / GA


def euler_load(length, B):
    """The pinned column's Euler load pi^2 B / L^2."""
    return math.pi ** 2 * B / length ** 2


def haringx_load(P_E, GA, EA=math.inf):
    """The buckling load of a shearable, extensible column whose shear strain is measured in the
    material frame: the root of P (1 - P / EA) + P^2 / kGA = P_E in (0, P_E]; with EA = oo,
    Haringx's (kGA / 2) (sqrt(1 + 4 P_E / kGA) - 1)."""
    a = 1.0 / GA - (0.0 if math.isinf(EA) else 1.0 / EA)
    return P_E if a == 0.0 else (math.sqrt(1.0 + 4.0 * a * P_E) - 1.0) / (2.0 * a)


def engesser_load(P_E, GA):
    """Engesser's shear-corrected buckling load P_E / (1 + P_E / kGA) (shear strain measured against
    the undeformed axis)."""
    return P_E / (1.0 + P_E / GA)


def cantilever_tip_deflection(rod, force):
    """The tip deflection (along e1, length units) of a cantilever ``CosseratRod`` under a small dead
    tip force (linear response at the straight state)."""
    if rod.support != "cantilever":
        raise ValueError(f"the rod must be a cantilever, got support {rod.support!r}")
    u0 = jnp.asarray(rod.straight())
    H = np.asarray(jax.jit(jax.hessian(rod.energy))(u0, 0.0, rod.params))
    f = np.asarray(jax.grad(lambda u: rod.full(u)[0][-1, 0])(u0)) * float(force)
    return float(np.linalg.solve(H, f) @ (f / float(force)))


def _first_branch_point(energy, u0, params, step, p_max, options):
    """The first located branch point of the branch of ``energy`` through (u0, 0), followed in its
    parameter up to p_max by pseudo-arclength (steps ``step``, the 4 lowest eigenvalues tracked)."""
    from ..continuation import ContinuationOptions
    from ..continuation.arclength import BifurcationProblem, PseudoArclength, continuation

    opts = options or ContinuationOptions(ds=step, ds_max=step, p_min=-step, p_max=p_max, k=4)
    branch = continuation(BifurcationProblem(energy, u0, 0.0, params), PseudoArclength(), opts, throw=False)
    found = [e for e in branch.events if str(getattr(e.kind, "value", e.kind)) == "branch_point" and e.converged]
    if not found:
        raise RuntimeError(f"no branch point below {p_max:.6g} ({branch.message})")
    return found[0]


def ring_critical_twist(ring, phi_max=None, options=None):
    """The critical twist of a ``CosseratRing``: its planar branch continued in the closure twist from
    0 to the first located branch point (an ``Event``: p the twist in rad, multiplicity 2).
    phi_max: default 1.3 times Michell's 2 pi sqrt(3) B / C; options: a ``ContinuationOptions``."""
    michell = 2.0 * math.pi * math.sqrt(3.0) * ring.B / ring.C
    phi_max = 1.3 * michell if phi_max is None else float(phi_max)
    return _first_branch_point(ring.energy, ring.circle(), ring.params, 0.1 * michell, phi_max, options)


def column_buckling_load(rod, p_max=None, options=None):
    """The first buckling load of a pinned ``CosseratRod`` column: the straight branch continued in
    the compressive load from 0 (pseudo-arclength, ``PseudoArclength``) to its first located branch
    point. Returns the located ``Event`` (p: the load; multiplicity 2: the two planes of bending).

    p_max: the largest load followed (default 1.2 times Euler's load); options: a
    ``ContinuationOptions`` (default: steps of a tenth of Euler's load, the 4 lowest eigenvalues tracked).
    RuntimeError where no branch point is found below p_max."""
    if rod.support != "pinned":
        raise ValueError(f"the rod must be a pinned column, got support {rod.support!r}")
    P_E = euler_load(rod.length, rod.B)
    p_max = 1.2 * P_E if p_max is None else float(p_max)
    return _first_branch_point(rod.energy, rod.straight(0.0), rod.params, 0.1 * P_E, p_max, options)
