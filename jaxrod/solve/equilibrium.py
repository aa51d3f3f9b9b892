"""Equilibria of a scene at a given imposed twist, each reported with its stability."""
from __future__ import annotations

import warnings

import math
from dataclasses import dataclass, replace

import jax
import jax.numpy as jnp
import numpy as np

from ..aot import cached_jit
from ..model.geometry import polyline_distance
from ..model.hessian import scaled_hessian
from ..validation import check_finite, check_int_at_least, check_positive
from ..model.neighbourhood import Neighbourhood
from ..linalg import sparse_contact
from ..linalg.backend import BACKEND_NAMES, choose_backend
from .solvers import LBFGS, ConvergenceError, DampedNewton, HostDampedNewton, Newton, Solution, StopReason, minimise
from ..linalg.stability import CONTACT_NEGATIVE_TOL, DEFAULT_NEGATIVE_TOL, Stability, stability

__all__ = ["Equilibrium", "EquilibriumOptions", "RelaxOptions", "solve_equilibrium", "relax", "relax_to_minimum",
           "relax_twist_free",
           "mode_step", "TopologyChangeError", "LeftBranchError", "scaled_energy", "scaled_zero_modes",
           "structured_hessian"]


# Module-level functions of (u, (scene, phi, nbr)): the solvers' jitted loops take the function as
# a static argument and the scene and its neighbourhood as pytree arguments, so one compilation
# serves every scene of the same kind and size, whatever its material or twist.
def scaled_energy(u, args):
    scene, phi, nbr = args
    return scene.scaled_energy(u, phi, nbr)


def scaled_zero_modes(u, args):
    scene, phi, _ = args
    return scene.scaled_zero_modes(u, phi)


def structured_hessian(u, args):
    scene, phi, nbr = args
    return scaled_hessian(scene, u, phi, nbr)


def neighbourhood_stale(u, args):
    scene, _, nbr = args
    return nbr.stale(scene.positions(scene.from_scaled(u)))


def _grown(scene, q, phi, nbr):
    """A fresh neighbourhood around q, at least as large as the last one (no recompilation)."""
    return scene.neighbourhood(q, phi, capacity=None if nbr is None else nbr.capacity)


class TopologyChangeError(RuntimeError):
    """The rod passed through itself (its writhe jumped by ~2): the knot type changed."""


class LeftBranchError(ConvergenceError):
    """A relaxation guided along a branch moved further from the guide shape than allowed: the
    state is jumping to another branch (raised early, before the jump is complete)."""


def _options(options, kind):
    """``options`` (None: the defaults) checked to be a ``kind`` (a float there is refused)."""
    if options is None:
        return kind()
    if not isinstance(options, kind):
        raise TypeError(f"options must be a {kind.__name__}, got {options!r}")
    return options


def _check_common(opts):
    """The knobs RelaxOptions and EquilibriumOptions share, each error naming its field."""
    check_positive("gtol", opts.gtol)
    if opts.max_steps is not None:
        check_int_at_least("max_steps", opts.max_steps, 0)
    check_int_at_least("k", opts.k, 1)
    if opts.negative_tol is not None and not (math.isfinite(opts.negative_tol) and opts.negative_tol >= 0.0):
        raise ValueError(f"negative_tol must be finite and >= 0, got {opts.negative_tol!r}")
    if not isinstance(opts.with_stability, bool):
        raise ValueError(f"with_stability must be True or False, got {opts.with_stability!r}")


