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
- ``knot_first_end(knot, side)``: a ``CosseratKnot``'s branch through its equilibrium at phi = 0
  followed in phi to its first located fold or branch point, with a knot's material sliding kept
  out of the events (``_knot_soft_modes``).
"""
from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["cantilever_tip_deflection", "timoshenko_deflection", "column_buckling_load", "euler_load", "haringx_load",
           "engesser_load", "ring_critical_twist", "knot_first_end", "relax_cosserat"]


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


def _first_branch_point(energy, u0, params, step, p_max, options, kinds=("branch_point",), soft_modes=None,
                        update_args=None, jacobian=None):
    """The first located event of one of ``kinds`` on the branch of ``energy`` through (u0, 0),
    followed in its parameter up to p_max (down to -p_max for step < 0) by pseudo-arclength (steps
    ``step``, the 4 lowest eigenvalues tracked), in chunks of a few steps that stop once it is
    located (at most ``options.max_steps`` steps in all). RuntimeError where the first such event
    on the path was detected but not located (a later one would be the wrong answer), or where
    none was detected."""
    from dataclasses import replace

    from ..continuation import ContinuationOptions
    from ..continuation.arclength import BifurcationProblem, PseudoArclength, continuation_until
    from ..continuation.options import ARCLENGTH_DEFAULTS

    span = (-abs(step), p_max) if step > 0 else (-p_max, abs(step))
    opts = options or ContinuationOptions(ds=step, ds_max=abs(step), p_min=span[0], p_max=span[1], k=4)
    max_steps = opts.max_steps or ARCLENGTH_DEFAULTS["max_steps"]

    def of_kind(events):
        return [e for e in events if str(getattr(e.kind, "value", e.kind)) in kinds]

    def first_found(points, events):
        if of_kind(events):
            return "detected"
        return f"stopped after max_steps = {max_steps} steps" if len(points) > max_steps else ""

    problem = BifurcationProblem(energy, u0, 0.0, params, soft_modes=soft_modes, update_args=update_args,
                                 jacobian=jacobian)
    branch = continuation_until(problem, PseudoArclength(), replace(opts, max_steps=8), first_found)
    found = of_kind(branch.events)
    if not found:
        raise RuntimeError(f"no {' or '.join(kinds)} within {p_max:.6g} ({branch.message})")
    if not found[0].converged:
        e = found[0]
        raise RuntimeError(f"the first end, a {getattr(e.kind, 'value', e.kind)} near p = {e.p:.8g}, was detected "
                           f"but not located (residual {e.residual:.3g}, critical eigenvalue "
                           f"{e.critical_eigenvalue:.3g})")
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


def relax_cosserat(knot, phi=0.0, u=None, tol=1e-9, max_iterations=30, params=None):
    """The equilibrium (free DOFs (n_free,)) of a ``CosseratKnot`` at closure twist phi by Newton's
    method with the exact Hessian, from u (default ``knot.start()``, the Kirchhoff equilibrium);
    RuntimeError if the gradient's norm does not fall below ``tol`` times the edge's bending force
    scale B / l^2. params: (B, C, EA, GA) (default ``knot.params``)."""
    params = knot.params if params is None else params
    grad, hess = jax.jit(jax.grad(knot.energy)), jax.jit(knot.hessian)
    u = jnp.asarray(knot.start() if u is None else u)
    scale = knot.B / (knot.length / knot.N) ** 2
    for _ in range(max_iterations):
        near = knot.contact_list(u)
        contact = (jnp.asarray(near.pairs), jnp.asarray(near.mask))
        g = grad(u, phi, params, contact)
        if float(jnp.linalg.norm(g)) <= tol * scale:
            return np.asarray(u)
        u = u - jnp.linalg.solve(hess(u, phi, params, contact), g)
    raise RuntimeError(f"Newton left a gradient of {float(jnp.linalg.norm(g)):.3e} after {max_iterations} steps")


def knot_first_end(knot, side, span=4.0 * math.pi, step=0.1 * math.pi, options=None, GA=None):
    """The first end of a ``CosseratKnot``'s branch through its equilibrium at phi = 0, followed
    in phi towards ``side`` ('plus': phi > 0, 'minus': phi < 0) for at most ``span`` radians: the
    located ``Event`` (a fold or a branch point; p the twist in rad). Material sliding along the
    centreline is a soft mode, kept out of the events as for Kirchhoff knots. GA: the shear
    stiffness kGA (default ``knot.GA``); the same knot at several GA reuses its compiled programs."""
    if side not in ("plus", "minus"):
        raise ValueError(f"side must be 'plus' or 'minus', got {side!r}")
    if GA is not None and not float(GA) > 0.0:
        raise ValueError(f"GA must be positive, got {GA!r}")
    sign = 1.0 if side == "plus" else -1.0
    params = knot.params if GA is None else (*knot.params[:3], float(GA))
    u0 = relax_cosserat(knot, params=params)
    from ..continuation import ContinuationOptions

    opts = options or ContinuationOptions(ds=sign * step, ds_max=5.0 * step, p_min=-span if sign < 0 else -step,
                                          p_max=span if sign > 0 else step, k=6, max_steps=1000)
    built = knot.contact_list(u0)

    def update_args(u, phi, args):  # the list rebuilt once a node has moved by a quarter of D
        nonlocal built
        x, x_built = np.asarray(knot.full(jnp.asarray(u))[0]), built.x_built
        if np.max(np.linalg.norm(x - x_built, axis=1)) <= 0.5 * built.skin:
            return args
        built = knot.contact_list(u, capacity=len(built.mask))  # the same shape: no new compile (grown if outgrown)
        return (args[0], jnp.asarray(built.pairs), jnp.asarray(built.mask))

    energy, hessian = knot.continuation_functions
    args = (params, jnp.asarray(built.pairs), jnp.asarray(built.mask))
    return _first_branch_point(energy, u0, args, sign * step, span, opts, ("fold", "branch_point"),
                               _knot_soft_modes(knot), update_args, hessian)


class _Nodes:
    """The view of a closed rod's nodes that ``sliding_fields`` reads."""

    closed = True

    def __init__(self, x):
        self.x = np.asarray(x)
        self.n_nodes = self.n_free_nodes = len(self.x)

    def unpack(self, q, phi):
        return (self.x,)


