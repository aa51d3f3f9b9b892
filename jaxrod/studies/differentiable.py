"""Equilibria and critical twists as JAX-differentiable functions of a scene's continuous parameters.

``critical_twist_function(scene, side, parameters)`` returns ``f(values) -> phi*`` and
``equilibrium_function(scene, phi, parameters, start)`` returns ``q(values)``; ``jax.grad``,
``jax.jacfwd``, ``jax.jvp``, ``jax.jit`` and ``jax.vmap`` go through both, and no derivative is a
finite difference or a differentiation through a solver's iterations:

- a knot's end is located once, at the scene's own values, by its twist study on the extended
  system (a fold, or a simple branch point); f follows that root of the fold system (F, sigma) or
  of the unfolded branch-point system (F + beta v0, sigma, tau) to other values by Newton's method
  (``jaxrod.continuation.arclength.roots``), and its derivatives of every order come from the
  implicit function theorem on the same system (``jaxrod.solve.implicit``): second derivatives by
  forward-over-reverse included. At a branch point of the symmetric branch the derivative is that
  of the symmetric branch's branch point (the unfolding keeps the symmetry). An end that another
  instability overtakes away from the base values is not noticed: ``critical_twists`` at those
  values says which end comes first;
- a ring's or clamped rod's end (Michell's and Greenhill's double branch points, where the unfolded
  system is singular) is located again at each value by ``critical_twist`` on the host, with the
  exact first derivative of the crossing eigenvalue (``critical_twist_sensitivity``) attached by
  ``jax.custom_jvp``; second derivatives are not available there;
- an equilibrium is the root of F = grad E = 0 with the gauge pinned (``pinned_problem``,
  ``knot_problem``: the rigid motions, and a knot's exact slide, held at their values in the start
  state), so its derivative is the one in that gauge; the zero modes never enter.

``jaxrod.studies.design`` uses these exact derivatives: the value of a parameter that puts an end
at a target, the widest stable twist window, and fits to measured onsets.
"""
from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from ..continuation.arclength.roots import branch_point_root, equilibrium_root, fold_root
from ..continuation.arclength.rods import knot_problem, pinned_problem
from ..continuation.kinds import EventKind
from ..linalg.bordered import DenseBackend
from ..solve.implicit import implicit_root
from .critical_ends import CriticalEnd, critical_twist_sensitivity, is_knot, knot_ends, parameter_value, ring_end

__all__ = ["critical_twist_function", "equilibrium_function", "SIDES"]

SIDES = ("plus", "minus")


def _names(scene, parameters):
    names = (parameters,) if isinstance(parameters, str) else tuple(parameters)
    if not names:
        raise ValueError("parameters: name at least one of " + ", ".join(scene.PARAMETERS))
    return names, np.array([parameter_value(scene, name) for name in names])  # ValueError for an unknown name


def _checked(values, names):
    values = jnp.asarray(values, jnp.float64)
    if values.shape != (len(names),):
        raise ValueError(f"values must have shape ({len(names)},), one per parameter {names}; got {values.shape}")
    return values


def _setter(names):
    """set_values(args, theta): a pinned rod's RodArgs with the parameters ``names`` set to theta
    (traceable: ``scene.with_params`` passes tracers, and checks concrete values)."""
    def set_values(args, theta):
        return args._replace(scene=args.scene.with_params(**{name: theta[i] for i, name in enumerate(names)}))

    return set_values


def _differentiable_root(system):
    """x(values) of a RootSystem, its last 64 host roots kept (a value and its derivatives share one)."""
    keep = functools.lru_cache(maxsize=64)(lambda key: system.solve(np.array(key)))
    solve = lambda theta: keep(tuple(float(v) for v in np.asarray(theta, dtype=np.float64)))  # noqa: E731
    return implicit_root(system.residual, solve, system.x0.size, system.jacobian)


def _ring_function(scene, side, names, phi_min, phi_max, options):
    """phi*(values) of a ring or clamped rod: located again on the host at each value, with the exact
    first derivative of its crossing eigenvalue attached by ``jax.custom_jvp``."""
    @functools.lru_cache(maxsize=64)
    def solve(values):
        rod = scene.with_params(**dict(zip(names, values)))
        end = ring_end(rod, side, phi_max if side == "plus" else phi_min, options)
        slope = [critical_twist_sensitivity(rod, end, name) for name in names]
        return np.float64(end.phi), np.asarray(slope, dtype=np.float64)

    shapes = (jax.ShapeDtypeStruct((), jnp.float64), jax.ShapeDtypeStruct((len(names),), jnp.float64))

    def located(values):
        host = lambda v: solve(tuple(float(x) for x in np.asarray(v, dtype=np.float64)))  # noqa: E731
        return jax.pure_callback(host, shapes, _checked(values, names), vmap_method="sequential")

    @jax.custom_jvp
    def slope_of(values):
        return located(values)[1]

    @slope_of.defjvp
    def _no_second_derivative(primals, tangents):
        raise NotImplementedError("second derivatives of a ring's or clamped rod's critical twist are not available "
                                  "(its end is a double branch point, where the unfolded system is singular); a knot's "
                                  "fold or simple branch point has them")

    @jax.custom_jvp
    def phi_star(values):
        return located(values)[0]

    @phi_star.defjvp
    def _phi_star_jvp(primals, tangents):
        phi = phi_star(primals[0])
        return phi, jnp.dot(slope_of(primals[0]), jnp.asarray(tangents[0], jnp.float64))

    return phi_star