@dataclass(frozen=True)
class RelaxOptions:
    """How ``relax`` and ``relax_to_minimum`` run (fields checked on construction; a ValueError
    names the wrong one).

    gtol: the result's max |gradient| of the scaled energy (default 1e-9).
    max_rounds: neighbourhood rebuilds allowed before giving up (default 200).
    max_steps: damped-Newton iterations between two rebuilds (None: 500).
    max_displacement: the cap on every node's step (physical length; None: D/4 with contact, so
      no strand can jump across another, else none).
    k: eigenpairs kept in the result's stability (default 8).
    with_stability: compute the result's stability (default True).
    negative_tol: an eigenvalue counts as negative below -negative_tol. None: 1e-10 in ``relax``;
      in ``relax_to_minimum`` 1e-6 with self-contact (sliding modes sit at |lambda| ~ 1e-7).
    linear_algebra: a backend name of ``jaxrod.linalg.backend.choose_backend``: "sparse" means
      ``HostDampedNewton`` on ``jaxrod.linalg.sparse_contact``, else the dense Hessian (Cholesky);
      the stability follows the same choice.
    """

    gtol: float = 1e-9
    max_rounds: int = 200
    max_steps: int | None = None
    max_displacement: float | None = None
    k: int = 8
    with_stability: bool = True
    negative_tol: float | None = None
    linear_algebra: str = "auto"

    def __post_init__(self):
        _check_common(self)
        check_int_at_least("max_rounds", self.max_rounds, 1)
        if self.max_displacement is not None:
            check_positive("max_displacement", self.max_displacement)
        if self.linear_algebra not in BACKEND_NAMES:
            raise ValueError(f"linear_algebra must be one of {BACKEND_NAMES}, got {self.linear_algebra!r}")


@dataclass(frozen=True)
class EquilibriumOptions:
    """How ``solve_equilibrium`` runs (fields checked on construction; a ValueError names one).

    method: 'newton' (exact Hessian, nearest stationary point: a continuation corrector), 'lbfgs'
      (minimiser), or 'auto' (the default: L-BFGS to 1e-5, then Newton to ``gtol``).
    gtol: the result's max |gradient| of the scaled energy (default 1e-9).
    max_steps: iterations allowed (None: the solver's default).
    k: eigenpairs kept in the result's stability (default 8).
    with_stability: compute the result's stability (default True).
    negative_tol: an eigenvalue counts as negative below -negative_tol (default 1e-10).
    near_null_tol: Newton leaves eigen-directions with |lambda| below it alone (default 0).
    """

    method: str = "auto"
    gtol: float = 1e-9
    max_steps: int | None = None
    k: int = 8
    with_stability: bool = True
    negative_tol: float = DEFAULT_NEGATIVE_TOL
    near_null_tol: float = 0.0

    def __post_init__(self):
        if self.method not in ("newton", "lbfgs", "auto"):
            raise ValueError(f"method must be 'newton', 'lbfgs' or 'auto', got {self.method!r}")
        _check_common(self)
        if not (math.isfinite(self.near_null_tol) and self.near_null_tol >= 0.0):
            raise ValueError(f"near_null_tol must be finite and >= 0, got {self.near_null_tol!r}")


def _relax_solver(scene, max_displacement, linear_algebra):
    """(solver, sparse) of ``relax``: the damped Newton of the backend ``choose_backend`` picks
    (the host one on SciPy's sparse factorisations where it picks "sparse"), every node's step
    capped at max_displacement (None: D/4 with contact, else none)."""
    has_contact = scene.has_term("contact")
    if max_displacement is not None:
        cap = float(max_displacement)
    else:
        cap = 0.25 * float(scene.material.D) if has_contact else math.inf
    max_step = cap / float(scene.length_scale)
    if choose_backend(scene, linear_algebra, offered=("dense", "sparse")).backend.name == "sparse":
        return HostDampedNewton(direction=sparse_contact.damped_newton_direction, max_step=max_step,
                                leave=neighbourhood_stale), True
    return DampedNewton(zero_modes=scaled_zero_modes if scene.n_zero_modes else None, max_step=max_step,
                        leave=neighbourhood_stale if scene.needs_neighbourhood else None,
                        hessian=structured_hessian), False


