"""Rods under end loads: end shortening, tension and end rotation (issue 19).

Two ways of loading a rod clamped at both ends along one axis (the clamp at s = 0 fixed; the far
clamp, at s = L, holds its edge along the same axis and its material frame turned by the end
rotation ``phi``):

* **Displacement control** (``shortened_rod``): the far clamp sits a prescribed distance from
  the near one, L - shortening along the axis (``EndLoadedRod``; ``with_shortening`` moves it,
  traceably, so the shortening can be a continuation parameter). The end loads are derivatives
  of the energy at the equilibrium, exact by autodiff (``end_loads``): the tension
  T = dE/d(end distance) and the axial end moment M = dE/d(phi).
* **Force control** (``ForceLoadedRod``): a dead load T pulls the far clamp along the axis
  (potential -T times the clamp's displacement along the axis); its position is a degree of
  freedom, either along the axis only (``end="slide"``) or in space (``end="free"``), while the
  clamp's direction and rotation stay imposed.

Both close the rod for its linking number with rays along the clamp axis (``ClampedRod``'s
closure): the far clamp moves but its edge stays on the axis direction, so Lk = Wr + Tw =
Lk0 + phi / 2 pi holds along any path without strand passage.

Analytic reference (``localized_helix``): the localized (homoclinic) helical buckle of a long
clamped rod under tension T and twisting moment M (Neukirch, van der Heijden and Thompson 2002,
J. Mech. Phys. Solids 50, eqs. 14-15). With m = M L/B, t = T L^2/B, gamma = C/B, lambda =
sqrt(t - m^2/4) and s measured from the rod's midpoint, the tangent's angle theta to the axis
and its azimuth psi obey

    1 - cos theta = (2 lambda^2 / t) sech^2(lambda s / L),    psi' = (m / L) / (1 + cos theta),

from the first integrals B/2 (theta'^2 + psi'^2 sin^2 theta) + T cos theta = T and
B psi' sin^2 theta + M cos theta = M (twisting moment M3 = M); integrating gives the end shortening
d L = integral (1 - cos theta) ds = 4 lambda L / t, the largest angle cos theta_max = m^2/(2t) - 1,
and the end rotation R = m / gamma (twist) + 4 arccos(m / (2 sqrt t)) (2 pi times the ray-closed
writhe of the loop).
"""
from __future__ import annotations

import copy
import dataclasses
import functools
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..model.contact import contact_energy  # noqa: F401  (the contact term is the scenes' own)
from ..model.hessian import project_out, scaled_hessian as structured_scaled_hessian
from ..model.material import Material
from ..model.scenes import ClampedRod, _pytree, clamped_rod
from ..solve.solvers import DampedNewton, Newton, minimise, orthonormal_columns
from ..linalg.stability import DEFAULT_NEGATIVE_TOL, _lowest_of, _stability_from_lowest
from ..validation import check_finite, check_int_at_least, check_positive

__all__ = [
    "EndLoadedRod",
    "shortened_rod",
    "with_shortening",
    "with_end_offset",
    "end_loads",
    "EndLoads",
    "ForceLoadedRod",
    "ForceEquilibrium",
    "localized_helix",
    "localized_helix_from_shortening",
    "LocalizedHelix",
    "localization_parameter",
    "LOCALIZATION_MIN",
    "reference_check",
    "ReferenceCheck",
    "stretch_shift",
    "gradient_tolerance",
    "with_material",
    "stiffening_stages",
    "solve_from_helix",
    "localized_helix_curve",
    "plectoneme_plateau",
    "Plectoneme",
    "helical_start",
    "straight_buckling_moment",
    "tension_twist_threshold",
    "clamped_tension_twist_threshold",
    "check_helix_resolution",
    "check_rotation_resolution",
    "tangent_angles",
    "envelope_error",
    "named_helix_roots",
    "select_helix_roots",
    "choose_helix_root",
    "nearest_localized_helix",
    "relative_error",
    "tension_roundoff",
    "coarse_nodes",
    "richardson_extrapolation",
    "helix_state",
    "helix_root_row",
    "helix_profiles",
    "HelixProfiles",
    "solve",
    "newton",
]

TWO_PI = 2.0 * math.pi


# ---------------------------------------------------------------------- displacement control
@_pytree(["material", "rest_lengths", "q_init", "x_clamped", "director_start", "Lk0", "end_offset",
          "contact_stiffness"], ["terms", "name", "contact_quadrature"])
@dataclass(frozen=True, eq=False)
class EndLoadedRod(ClampedRod):
    """A ``ClampedRod`` whose far clamp (nodes N-2, N-1) is displaced by ``end_offset`` (3,) from
    its place one rod length from the near clamp; its edge keeps the axis direction. A shortening
    s is ``end_offset = -s * axis``. DOFs as ``ClampedRod``: q = [x[2:N-2].ravel(), theta[1:M-1]].
    ``contact_stiffness``: kappa_c of soft self-contact when "contact" is a term (as ``ClosedRod``);
    ``contact_quadrature``: Gauss points per segment in the contact integral (static: 1, 2 or 3)."""

    end_offset: np.ndarray = None
    contact_stiffness: float = 0.0
    contact_quadrature: int = 2

    # Rotating the interior nodes rigidly about the clamp axis, twist angles unchanged, leaves the
    # energy exactly unchanged: both clamped edges lie on the axis, the twist angles are measured
    # from space-parallel reference frames (which turn with the rod) and the far clamp's angle
    # (``end_angle``, the tantrix holonomy) is invariant. One exact zero mode.
    n_zero_modes = 1

    def zero_modes(self, q, phi):
        """(n, 1): the rigid rotation of the interior nodes about the clamp axis."""
        xi, theta = self.interior(q)
        rot = jnp.cross(self.axis[None, :], xi - self.x_clamped[0][None, :]).ravel()
        return jnp.concatenate([rot, jnp.zeros_like(theta)])[:, None]

    def nodes(self, q):
        xi, _ = self.interior(q)
        c = self.x_clamped
        return jnp.concatenate([c[:2], xi, c[2:] + self.end_offset[None, :]], axis=0)

    @property
    def shortening(self):
        """Distance the far clamp has moved towards the near one along the axis."""
        return -jnp.dot(self.end_offset, self.axis)

    @property
    def clamp_length(self):
        """L: the rest length between the clamps' material points (the midpoints of the clamped
        end edges), (N - 2) edges; ``length`` counts all N - 1 edges."""
        return jnp.sum(self.voronoi)

    @property
    def end_distance(self):
        """Distance between the clamp points along the axis (L when the shortening is 0)."""
        return self.clamp_length - self.shortening


def with_end_offset(scene, offset):
    """``scene`` with its far clamp displaced by ``offset`` (3,) from the unshortened position.
    Traceable (offset may be a tracer): a shallow copy, no validation."""
    new = copy.copy(scene)
    object.__setattr__(new, "end_offset", jnp.asarray(offset, dtype=jnp.float64))
    return new


def with_shortening(scene, shortening):
    """``scene`` with the far clamp ``shortening`` closer to the near one along the axis. Traceable."""
    return with_end_offset(scene, -shortening * scene.axis)


def shortened_rod(N, length, material, shortening=0.0, axis=(0.0, 0.0, 1.0), contact_stiffness=None, Lk0=0.0,
                  contact_quadrature=2):
    """A rod of rest length ``length`` (between the clamps' material points, as ``clamped_rod``)
    with N nodes, clamped at both ends along ``axis``, the far clamp ``shortening`` closer than one
    rod length (0 <= shortening < length). q_init: the interior nodes evenly spaced between the
    clamps on the axis (uniformly compressed, straight) and no twist.
    contact_stiffness: kappa_c of soft self-contact (needs the material's D); None: no contact.
    contact_quadrature: Gauss points per segment of the contact integral (1, 2 or 3; 3 where
    strands cross at short contacts with edges near D, as in a knot pulled tight)."""
    if contact_quadrature not in (1, 2, 3):
        raise ValueError(f"contact_quadrature must be 1, 2 or 3 Gauss points per segment, got {contact_quadrature!r}")
    base = clamped_rod(N, length, material, axis=axis)
    length = float(length)
    s = check_finite("shortening", shortening)
    if not 0.0 <= s < length:
        raise ValueError(f"shortening must lie in [0, length) = [0, {length:g}), got {shortening!r}")
    terms = base.terms
    kc = 0.0
    if contact_stiffness is not None:
        if material.D is None:
            raise ValueError("contact needs the rod diameter: give the material a D")
        kc = check_positive("contact_stiffness", contact_stiffness)
        terms = terms + ("contact",)
    a = np.asarray(base.axis)
    xc = np.asarray(base.x_clamped)
    n_free = N - 4
    q0 = np.asarray(base.q_init).copy()
    # evenly spaced between the near clamp's node 1 and the far clamp's node N-2
    start, stop = xc[1], xc[2] - s * a
    frac = np.arange(1, n_free + 1) / (n_free + 1)
    q0[:3 * n_free] = (start[None, :] + frac[:, None] * (stop - start)[None, :]).ravel()
    return EndLoadedRod(material=material, rest_lengths=base.rest_lengths, q_init=jnp.asarray(q0),
                        x_clamped=base.x_clamped, director_start=base.director_start, Lk0=float(Lk0),
                        end_offset=jnp.asarray(-s * a), contact_stiffness=kc, terms=terms,
                        name="end-loaded rod", contact_quadrature=int(contact_quadrature))


@dataclass(frozen=True)
class EndLoads:
    """End loads at an equilibrium: T the axial tension (> 0 pulls the clamps together), M the
    axial twisting moment at the far clamp, force (3,) dE/d(far clamp position) (its component
    along the axis is T; lateral components are the clamp's lateral reaction), M_twist the
    twisting moment C * (twist per length) along the rod (equal to M at an equilibrium: the
    twist equation makes every vertex's twist per length equal)."""

    T: float
    M: float
    force: np.ndarray
    M_twist: float