def _knot_soft_modes(knot):
    """The ``soft_modes`` hook of a ``CosseratKnot``: the direction of the span of the lowest
    eigenvectors nearest material sliding, split off as soft where its node motions are, to less than
    ``SLIDING_FRACTION``, motions along the tangents plus a rigid motion and carry most of the mode
    (the frames' rotations, in length units, the rest: a slide also turns each frame by its twist
    and curvature times the distance slid, ~0.5 rad per edge length at 6 pi of twist on 41 edges,
    so they cannot count against it); the rest of the span as Ritz pairs."""
    import scipy.linalg

    from ..linalg.sliding import SLIDING_FRACTION, sliding_fields

    N, free, l = knot.N, knot.free, knot.length / knot.N

    def soft_modes(u, p, values, vectors):
        x, _ = knot.full(jnp.asarray(u))
        perp, rigid = sliding_fields(_Nodes(np.asarray(x)), 0.0)
        V = np.zeros((6 * N, vectors.shape[1]))
        V[free] = np.asarray(vectors)
        V[3 * N:] *= l
        off = np.einsum("nij,njm->nim", perp, V[:3 * N].reshape(N, 3, -1)).reshape(3 * N, -1)
        basis, _ = np.linalg.qr(rigid)
        off -= basis @ (basis.T @ off)
        moved = V[:3 * N].T @ V[:3 * N]
        lam, m = np.asarray(values), len(values)
        if m == 0 or np.linalg.eigvalsh(moved)[-1] <= 1e-12 * np.trace(V.T @ V):
            return lam, np.asarray(vectors), np.zeros(m, dtype=bool)
        G = off.T @ off
        g, C = scipy.linalg.eigh(0.5 * (G + G.T), 0.5 * (moved + moved.T) + 1e-12 * np.eye(m) * np.trace(moved))
        c = C[:, 0] / np.linalg.norm(C[:, 0])
        share = float(c @ moved @ c) / float(c @ (V.T @ V) @ c)
        if g[0] >= SLIDING_FRACTION or share < 0.5:
            return lam, np.asarray(vectors), np.zeros(m, dtype=bool)
        rest = np.linalg.svd(np.eye(m) - np.outer(c, c))[0][:, :m - 1]
        K = rest.T @ (lam[:, None] * rest)
        ritz, R = np.linalg.eigh(0.5 * (K + K.T))
        vals = np.concatenate([[float(c @ (lam * c))], ritz])
        coef = np.concatenate([c[:, None], rest @ R], axis=1)
        order = np.argsort(vals, kind="stable")
        return vals[order], (np.asarray(vectors) @ coef)[:, order], order == 0
    return soft_modes
