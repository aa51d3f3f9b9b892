"""Scenes and their constructors: rings, closed curves and knots, clamped and free rods.

The scene classes live in ``jaxrod.model.rods`` (``Scene``, ``ClosedRod``, ``ClampedRod``,
``FreeRod``), the energy terms they sum in ``jaxrod.model.terms`` and the knots' point tables in
``jaxrod.model.knots``; all of them are importable from here. A scene's terms are extended with
``scene.with_terms(term, ...)``."""
from __future__ import annotations

import math
import warnings
from dataclasses import replace

import jax.numpy as jnp
import numpy as np

from .geometry import closest_approach, perpendicular_unit, resample_closed
from .knots import IDEAL_ROPELENGTH, IDEAL_TREFOIL_ROPELENGTH, KNOT_NAMES, knot_points, trefoil_points
from .material import Material
from .rods import ClampedRod, ClosedRod, FreeRod, Scene, _pytree  # noqa: F401  (_pytree: scene subclasses)
from .terms import Bend, Contact, Coupling, Stretch, Term, Twist
from .topology import writhe
from ..validation import check_finite, check_int_at_least, check_positive, is_traced, require_concrete

__all__ = ["Scene", "ClosedRod", "ClampedRod", "FreeRod", "Term", "Coupling", "Stretch", "Bend", "Twist", "Contact",
           "ring", "michell_ring", "closed_curve", "clamped_rod", "free_rod", "michell_critical_twist", "figure_eight_energy",
           "clamped_critical_twist", "trefoil", "knot", "knot_points", "IDEAL_ROPELENGTH", "trefoil_points",
           "torus_knot", "IDEAL_TREFOIL_ROPELENGTH"]

TWO_PI = 2.0 * math.pi


def michell_critical_twist(nu):
    """Michell's critical total twist of a ring: 2 pi sqrt(3) B/C = 2 pi sqrt(3) (1 + nu)."""
    return TWO_PI * math.sqrt(3.0) * (1.0 + nu)


def figure_eight_energy(length=TWO_PI, B=1.0):
    """Bending energy of the closed planar figure-eight elastica of the given length, in units of B.

    The zero-thickness limit of Michell's buckled ring at its first self-contact: a strand passage
    changes Wr by 2, so the touching curve of a vanishing thickness is the nearly planar one with
    Wr = 1; a planar closed curve other than the circle is in equilibrium only untwisted (Tw = 0),
    so Lk = 1 (imposed twist 2 pi) and the curve is a free closed elastica: the figure eight.
    Its curvature is 2 k alpha cn(alpha s | m), m = k^2, closed over one period 4K(m)/alpha =
    length where 2E(m) = K(m) (m = 0.8261148); (B/2) int kappa^2 ds = 32 B K(m)^2 (m - 1/2) / length:
    8.9476598 B/R for a ring of radius R (length 2 pi R)."""
    from scipy.optimize import brentq  # noqa: PLC0415  (host-side constants only)
    from scipy.special import ellipe, ellipk  # noqa: PLC0415

    check_positive("length", length)
    m = brentq(lambda m: 2.0 * ellipe(m) - ellipk(m), 0.5, 0.99, xtol=1e-15)
    return 32.0 * B * float(ellipk(m)) ** 2 * (m - 0.5) / length


def clamped_critical_twist(B, C):
    """Critical twist of a straight rod clamped at both ends at fixed distance (no tension):
    the end moment M = C phi / L reaches M L / B = 8.9868 (twice the first positive root of
    tan x = x), so phi* = 8.9868 B / C."""
    x = 4.493409457909064  # first positive root of tan x = x
    return 2.0 * x * B / C


def _check_material(material):
    if not isinstance(material, Material):
        raise TypeError(f"material must be a jaxrod.Material, got {type(material).__name__}")
    return material


# A drawn curve's writhe this far from the nearest integer leaves Lk0 = round(writhe) in doubt
# (a warning); the standard trefoil drawing sits at 3.35 and relaxes to 3.05 with Lk0 = 3.
AMBIGUOUS_WRITHE = 0.4


