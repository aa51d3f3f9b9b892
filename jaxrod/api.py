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
from dataclasses import dataclass, replace

import numpy as np

from .linalg.sliding import SLIDING_FRACTION, sliding_fraction
from .linalg.stability import Stability, stability as lowest_modes
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


from .studies.critical_ends import (  # noqa: E402,F401  (the public names; see that module)
    CriticalEnd, CriticalTwists, critical_twist_sensitivity, critical_twists, parameter_value,
)