def relax(scene, phi=0.0, q0=None, options=None, *, previous=None, nbr=None, guide=None, progress=None):
    """Minimise the energy of a scene (with or without self-contact) from q0 (default scene.q_init)
    without letting the rod pass through itself; ``options``: a ``RelaxOptions`` (tolerance,
    budgets, step cap, stability, linear algebra). Damped Newton (exact structured Hessian, shifted
    positive definite) with every node's step capped at ``max_displacement``; the run pauses,
    rebuilds the neighbourhood and resumes whenever a node has moved more than skin/2. A writhe jump
    of 1 or more between pauses raises ``TopologyChangeError``; ``previous`` (an Equilibrium) makes
    the first comparison against its writhe. ``nbr``: a neighbourhood to start from (its capacity is
    kept). ``guide``: (x_guide (N,3), distance): raise ``LeftBranchError`` as soon as, at a pause,
    the shape is further than ``distance`` from x_guide (``polyline_distance``). ``progress``:
    optional callable(str). Returns the ``Equilibrium``; its ``neighbourhood`` is valid at the
    equilibrium."""
    opts = _options(options, RelaxOptions)
    gtol, max_steps, max_displacement, linear_algebra = opts.gtol, opts.max_steps, opts.max_displacement, \
        opts.linear_algebra
    negative_tol = DEFAULT_NEGATIVE_TOL if opts.negative_tol is None else opts.negative_tol
    phi = check_finite("phi", phi)
    q = np.asarray(scene.q_init if q0 is None else q0, dtype=float)
    say = progress or (lambda s: None)
    solver, sparse = _relax_solver(scene, max_displacement, linear_algebra)
    if not (scene.needs_neighbourhood and nbr is not None and not nbr.stale(np.asarray(scene.positions(q)))):
        nbr = _grown(scene, q, phi, nbr)
    # else the given neighbourhood still holds at q0 (no strand passage): the O(N^2) writhe at q0 is
    # not needed; the drift test below repeats the round if the writhe moved too far.
    wr_start = float(nbr.wr_ref)
    wr_last = wr_start if previous is None else float(previous.Wr)
    if abs(wr_start - wr_last) >= 1.0:
        raise TopologyChangeError(
            f"the starting state's writhe differs from the previous equilibrium's ({wr_last:.4f}) by 1 or more: "
            "the step passed the rod through itself"
        )
    total = 0
    for round_ in range(opts.max_rounds):
        u0 = scene.to_scaled(np.asarray(q, dtype=float))
        sol = minimise(scaled_energy, u0, (scene, jnp.asarray(phi), nbr), solver, gtol, max_steps, throw=False)
        total += sol.iterations
        q = scene.from_scaled(np.asarray(sol.y))
        upd = nbr.update(scene, q, phi)
        wr = float(upd.nbr.wr_ref)
        say(f"relax round {round_}: {sol.reason}, {sol.iterations} steps, |g| = {sol.grad_norm:.2e}, Wr = {wr:.4f}")
        if abs(wr - wr_last) >= 1.0:
            raise TopologyChangeError(f"writhe jumped from {wr_last:.4f} to {wr:.4f}: the rod passed through itself")
        wr_last = wr
        if guide is not None and sol.reason is StopReason.LEFT_REGION:
            moved = polyline_distance(np.asarray(scene.positions(jnp.asarray(q))), guide[0], scene.closed)
            if moved > guide[1]:
                raise LeftBranchError(f"the state moved {moved:.3g} from the guide shape (more than {guide[1]:.3g})")
        nbr = upd.nbr
        if sol.reason is StopReason.LEFT_REGION or upd.drifted:
            continue
        if not sol.converged:
            raise ConvergenceError(f"relaxation did not converge: {sol!r}", solution=sol, q=q)
        sol = Solution(y=sol.y, value=sol.value, grad_norm=sol.grad_norm, iterations=total,
                       converged=True, reason=StopReason.CONVERGED, solver=f"{sol.solver}({round_ + 1} rounds)",
                       gtol=sol.gtol)
        return equilibrium_from_solution(scene, phi, sol, nbr, k=opts.k, with_stability=opts.with_stability,
                                         negative_tol=negative_tol, linear_algebra="sparse" if sparse else "dense")
    raise ConvergenceError(f"relaxation needed more than {opts.max_rounds} neighbourhood rebuilds")


def mode_step(scene, scaled_mode, distance):
    """The DOF step (physical units, (n,)) along an eigenvector ``scaled_mode`` (scaled DOFs)
    that moves the node moving most by ``distance``: how far a state is pushed off a saddle or a
    branch end along its critical mode."""
    mode_q = scene.from_scaled(np.asarray(scaled_mode))
    x_mode = np.asarray(scene.unpack(jnp.asarray(mode_q), 0.0)[0])
    amp = distance / max(float(np.max(np.linalg.norm(x_mode, axis=1))), 1e-300)
    return amp * mode_q


# Twist (turns) that a closed rod relaxed at phi = 0 may store before Lk0 is called into question
# (a loose knot with the right Lk0 stores a few hundredths).
TWIST_FREE_TOL = 0.25