def closed_curve(points, *, material, N=None, length=None, Lk0=None, name="closed curve", contact_stiffness=None):
    """A closed rod along the closed polyline ``points`` (M,3) (last point not repeating the first).

    The curve is resampled to N nodes equally spaced in arc length (default N = M) and scaled to
    total length ``length`` (default: its own); every edge gets rest length L/N. Lk0 defaults to
    the integer nearest the writhe (a warning when that is ambiguous); that is the twist-free rod
    only if the curve is close to its relaxed shape (``relax_to_minimum`` warns otherwise). The
    twist angles start uniform. contact_stiffness: kappa_c (units of B/D^3) of soft self-contact,
    which needs the material's D; None (default): no contact.

    ``length``, ``contact_stiffness`` and the material's parameters may be jax tracers (then
    unchecked); ``points``, N and Lk0 must be concrete.
    """
    _check_material(material)
    x, perimeter, N = _resampled_closed_points(points, N)
    scale = None  # a traced length: the curve stays at its own size until Lk0 and the twist are fixed
    if length is not None:
        length = check_positive("length", length)
        if is_traced(length):
            x, scale = x - x.mean(axis=0), length / perimeter
        else:
            x = (x - x.mean(axis=0)) * (length / perimeter)
    else:
        length = perimeter
    Lk0, theta = _linking_and_twist(x, N, Lk0, material, name)
    if scale is None:
        rest, q0 = np.full(N, length / N), np.concatenate([x.ravel(), theta])
    else:  # the writhe, Lk0 and the holonomy do not depend on the scale
        rest, q0 = jnp.full(N, length / N, dtype=jnp.float64), jnp.concatenate([(jnp.asarray(x) * scale).ravel(), jnp.asarray(theta)])
    scene = ClosedRod(material=material, rest_lengths=jnp.asarray(rest), q_init=jnp.asarray(q0), Lk0=float(Lk0), name=name)
    if contact_stiffness is None:
        return scene
    if material.D is None:
        raise ValueError("contact needs the rod diameter: give the material a D")
    stiffness = check_positive("contact_stiffness", contact_stiffness)
    return replace(scene, contact_stiffness=stiffness).with_terms(Contact())


def _resampled_closed_points(points, N):
    """(x (N, 3), perimeter, N): ``points`` checked and resampled to N nodes equally spaced in
    arc length, or ValueError (not (M, 3), not finite, too short, passing through itself)."""
    require_concrete("points", points, "the curve fixes the scene's linking number and its twist")
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (M, 3), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points must be finite")
    N = check_int_at_least("N", pts.shape[0] if N is None else N, 4)
    given = float(np.sum(np.linalg.norm(np.roll(pts, -1, axis=0) - pts, axis=0 if pts.shape[0] < 2 else 1)))
    if pts.shape[0] < 3 or not given > 0.0:
        raise ValueError(f"points must describe a closed curve of positive length (got {pts.shape[0]} point(s) "
                         f"of total length {given:.3g})")
    x = resample_closed(pts, N)
    perimeter = float(np.sum(np.linalg.norm(np.roll(x, -1, axis=0) - x, axis=1)))
    gap = closest_approach(x, closed=True)
    if gap <= 1e-9 * perimeter:
        # Its writhe, and so the holonomy's branch and Lk0, is undefined; a rod cannot lie there.
        raise ValueError(f"points: the curve (resampled to N = {N}) passes through itself "
                         f"(two segments {gap:.2g} apart)")
    return x, perimeter, N


def _linking_and_twist(x, N, Lk0, material, name):
    """(Lk0, theta (N,)): Lk0 checked, or the integer nearest the writhe of the nodes x (a warning
    when that is ambiguous), and the uniform twist angles that spread the joint's holonomy."""
    wr = float(writhe(jnp.asarray(x), closed=True))
    if Lk0 is None:
        Lk0 = int(round(wr))
        if abs(wr - Lk0) > AMBIGUOUS_WRITHE:
            warnings.warn(f"points: the curve's writhe {wr:.3f} is nearly half-way between two integers: Lk0 = {Lk0} "
                          f"taken (the nearer one); give Lk0 if the untwisted rod has another linking number",
                          stacklevel=3)
    else:
        Lk0 = check_int_at_least("Lk0", Lk0, -10**6)
    # only the nodes and Lk0 enter the joint's twist: the probe's rest lengths are placeholders
    probe = ClosedRod(material=material, rest_lengths=jnp.ones(N), q_init=jnp.zeros(4 * N), Lk0=float(Lk0), name=name)
    rho = float(probe.joint_reference_twist(jnp.asarray(x)))
    return Lk0, rho * np.arange(N) / N  # every vertex, the joint included, then carries rho / N


DEFAULT_CONTACT_STIFFNESS = 100.0
# Young's modulus of the seed paper's elastomer rod, 0.474 MPa (= N/mm^2, for lengths in mm): the
# default of every knot factory and of the CLI. It scales energies only.
PAPER_YOUNG_MODULUS = 0.474
# Fewest nodes of a trefoil: three crossings need a few edges each to be resolved at all.
MIN_TREFOIL_NODES = 24
# A knot with L/D below this multiple of its ideal ropelength is "nearly tight" (a warning).
NEARLY_TIGHT = 1.25