def _knot_function(scene, side, names, base, end, phi_min, phi_max, options):
    """phi*(values) of a knot: its end (located here unless given) followed as the root of its
    extended system, differentiable to any order."""
    if end is None:
        end = knot_ends(scene, phi_min, phi_max, options).get(side)
        if end is None:
            raise RuntimeError(f"no branch end on the {side} side between {phi_min / math.pi:+.4f} pi and "
                               f"{phi_max / math.pi:+.4f} pi")
    elif not isinstance(end, CriticalEnd) or end.side != side or not hasattr(end.source, "rod"):
        raise ValueError(f"end must be the {side} CriticalEnd of critical_twists(scene) for this knot")
    if end.kind not in (EventKind.FOLD, EventKind.BRANCH_POINT) or end.multiplicity > 1:
        raise ValueError(f"the {side} end is a {end.kind} of multiplicity {end.multiplicity}: a knot's critical twist "
                         "is differentiated at a fold or a simple branch point (a regular extended system)")
    problem, ev = end.source.rod.problem, end.source.event
    make = fold_root if end.kind == EventKind.FOLD else branch_point_root
    system = make(problem, np.asarray(ev.u), float(ev.p), np.asarray(ev.v[:, 0]), _setter(names), base,
                  problem.args._replace(nbr=None))
    root = _differentiable_root(system)

    def phi_star(values):
        return root(_checked(values, names))[system.p_index]

    phi_star.end = end
    return phi_star


def critical_twist_function(scene, side, parameters, phi_min=-8.0 * math.pi, phi_max=8.0 * math.pi, options=None,
                            *, end=None):
    """phi* of one side as a differentiable function of some of the scene's parameters.

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod at the base values; its other parameters, geometry and terms stay fixed.
    side : str
        'plus' (the end found twisting up from phi = 0) or 'minus'.
    parameters : sequence of str
        Names in ``scene.PARAMETERS`` ('B', 'C', 'EA', 'D', 'nu', 'contact_stiffness', 'diameter'), in the order
        of ``values``.
    phi_min, phi_max, options
        As for ``critical_twists``.
    end : CriticalEnd, optional
        A knot's end on this side from ``critical_twists(scene)``: not located again.

    Returns
    -------
    callable
        ``f(values)`` with values (k,) -> phi* (scalar, rad), float64. ``f.base`` holds the scene's
        own values (k,), a starting point; for a knot ``f.end`` is its ``CriticalEnd`` there.

    Raises
    ------
    ValueError
        An unknown side or parameter, or no parameter; for a knot, an end that is neither a fold nor
        a simple branch point. RuntimeError: a knot with no end in the range (a knot's end is located
        when f is made). Evaluating f raises what ``critical_twists`` raises for a ring (no end in
        the range); for a knot, where Newton does not find the end at the values asked.
    """
    if side not in SIDES:
        raise ValueError(f"side must be 'plus' or 'minus', got {side!r}")
    names, base = _names(scene, parameters)
    if is_knot(scene):
        phi_star = _knot_function(scene, side, names, base, end, phi_min, phi_max, options)
    else:
        phi_star = _ring_function(scene, side, names, phi_min, phi_max, options)
    phi_star.base = base
    phi_star.parameters = names
    return phi_star


def equilibrium_function(scene, phi, parameters, start):
    """The equilibrium at the twist phi as a differentiable function of some of the scene's parameters.

    The equilibrium ``start`` is followed to other parameter values by Newton's method on F = grad E
    = 0 with the gauge pinned (``pinned_problem``; a knot's ``knot_problem``): the rigid motions (and
    a knot's exact slide) are held at their values in ``start``, so the zero modes never enter and
    the derivative is the one in that gauge. Derivatives of every order by the implicit function
    theorem (``jaxrod.solve.implicit``); the linear algebra is dense (N up to a few hundred).

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod at the base values.
    phi : float
        The imposed twist (rad).
    parameters : sequence of str
        Names in ``scene.PARAMETERS``, in the order of ``values``.
    start : Equilibrium or array_like (n_dof,)
        An equilibrium of ``scene`` at phi (``relax_to_minimum``, ``newton``), or its DOFs q.

    Returns
    -------
    callable
        ``q(values)`` with values (k,) -> q (n_dof,) float64, the physical DOFs (node positions, then
        frame angles); ``q.base`` holds the scene's own values (k,).

    Raises
    ------
    ValueError
        An unknown parameter, or a start of the wrong shape. Evaluating q raises RuntimeError where
        Newton does not find the equilibrium at the values asked.
    """
    names, base = _names(scene, parameters)
    q0 = np.asarray(getattr(start, "q", start), dtype=float)
    if q0.shape != (scene.n_dof,):
        raise ValueError(f"start must be an equilibrium of the scene or its DOFs ({scene.n_dof},); got shape {q0.shape}")
    rod = (knot_problem if is_knot(scene) else pinned_problem)(scene, q0, float(phi), backend=DenseBackend())
    args = rod.problem.args
    exact = args._replace(nbr=None) if args.nbr is not None else args
    system = equilibrium_root(rod.problem, rod.restrict(scene.to_scaled(q0)), float(phi), _setter(names), base, exact)
    root = _differentiable_root(system)
    u_ref, free = jnp.asarray(rod.u_ref), jnp.asarray(rod.free)

    def q(values):
        return scene.from_scaled(u_ref.at[free].set(root(_checked(values, names))))

    q.base = base
    q.parameters = names
    return q
