"""The notebook user's API: one call per task, for rings, knots and clamped rods alike.

Scene builders (``ring``, ``michell_ring``, ``knot``, ``trefoil``, ``torus_knot``, ``clamped_rod``,
``free_rod``, ``closed_curve``) share one convention: the shape is positional (``knot(name)``,
``torus_knot(p, q)``, ``closed_curve(points)``; none for the others) and every quantity is
keyword-only, under one naming: ``N`` the node count, ``D`` the rod's diameter and ``L`` its length
(mm for knots; rings and clamped rods in units of their radius or length), ``material`` a
``Material``, ``nu`` the Poisson ratio. For example ``knot("3_1", N=61, D=8.0, L=292.0)``,
``ring(N=48, material=m)``, ``clamped_rod(N=41, length=1.0, material=m)``.

The tasks:

- ``equilibrium(scene, phi, start)``: a minimum at the imposed twist phi (rad), or any stationary
  state when asked (``SolveOptions(minimum=False)``), with its ``StabilityReport``;
- ``stability(scene, state)``: the one stability rule (``StabilityReport``): the Morse index counts
  the negative modes that change the shape; the rigid-motion zero modes and the sliding modes
  (strands slipping along the centreline) are counted apart;
- ``follow_twist(scene, phi_start, phi_stop, options, observer=Observer(on_point=...))``:
  continuation, one callback signature ``on_point(PathPoint)``;
- ``critical_twists(scene)``: the first instability on each side of phi = 0, one ``CriticalTwists``;
- ``critical_twist_sensitivity(scene, end, parameter)``: d phi* / d parameter.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from .continuation import ContinuationOptions, critical_twist
from .continuation.kinds import EventKind
from .linalg.sliding import SLIDING_FRACTION, sliding_fraction
from .linalg.stability import Stability, critical_twist_derivative, stability as lowest_modes
from .linalg.tolerances import CONTACT_NEGATIVE_TOL, scaled_negative_tol
from .solve.equilibrium import Equilibrium, RelaxOptions, relax, relax_to_minimum

__all__ = ["SolveOptions", "StabilityReport", "CriticalEnd", "CriticalTwists", "equilibrium", "stability",
           "critical_twists", "critical_twist_sensitivity", "FAR_START"]

# A single solve that starts further than this (rad) from its start state's twist may land on
# another branch (the trefoil relaxed at 6 pi from its zero-twist state lands on the buckled one).
FAR_START = math.pi


@dataclass(frozen=True)
class SolveOptions:
    """What ``equilibrium`` returns and how it solves.

    Parameters
    ----------
    minimum : bool, optional
        True (default) returns a minimum: a state that converges to a saddle (along a sliding or
        a shape mode) is pushed along its negative mode and relaxed again, as
        ``relax_to_minimum`` does; False returns the stationary state the solver converged to,
        whatever its stability.
    relax : RelaxOptions or None, optional
        The solver's tolerance, budgets and linear algebra (None: the defaults).
    far_start : float, optional
        Warn when |phi - start twist| exceeds this (rad; default pi).

    Raises
    ------
    TypeError
        ``minimum`` not a bool, or ``relax`` not a ``RelaxOptions``.
    ValueError
        ``far_start`` not a positive number.
    """

    minimum: bool = True
    relax: RelaxOptions | None = None
    far_start: float = FAR_START

    def __post_init__(self):
        if not isinstance(self.minimum, (bool, np.bool_)):
            raise TypeError(f"minimum must be True or False, got {self.minimum!r}")
        if self.relax is not None and not isinstance(self.relax, RelaxOptions):
            raise TypeError(f"relax must be a RelaxOptions, got {self.relax!r}")
        if not (isinstance(self.far_start, (int, float)) and self.far_start > 0):
            raise ValueError(f"far_start must be a number > 0 (rad), got {self.far_start!r}")


@dataclass(frozen=True)
class StabilityReport(Stability):
    """A state's stability under the one rule every public function uses.

    eigenvalues (k,), eigenvectors (n, k): the lowest eigenpairs of the Hessian (dimensionless,
    scaled DOFs), zero modes removed; n_negative: eigenvalues below -tol (the solver's count);
    n_zero_modes: the rigid motions (and the uniform twist shift) removed; morse_index: the
    negative modes that change the shape; n_sliding: the modes that slide (sliding fraction below
    ``SLIDING_FRACTION``) with eigenvalue below ``band`` (negative or near-null: a knot's strands
    slipping), counted apart from the Morse index; sliding: (k,) bool, which computed modes slide;
    band: the near-null band (CONTACT_NEGATIVE_TOL on knots, else tol); minimum: no eigenvalue
    below -band (the state is a minimum); saddle_mode: index into eigenvalues of the most negative
    mode when not a minimum, else None; saddle_kind: 'shape' or 'sliding' (None at a minimum)."""

    morse_index: int = 0
    n_sliding: int = 0
    sliding: tuple = ()
    band: float = 0.0
    minimum: bool = True
    saddle_mode: int | None = None
    saddle_kind: str | None = None

    def __repr__(self):
        lam = ", ".join(f"{v:.3e}" for v in self.eigenvalues[:6])
        saddle = "" if self.minimum else f", saddle along mode {self.saddle_mode} ({self.saddle_kind})"
        return (f"StabilityReport(minimum={self.minimum}, morse_index={self.morse_index}, "
                f"n_sliding={self.n_sliding}, n_zero_modes={self.n_zero_modes}{saddle}, lowest=[{lam}])")


def _can_slide(scene):
    return int(scene.n_free_nodes) == int(scene.n_nodes) and scene.has_term("contact")


def _report(scene, q, modes):
    """The ``StabilityReport`` of the state q from its lowest eigenpairs ``modes`` (a Stability)."""
    lam = np.asarray(modes.eigenvalues)
    band = CONTACT_NEGATIVE_TOL if scene.has_term("contact") else float(modes.tol)
    low = lam < band
    slides = np.zeros(lam.shape, dtype=bool)
    if _can_slide(scene) and np.any(low):
        slides[low] = sliding_fraction(scene, q, np.asarray(modes.eigenvectors)[:, low]) < SLIDING_FRACTION
    negative = lam < -modes.tol
    # eigenvalues below -tol beyond the k computed are shape modes (a slide is near-null)
    morse = int(np.sum(negative & ~slides)) + max(int(modes.n_negative) - int(np.sum(negative)), 0)
    below_band = lam < -band
    minimum = not np.any(below_band) and morse == 0
    saddle = None if minimum else int(np.argmin(lam))
    return StabilityReport(
        eigenvalues=lam, eigenvectors=np.asarray(modes.eigenvectors), n_negative=int(modes.n_negative),
        n_zero_modes=int(modes.n_zero_modes), stable=bool(modes.stable), tol=float(modes.tol),
        morse_index=morse, n_sliding=int(np.sum(slides & low)), sliding=tuple(bool(s) for s in slides),
        band=float(band), minimum=bool(minimum), saddle_mode=saddle,
        saddle_kind=None if saddle is None else ("sliding" if slides[saddle] else "shape"))


def stability(scene, state, phi=None, k=8):
    """The stability of a state of ``scene`` under the one rule every public function uses.

    The Morse index counts the negative modes that change the shape; the zero modes (rigid
    motions) and the sliding modes (strands slipping along the centreline, |lambda| within the
    near-zero band) are counted apart.

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod.
    state : Equilibrium or array_like of shape (n_dof,)
        An equilibrium (its twist and contact neighbourhood used), or physical DOFs q.
    phi : float, optional
        Imposed twist (rad); required with a bare q, overrides an equilibrium's twist.
    k : int, optional
        Eigenpairs computed (at least 8; more where more are negative).

    Returns
    -------
    StabilityReport
        The lowest eigenvalues (k,) of the scaled Hessian (units of B/l, l the edge length; zero
        modes removed), eigenvectors (n_dof, k), ``morse_index``, ``n_sliding``,
        ``n_zero_modes``, ``band`` and ``minimum``.

    Raises
    ------
    ValueError
        A bare q without ``phi``.
    """
    if isinstance(state, Equilibrium):
        q, phi = np.asarray(state.q), float(state.phi if phi is None else phi)
        nbr = state.neighbourhood
    else:
        if phi is None:
            raise ValueError("stability(scene, q, phi): give the twist phi (rad) with a bare state q")
        q, phi, nbr = np.asarray(state, dtype=float), float(phi), None
    tol = scaled_negative_tol(scene)
    modes = lowest_modes(scene, q, phi, k=max(int(k), 8), tol=tol, nbr=nbr)
    if modes.n_negative > len(modes.eigenvalues):
        modes = lowest_modes(scene, q, phi, k=int(modes.n_negative) + 2, tol=tol, nbr=nbr)
    return _report(scene, q, modes)


def _start(scene, phi, start, far):
    """(q0, previous equilibrium or None) of a solve at phi from ``start``; warns when the start's
    twist is further than ``far`` from phi."""
    if start is None:
        q0, previous, phi0 = None, None, 0.0
    elif isinstance(start, Equilibrium):
        q0, previous, phi0 = np.asarray(start.q), start, float(start.phi)
    else:
        q0, previous, phi0 = np.asarray(start, dtype=float), None, None
    if phi0 is not None and abs(phi - phi0) > far:
        warnings.warn(f"one solve at phi = {phi / math.pi:+.4f} pi from a state at {phi0 / math.pi:+.4f} pi "
                      f"({abs(phi - phi0) / math.pi:.2f} pi away): it may land on another branch; follow the "
                      "twist there (follow_twist) to stay on the start's branch", stacklevel=3)
    return q0, previous


def equilibrium(scene, phi=0.0, start=None, options=None):
    """An equilibrium of ``scene`` at an imposed twist, relaxed from ``start``.

    With the default options the result is a minimum: a state that converged to a saddle is
    pushed off it along its negative mode and relaxed again. Warns (UserWarning) when phi is
    more than ``options.far_start`` from the start's twist (the solve may land on another branch).

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod.
    phi : float, optional
        Imposed twist (rad; default 0).
    start : None, Equilibrium or array_like of shape (n_dof,), optional
        None: the scene's initial shape, at zero twist; an ``Equilibrium`` (e.g. the state at
        another twist); or physical DOFs q.
    options : SolveOptions, optional
        What to return and how to solve (default: a minimum).

    Returns
    -------
    Equilibrium
        q (n_dof,), phi (rad), energy (units of the material: N mm for knots built in mm and
        MPa), Wr, Tw, Lk, and ``stability`` a ``StabilityReport``; with
        ``SolveOptions(minimum=False)`` the report names the mode that makes a saddle
        (``saddle_mode``, ``saddle_kind``).

    Raises
    ------
    TypeError
        ``options`` is not a ``SolveOptions``.
    ValueError
        ``start`` of the wrong shape or not finite.
    ConvergenceError
        The solver did not converge, or no minimum was found near the converged state.
    TopologyChangeError
        The rod passed through itself during the relaxation (a knot's type changed).
    """
    opts = SolveOptions() if options is None else options
    if not isinstance(opts, SolveOptions):
        raise TypeError(f"options must be a SolveOptions, got {opts!r}")
    phi = float(phi)
    q0, previous = _start(scene, phi, start, opts.far_start)
    relax_opts = opts.relax or RelaxOptions()
    e = relax(scene, phi, q0, relax_opts, previous=previous)
    report = stability(scene, e)
    if opts.minimum and not report.minimum:
        band_opts = replace(relax_opts, negative_tol=report.band)
        e = relax_to_minimum(scene, phi, e.q, band_opts)
        report = stability(scene, e)
    return replace(e, stability=report)


@dataclass(frozen=True)
class CriticalEnd:
    """Where the stable branch from phi = 0 ends on one side.

    side: 'plus' or 'minus'; phi: the critical twist (rad); kind: an ``EventKind`` (FOLD or
    BRANCH_POINT for a knot's located end; BRANCH_POINT for a ring's or clamped rod's crossing
    eigenvalue); bracket: (phi_a, phi_b) where the stability changed; phi_error: bound on the
    location error (rad); q: (n,) the state at the end (physical DOFs); mode: (n,) the critical
    mode (scaled DOFs); multiplicity: eigenvalues crossing together; discretisation_error: an
    estimate of |phi* - phi*(N -> inf)| (rad) when asked (``critical_twists(...,
    discretisation_error=True)``), else None; source: the located object
    (a ``CriticalPoint`` or the study's ``BranchEnd``), which ``critical_twist_sensitivity`` reads."""

    side: str
    phi: float
    kind: EventKind
    bracket: tuple
    phi_error: float
    q: np.ndarray = field(repr=False)
    mode: np.ndarray = field(repr=False)
    multiplicity: int = 1
    discretisation_error: float | None = None
    source: object = field(default=None, repr=False)


@dataclass(frozen=True)
class CriticalTwists:
    """The critical twists on both sides of phi = 0: ``plus`` and ``minus``, each a ``CriticalEnd``
    (phi in rad, q (n,) physical DOFs, mode (n,) scaled DOFs); ``seconds``: wall time."""

    plus: CriticalEnd
    minus: CriticalEnd
    seconds: float = 0.0

    def __iter__(self):
        return iter((self.plus, self.minus))


def _is_knot(scene):
    return bool(getattr(scene, "closed", False)) and scene.has_term("contact")


def _ring_end(scene, side, phi_stop, options):
    cp = critical_twist(scene, 0.0, phi_stop, options)
    return CriticalEnd(side=side, phi=float(cp.phi), kind=EventKind.BRANCH_POINT, bracket=tuple(cp.bracket),
                       phi_error=float(cp.phi_error), q=np.asarray(cp.equilibrium.q), mode=np.asarray(cp.mode),
                       multiplicity=int(cp.multiplicity), source=cp)


def _knot_ends(scene, phi_min, phi_max, options, error=False):
    """{side: CriticalEnd} of a knot: the twist study's first end on each side, located exactly on
    the extended system (``unstable_branches``), as ``run_knot_study`` does; with ``error`` each
    end's discretisation error from the study's files (``_knot_errors``)."""
    import contextlib
    import tempfile

    # the coarse companion starts from the study's step files: only then are they written
    with tempfile.TemporaryDirectory(prefix="jaxrod-critical-") if error else contextlib.nullcontext() as out:
        found, study = _located_knot_ends(scene, phi_min, phi_max, options, out)
        if error and set(found) == {"plus", "minus"}:  # else critical_twists refuses the missing side
            found = _knot_errors(scene, study, out, found, max(-phi_min, phi_max), options)
    return found


def _located_knot_ends(scene, phi_min, phi_max, options, out):
    from .studies.diagram import unstable_branches
    from .studies.twist import twist_study

    study = twist_study(scene, phi_min, phi_max, options, out=out)
    diagram = unstable_branches(scene, study, parallel=False)
    found = {}
    for inst, end in zip(study.critical.get("instabilities", []), diagram.ends):
        side = inst["direction"]
        if side in found:
            continue
        if end.event is None or not end.event.converged:
            raise RuntimeError(f"{side}: the end bracketed at {inst['phi'] / math.pi:+.6f} pi was not located: "
                               f"{end.message}")
        ev = end.event
        found[side] = CriticalEnd(side=side, phi=float(ev.p), kind=EventKind(ev.kind), bracket=tuple(inst["bracket"]),
                                  phi_error=float(ev.residual), q=end.rod.q(ev.u), mode=np.asarray(ev.v[:, 0]),
                                  multiplicity=int(ev.multiplicity), source=end)
    return found, study


def _no_estimate(side, N_c, reason):
    return RuntimeError(f"{side}: no discretisation error estimate: the end was not found again at the coarse "
                        f"level N = {N_c}: {reason}")


def _knot_errors(scene, study, out, found, span, options):
    """``found`` with each end's discretisation error: ``coarse_companion`` on the study in ``out``."""
    from .studies.coarse import coarse_companion, coarse_level
    from .studies.twist import study_options

    o = study_options(options)
    coarse = coarse_companion(scene, out, study.critical, span=span, step=o.step, tol=o.tol, sides=tuple(found))
    for side in found:
        if side not in coarse:
            raise _no_estimate(side, coarse_level(scene), coarse.reasons.get(side, "no end"))
        found[side] = replace(found[side], discretisation_error=float(coarse[side][1].error))
    return found


def _ring_errors(scene, ends, phi_min, phi_max, options):
    """``ends`` with each end's discretisation error: the closed rod resampled to the coarse level
    (``refine_scene``), its crossing located again, and Richardson's two-level estimate."""
    from .continuation import NoCrossingError
    from .studies.accuracy import refine_scene, richardson
    from .studies.coarse import coarse_level

    N, N_c = int(scene.n_nodes), coarse_level(scene)
    coarse = refine_scene(scene, np.asarray(scene.q_init)[: 3 * N].reshape(N, 3), N_c)
    for side, stop in (("plus", phi_max), ("minus", phi_min)):
        try:
            cp = critical_twist(coarse, 0.0, stop, options)
        except NoCrossingError as exc:
            raise _no_estimate(side, N_c, exc) from exc
        end = ends[side]
        estimate = richardson([N_c, N], [float(cp.phi), end.phi], [float(cp.phi_error), end.phi_error])
        ends[side] = replace(end, discretisation_error=float(estimate.error))
    return ends


def _check_estimable(scene):
    """Refuses, before any work, a scene whose discretisation error cannot be estimated."""
    from .studies.coarse import coarse_level

    if not getattr(scene, "closed", False):
        raise ValueError(f"discretisation_error: estimated for closed rods (rings and knots), which are resampled "
                         f"to a coarser level; got a {type(scene).__name__}")
    coarse_level(scene)


def critical_twists(scene, phi_min=-8.0 * math.pi, phi_max=8.0 * math.pi, options=None, *,
                    discretisation_error=False):
    """The critical twists of ``scene`` on both sides of phi = 0: the first twist, going up and
    going down from the relaxed state at phi = 0, where the stable branch ends.

    Rings and clamped rods: the crossing eigenvalue located by ``critical_twist``. Knots: the
    twist study's branch ends (``twist_study``), each located on the extended system as a fold
    or branch point (``unstable_branches``).

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod.
    phi_min, phi_max : float, optional
        The range searched (rad; default -8 pi and 8 pi); phi_min < 0 < phi_max.
    options : ContinuationOptions, optional
        Step, tolerances and linear algebra (None: each engine's defaults).
    discretisation_error : bool, optional
        Also estimate each end's |phi* - phi*(N -> inf)| (rad, in
        ``CriticalEnd.discretisation_error``): the end is found again on the rod resampled to
        N_c = (N + 1) / 2 nodes, and the two levels give Richardson's estimate (order 2 assumed,
        Roache's factor 3) plus the two locations' own errors. Closed rods only.

    Returns
    -------
    CriticalTwists
        ``plus`` and ``minus``, each a ``CriticalEnd``: phi (rad), kind (``EventKind``),
        bracket (rad), phi_error (rad), q (n_dof,) and mode (n_dof,).

    Raises
    ------
    ValueError
        phi_min < 0 < phi_max does not hold; ``discretisation_error`` on an open rod; or
        ``CoarseLevelTooSmall`` (a ValueError, before any work) when N_c is below the rod's
        resolution (8 nodes; a knot 24 and L/D).
    TypeError
        ``discretisation_error`` is not a bool.
    NoCrossingError
        A ring or clamped rod whose stability does not change in the range (names the side).
    RuntimeError
        A knot with no located end on a side in the range, or a coarse level that finds no end
        (the message names the side and the reason).
    """
    import time

    t0 = time.perf_counter()
    if not phi_min < 0.0 < phi_max:
        raise ValueError(f"phi_min must be < 0 < phi_max (rad), got {phi_min!r}, {phi_max!r}")
    if not isinstance(discretisation_error, (bool, np.bool_)):
        raise TypeError(f"discretisation_error must be True or False, got {discretisation_error!r}")
    if discretisation_error:
        _check_estimable(scene)
    if _is_knot(scene):
        ends = _knot_ends(scene, phi_min, phi_max, options, discretisation_error)
        missing = [s for s in ("plus", "minus") if s not in ends]
        if missing:
            raise RuntimeError(f"no branch end on the {' and '.join(missing)} side between "
                               f"{phi_min / math.pi:+.4f} pi and {phi_max / math.pi:+.4f} pi")
    else:
        ends = {"plus": _ring_end(scene, "plus", phi_max, options),
                "minus": _ring_end(scene, "minus", phi_min, options)}
        if discretisation_error:
            ends = _ring_errors(scene, ends, phi_min, phi_max, options)
    return CriticalTwists(plus=ends["plus"], minus=ends["minus"], seconds=time.perf_counter() - t0)


def _knot_sensitivity(scene, end, parameter):
    """d phi*/d parameter at a knot's located fold (``fold_sensitivity`` on its extended system)."""
    from .continuation.arclength import branch_point_sensitivity, fold_sensitivity

    if end.kind not in (EventKind.FOLD, EventKind.BRANCH_POINT):
        raise ValueError(f"the {end.side} end is a {end.kind}: the sensitivity of a knot's critical twist is "
                         "computed at a fold or a simple branch point (the implicit function theorem on its system)")
    rod, ev = end.source.rod, end.source.event
    base = parameter_value(rod.problem.args.scene, parameter)

    def set_mu(args, mu):
        return args._replace(scene=args.scene.with_params(**{parameter: mu}))

    at = fold_sensitivity if end.kind == EventKind.FOLD else branch_point_sensitivity
    return float(at(rod.problem, ev, set_mu, base))


def parameter_value(scene, parameter):
    """The value of a continuous parameter of ``scene`` (a name in ``scene.PARAMETERS``; nu = B/C - 1)."""
    if parameter not in scene.PARAMETERS:
        raise ValueError(f"parameter must be one of {', '.join(scene.PARAMETERS)}, got {parameter!r}")
    if parameter == "nu":
        return float(scene.material.B) / float(scene.material.C) - 1.0
    if parameter == "contact_stiffness":
        return float(scene.contact_stiffness)
    return float(getattr(scene.material, parameter))


def critical_twist_sensitivity(scene, end, parameter):
    """The derivative d phi* / d parameter of a critical twist.

    Rings and clamped rods: the implicit function theorem on the crossing eigenvalue
    (``critical_twist_derivative``); knots: on the fold system at a located fold
    (``fold_sensitivity``), on the unfolded branch-point system at a simple branch point
    (``branch_point_sensitivity``).

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod the end was located on.
    end : CriticalEnd
        An end of ``critical_twists(scene)``.
    parameter : str
        'B', 'C', 'EA', 'D', 'nu' or 'contact_stiffness', changed as ``scene.with_params``
        changes it (nu sets C = B/(1+nu); D is the contact diameter only).

    Returns
    -------
    float
        d phi* / d parameter, in rad per unit of the parameter (e.g. rad/mm for D).

    Raises
    ------
    TypeError
        ``end`` is not a ``CriticalEnd``.
    ValueError
        An unknown parameter, or a knot's end that is neither a fold nor a branch point.
    """
    if not isinstance(end, CriticalEnd):
        raise TypeError(f"end must be a CriticalEnd (from critical_twists), got {type(end).__name__}")
    if _is_knot(scene):
        return _knot_sensitivity(scene, end, parameter)
    return float(critical_twist_derivative(scene, end.source, parameter))