def check_knot_resolution(N, D, L, minimum):
    """N as an int, or ValueError naming N: at least ``minimum`` and at least L/D, so that no edge
    is longer than the diameter (else strands fall between the contact quadrature points). With D
    or L a jax tracer only N itself is checked."""
    N = check_int_at_least("N", N, minimum)
    if is_traced(D) or is_traced(L):
        return N
    need = math.ceil(L / D - 1e-9)
    if N < need:
        raise ValueError(f"N = {N} gives edges of {L / N / D:.2f} D: self-contact needs edges no longer than the "
                         f"diameter, N >= L/D = {need}")
    return N


def trefoil(*, N, D, L, E=PAPER_YOUNG_MODULUS, nu=0.5, chirality="right", contact_stiffness=DEFAULT_CONTACT_STIFFNESS):
    """A closed trefoil knot of rod diameter D and length L, N nodes, material (E, nu, D); E in MPa
    for lengths in mm (default 0.474, the seed paper's elastomer), energies then in N mm. Refuses
    L/D below the ideal trefoil's 16.372. The initial curve is the standard parametrisation scaled
    to length L (not yet relaxed). D, L, E, nu and contact_stiffness may be jax tracers (their
    checks then skipped); N and the chirality must be concrete."""
    return _knot_scene("3_1", lambda n: trefoil_points(n, chirality), D, L, N, E, nu, contact_stiffness,
                       f"{chirality}-handed trefoil")


def knot(name, *, N, D, L, E=PAPER_YOUNG_MODULUS, nu=0.5, contact_stiffness=DEFAULT_CONTACT_STIFFNESS, Lk0=None):
    """A closed rod tied in a tabulated knot, with soft self-contact.

    The initial curve is the knot's parametrisation (``knot_points``) scaled to length L, not
    yet relaxed. D, L, E, nu and contact_stiffness may be jax tracers (the checks on L/D are
    then skipped); name, N and Lk0 must be concrete.

    Parameters
    ----------
    name : str
        '3_1', '4_1', '5_1' or '5_2'.
    N : int
        Nodes, at least 24 and, with contact, at least L/D (no edge longer than the diameter).
    D : float
        Rod diameter (mm).
    L : float
        Rod length (mm); L/D at least the knot's ideal ropelength (``IDEAL_ROPELENGTH``).
    E : float, optional
        Young's modulus (MPa = N/mm^2; default 0.474). Energies are then in N mm.
    nu : float, optional
        Poisson ratio in (-1, 0.5] (default 0.5): C = B/(1+nu).
    contact_stiffness : float or None, optional
        Contact stiffness kappa_c (units of B/D^3; default 100); None: no self-contact.
    Lk0 : int, optional
        Linking number at zero twist (default: the drawn curve's writhe, rounded).

    Returns
    -------
    ClosedRod
        The scene; its DOFs ``q_init`` have shape (4 N,): 3 N coordinates (mm), then N twist
        angles (rad).

    Raises
    ------
    ValueError
        An unknown ``name``, L/D below the ideal ropelength, N too small, or a parameter out of
        range (the message names it). Warns (UserWarning) when L/D is within 25% of the ideal.
    """
    if name not in IDEAL_ROPELENGTH:
        raise ValueError(f"knot must be one of {', '.join(IDEAL_ROPELENGTH)}, got {name!r}")
    return _knot_scene(name, lambda n: knot_points(name, n), D, L, N, E, nu, contact_stiffness, KNOT_NAMES[name],
                       Lk0=Lk0)


def _knot_scene(name, points, D, L, N, E, nu, contact_stiffness, title, Lk0=None):
    """The checks every knot shares, then ``closed_curve`` through ``points(n)`` ((n, 3), the
    parametrisation sampled at n = max(4 N, 400) points); L/D is not checked for a traced D or L."""
    D = check_positive("D", D)
    L = check_positive("L", L)
    ideal = IDEAL_ROPELENGTH[name]
    concrete_ratio = not (is_traced(D) or is_traced(L))
    if concrete_ratio and L / D < ideal:
        raise ValueError(
            f"L/D = {L / D:.3f} is below the ideal {KNOT_NAMES[name]}'s ropelength {ideal}: "
            f"no {KNOT_NAMES[name]} of this rod can exist (increase L or decrease D)"
        )
    N = check_int_at_least("N", N, MIN_TREFOIL_NODES)
    if contact_stiffness is not None:
        N = check_knot_resolution(N, D, L, minimum=MIN_TREFOIL_NODES)
    if concrete_ratio and L / D < NEARLY_TIGHT * ideal:
        warnings.warn(
            f"L/D = {L / D:.2f} is within {100 * (NEARLY_TIGHT - 1):.0f}% of the ideal {KNOT_NAMES[name]}'s "
            f"{ideal}: the knot is nearly tight, and its equilibria depend on the contact stiffness", stacklevel=3)
    mat = Material.from_engineering(E, nu, D)
    return closed_curve(points(max(4 * N, 400)), material=mat, N=N, length=L, name=title,
                        contact_stiffness=contact_stiffness, Lk0=Lk0)