# ---------------------------------------------------------------------- compiled pieces
# Python compositions of separately jitted pieces (as ``jaxrod.linalg.stability``): the structured
# Hessian, the largest program to compile (~2-4 s per scene shape), is compiled once per shape in
# ``_rod_hessian`` and shared by Newton's steps, the stability analysis, the force-loaded rod's
# rod block and ``straight_buckling_moment``; the gradient and the end loads are one program
# (``_rod_gradients``). One jit around each solve compiled the Hessian into each of them.
def _f64(x):
    """A float64 array (never weakly typed: one compiled program per shape, whatever the caller passes)."""
    return jnp.asarray(np.asarray(x, dtype=np.float64))


def _offset_scaled_energy(scene, u, off, phi, nbr):
    return with_end_offset(scene, off).scaled_energy(u, phi, nbr)


@jax.jit
def _rod_all(scene, u, phi, nbr):
    """Everything Newton, the stability analysis and the end loads need at scaled DOFs u, in one
    program: (scaled energy, its gradient in u (n,), dE/d(far clamp offset) (3,) and dE/dphi in
    physical units, the twisting moment C * twist per length, the structured scaled Hessian
    (n, n), the zero-mode generators (n, k), scaled)."""
    val, (gu, goff, gphi) = jax.value_and_grad(_offset_scaled_energy, argnums=(1, 2, 3))(
        scene, u, scene.end_offset, phi, nbr)
    tw = scene.vertex_twists(u * scene.dof_scale, phi, nbr)
    M_twist = scene.material.C * jnp.sum(tw) / jnp.sum(scene.voronoi)
    es = scene.energy_scale
    return (val, gu, goff * es, gphi * es, M_twist, structured_scaled_hessian(scene, u, phi, nbr),
            scene.scaled_zero_modes(u, phi))


def _rod_gradients(scene, u, phi, nbr):
    """(scaled energy, gradient in u, dE/d(offset), dE/dphi, M_twist), host arrays."""
    return jax.device_get(_rod_all(scene, _f64(u), _f64(phi), nbr)[:5])


def _rod_hessian(scene, u, phi, nbr):
    """(structured scaled Hessian (n, n), zero-mode generators (n, k)), host arrays."""
    return jax.device_get(_rod_all(scene, _f64(u), _f64(phi), nbr)[5:])


def _project(h, z):
    """(H with the zero modes projected out and lifted to the top, n_zero), on the host: as
    ``jaxrod.linalg.stability``'s projected Hessian (``orthonormal_columns``, ``project_out``)."""
    h, z = np.asarray(h), np.asarray(z)
    if z.shape[1] == 0:
        return h, 0
    uz, sv, _ = np.linalg.svd(z, full_matrices=False)
    keep = sv > 1e-10 * np.max(sv) if np.max(sv) > 0.0 else np.zeros_like(sv, dtype=bool)
    z = uz * keep[None, :]
    return project_out(h, z, xp=np), int(np.sum(keep))


@jax.jit
def _offset_coupling(scene, u, phi, nbr):
    """(n + 3, 3): d/d(far clamp offset, physical) of [dE_s/du (n,), dE_s/d(offset) (3,)], E_s the
    scaled energy: the force-loaded rod's end rows and columns, by 3 forward-over-reverse products."""
    def g(off):
        gu, goff = jax.grad(_offset_scaled_energy, argnums=(1, 2))(scene, u, off, phi, nbr)
        return jnp.concatenate([gu, goff])

    return jax.jacfwd(g)(scene.end_offset)


# Eigenvalues of the scaled Hessian are known to ~ eps max|H_ii| only; a stiff rod's stretching
# entries, EA h^2/B ~ 1e8 at EA L^2/B ~ 1e12, then lift that noise (the projected-out axial
# rotation's eigenvalue, ~1e-8) above DEFAULT_NEGATIVE_TOL: it is not counted as negative.
EIGEN_ROUNDOFF_ULPS = 256.0


def _rod_stability(scene, u, phi, nbr, k, tol=DEFAULT_NEGATIVE_TOL):
    """``jaxrod.linalg.stability.stability`` on the shared compiled Hessian (same projection, same
    lowest-eigenpair routine and tolerance, raised to the Hessian's roundoff,
    EIGEN_ROUNDOFF_ULPS eps max|H_ii|, where that is larger)."""
    h, z = _rod_hessian(scene, u, phi, nbr)
    tol = max(float(tol), EIGEN_ROUNDOFF_ULPS * np.finfo(float).eps * float(np.max(np.abs(np.diag(np.asarray(h))))))
    hp, n_zero = _project(h, z)
    lam, vec, n_neg = _lowest_of(hp, tol)
    return _stability_from_lowest(np.asarray(lam), np.asarray(vec), int(n_zero), int(n_neg), k, tol)


def end_loads(scene, q, phi, nbr=None):
    """The ``EndLoads`` of state q (physical DOFs) at end rotation phi: exact partial derivatives of
    the energy in the far clamp's position and in phi (at an equilibrium these are the total
    derivatives of the equilibrium energy, by the envelope theorem). ``nbr``: the state's
    neighbourhood (``Equilibrium.neighbourhood``; built here if None)."""
    q = np.asarray(q, dtype=float)
    phi = check_finite("phi", phi)
    if nbr is None:
        nbr = scene.neighbourhood(q, phi)
    _, _, f, M, Mt = _rod_gradients(scene, scene.to_scaled(q), phi, nbr)
    f = np.asarray(f)
    return EndLoads(float(np.dot(f, np.asarray(scene.axis))), float(M), f, float(Mt))


# ---------------------------------------------------------------------- Newton with a capped step
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


def _host(fun):
    fun.host = True
    return fun


def newton(fun, hessian, y0, args, zero_modes=None, gtol=1e-9, max_step=0.5, max_steps=100, throw=True,
           value_and_grad=None, evaluate=None):
    """The stationary point of ``fun(y, args)`` nearest y0 (stable or not) by Newton's method with
    the exact ``hessian(y, args)`` (it may return (H, zero modes)), each step's largest component
    capped at ``max_step`` (scaled units: an edge length), exact symmetry directions
    ``zero_modes(y, args) -> (n, k)`` lifted out of the solve. No line search on |grad|: on a
    stiff (nearly inextensible) rod a good Newton step often raises |grad| for one iteration (a
    second-order stretch), which a merit test refuses, and the iteration then crawls.
    A Python loop over jitted pieces (``hessian``, ``zero_modes`` and ``value_and_grad(y, args)
    -> (value, grad)`` are jitted unless already jitted or marked host compositions), so that
    the compiled Hessian is shared with the stability analysis; ``evaluate(y, args) -> (value,
    grad, H, zero modes)``, where given, replaces all three (one program per step). Returns a
    ``jaxrod.solve.solvers.Solution``."""
    from ..solve.solvers import ConvergenceError, Solution, StopReason  # noqa: PLC0415

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


def _rod_evaluate(u, args):
    """(scaled energy, gradient, Hessian, zero modes) of an ``EndLoadedRod``: one program."""
    scene, phi, nbr = args
    val, gu, _, _, _, h, z = jax.device_get(_rod_all(scene, _f64(u), _f64(phi), nbr))
    return float(val), gu, h, z


def _check_scene(scene):
    if not isinstance(scene, EndLoadedRod):
        raise TypeError(f"scene must be an EndLoadedRod (jaxrod.studies.endloads.shortened_rod), got {type(scene).__name__}")