def warn_if_twisted_at_zero(scene, eq):
    """Warn when a closed rod relaxed at phi = 0 stores more than a quarter turn of twist: its Lk0
    (by default the integer nearest the drawn curve's writhe) is then not the twist-free rod's
    linking number. Returns True if it warned."""
    Lk0 = getattr(scene, "Lk0", None)
    if Lk0 is None or not abs(float(eq.Tw)) > TWIST_FREE_TOL:
        return False
    twist_free = int(round(float(eq.Wr)))
    warnings.warn(
        f"the rod relaxed at phi = 0 stores Tw = {float(eq.Tw):+.3f} turns of twist (Wr = {float(eq.Wr):.3f}, "
        f"Lk0 = {int(round(Lk0))}), more than {TWIST_FREE_TOL} turn: phi = 0 is not the untwisted rod. Lk0 is "
        f"the integer nearest the writhe of the curve as drawn; the relaxed rod would be twist-free with "
        f"Lk0 = {twist_free}. Give Lk0 if this is not what you meant (closed_curve(..., Lk0=...), the CLI's --lk0)",
        stacklevel=3)
    return True


def relax_to_minimum(scene, phi=0.0, q0=None, options=None, *, push=None, max_pushes=4, progress=None):
    """``relax`` (with ``options``, a ``RelaxOptions``), then make sure the result is a minimum:
    a symmetric starting shape can relax onto a saddle that the symmetry-keeping minimiser never
    leaves. While the equilibrium has an eigenvalue below -options.negative_tol (default 1e-6 with
    contact, else 1e-10), the state is pushed both ways along the most negative eigenvector (by
    ``push``, default D/2 at the node that moves most) and relaxed again; the lower-energy result
    is kept. Returns a stable ``Equilibrium`` (stability always computed); raises
    ``ConvergenceError`` if ``max_pushes`` pushes leave it unstable."""

    opts = _options(options, RelaxOptions)
    if opts.negative_tol is None:
        opts = replace(opts, negative_tol=CONTACT_NEGATIVE_TOL if scene.has_term("contact") else DEFAULT_NEGATIVE_TOL)
    opts = replace(opts, with_stability=True)
    check_int_at_least("max_pushes", max_pushes, 0)
    say = progress or (lambda s: None)
    e = relax(scene, phi, q0, opts)
    if phi == 0.0:
        warn_if_twisted_at_zero(scene, e)
    if push is None:
        push = 0.5 * float(scene.material.D)
    for _ in range(max_pushes):
        if e.stability.stable:
            return e
        step = mode_step(scene, e.stability.eigenvectors[:, 0], push)
        say(f"relaxed state is a saddle (lowest eigenvalue {e.stability.eigenvalues[0]:.3e}): pushing along it")
        found = []
        for sign in (1.0, -1.0):
            try:
                found.append(relax(scene, phi, e.q + sign * step, opts, previous=e, nbr=e.neighbourhood))
            except (ConvergenceError, TopologyChangeError) as exc:
                say(f"  push {'+' if sign > 0 else '-'}: {type(exc).__name__}: {exc}")
        if not found:
            break
        e = min(found, key=lambda f: (not f.stability.stable, f.energy))
    if e.stability.stable:
        return e
    raise ConvergenceError(f"no stable equilibrium found near the relaxed state at phi = {phi / math.pi:+.6f} pi after "
                           f"{max_pushes} pushes along the unstable mode: {e.stability!r}")


@dataclass(frozen=True)
class Equilibrium:
    """A converged equilibrium.

    q: (n,) free DOFs (physical units); x: (N,3) nodes; theta: (M,) edge twist angles; phi: imposed
    twist; energy: total; energy_terms: dict per term; solution: the solver's ``Solution``
    (iterations, gradient norm, stop reason); stability: ``Stability`` (or None when explicitly not
    computed); Wr, Tw, Lk: writhe, twist and linking number (open clamped rods: of the centreline
    extended along the clamp axis); neighbourhood: the ``Neighbourhood`` (contact candidates,
    writhe) valid at this state, for fast evaluations around it."""

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
    neighbourhood: Neighbourhood | None = None

    @property
    def stable(self):
        return None if self.stability is None else self.stability.stable

    def __repr__(self):
        return (
            f"Equilibrium(phi={self.phi:.6g}, energy={self.energy:.10g}, Wr={self.Wr:.6f}, "
            f"Tw={self.Tw:.6f}, Lk={self.Lk:.6f}, {self.solution!r}, {self.stability!r})"
        )