def torus_knot(p, q, *, N, D, L, E=PAPER_YOUNG_MODULUS, nu=0.5, radii=(2.0, 1.0),
               contact_stiffness=DEFAULT_CONTACT_STIFFNESS):
    """The (p, q) torus knot ((R + r cos qt) cos pt, (R + r cos qt) sin pt, r sin qt) as a
    closed rod, scaled to length L, not yet relaxed.

    D, L, E, nu and contact_stiffness may be jax tracers; p, q, N and the radii must be concrete.

    Parameters
    ----------
    p, q : int
        Coprime positive integers: turns around the torus axis and through its hole.
    N : int
        Nodes, at least 4 and, with contact, at least L/D.
    D : float
        Rod diameter (mm).
    L : float
        Rod length (mm).
    E : float, optional
        Young's modulus (MPa; default 0.474). Energies are then in N mm.
    nu : float, optional
        Poisson ratio in (-1, 0.5] (default 0.5).
    radii : (float, float), optional
        (R, r) of the drawn curve (default (2, 1)); only the shape matters, it is rescaled to L.
    contact_stiffness : float or None, optional
        Contact stiffness kappa_c (units of B/D^3; default 100); None: no self-contact.

    Returns
    -------
    ClosedRod
        The scene; ``q_init`` has shape (4 N,).

    Raises
    ------
    ValueError
        p and q not coprime, N too small, a traced radius, or a parameter out of range.
    """
    p = check_int_at_least("p", p, 1)
    q = check_int_at_least("q", q, 1)
    if math.gcd(p, q) != 1:
        raise ValueError(f"p and q must be coprime for a knot, got p={p}, q={q}")
    D = check_positive("D", D)
    L = check_positive("L", L)
    N = check_int_at_least("N", N, 4)
    if contact_stiffness is not None:
        N = check_knot_resolution(N, D, L, minimum=4)
    R, r = (require_concrete("radii", v, "they draw the curve, which fixes the linking number") for v in radii)
    t = TWO_PI * np.arange(max(4 * N, 400)) / max(4 * N, 400)
    pts = np.stack([(R + r * np.cos(q * t)) * np.cos(p * t), (R + r * np.cos(q * t)) * np.sin(p * t), r * np.sin(q * t)], axis=1)
    mat = Material.from_engineering(E, nu, D)
    return closed_curve(pts, material=mat, N=N, length=L, name=f"T({p},{q}) torus knot",
                        contact_stiffness=contact_stiffness)


def ring(*, N, material, radius=1.0, Lk0=0):
    """A planar circular ring: the regular N-gon whose edges have the rest length 2 pi radius / N.

    The radius and the material's parameters may be jax tracers; N and Lk0 set the scene's
    structure and must be concrete.

    Parameters
    ----------
    N : int
        Nodes, at least 4.
    material : Material
        Stiffnesses (B, C, EA and optionally D).
    radius : float, optional
        Radius of the rest circle (length unit of the material; default 1).
    Lk0 : int, optional
        Linking number at zero twist (default 0).

    Returns
    -------
    ClosedRod
        The scene; ``q_init`` has shape (4 N,): 3 N coordinates, then N twist angles (rad).

    Raises
    ------
    TypeError
        ``material`` is not a ``Material``.
    ValueError
        N below 4, a radius that is not positive, or a traced Lk0.
    """
    _check_material(material)
    N = check_int_at_least("N", N, 4)
    radius = check_positive("radius", radius)
    Lk0 = require_concrete("Lk0", Lk0, "it fixes the holonomy's 2 pi branch")
    xp = jnp if is_traced(radius) else np  # numpy for concrete values: the scene is built on the host
    edge = TWO_PI * radius / N
    r_poly = edge / (2.0 * math.sin(math.pi / N))
    s = TWO_PI * np.arange(N) / N
    x = xp.stack([r_poly * xp.cos(s), r_poly * xp.sin(s), xp.zeros(N)], axis=1)
    q0 = xp.concatenate([x.ravel(), xp.zeros(N)])
    return ClosedRod(material=material, rest_lengths=jnp.full(N, edge, dtype=jnp.float64), q_init=jnp.asarray(q0), Lk0=float(Lk0), name="ring")