def _check_q(scene, name, q):
    q = np.asarray(q, dtype=float)
    if q.shape != (scene.n_dof,):
        raise ValueError(f"{name} must have shape ({scene.n_dof},) (the scene's DOFs), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ValueError(f"{name} must be finite")
    return q


# Newton's stopping test for a rod under end loads, in the rod's own force units: the residual
# force on every node below BEND_RTOL * B/L^2 (the bending scale; T L^2/B of the loops solved
# here is 1e2 ... 1e3) plus ROUNDOFF_ULPS roundoffs of the stretching and bending forces. A node's
# stretching force EA (|e|/h - 1) is computed from coordinates of size ~L: its roundoff is
# ~ eps (L/h) EA, which passes 1e-8 of the scaled gradient (a force of 1e-8 B/h^2) from
# EA ~ 1e10 B/L^2 at N = 240 on; the bending forces' (B/h^2 in place of EA) matters only at large N.
BEND_RTOL = 1e-6
ROUNDOFF_ULPS = 4.0


def gradient_tolerance(scene):
    """Newton's tolerance on the max |gradient| of ``scene``'s scaled energy (``solve``'s default):
    a residual force per node of BEND_RTOL B/L^2 + ROUNDOFF_ULPS eps (L/h) (EA + B/h^2), in the
    scaled gradient's unit B/h^2 (h the edge length, L the clamps' distance): the same relative
    accuracy at every EA, never below the roundoff of the stretching forces (a stiff rod,
    EA L^2/B ~ 1e9 and more, reaches no fixed tolerance). The twist angles' components (moments
    in units of B/h) are held to the same number, which is stricter for them."""
    _check_scene(scene)
    B, EA = float(scene.material.B), float(scene.material.EA)
    L, h = float(scene.clamp_length), float(scene.length_scale)
    force = BEND_RTOL * B / L ** 2 + ROUNDOFF_ULPS * np.finfo(float).eps * (L / h) * (EA + B / h ** 2)
    return force * h * h / B


def with_material(scene, material):
    """``scene`` with its material replaced (a shallow copy: the same compiled programs, the
    material's stiffnesses being leaves)."""
    if not isinstance(material, Material):
        raise TypeError(f"material must be a jaxrod.model.material.Material, got {type(material).__name__}")
    new = copy.copy(scene)
    object.__setattr__(new, "material", material)
    return new


def solve(scene, phi, q0, gtol=None, max_step=0.5, max_steps=200, k=8, throw=True, with_stability=True):
    """Equilibrium (``jaxrod.Equilibrium``, with its stability) of an ``EndLoadedRod`` at end
    rotation phi nearest q0 (physical DOFs), by ``newton`` on the scaled energy (the axial
    rotation lifted out) to max |gradient| <= gtol (None: ``gradient_tolerance(scene)``). Without
    contact only (the exact writhe fixes the twist's branch).
    Refused: a scene too coarse for its end rotation (more than ``MAX_TWIST_PER_EDGE`` rad of
    imposed twist per edge: N named), non-finite phi or q0, non-positive gtol or max_step."""
    from ..solve.equilibrium import equilibrium_from_solution  # noqa: PLC0415

    _check_scene(scene)
    phi = check_finite("phi", phi)
    gtol = gradient_tolerance(scene) if gtol is None else check_positive("gtol", gtol)
    check_positive("max_step", max_step)
    check_rotation_resolution(scene.n_nodes, phi)
    q0 = _check_q(scene, "q0", q0)
    nbr = scene.neighbourhood(q0, phi)
    sol = newton(None, None, scene.to_scaled(q0), (scene, phi, nbr), gtol=gtol, max_step=max_step,
                 max_steps=max_steps, throw=throw, evaluate=_rod_evaluate)
    q = scene.from_scaled(np.asarray(sol.y))
    nbr = scene.neighbourhood(q, phi)
    e = equilibrium_from_solution(scene, phi, sol, nbr, k=k, with_stability=False)
    if with_stability:
        e = dataclasses.replace(e, stability=_rod_stability(scene, sol.y, phi, nbr, k))
    return e


# A Newton step moves nodes across their edges, and the second-order stretch that causes, EA times
# (step / h)^2, dwarfs the loads of a stiff rod: from the analytic loop (a few per cent off the
# discrete one at the N used) Newton then wanders, or lands on the other loop of the same (d, R)
# (measured at N = 120: EA L^2/B = 1e8 gave t = 176 for 320; 1e12 did not converge).
# ``solve_from_helix`` solves a softer rod first, EA_0 = STIFFEN_FROM max(t, 4 pi^2) B/L^2 (never so
# soft that compressing the rod by the shortening costs less than buckling it, 4 pi^2 B/L^2), then
# stiffens it by at most STIFFEN_FACTOR per stage, each stage started from the last's state with
# its strains scaled down to the new EA (``_restretched``: the tension kept; started as it was, the
# state's tension jumps by the stage's factor, and at N = 400 the loop slid off along its soft
# modes, eigenvalues ~1e-7 in scaled units, to the other loop).
STIFFEN_FROM = 1e3
STIFFEN_FACTOR = 100.0


def stiffening_stages(scene, t):
    """The stretch stiffnesses EA (ascending, the last the scene's own) at which
    ``solve_from_helix`` solves a rod carrying t = TL^2/B."""
    _check_scene(scene)
    B, EA, L = float(scene.material.B), float(scene.material.EA), float(scene.clamp_length)
    ea0 = STIFFEN_FROM * max(float(t), 4.0 * math.pi ** 2) * B / L ** 2
    if EA <= ea0:
        return [EA]
    n = math.ceil(math.log(EA / ea0) / math.log(STIFFEN_FACTOR) - 1e-12)
    return [ea0 * (EA / ea0) ** (j / n) for j in range(n)] + [EA]


def solve_from_helix(scene, m, t, phi, gtol=None, max_steps=200, k=8, throw=True, with_stability=True):
    """Equilibrium of ``scene`` (an ``EndLoadedRod``) at end rotation phi, from NvdHT's loop (m, t)
    (``helical_start``; either sign of m), by ``solve``: through ``stiffening_stages`` (the same
    rod at increasing EA, each stage started from the last's state restretched to its EA; the
    compiled programs shared), the last to gtol (None: ``gradient_tolerance``). Refused: as
    ``helical_start`` and ``solve``.
    Raises ``jaxrod.solve.solvers.ConvergenceError`` (with ``throw``) where a stage does not converge."""
    _check_scene(scene)
    q = helical_start(scene, m, t, phi)
    stages = stiffening_stages(scene, t)
    for EA, stiffer in zip(stages[:-1], stages[1:]):
        soft = with_material(scene, dataclasses.replace(scene.material, EA=EA))
        q = solve(soft, phi, q, max_steps=max_steps, throw=throw, with_stability=False).q
        q = _restretched(scene, q, EA / stiffer)
    return solve(scene, phi, q, gtol=gtol, max_steps=max_steps, k=k, throw=throw, with_stability=with_stability)


# ---------------------------------------------------------------------- force control
_BASES = {"slide": 1, "free": 3}


def _offset_basis(scene, end):
    """(k, 3) directions in which the loaded end may move: the axis, or the three axes of space."""
    if end == "slide":
        return jnp.asarray(scene.axis)[None, :]
    return jnp.eye(3)


def _force_split(scene, u):
    n = scene.n_dof
    return u[:n], u[n:]


def force_energy(u, args):
    """Scaled energy of the force-loaded rod: u = [scaled rod DOFs (n,), end offset coordinates
    (k,) in units of the edge length]; args = (scene, phi, T, nbr, basis (k, 3)). The potential of
    the dead load is -T * (end offset . axis)."""
    scene, phi, T, nbr, basis = args
    ur, w = _force_split(scene, u)
    off = (w * scene.length_scale) @ basis
    rod = with_end_offset(scene, off)
    return rod.scaled_energy(ur, phi, nbr) - T * jnp.dot(off, scene.axis) / scene.energy_scale


_force_grad = jax.grad(force_energy)


def force_zero_modes(u, args):
    """(n + k, 1): the rigid rotation about the clamp axis (interior nodes and, for a free end,
    the end offset), in the scaled unknowns: an exact symmetry, as for ``EndLoadedRod``."""
    scene, phi, T, nbr, basis = args
    ur, w = _force_split(scene, u)
    off = (w * scene.length_scale) @ basis
    rod = with_end_offset(scene, off)
    z = rod.scaled_zero_modes(ur, phi)[:, 0]
    zw = basis @ jnp.cross(scene.axis, off) / scene.length_scale
    return jnp.concatenate([z, zw])[:, None]


def force_hessian(u, args):
    """Exact Hessian of ``force_energy``: the rod block by the structured assembly
    (``jaxrod.model.hessian``) at the current end position, the k end rows and columns by k
    Hessian-vector products."""
    scene, phi, T, nbr, basis = args
    ur, w = _force_split(scene, u)
    n, k = ur.shape[0], w.shape[0]
    rod = with_end_offset(scene, (w * scene.length_scale) @ basis)
    h_rr = structured_scaled_hessian(rod, ur, phi, nbr)
    e_w = jnp.concatenate([jnp.zeros((k, n)), jnp.eye(k)], axis=1)
    cols = jax.vmap(lambda e: jax.jvp(lambda uu: _force_grad(uu, args), (u,), (e,))[1])(e_w)  # (k, n + k)
    h = jnp.zeros((n + k, n + k), dtype=u.dtype).at[:n, :n].set(h_rr).at[n:, :].set(cols).at[:, n:].set(cols.T)
    return 0.5 * (h + h.T)


@dataclass(frozen=True)
class ForceEquilibrium:
    """An equilibrium of a ``ForceLoadedRod``: u (scaled DOFs, the end's included), q (physical rod
    DOFs), x (N, 3) nodes, end_offset (3,), extension (end offset along the axis: negative when the
    ends come closer), T, phi, M (axial moment dE/dphi), Wr, Tw, Lk, energy (rod only),
    grad_norm, converged, iterations, eigenvalues (lowest, scaled), morse (negative count)."""

    u: np.ndarray
    q: np.ndarray
    x: np.ndarray
    end_offset: np.ndarray
    extension: float
    T: float
    phi: float
    M: float
    Wr: float
    Tw: float
    Lk: float
    energy: float
    grad_norm: float
    converged: bool
    iterations: int
    eigenvalues: np.ndarray
    morse: int


class ForceLoadedRod:
    """A rod clamped at its near end, with a dead load T pulling its far clamp along the axis and
    the far clamp's material frame turned by phi. ``end``: "slide" (the far clamp moves along the
    axis only) or "free" (it moves in space; its edge stays along the axis). ``rod``: an
    ``EndLoadedRod`` (``shortened_rod(..., shortening=0)``) giving material, N and contact.

    The unknowns are u = [rod's scaled DOFs, end offset in edge lengths (1 or 3)]; T and phi are
    parameters (``problem`` gives the BifurcationProblem in either)."""

    def __init__(self, rod, end="slide"):
        if end not in _BASES:
            raise ValueError(f"end must be 'slide' or 'free', got {end!r}")
        if not isinstance(rod, EndLoadedRod):
            raise TypeError("rod must be an EndLoadedRod (jaxrod.studies.endloads.shortened_rod)")
        self.rod = with_end_offset(rod, jnp.zeros(3))
        self.end = end
        self.k = _BASES[end]
        self.basis = _offset_basis(self.rod, end)
        self._basis = np.asarray(self.basis, dtype=float)
        self._axis = np.asarray(self.rod.axis, dtype=float)
        self._ls = float(self.rod.length_scale)
        self._es = float(self.rod.energy_scale)

    def args(self, phi, T, nbr=None):
        return (self.rod, jnp.asarray(phi, dtype=jnp.float64), jnp.asarray(T, dtype=jnp.float64), nbr, self.basis)

    def u_from(self, q, offset):
        """Scaled unknowns from rod DOFs q and the end offset (3,) (its part along the allowed basis)."""
        w = np.asarray(self.basis) @ np.asarray(offset, dtype=float) / float(self.rod.length_scale)
        return np.concatenate([np.asarray(self.rod.to_scaled(np.asarray(q, dtype=float))), w])

    def straight(self, T, phi=0.0):
        """The straight state under tension T twisted by phi: uniform stretch T/EA, uniform twist."""
        strain = float(T) / float(self.rod.material.EA)
        # the clamped end edges are rigid: the N - 3 interior edges carry the stretch
        ext = strain * float(self.rod.length_scale) * (self.rod.n_nodes - 3)
        a = np.asarray(self.rod.axis)
        xc = np.asarray(self.rod.x_clamped)
        n_free = self.rod.n_nodes - 4
        q = np.asarray(self.rod.q_init).copy()
        start, stop = xc[1], xc[2] + ext * a
        frac = np.arange(1, n_free + 1) / (n_free + 1)
        q[:3 * n_free] = (start[None, :] + frac[:, None] * (stop - start)[None, :]).ravel()
        n_edges = self.rod.n_nodes - 1
        q[3 * n_free:] = float(phi) * np.arange(1, n_edges - 1) / (n_edges - 1)
        return self.u_from(q, ext * a)

    def solve(self, T, phi, u0, method="newton", gtol=1e-8, max_steps=None, throw=True, k=6):
        """Equilibrium at (T, phi) from u0: "newton" (nearest stationary point) or "damped" (a
        minimiser: damped Newton). Returns a ``ForceEquilibrium`` with its stability.
        Refused: non-positive or non-finite T, non-finite phi or u0, a rod too coarse for the
        end rotation (N named)."""
        from ..solve.solvers import ConvergenceError  # noqa: PLC0415

        T = check_positive("T", T)
        phi = check_finite("phi", phi)
        check_positive("gtol", gtol)
        check_rotation_resolution(self.rod.n_nodes, phi)
        u0 = np.asarray(u0, dtype=float)
        if u0.shape != (self.rod.n_dof + self.k,):
            raise ValueError(f"u0 must have shape ({self.rod.n_dof + self.k},) (rod DOFs and end offset), got {u0.shape}")
        if not np.all(np.isfinite(u0)):
            raise ValueError("u0 must be finite")
        if method == "newton":
            # the neighbourhood (the writhe that fixes the twist's branch; contact candidates) is
            # frozen during Newton's steps and rebuilt at the result, until the result is an
            # equilibrium with its own neighbourhood
            u = u0
            for _ in range(5):
                nbr = self._neighbourhood(u, phi)
                sol = newton(None, self._hessian, u, (phi, T, nbr), gtol=gtol,
                             max_steps=200 if max_steps is None else max_steps, throw=False,
                             value_and_grad=self._value_and_grad)
                u = sol.y
                if not sol.converged:
                    break
                _, g = self._value_and_grad(u, (phi, T, self._neighbourhood(u, phi)))
                gnorm = float(np.max(np.abs(g)))
                if gnorm <= gtol:
                    break
                sol = dataclasses.replace(sol, grad_norm=gnorm, converged=False)
            if throw and not sol.converged:
                raise ConvergenceError(f"capped Newton did not converge: {sol!r}", solution=sol)
        elif method == "damped":
            solver = DampedNewton(hessian=force_hessian, zero_modes=force_zero_modes)
            sol = minimise(force_energy, u0, self.args(phi, T), solver, gtol, max_steps, throw=throw)
        else:
            raise ValueError(f"method must be 'newton' or 'damped', got {method!r}")
        return self.equilibrium(sol.y, T, phi, sol=sol, k=k)

    # host compositions of the rod's compiled pieces (``_rod_gradients``, ``_rod_hessian``,
    # ``_offset_coupling``): the force-loaded rod shares the displacement-controlled rod's programs
    def _state(self, u):
        u = np.asarray(u, dtype=float)
        n = self.rod.n_dof
        off = self._ls * (u[n:] @ self._basis)
        return with_end_offset(self.rod, off), u[:n], off

    def _neighbourhood(self, u, phi):
        rod, ur, _ = self._state(u)
        return rod.neighbourhood(np.asarray(rod.from_scaled(ur)), phi)

    @_host
    def _value_and_grad(self, u, args):
        phi, T, nbr = args
        rod, ur, off = self._state(u)
        val, gu, goff, _, _ = _rod_gradients(rod, ur, phi, nbr)
        value = float(val) - float(T) * float(off @ self._axis) / self._es
        gw = self._basis @ (np.asarray(goff) - float(T) * self._axis) * self._ls / self._es
        return value, np.concatenate([np.asarray(gu), gw])

    @_host
    def _hessian(self, u, args):
        """(exact Hessian of ``force_energy`` (n + k, n + k), the zero mode (n + k, 1))."""
        phi, T, nbr = args
        rod, ur, off = self._state(u)
        h_rr, z_r = _rod_hessian(rod, ur, phi, nbr)
        c = np.asarray(_offset_coupling(rod, _f64(ur), _f64(phi), nbr))
        n, b = ur.shape[0], self._basis
        cols = self._ls * c[:n] @ b.T
        hww = self._ls ** 2 * b @ c[n:] @ b.T
        h = np.block([[np.asarray(h_rr), cols], [cols.T, 0.5 * (hww + hww.T)]])
        zw = b @ np.cross(self._axis, off) / self._ls
        return h, np.concatenate([np.asarray(z_r)[:, 0], zw])[:, None]

    def equilibrium(self, u, T, phi, sol=None, k=6):
        from ..solve.equilibrium import _diagnostics  # noqa: PLC0415

        u = np.asarray(u, dtype=float)
        rod, ur, off = self._state(u)
        nbr = rod.neighbourhood(np.asarray(rod.from_scaled(ur)), phi)
        args = (phi, T, nbr)
        _, g = self._value_and_grad(u, args)
        h, z = self._hessian(u, args)
        _, _, _, M, _ = _rod_gradients(rod, ur, phi, nbr)
        q, x, _, terms, tw = jax.device_get(_diagnostics(rod, _f64(ur), _f64(phi), nbr))
        nz = np.linalg.norm(z)
        if nz > 0.0:  # lift the axial rotation (exact zero mode) above the spectrum
            z = z / nz
            p = np.eye(h.shape[0]) - z @ z.T
            h = p @ h @ p + (np.max(np.abs(np.diag(h))) + 1.0) * (z @ z.T)
        lam = np.linalg.eigvalsh(h)
        wr = float(nbr.wr_ref)
        tol = 1e-10 * max(float(np.max(np.abs(np.diag(h)))), 1.0)
        return ForceEquilibrium(
            u=u, q=np.asarray(q), x=np.asarray(x), end_offset=np.asarray(off),
            extension=float(np.dot(off, self._axis)), T=float(T), phi=float(phi), M=float(M), Wr=wr, Tw=float(tw),
            Lk=wr + float(tw), energy=float(sum(float(v) for v in terms.values())),
            grad_norm=float(np.max(np.abs(g))),
            converged=True if sol is None else bool(sol.converged), iterations=0 if sol is None else sol.iterations,
            eigenvalues=lam[:k], morse=int(np.sum(lam < -tol)))

    def problem(self, parameter, u0, T, phi):
        """BifurcationProblem in ``parameter`` ("phi" or "T") at fixed other load, started at u0."""
        from ..continuation.arclength import BifurcationProblem  # noqa: PLC0415

        if parameter == "phi":
            return BifurcationProblem(_force_energy_phi, u0, float(phi), (self.rod, jnp.asarray(float(T)), None,
                                                                          self.basis), jacobian=_force_jacobian_phi)
        if parameter == "T":
            return BifurcationProblem(_force_energy_T, u0, float(T), (self.rod, jnp.asarray(float(phi)), None,
                                                                      self.basis), jacobian=_force_jacobian_T)
        raise ValueError(f"parameter must be 'phi' or 'T', got {parameter!r}")


def _force_energy_phi(u, p, args):
    scene, T, nbr, basis = args
    return force_energy(u, (scene, p, T, nbr, basis))


def _force_jacobian_phi(u, p, args):
    scene, T, nbr, basis = args
    return force_hessian(u, (scene, p, T, nbr, basis))


def _force_energy_T(u, p, args):
    scene, phi, nbr, basis = args
    return force_energy(u, (scene, phi, p, nbr, basis))


def _force_jacobian_T(u, p, args):
    scene, phi, nbr, basis = args
    return force_hessian(u, (scene, phi, p, nbr, basis))


# ---------------------------------------------------------------------- continuation in the shortening
def shortening_energy(u, p, args):
    """Scaled energy of an ``EndLoadedRod`` with p = shortening; args = (scene, phi): a
    ``BifurcationProblem`` energy (jaxrod.continuation.arclength)."""
    scene, phi = args
    return with_shortening(scene, p).scaled_energy(u, phi)


def shortening_jacobian(u, p, args):
    scene, phi = args
    return structured_scaled_hessian(with_shortening(scene, p), u, phi, None)


def rotation_energy(u, p, args):
    """Scaled energy with p = end rotation phi; args = (scene,)."""
    (scene,) = args
    return scene.scaled_energy(u, p)


def rotation_jacobian(u, p, args):
    (scene,) = args
    return structured_scaled_hessian(scene, u, p, None)


def shortening_problem(scene, q0, phi):
    """BifurcationProblem with p = shortening (start: scene's shortening), phi fixed; u = scaled q."""
    from ..continuation.arclength import BifurcationProblem  # noqa: PLC0415

    return BifurcationProblem(shortening_energy, scene.to_scaled(np.asarray(q0, dtype=float)),
                              float(scene.shortening), (scene, jnp.asarray(float(phi))), jacobian=shortening_jacobian)


def rotation_problem(scene, q0, phi0):
    """BifurcationProblem with p = end rotation phi at the scene's shortening; u = scaled q."""
    from ..continuation.arclength import BifurcationProblem  # noqa: PLC0415

    return BifurcationProblem(rotation_energy, scene.to_scaled(np.asarray(q0, dtype=float)), float(phi0), (scene,),
                              jacobian=rotation_jacobian)


# ---------------------------------------------------------------------- analytic results
@dataclass(frozen=True)
class LocalizedHelix:
    """The localized helical buckle of NvdHT 2002 for (m, t, gamma): lam = sqrt(t - m^2/4), end
    rotation R (rad), end shortening d (per length), theta_max, writhe Wr (ray-closed, infinite
    rod) = (2/pi) arccos(m / (2 sqrt t)), twist Tw = m / (2 pi gamma)."""

    m: float
    t: float
    gamma: float
    lam: float
    R: float
    d: float
    theta_max: float
    Wr: float
    Tw: float


def localized_helix(m, t, gamma):
    """NvdHT 2002 eqs. 14-15 for m = ML/B, t = TL^2/B, gamma = C/B (needs m^2 < 4t). Either sign
    of m: the mirror image (x, y, z) -> (x, -y, z) of the loop with moment m is the loop with -m
    at the same t, its end rotation and writhe of the opposite sign, R(-m) = -R(m) (eq. 14 as
    printed, R = m/gamma + 4 arccos(m / 2 sqrt t), is the m > 0 branch)."""
    m, t, gamma = check_finite("m", m), check_positive("t", t), check_positive("gamma", gamma)
    if not m * m < 4.0 * t:
        raise ValueError(f"need m^2 < 4 t (below the straight rod's threshold M = 2 sqrt(BT)), got m = {m}, t = {t}")
    lam = localization_parameter(m, t)
    sign = math.copysign(1.0, m)
    ac = math.acos(abs(m) / (2.0 * math.sqrt(t)))
    return LocalizedHelix(m=m, t=t, gamma=gamma, lam=lam, R=m / gamma + sign * 4.0 * ac,
                          d=math.sqrt(16.0 / t * (1.0 - m * m / (4.0 * t))),
                          theta_max=math.acos(m * m / (2.0 * t) - 1.0), Wr=sign * 2.0 * ac / math.pi,
                          Tw=m / (TWO_PI * gamma))


def localized_helix_from_shortening(d, R, gamma):
    """The (m, t) of every localized helix with end shortening d (per length) and end rotation R
    (rad) at gamma, from NvdHT eqs. 14-15: with u = d^2 t / 16 in (0, 1), m = 8 sqrt(u(1-u)) / d and
    |R| = |m| / gamma + 4 arcsin(sqrt u), solved for u (all roots), m taking the sign of R (the
    mirror image: (d, -R) has the loops (-m, t) of (d, R)). Returns a list of LocalizedHelix,
    ascending in t (none for R = 0)."""
    from scipy.optimize import brentq  # noqa: PLC0415

    d, gamma = check_positive("d", d), check_positive("gamma", gamma)
    if not d < 1.0:
        raise ValueError(f"d (end shortening / L) must be below 1, got {d!r}")
    R = check_finite("R", R)
    sign, R = math.copysign(1.0, R), abs(R)

    def f(u):
        return 8.0 * math.sqrt(u * (1.0 - u)) / (d * gamma) + 4.0 * math.asin(math.sqrt(u)) - R

    grid = np.linspace(1e-12, 1.0 - 1e-12, 4001)
    vals = np.array([f(u) for u in grid])
    out = []
    for i in np.nonzero(np.sign(vals[:-1]) * np.sign(vals[1:]) <= 0)[0]:
        u = brentq(f, grid[i], grid[i + 1], xtol=1e-15, rtol=1e-15)
        t = 16.0 * u / d ** 2
        if out and abs(t / out[-1].t - 1.0) < 1e-9:  # a root on a grid point, found from both sides
            continue
        out.append(localized_helix(sign * 8.0 * math.sqrt(u * (1.0 - u)) / d, t, gamma))
    return out


# ---------------------------------------------------------------------- where the formulas hold
# NvdHT's eqs. 14-15 describe a loop on an infinite, inextensible rod. They are taken as the
# reference of a clamped rod of length L while both errors are small: the finite length's (the
# loop's tails cut at the clamps, ~ e^-lambda) and the stretch's.
LOCALIZATION_MIN = 13.0
# The largest relative shift of t that the stretch T/EA may cause (first-order estimate,
# ``stretch_shift``) for the inextensible formulas to stand as the reference.
STRETCH_SHIFT_MAX = 1e-4


def localization_parameter(m, t):
    """The localization parameter lambda = sqrt(t - m^2/4) of NvdHT's loop (m = ML/B, t = TL^2/B;
    0 where m^2 >= 4t: no loop). The loop's core is L/lambda wide: 1 - cos theta = (2 lambda^2/t)
    sech^2(lambda s/L), so at the clamps (s = +-L/2) the infinite rod's tails have decayed to
    ~ 8 (lambda^2/t) e^-lambda, and the clamped rod of length L differs from the infinite one by
    O(e^-lambda). The formulas are a reference for lambda >= ``LOCALIZATION_MIN`` = 13
    (e^-13 = 2e-6: below the discretisation error of the N used; at lambda ~ 1 the loop is no
    loop but a buckle as long as the rod)."""
    m, t = float(m), float(t)
    return math.sqrt(max(t - 0.25 * m * m, 0.0))


def stretch_shift(ref, ea):
    """First-order estimate of the relative change of t = TL^2/B that stretching causes at the
    imposed (d, R) of the localized helix ``ref``, for a rod of stretch stiffness ea = EA L^2/B
    (None or inf: inextensible, 0). The stretch eps = T/EA = t/ea lengthens the rod to L(1 + eps):
    the inextensible loop of that length with the same end distance L(1 - d) has the shortening
    d' = (d + eps)/(1 + eps) of its own length and t' = T L'^2/B = t (1 + eps)^2; t' is followed
    from ``ref`` to d' along eqs. 14-15 at fixed R (the root nearest ref)."""
    if ea is None or math.isinf(ea):
        return 0.0
    ea = check_positive("ea", ea)
    eps = ref.t / ea
    d2 = (ref.d + eps) / (1.0 + eps)
    if not d2 < 1.0:
        return math.inf
    found = localized_helix_from_shortening(d2, ref.R, ref.gamma) if ref.R != 0.0 else []
    if not found:
        return math.inf
    t2 = min(found, key=lambda h: abs(h.t - ref.t)).t
    return abs(t2 / (1.0 + eps) ** 2 / ref.t - 1.0)


@dataclass(frozen=True)
class ReferenceCheck:
    """Whether NvdHT's formulas are the reference of a clamped rod at ``LocalizedHelix`` ref:
    valid, and the reasons (tuple of str, empty when valid) otherwise; lam the localization
    parameter, stretch = T/EA, shift the estimated relative change of t by the stretch."""

    valid: bool
    reasons: tuple
    lam: float
    stretch: float
    shift: float

    @property
    def reason(self):
        """The reasons in one line, or None when valid."""
        return "; ".join(self.reasons) if self.reasons else None


def reference_check(ref, ea=None):
    """``ReferenceCheck`` of the localized helix ``ref`` (``localized_helix``) as the reference of
    a clamped rod of length L with stretch stiffness ea = EA L^2/B (None: inextensible): valid
    when the loop is localized (lambda >= ``LOCALIZATION_MIN``) and the stretch shifts t by less
    than ``STRETCH_SHIFT_MAX`` (``stretch_shift``)."""
    lam = localization_parameter(ref.m, ref.t)
    reasons = []
    if lam < LOCALIZATION_MIN:
        reasons.append(f"not localized: lambda = sqrt(t - m^2/4) = {lam:.3g} < {LOCALIZATION_MIN:g} (the formulas "
                       f"are for a loop much shorter than the rod; its tails reach the clamps, error ~ e^-lambda)")
    stretch = 0.0 if ea is None or math.isinf(ea) else ref.t / float(ea)
    shift = stretch_shift(ref, ea)
    if shift > STRETCH_SHIFT_MAX:
        reasons.append(f"extensible: the stretch T/EA = {stretch:.2g} shifts t by ~{shift:.1e} "
                       f"(> {STRETCH_SHIFT_MAX:g}; the formulas are for an inextensible rod)")
    return ReferenceCheck(valid=not reasons, reasons=tuple(reasons), lam=lam, stretch=stretch, shift=shift)


def localized_helix_curve(m, t, s, L=1.0):
    """The localized helix's tangent angle theta(s), azimuth psi(s) and centreline r(s) (n, 3) at
    arc lengths s (n,) from the midpoint (ascending), for a rod of length L along z; r(0) is on the
    z axis' tail line (r -> (0, 0, s - ...) as s -> -inf up to the common lateral offset, which is
    removed: the tails lie on the z axis). Integrated with DOP853 (rtol 1e-12)."""
    from scipy.integrate import solve_ivp  # noqa: PLC0415

    localized_helix(m, t, 1.0)  # m finite, t positive, m^2 < 4 t
    L = check_positive("L", L)
    s = np.asarray(s, dtype=float)
    if not np.all(np.isfinite(s)):
        raise ValueError("s must be finite")
    lam = localization_parameter(m, t)
    c = 2.0 * lam * lam / t

    def one_minus_cos(x):
        return c / np.cosh(lam * x / L) ** 2

    def rhs(x, y):
        om = one_minus_cos(x)
        ct = 1.0 - om
        st = math.sqrt(max(om * (2.0 - om), 0.0))
        psi = y[3]
        return [st * math.cos(psi), st * math.sin(psi), ct, (m / L) / (2.0 - om)]

    # integrate outwards from the midpoint both ways (psi(0) = 0, r(0) = 0), then shift the tails to the axis
    far = 40.0 * L / lam  # sech^2 ~ e^-80 there: the tails are straight
    out = {}
    for sign in (1.0, -1.0):
        span = (0.0, sign * max(far, float(np.max(np.abs(s)))))
        sol = solve_ivp(rhs, span, [0.0, 0.0, 0.0, 0.0], method="DOP853", rtol=1e-12, atol=1e-14, dense_output=True)
        out[sign] = sol
    tail = out[1.0].sol(max(far, float(np.max(np.abs(s)))))
    y = np.empty((s.size, 4))
    pos = s >= 0
    if np.any(pos):
        y[pos] = out[1.0].sol(s[pos]).T
    if np.any(~pos):
        y[~pos] = out[-1.0].sol(s[~pos]).T
    r = y[:, :3].copy()
    r[:, :2] -= tail[:2]
    theta = np.arccos(np.clip(1.0 - one_minus_cos(s), -1.0, 1.0))
    return theta, y[:, 3], r


@dataclass(frozen=True)
class Plectoneme:
    """The hard-contact two-phase plectoneme at tension T (``plectoneme_plateau``): M the plateau
    torque, alpha the superhelix angle (rad, strand tangent to the plectoneme axis), r = D/2, slope
    d(extension)/d(turns) = -4 pi r / sin 2 alpha, writhe_per_length sin 2 alpha / (4 pi r)."""

    M: float
    alpha: float
    r: float
    slope: float
    writhe_per_length: float


def plectoneme_plateau(B, T, D):
    """The torque plateau of a plectoneme of a rod of bending stiffness B and diameter D under
    tension T, in the two-phase model with hard contact: two strands wound at radius r = D/2 about
    the plectoneme axis with helix angle alpha (curvature sin^2 alpha / r, writhe sin 2 alpha /
    (4 pi r) per length), coexisting with straight tails; the end loop neglected (long plectonemes).
    Per length, at torque M, the plectoneme's B sin^4 alpha / (2 r^2) - M sin 2 alpha / (2 r) equals
    the straight phase's -T, stationary in alpha:

        M r / B = 2 sin^3 alpha cos alpha / cos 2 alpha,
        T r^2 / B = sin^4 alpha (1 + 2 cos^2 alpha) / (2 cos 2 alpha).

    For T r^2 / B -> 0, M -> 2 (2/3)^(3/4) B^(1/4) T^(3/4) r^(1/2) (alpha^4 ~ 2 T r^2 / 3 B)."""
    from scipy.optimize import brentq  # noqa: PLC0415

    B, T, D = check_positive("B", B), check_positive("T", T), check_positive("D", D)
    r = 0.5 * D
    tau = T * r * r / B

    def f(a):
        return math.sin(a) ** 4 * (1.0 + 2.0 * math.cos(a) ** 2) / (2.0 * math.cos(2.0 * a)) - tau

    a = brentq(f, 1e-12, math.pi / 4.0 - 1e-12, xtol=1e-15, rtol=1e-15)
    M = 2.0 * B * math.sin(a) ** 3 * math.cos(a) / (r * math.cos(2.0 * a))
    return Plectoneme(M=M, alpha=a, r=r, slope=-4.0 * math.pi * r / math.sin(2.0 * a),
                      writhe_per_length=math.sin(2.0 * a) / (4.0 * math.pi * r))


# Edges per core width L / lambda of the localized helix, and the largest twist per edge (rad),
# below which ``check_helix_resolution`` refuses N: at 6 edges per core the end loads are still
# O(h^2) (measured: t within 7 % at N = 120, lambda = 14.1).
EDGES_PER_CORE = 6.0
# The twist energy of uniform twist is exact at any angle per edge (C m^2 / 2 l, m not wrapped);
# what coarse edges lose is the bending-twist coupling of the loop, which the core-width rule
# covers. pi/2 per edge keeps the material frame's rotation between edges well below the half
# turn at which a drawn stripe aliases. (0.5 rad refused the PyElastica case at N < 342, which
# solved at N = 202 and 302 on the h^2 trend of the finer N: benchmarks/peer_pyelastica.py.)
MAX_TWIST_PER_EDGE = 0.5 * math.pi


def check_rotation_resolution(N, phi):
    """N as an int, or ValueError naming N: an end rotation phi (rad) spread over N - 1 edges needs
    at most ``MAX_TWIST_PER_EDGE`` (pi/2) rad per edge (N >= |phi| / (pi/2) + 2)."""
    N = check_int_at_least("N", N, 5)
    need = math.ceil(abs(float(phi)) / MAX_TWIST_PER_EDGE) + 2
    if N < need:
        raise ValueError(f"N = {N} is too few nodes for the end rotation {float(phi) / TWO_PI:.3g} turns "
                         f"(at most {MAX_TWIST_PER_EDGE} rad of twist per edge): N >= {need}")
    return N


def check_helix_resolution(N, m, t, R):
    """N as an int, or ValueError naming N: the localized helix (m, t) with end rotation R needs
    N - 2 >= 6 lambda edges (6 per core width L / lambda) and at most pi/2 rad of twist per edge."""
    N = check_int_at_least("N", N, 8)
    lam = localization_parameter(m, t)
    need = max(math.ceil(EDGES_PER_CORE * lam), math.ceil(abs(R) / MAX_TWIST_PER_EDGE)) + 2
    if N < need:
        raise ValueError(f"N = {N} is too few nodes for the loop asked (lambda = {lam:.3g}, end rotation "
                         f"{R / TWO_PI:.3g} turns): N >= {need}")
    return N


def _closed_tangents(theta, psi, span, lengths=None, sweeps=20):
    """Unit tangents (n, 3) near the polar angles theta (n,) and azimuths psi (n,) to the axis z
    such that the edges of ``lengths`` (n,; None: 1) along them sum to (0, 0, span): an open
    polyline that meets the far clamp. Alternately, the polar angles are scaled by one factor k
    (the axial span: k = 1 + O(e^-lambda) for a localized loop; a loop wider than the rod, whose
    shortening lies mostly outside it, is steepened rather than compressed) and the lateral sum is
    removed, mostly from the edges nearest the axis (a lateral shift of an axial edge stretches
    nothing)."""
    from scipy.optimize import brentq  # noqa: PLC0415

    theta, psi = np.asarray(theta, dtype=float), np.asarray(psi, dtype=float)
    ell = np.ones_like(theta) if lengths is None else np.asarray(lengths, dtype=float)
    w = 1.0 / (np.sin(theta) ** 2 + 1e-4)
    w /= np.sum(w)
    for _ in range(sweeps):
        top = math.pi / max(float(np.max(theta)), 1e-300)
        gap = lambda k: float(np.sum(ell * np.cos(np.minimum(k * theta, math.pi)))) - span  # noqa: E731, B023
        g1 = gap(1.0)
        if g1 > 0.0 and gap(top) < 0.0:
            theta = np.minimum(brentq(gap, 1.0, top, xtol=1e-15) * theta, math.pi)
        elif g1 < 0.0:
            theta = brentq(gap, 0.0, 1.0, xtol=1e-15) * theta
        tangent = np.stack([np.sin(theta) * np.cos(psi), np.sin(theta) * np.sin(psi), np.cos(theta)], axis=1)
        lateral = np.sum(ell[:, None] * tangent[:, :2], axis=0)
        if float(np.max(np.abs(lateral))) < 1e-13 * len(theta):
            break
        tangent[:, :2] -= (w / ell)[:, None] * lateral[None, :]
        tangent /= np.linalg.norm(tangent, axis=1)[:, None]
        theta, psi = np.arccos(np.clip(tangent[:, 2], -1.0, 1.0)), np.arctan2(tangent[:, 1], tangent[:, 0])
    return tangent


def _frame(scene):
    """(e1, e2, e3): the near clamp's director, e3 x e1, the clamp axis."""
    e3 = np.asarray(scene.axis, dtype=float)
    e1 = np.asarray(scene.director_start, dtype=float)
    return e1, np.cross(e3, e1), e3


def _interior_from_tangents(scene, theta, psi, lengths=None):
    """The interior nodes (n - 4, 3) of ``scene`` on the polyline from the near clamp's node 1
    whose free edges 1 ... n - 3 have ``lengths`` (in edge lengths h; None: 1) and lie near the
    polar angles theta and azimuths psi in the clamps' frame (``_frame``), closed onto the far
    clamp's node n - 2 (``_closed_tangents``; the roundoff left spread evenly)."""
    n, h = scene.n_nodes, float(scene.length_scale)
    xc = np.asarray(scene.x_clamped)
    start, stop = xc[1], xc[2] + np.asarray(scene.end_offset)
    e1, e2, e3 = _frame(scene)
    ell = np.ones(n - 3) if lengths is None else np.asarray(lengths, dtype=float)
    tangent = _closed_tangents(theta, psi, float(np.dot(stop - start, e3)) / h, ell)
    r = h * np.cumsum(ell[:, None] * tangent, axis=0)  # nodes 2 ... n - 2 from node 1, in the frame
    x = start + r[:, :1] * e1 + r[:, 1:2] * e2 + r[:, 2:3] * e3
    miss = x[-1] - stop
    return x[:-1] - (np.arange(1, n - 3) / (n - 3))[:, None] * miss[None, :]


def _restretched(scene, q, ratio):
    """q with every free edge's strain multiplied by ``ratio``, the edges' directions kept but
    re-closed onto the far clamp (``_interior_from_tangents``), the twist angles unchanged: the
    predictor of a stiffening stage, EA -> EA / ratio at nearly the same tension."""
    q = np.asarray(q, dtype=float)
    n = scene.n_nodes
    x = np.asarray(scene.nodes(jnp.asarray(q)))
    e = np.diff(x, axis=0)[1:n - 2]
    ell = np.linalg.norm(e, axis=1)
    rest = np.asarray(scene.rest_lengths)[1:n - 2]
    e1, e2, e3 = _frame(scene)
    tau = e / ell[:, None]
    theta = np.arccos(np.clip(tau @ e3, -1.0, 1.0))
    psi = np.arctan2(tau @ e2, tau @ e1)
    lengths = rest * (1.0 + (ell / rest - 1.0) * ratio) / float(scene.length_scale)
    xi = _interior_from_tangents(scene, theta, psi, lengths)
    return np.concatenate([xi.ravel(), q[3 * (n - 4):]])


def helical_start(scene, m, t, phi):
    """A starting state q for ``scene`` (an ``EndLoadedRod``) near the localized helix (m, t): the
    interior nodes on a polyline of the rest edge length along the analytic tangent (s measured
    from the rod's midpoint, the near clamp's point at s = -L/2), closed onto the far clamp, and
    the twist spread evenly so the far clamp's frame is
    turned by phi (m < 0: the mirror image of the loop with -m, for phi < 0). Refused: N too few
    for the loop (``check_helix_resolution``), m^2 >= 4 t."""
    _check_scene(scene)
    phi = check_finite("phi", phi)
    localized_helix(m, t, 1.0)  # m finite, t positive, m^2 < 4 t
    check_helix_resolution(scene.n_nodes, m, t, phi)
    L = float(scene.clamp_length)
    n = scene.n_nodes
    h = L / (n - 2)
    # edges of the rest length h along the analytic tangent at their midpoints, s_i = -L/2 + i h
    # (edge 0 and edge n - 2 the clamped ones, on the axis), closed onto the far clamp
    # (``_closed_tangents``: the tails' slope cut at the clamps, ~ e^-lambda/2, leaves a lateral
    # miss). Chords of the analytic curve instead are short by ~(kappa h)^2 / 24, a strain whose
    # force EA (kappa h)^2 / 24 dwarfs the loads of a stiff rod.
    s_mid = -0.5 * L + h * np.arange(1, n - 2)
    theta_a, psi_a, _ = localized_helix_curve(m, t, s_mid, L)
    xi = _interior_from_tangents(scene, theta_a, psi_a)
    # twist: theta_end = phi + end angle, spread over the edges
    probe = np.concatenate([xi.ravel(), np.zeros(n - 3)])
    x_full = np.asarray(scene.nodes(jnp.asarray(probe)))
    theta_end = float(phi) + float(scene.end_angle(jnp.asarray(x_full)))
    m_edges = n - 1
    theta = theta_end * np.arange(1, m_edges - 1) / (m_edges - 1)
    return np.concatenate([xi.ravel(), theta])


# ---------------------------------------------------------------------- tension and twist: onset
def tension_twist_threshold(B, T):
    """The infinite rod's buckling moment under tension T: M = 2 sqrt(B T)."""
    return 2.0 * math.sqrt(check_positive("B", B) * check_positive("T", T))


def straight_buckling_moment(rod, T, phi_hi=None, tol=1e-10):
    """The buckling twist of the straight rod ``rod`` (an EndLoadedRod at 0 shortening) under
    tension T (its ends held at the stretched length (1 + T/EA) L; the straight state's stability
    is the same under force control, its end motion decoupled from the lateral modes): the phi at
    which the straight state's lowest eigenvalue crosses zero (a double eigenvalue: the helical
    mode and its rotation), by bisection then secant. Returns (phi_c, M_c = C phi_c / L)."""
    import scipy.linalg  # noqa: PLC0415

    _check_scene(rod)
    T = check_positive("T", T)
    C = float(rod.material.C)
    L = float(rod.clamp_length)
    B = float(rod.material.B)
    fr = ForceLoadedRod(rod, "slide")
    ext = float(fr.straight(T)[-1]) * float(rod.length_scale)
    scene = with_end_offset(rod, ext * np.asarray(rod.axis))
    u0 = fr.straight(T, 0.0)[:-1]
    # the straight states all have writhe 0: one neighbourhood serves every phi
    nbr = scene.neighbourhood(np.asarray(scene.from_scaled(u0)), 0.0)

    def low(phi):
        h, _ = _rod_hessian(scene, fr.straight(T, phi)[:-1], phi, nbr)
        return float(scipy.linalg.eigh(np.asarray(h), subset_by_index=[0, 0], eigvals_only=True,
                                       driver="evr", check_finite=False)[0])

    # bracket: the threshold lies between the infinite rod's 2 sqrt(BT) and above Greenhill's M L/B
    lo = 0.5 * min(2.0 * math.sqrt(B * T), 8.9868 * B / L) * L / C
    hi = phi_hi if phi_hi is not None else 1.05 * (2.0 * math.sqrt(B * T) + 8.9868 * B / L) * L / C
    f_lo, f_hi = low(lo), low(hi)
    if not (f_lo > 0.0 > f_hi):
        raise ValueError(f"no buckling twist bracketed in [{lo:.4g}, {hi:.4g}] (lowest eigenvalues {f_lo:.3g}, {f_hi:.3g})")
    from scipy.optimize import brentq  # noqa: PLC0415

    phi_c = brentq(low, lo, hi, xtol=tol * hi, rtol=1e-14)
    return phi_c, C * phi_c / L


def _clamped_twist_matrix(m, t, n_quad=64):
    """The 3 x 3 complex matrix whose singularity is the onset of buckling of a straight rod of
    length 1 (B = 1), clamped at both ends, under tension t and axial moment m. Linearised
    Kirchhoff equations for the complex tangent deviation v = x' + i y':
    v'' - i m v' - t v = const, so v = c0 + e^{i a s} (c1 cosh(b s) + c2 sinh(b s) / b) with
    a = m / 2, b = sqrt(t - m^2/4) (complex past 2 sqrt t; the basis is smooth through b = 0);
    clamped ends: v(0) = v(1) = 0 and integral_0^1 v ds = 0 (the ends stay on the axis)."""
    a = 0.5 * m
    b = np.sqrt(complex(t - 0.25 * m * m))
    b = b if abs(b) > 1e-12 else 1e-12

    def f(s):
        s = np.asarray(s, dtype=float)
        e = np.exp(1j * a * s)
        if abs(b) < 5.0:
            return np.stack([np.ones_like(s, dtype=complex), e * np.cosh(b * s), e * np.sinh(b * s) / b], axis=-1)
        # large |b| (long rods): the same span with columns bounded on [0, 1] (no overflow)
        return np.stack([np.ones_like(s, dtype=complex), e * np.exp(b * (s - 1.0)), e * np.exp(-b * s)], axis=-1)

    x, w = np.polynomial.legendre.leggauss(max(n_quad, int(4 * abs(b)) + 16))
    integral = 0.5 * np.sum(w[:, None] * f(0.5 * (x + 1.0)), axis=0)
    return np.stack([f(0.0), f(1.0), integral], axis=0)


def _clamped_twist_matrices(ms, t, n_quad=64):
    """``_clamped_twist_matrix`` for an array of m (K,) at once: (K, 3, 3) (the scan's batch;
    quadrature with the batch's largest point count)."""
    ms = np.asarray(ms, dtype=float)
    a = 0.5 * ms
    b = np.sqrt((t - 0.25 * ms * ms).astype(complex))
    b = np.where(np.abs(b) > 1e-12, b, 1e-12)
    x, w = np.polynomial.legendre.leggauss(max(n_quad, int(4 * np.max(np.abs(b))) + 16))
    small = (np.abs(b) < 5.0)[:, None]

    def f(s):  # (K, n_s, 3) at points s (n_s,)
        s = np.asarray(s, dtype=float)[None, :]
        bb, e = b[:, None], np.exp(1j * a[:, None] * s)
        with np.errstate(all="ignore"):
            c1 = np.where(small, np.cosh(bb * s), np.exp(bb * (s - 1.0)))
            c2 = np.where(small, np.sinh(bb * s) / bb, np.exp(-bb * s))
        return np.stack([np.ones_like(e), e * c1, e * c2], axis=-1)

    integral = 0.5 * np.einsum("q,kqj->kj", w, f(0.5 * (x + 1.0)))
    return np.stack([f([0.0])[:, 0], f([1.0])[:, 0], integral], axis=1)


def clamped_tension_twist_threshold(B, T, L, n_scan=400):
    """The buckling moment M_c of a straight rod of length L clamped at both ends under tension T
    (continuum, inextensible): the smallest m = M L / B at which ``_clamped_twist_matrix`` is
    singular, found by scanning its smallest singular value and refining the first zero. Tends to
    Greenhill's 8.9868 B / L as T -> 0 and to 2 sqrt(B T) as L sqrt(T / B) -> infinity."""
    from scipy.optimize import minimize_scalar  # noqa: PLC0415

    B, T, L = check_positive("B", B), check_positive("T", T), check_positive("L", L)
    t = T * L * L / B
    sig = lambda m: float(np.linalg.svd(_clamped_twist_matrix(m, t), compute_uv=False)[-1])  # noqa: E731
    hi = 2.0 * math.sqrt(t) + 12.0
    grid = np.linspace(0.05 * hi, hi, max(n_scan, min(int(50 * hi), 40000)))
    n_scan = grid.size
    vals = np.linalg.svd(_clamped_twist_matrices(grid, t), compute_uv=False)[:, -1]
    scale = np.max(vals)
    for i in range(1, n_scan - 1):
        if vals[i] <= vals[i - 1] and vals[i] <= vals[i + 1]:
            res = minimize_scalar(sig, bounds=(grid[i - 1], grid[i + 1]), method="bounded",
                                  options={"xatol": 1e-10 * hi})
            if res.fun < 1e-4 * scale:
                # polish: det(m) is analytic, ~ det'(m*) (m - m*) near the root with a complex
                # slope; least-squares real steps (Gauss-Newton on |det|^2) converge quadratically
                det = lambda m: np.linalg.det(_clamped_twist_matrix(m, t))  # noqa: E731
                m = res.x
                for _ in range(20):
                    dm = 1e-6 * max(1.0, abs(m))
                    slope = (det(m + dm) - det(m - dm)) / (2.0 * dm)
                    step = -float(np.real(np.conj(slope) * det(m))) / float(abs(slope) ** 2)
                    m += step
                    if abs(step) < 1e-14 * max(1.0, abs(m)):
                        break
                if sig(m) < 1e-9 * scale:
                    return m * B / L
    raise ValueError(f"no buckling moment found below m = {hi:.4g} (t = {t:.4g})")


def tangent_angles(x, axis=(0.0, 0.0, 1.0)):
    """The angle (M,) of each edge of the polyline x (N, 3) to ``axis``."""
    e = np.diff(np.asarray(x, dtype=float), axis=0)
    e /= np.linalg.norm(e, axis=1)[:, None]
    a = np.asarray(axis, dtype=float)
    return np.arccos(np.clip(e @ (a / np.linalg.norm(a)), -1.0, 1.0))


def envelope_error(x, m, t, L=1.0, axis=(0.0, 0.0, 1.0)):
    """L1 distance over s, integral |theta_h(s) - theta(s)| ds / L, between the tangent angle of
    a clamped rod's nodes x (N, 3) (edge i at s = i h - L/2 from the midpoint, h = L / (N - 2):
    edges 0 and N-2 are the clamps) and the localized helix's theta(s) (``localized_helix_curve``)."""
    localized_helix(m, t, 1.0)  # m finite, t positive, m^2 < 4 t
    L = check_positive("L", L)
    th = tangent_angles(x, axis)
    n_edges = th.size
    h = L / (n_edges - 1)
    s = np.arange(n_edges) * h - 0.5 * L
    lam = localization_parameter(m, t)
    exact = np.arccos(np.clip(1.0 - 2.0 * lam * lam / t / np.cosh(lam * s / L) ** 2, -1.0, 1.0))
    w = np.full(n_edges, h)
    w[[0, -1]] = 0.5 * h  # trapezoidal weights between the clamps
    return float(np.sum(w * np.abs(th - exact)) / L)


# ---------------------------------------------------------------------- a solved loop against the reference
def named_helix_roots(found):
    """Names of the localized helices ``found`` at one end shortening and rotation (a list of
    ``LocalizedHelix``, ascending in t, as ``localized_helix_from_shortening`` gives them): a list
    of (name, LocalizedHelix) in the same order, "only" for one root, else "small" and "large"
    for the first two and "t2", "t3", ... for any further ones."""
    names = ["only"] if len(found) == 1 else ["small", "large"] + [f"t{i}" for i in range(2, len(found))]
    return list(zip(names, found))


def select_helix_roots(named, root):
    """The named roots (``named_helix_roots``) to solve for the choice ``root``: "small" or
    "large" keeps the first or last of several, anything else ("stable", "both") all of them."""
    if root in ("small", "large") and len(named) > 1:
        return [named[0] if root == "small" else named[-1]]
    return list(named)


def choose_helix_root(candidates, n_found, root):
    """(name, reason) of the loop taken among the solved roots ``candidates``, a non-empty list of
    (name, t, stable) in the order solved (t = TL^2/B of the analytic loop, stable the computed
    stability under fixed ends), of the ``n_found`` roots at the imposed ends, for the choice
    ``root`` ("stable", "small", "large" or "both"): the one solved where only one is (or was
    asked for), else the stable one; where none or several are stable, the larger t."""
    if n_found == 1 or root in ("small", "large") or len(candidates) == 1:
        why = "the only root" if n_found == 1 else f"--root {root}" \
            if root in ("small", "large") else "the only root solved"
        return candidates[0][0], why
    stable = [c for c in candidates if c[2]]
    taken = max(stable or candidates, key=lambda c: c[1])[0]
    why = ("the stable root" if len(stable) == 1 else
           "no root is stable: the larger t" if not stable else "both roots are stable: the larger t")
    return taken, why


def nearest_localized_helix(d, R, gamma, m, t):
    """The localized helix at end shortening d (per length) and end rotation R (rad) nearest the
    computed loads m = ML/B, t = TL^2/B (of the two branches meeting at the fold in R, the one
    with the least |t_h/t - 1| + |m_h/m - 1|), or None where there is none at (d, R)."""
    found = localized_helix_from_shortening(d, R, gamma)
    return min(found, key=lambda x: abs(x.t / t - 1) + abs(x.m / m - 1)) if found else None


def relative_error(value, reference, valid=True):
    """value / reference - 1, or None where the reference does not apply (not valid)."""
    return value / reference - 1.0 if valid else None


def tension_roundoff(N, EA, T):
    """The relative roundoff of the tension T (force) of a rod of N nodes and stretch stiffness
    EA (force): T is EA times a strain, whose roundoff is ~ ``ROUNDOFF_ULPS`` eps (L/h)."""
    return ROUNDOFF_ULPS * np.finfo(float).eps * (N - 2) * EA / max(abs(T), 1e-300)


def coarse_nodes(N):
    """The node count of the rod with edges twice as long as those of N nodes (exactly, for even
    N): the coarse level of ``richardson_extrapolation``."""
    return (N - 2) // 2 + 2


def richardson_extrapolation(fine, coarse, N_fine, N_coarse):
    """Richardson's O(h^2) extrapolation of a quantity (scalar, any units) computed on clamped
    rods of N_fine and N_coarse nodes (edge length h = L / (N - 2)): (r^2 fine - coarse) / (r^2 - 1),
    r = h_coarse / h_fine."""
    r2 = ((N_fine - 2) / (N_coarse - 2)) ** 2
    return (r2 * fine - coarse) / (r2 - 1.0)


def helix_state(scene, eq, R, ref, B, ea):
    """One equilibrium ``eq`` of the ``EndLoadedRod`` ``scene`` (length L = 1) at end rotation R
    (rad) beside the localized helix ``ref`` (or None: no analytic loop): a dict of the end
    loads R, M (moment), T (force), m = ML/B, t = TL^2/B (B the bending stiffness), theta_max
    (rad), Lk, Wr, Tw, Lk_expected = R / 2 pi, the Morse index (morse, stable,
    lowest_eigenvalue), and the analytic m, t, theta_max, Wr, Tw (None without ref) with
    reference_valid (``reference_check`` at ea = EA L^2/B; None without ref)."""
    loads = end_loads(scene, eq.q, R, eq.neighbourhood)
    ok = None if ref is None else reference_check(ref, ea).valid
    return {"R": R, "M": loads.M, "T": loads.T, "m": loads.M / B, "t": loads.T / B,  # L = 1
            "m_analytic": None if ref is None else ref.m, "t_analytic": None if ref is None else ref.t,
            "reference_valid": ok,
            "theta_max": float(tangent_angles(eq.x).max()),
            "theta_max_analytic": None if ref is None else ref.theta_max,
            "Lk": eq.Lk, "Wr": eq.Wr, "Tw": eq.Tw, "Lk_expected": R / (2 * math.pi),
            "Wr_analytic": None if ref is None else ref.Wr, "Tw_analytic": None if ref is None else ref.Tw,
            "morse": eq.stability.n_negative, "stable": bool(eq.stability.stable),
            "lowest_eigenvalue": float(eq.stability.eigenvalues[0])}


def helix_root_row(name, ref, check, state=None, attempted=False, note=None):
    """One root's comparison with its analytic loop: the dict of its name, the analytic m, t and
    lambda of ``ref`` (``LocalizedHelix``), whether the reference applies (``check``, a
    ``ReferenceCheck``: reference_valid, reference_reason), and from ``state`` (``helix_state``,
    None where not solved) the computed m, t, their relative errors (None where the reference
    does not apply), morse, stable and converged (True; where not solved None, or False where
    Newton was ``attempted`` and failed, with ``note``, why it was left out)."""
    row = {"root": name, "m_analytic": ref.m, "t_analytic": ref.t, "lambda": ref.lam,
           "reference_valid": check.valid, "reference_reason": check.reason}
    if state is not None:
        row.update(m=state["m"], t=state["t"], m_rel_error=relative_error(state["m"], ref.m, check.valid),
                   t_rel_error=relative_error(state["t"], ref.t, check.valid), morse=state["morse"],
                   stable=state["stable"], converged=True)
    else:
        row.update(m=None, t=None, m_rel_error=None, t_rel_error=None, morse=None, stable=None,
                   converged=False if attempted else None, note=note)
    return row


@dataclass(frozen=True)
class HelixProfiles:
    """A clamped rod's loop beside the localized helix (``helix_profiles``), lengths in units of L:
    s_edge (N-1,) the edges' midpoints from the rod's middle, theta (N-1,) their tangent angles
    to the axis (rad) and theta_analytic (N-1,) the helix's; s_node (N,) the nodes' arc lengths,
    x (N, 3) the nodes turned about the axis onto the helix and r (N, 3) the helix's centreline,
    both shifted so that the first edge's midpoint is at the origin."""

    s_edge: np.ndarray
    theta: np.ndarray
    theta_analytic: np.ndarray
    s_node: np.ndarray
    x: np.ndarray
    r: np.ndarray

    def max_distance(self):
        """The largest distance (units of L) between a node and its analytic counterpart."""
        return float(np.max(np.linalg.norm(self.x - self.r, axis=1)))


def helix_profiles(x, ref, L=1.0):
    """``HelixProfiles`` of the nodes x (N, 3) of a clamped rod of length L along z (edges 0 and
    N-2 the clamps) against the localized helix ``ref`` (``LocalizedHelix``): the tangent angles
    of the edges and the centreline, the computed loop turned about the axis (a symmetry) onto
    the analytic one."""
    N = len(x)
    theta = tangent_angles(x)
    h_edge = L / (theta.size - 1)
    s_edge = np.arange(theta.size) * h_edge - 0.5 * L
    theta_exact = np.arccos(np.clip(1.0 - 2.0 * ref.lam ** 2 / ref.t / np.cosh(ref.lam * s_edge / L) ** 2, -1, 1))
    s_node = (np.arange(N) - 0.5) * h_edge - 0.5 * L
    _, _, r = localized_helix_curve(ref.m, ref.t, s_node, L)
    r = r - 0.5 * (r[0] + r[1])
    x = x - 0.5 * (x[0] + x[1])
    ang = math.atan2(float(np.sum(x[:, 0] * r[:, 1] - x[:, 1] * r[:, 0])), float(np.sum(x[:, :2] * r[:, :2])))
    c, s_ = math.cos(ang), math.sin(ang)
    x = np.stack([c * x[:, 0] - s_ * x[:, 1], s_ * x[:, 0] + c * x[:, 1], x[:, 2]], axis=1)
    return HelixProfiles(s_edge=s_edge, theta=theta, theta_analytic=theta_exact, s_node=s_node, x=x, r=r)