def solve_equilibrium(scene, phi=0.0, q0=None, options=None, *, nbr=None, throw=True):
    """Equilibrium of ``scene`` at imposed twist ``phi`` starting from ``q0`` (default
    scene.q_init); ``options``: an ``EquilibriumOptions`` (method, tolerance, budget, stability).
    nbr: a ``Neighbourhood`` to reuse (its capacity is kept); it is rebuilt around q0 and, if the
    state moved out of it (contact list stale, writhe drifted), around the result, and the solve
    repeated. The result carries its stability (k lowest eigenvalues, negative count) unless
    ``options.with_stability`` is False. Raises ``ConvergenceError`` if the solver fails and
    ``throw``."""
    opts = _options(options, EquilibriumOptions)
    method, gtol, max_steps = opts.method, opts.gtol, opts.max_steps
    phi = check_finite("phi", phi)
    q0 = np.asarray(scene.q_init if q0 is None else q0, dtype=float)
    if q0.shape != (scene.n_dof,):
        raise ValueError(f"q0 must have shape ({scene.n_dof},), got {q0.shape}")
    if not np.all(np.isfinite(q0)):
        raise ValueError("q0 must be finite")
    newton = Newton(zero_modes=scaled_zero_modes if scene.n_zero_modes else None,
                    near_null_tol=float(opts.near_null_tol),
                    hessian=structured_hessian)
    q = q0
    nbr = _grown(scene, q, phi, nbr)
    for _ in range(20):
        u0 = scene.to_scaled(np.asarray(q, dtype=float))
        args = (scene, jnp.asarray(phi), nbr)
        if method == "newton":
            sol = minimise(scaled_energy, u0, args, newton, gtol, max_steps, throw=False)
        elif method == "lbfgs":
            sol = minimise(scaled_energy, u0, args, LBFGS(), gtol, max_steps, throw=False)
        else:
            # L-BFGS stops at once where |g| <= 1e-5 already: ask the Newton loop (compiled for
            # the polish anyway) for |g| first, and compile L-BFGS only when it has work to do.
            probe = minimise(scaled_energy, u0, args, newton, gtol, 0, throw=False)
            if probe.grad_norm <= max(gtol, 1e-5):
                pre = replace(probe, iterations=0)
            else:
                pre = minimise(scaled_energy, u0, args, LBFGS(), max(gtol, 1e-5), max_steps, throw=False)
            start = pre.y if np.all(np.isfinite(pre.y)) else np.asarray(u0)
            sol = minimise(scaled_energy, start, args, newton, gtol, None, throw=False)
            sol = Solution(
                y=sol.y, value=sol.value, grad_norm=sol.grad_norm,
                iterations=pre.iterations + sol.iterations, converged=sol.converged,
                reason=sol.reason, solver=f"lbfgs({pre.iterations})+newton({sol.iterations})", gtol=sol.gtol,
            )
        if not np.all(np.isfinite(sol.y)):
            break
        q = scene.from_scaled(np.asarray(sol.y))
        upd = nbr.update(scene, q, phi)
        nbr = upd.nbr
        if not upd.outdated:
            break
    if throw and not sol.converged:
        raise ConvergenceError(f"{sol.solver} did not converge: {sol!r}")
    return equilibrium_from_solution(scene, phi, sol, nbr, opts.k, opts.with_stability, opts.negative_tol)


@cached_jit
def _diagnostics(scene, u, phi, nbr):
    q = scene.from_scaled(u)
    x, theta = scene.unpack(q, phi, nbr)
    return q, x, theta, scene.energy_terms(q, phi, nbr), scene.twist(q, phi, nbr)