def michell_ring(*, N, nu=0.5, slenderness=0.01, radius=1.0):
    """Michell's ring: B = 1, C = B/(1+nu), diameter D = slenderness * radius, EA = 16 B/D^2.

    At the default D/R = 0.01 extensibility shifts the critical twist by ~1e-5 relative or less.
    nu, slenderness and radius may be jax tracers (their values then unchecked); N must be concrete.

    Parameters
    ----------
    N : int
        Nodes, at least 4.
    nu : float, optional
        Poisson ratio in (-1, 0.5] (default 0.5).
    slenderness : float, optional
        D / radius (default 0.01).
    radius : float, optional
        Ring radius (default 1; energies then in units of B/radius).

    Returns
    -------
    ClosedRod
        The ring scene (see ``ring``).

    Raises
    ------
    ValueError
        N below 4, nu outside (-1, 0.5], or a slenderness or radius that is not positive.
    """
    nu = check_finite("nu", nu)
    slenderness = check_positive("slenderness", slenderness)
    radius = check_positive("radius", radius)
    mat = Material.from_ratio(B=1.0, nu=nu, D=slenderness * radius)
    return ring(N=N, material=mat, radius=radius)


def clamped_rod(*, N, length, material, axis=(0.0, 0.0, 1.0)):
    """Straight rod of N nodes along ``axis``, clamped at both ends.

    The clamped first and last edges are rigid; the material frame of an edge lives at its
    midpoint, so the clamps act at the midpoints of the end edges, and those are ``length`` apart
    (edge length = length/(N-2)). The twisted straight rod then stores exactly C phi^2/(2 length).
    ``length`` and the material's parameters may be jax tracers; N and the axis must be concrete.

    Parameters
    ----------
    N : int
        Nodes, at least 5.
    length : float
        Distance between the clamps (length unit of the material).
    material : Material
        Stiffnesses (B, C, EA and optionally D).
    axis : (3,) array_like, optional
        Direction of the rod (default z); normalised.

    Returns
    -------
    ClampedRod
        The scene; ``q_init`` has shape (4 N - 15,): the 3 (N - 4) coordinates of the free
        nodes, then the N - 3 free edges' twist angles (rad).

    Raises
    ------
    TypeError
        ``material`` is not a ``Material``.
    ValueError
        N below 5, a length that is not positive, or an axis that is not a finite non-zero 3-vector.
    """
    _check_material(material)
    N = check_int_at_least("N", N, 5)
    length = check_positive("length", length)
    xp = jnp if is_traced(length) else np  # numpy for concrete values: the scene is built on the host
    a = np.asarray(require_concrete("axis", axis, "it sets the clamps' frame"), dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)) or np.linalg.norm(a) == 0:
        raise ValueError(f"axis must be a finite non-zero 3-vector, got {axis!r}")
    a = a / np.linalg.norm(a)
    edge = length / (N - 2)
    x = (xp.arange(N) - 0.5)[:, None] * edge * xp.asarray(a)[None, :]
    d0 = np.asarray(perpendicular_unit(jnp.asarray(a)))
    q0 = xp.concatenate([x[2:-2].ravel(), xp.zeros(N - 3)])
    return ClampedRod(
        material=material,
        rest_lengths=jnp.full(N - 1, edge, dtype=jnp.float64),
        q_init=jnp.asarray(q0),
        x_clamped=jnp.asarray(x[np.array([0, 1, -2, -1])]),
        director_start=jnp.asarray(d0),
        name="clamped rod",
    )


def free_rod(*, N, length, material):
    """Straight free rod of N nodes along z. ``length`` and the material's parameters may be jax
    tracers; N must be concrete."""
    _check_material(material)
    N = check_int_at_least("N", N, 4)
    length = check_positive("length", length)
    edge = length / (N - 1)
    if is_traced(length):
        x = jnp.zeros((N, 3)).at[:, 2].set(jnp.arange(N) * edge)
        q0 = jnp.concatenate([x.ravel(), jnp.zeros(N - 1)])
    else:  # numpy for concrete values: the scene is built on the host
        x = np.zeros((N, 3))
        x[:, 2] = np.arange(N) * edge
        q0 = np.concatenate([x.ravel(), np.zeros(N - 1)])
    return FreeRod(material=material, rest_lengths=jnp.full(N - 1, edge, dtype=jnp.float64), q_init=jnp.asarray(q0), name="free rod")
