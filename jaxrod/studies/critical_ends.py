"""Critical twists of a scene on both sides of phi = 0 (``critical_twists``) and their
sensitivities to its continuous parameters (``critical_twist_sensitivity``): rings and clamped rods
by the crossing eigenvalue, knots by the twist study's ends located on their extended systems.
``jaxrod.critical_twists`` and ``jaxrod.critical_twist_sensitivity`` are these."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..continuation import critical_twist
from ..continuation.kinds import EventKind
from ..linalg.stability import critical_twist_derivative

__all__ = ["CriticalEnd", "CriticalTwists", "critical_twists", "critical_twist_sensitivity", "parameter_value",
           "is_knot", "ring_end", "knot_ends"]


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


def is_knot(scene):
    return bool(getattr(scene, "closed", False)) and scene.has_term("contact")


def ring_end(scene, side, phi_stop, options):
    cp = critical_twist(scene, 0.0, phi_stop, options)
    return CriticalEnd(side=side, phi=float(cp.phi), kind=EventKind.BRANCH_POINT, bracket=tuple(cp.bracket),
                       phi_error=float(cp.phi_error), q=np.asarray(cp.equilibrium.q), mode=np.asarray(cp.mode),
                       multiplicity=int(cp.multiplicity), source=cp)


def knot_ends(scene, phi_min, phi_max, options, error=False):
    """{side: CriticalEnd} of a knot: the twist study's first end on each side, located exactly on
    the extended system (``unstable_branches``), as ``run_knot_study`` does; with ``error`` each
    end's discretisation error from the study's files (``_knot_errors``)."""
    import contextlib
    import tempfile

    # the coarse companion starts from the study's step files: only then are they written
    with tempfile.TemporaryDirectory(prefix="jaxrod-critical-") if error else contextlib.nullcontext() as out:
        found, study = _locatedknot_ends(scene, phi_min, phi_max, options, out)
        if error and set(found) == {"plus", "minus"}:  # else critical_twists refuses the missing side
            found = _knot_errors(scene, study, out, found, max(-phi_min, phi_max), options)
    return found


def _locatedknot_ends(scene, phi_min, phi_max, options, out):
    from .diagram import unstable_branches
    from .twist import twist_study

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
    from .coarse import coarse_companion, coarse_level
    from .twist import study_options

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
    from ..continuation import NoCrossingError
    from .accuracy import refine_scene, richardson
    from .coarse import coarse_level

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
    from .coarse import coarse_level

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
    if is_knot(scene):
        ends = knot_ends(scene, phi_min, phi_max, options, discretisation_error)
        missing = [s for s in ("plus", "minus") if s not in ends]
        if missing:
            raise RuntimeError(f"no branch end on the {' and '.join(missing)} side between "
                               f"{phi_min / math.pi:+.4f} pi and {phi_max / math.pi:+.4f} pi")
    else:
        ends = {"plus": ring_end(scene, "plus", phi_max, options),
                "minus": ring_end(scene, "minus", phi_min, options)}
        if discretisation_error:
            ends = _ring_errors(scene, ends, phi_min, phi_max, options)
    return CriticalTwists(plus=ends["plus"], minus=ends["minus"], seconds=time.perf_counter() - t0)


def _knot_sensitivity(scene, end, parameter):
    """d phi*/d parameter at a knot's located fold (``fold_sensitivity`` on its extended system) or
    simple branch point (``branch_point_sensitivity`` on the unfolded system)."""
    from ..continuation.arclength import branch_point_sensitivity, fold_sensitivity

    if end.kind not in (EventKind.FOLD, EventKind.BRANCH_POINT):
        raise ValueError(f"the {end.side} end is a {end.kind}: the sensitivity of a knot's critical twist is "
                         "computed at a fold or a simple branch point (the implicit function theorem on its system)")
    if end.kind == EventKind.BRANCH_POINT and end.multiplicity > 1:
        # the unfolded system is singular where two eigenvalues cross together: no derivative
        raise ValueError(f"the {end.side} end is a branch point of multiplicity {end.multiplicity}: its location "
                         "has no derivative from the unfolded system (a simple branch point has)")
    rod, ev = end.source.rod, end.source.event
    base = parameter_value(rod.problem.args.scene, parameter)

    def set_mu(args, mu):
        return args._replace(scene=args.scene.with_params(**{parameter: mu}))

    at = fold_sensitivity if end.kind == EventKind.FOLD else branch_point_sensitivity
    return float(at(rod.problem, ev, set_mu, base))


def parameter_value(scene, parameter):
    """The value of a continuous parameter of ``scene`` (a name in ``scene.PARAMETERS``; nu = B/C - 1)."""
    return float(scene.parameter(parameter))


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
    if is_knot(scene):
        return _knot_sensitivity(scene, end, parameter)
    return float(critical_twist_derivative(scene, end.source, parameter))