def equilibrium_from_solution(scene, phi, sol, nbr, k=8, with_stability=True, negative_tol=DEFAULT_NEGATIVE_TOL,
                              linear_algebra="auto"):
    """Wrap a solver ``Solution`` (scaled DOFs) into an ``Equilibrium`` with its diagnostics;
    ``nbr`` must be the neighbourhood built at sol.y (its writhe is the state's)."""
    q, x, theta, terms, tw = jax.device_get(_diagnostics(scene, jnp.asarray(sol.y), jnp.asarray(phi), nbr))
    terms = {k_: float(v) for k_, v in terms.items()}
    wr, tw = float(nbr.wr_ref), float(tw)
    stab = stability(scene, q, phi, k=k, tol=negative_tol, nbr=nbr, linear_algebra=linear_algebra) \
        if with_stability else None
    return Equilibrium(
        q=q, x=np.asarray(x), theta=np.asarray(theta), phi=phi, energy=float(sum(terms.values())),
        energy_terms=terms, solution=sol, stability=stab, Wr=wr, Tw=tw, Lk=wr + tw, neighbourhood=nbr,
    )


# Fields of an Equilibrium's ``Solution`` kept in a checkpoint (y, the scaled DOFs, separately).
_SOLUTION_SCALARS = ("value", "grad_norm", "iterations", "converged", "reason", "solver", "gtol")


def equilibrium_arrays(e, prefix):
    """What rebuilds ``e`` exactly (``equilibrium_from_arrays``), as numpy arrays named
    ``prefix + field`` for an npz file: the solver's scaled DOFs and scalars, phi and the
    neighbourhood; the diagnostics are recomputed bit for bit, the stability is not stored."""
    nbr = e.neighbourhood
    out = {prefix + "y": np.asarray(e.solution.y), prefix + "phi": np.asarray(float(e.phi))}
    for key in _SOLUTION_SCALARS:
        value = getattr(e.solution, key)
        out[prefix + "solution_" + key] = np.asarray(str(value) if key in ("reason", "solver") else value)
    for key in ("pairs", "mask", "x_built", "skin", "wr_ref"):
        out[prefix + "nbr_" + key] = np.asarray(getattr(nbr, key))
    return out


def equilibrium_from_arrays(scene, arrays, prefix):
    """The ``Equilibrium`` stored by ``equilibrium_arrays`` (without its stability)."""
    get = lambda key: arrays[prefix + key]  # noqa: E731
    nbr = Neighbourhood(*(jnp.asarray(get("nbr_" + key)) for key in ("pairs", "mask", "x_built", "skin", "wr_ref")))
    sol = Solution(
        y=np.asarray(get("y")), value=float(get("solution_value")), grad_norm=float(get("solution_grad_norm")),
        iterations=int(get("solution_iterations")), converged=bool(get("solution_converged")),
        reason=StopReason(str(get("solution_reason"))), solver=str(get("solution_solver")),
        gtol=float(get("solution_gtol")),
    )
    return equilibrium_from_solution(scene, float(get("phi")), sol, nbr, with_stability=False)


def relax_twist_free(scene, q0=None, options=None, *, max_rounds=3, progress=None):
    """A closed rod relaxed at phi = 0 with the linking number that leaves it least twisted.

    ``relax_to_minimum`` at phi = 0 from q0 (None: the scene's start); then, while Lk0 is not the integer nearest the relaxed writhe
    (the rod stores more than half a turn of twist: a drawing whose writhe is far from the relaxed
    knot's, such as the torus knot T(2,5)), Lk0 is set to that integer and the rod relaxed again
    from there, at most ``max_rounds`` times. Lk0 is an integer, so up to half a turn may remain.
    Returns (scene, Equilibrium): the scene with that Lk0 (the one given where it was right), whose
    phi = 0 is the untwisted knot. A scene without Lk0 (a clamped rod) is relaxed once."""
    check_int_at_least("max_rounds", max_rounds, 0)
    say = progress or (lambda s: None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the twist stored at phi = 0 is what this corrects
        e = relax_to_minimum(scene, 0.0, q0, options=options)
        for _ in range(max_rounds):
            if getattr(scene, "Lk0", None) is None or round(float(e.Wr)) == round(float(scene.Lk0)):
                break
            say(f"relaxed at phi = 0 with Lk0 = {round(float(scene.Lk0))}: Wr = {float(e.Wr):.3f}, "
                f"Tw = {float(e.Tw):+.3f} turns; Lk0 = {round(float(e.Wr))} instead")
            scene = replace(scene, Lk0=float(round(float(e.Wr))))
            e = relax_to_minimum(scene, 0.0, e.q, options=options)
    if abs(float(e.Tw)) > 0.5:  # max_rounds reached without settling
        warn_if_twisted_at_zero(scene, e)
    return scene, e
