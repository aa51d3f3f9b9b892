"""The one entry of continuation: ``continuation(problem, algorithm, options, observer=)``.

    continuation(TwistProblem(scene, 0.0, 8 * pi), StableOnly(), options)   -> TwistPath
    continuation(BifurcationProblem(energy, u0, p0), PseudoArclength(), options)  -> Branch

The options are one ``ContinuationOptions`` for both algorithms, each refusing the fields it never
reads; the observer's ``on_point`` receives each accepted point (a ``PathPoint`` or a ``Point``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .algorithms import PseudoArclength, StableOnly
from .arclength.continuation import continuation as _arclength_continuation
from .arclength.problem import BifurcationProblem
from .follow import follow_twist
from .options import Observer, observed


@dataclass(frozen=True)
class TwistProblem:
    """A rod scene twisted from ``phi_start`` towards ``phi_stop``: the problem ``StableOnly``
    continues.

    Parameters
    ----------
    scene : ClosedRod or ClampedRod
        The rod.
    phi_start : float, optional
        Twist of the first state (rad; default 0).
    phi_stop : float, optional
        Twist to reach (rad; default 8 pi).
    start : Equilibrium or array_like of shape (n_dof,), optional
        An ``Equilibrium`` used as is, an initial guess of the DOFs at phi_start, or None (the
        scene's ``q_init``, relaxed first).
    """

    scene: object
    phi_start: float = 0.0
    phi_stop: float = 8.0 * math.pi
    start: object = None


def continuation(problem, algorithm, options=None, *, observer=None, **keywords):
    """Follow a branch of equilibria of ``problem`` with ``algorithm``.

    Parameters
    ----------
    problem : TwistProblem or BifurcationProblem
        A ``TwistProblem`` (with ``StableOnly``) or a ``BifurcationProblem`` (with
        ``PseudoArclength``: F(u, p) = grad_u E = 0, u (n,), p the continued parameter).
    algorithm : StableOnly or PseudoArclength
        How the branch is followed.
    options : ContinuationOptions, optional
        Tolerances and budgets (None: the defaults); each algorithm refuses the fields it never
        reads.
    observer : Observer, optional
        ``StableOnly`` calls progress, on_point, on_instability and on_state;
        ``PseudoArclength`` calls on_point.
    **keywords
        Passed to the algorithm's loop: ``resume`` (a ``PathState``) for ``StableOnly``;
        ``start``, ``throw``, ``start_tol`` for ``PseudoArclength``.

    Returns
    -------
    TwistPath or Branch
        ``TwistPath`` (``StableOnly``): the stable path, its located ends and switches.
        ``Branch`` (``PseudoArclength``): the points with their spectra and the located events.

    Raises
    ------
    TypeError
        An algorithm that is not one of the two, or a problem of the other kind.
    ValueError
        An option the algorithm never reads, or a value that is not allowed.
    ContinuationError
        (``PseudoArclength``, throw=True) a corrector failed or an event was not located to
        ``event_tol``.
    """
    if isinstance(algorithm, StableOnly):
        _check_problem(problem, TwistProblem, algorithm)
        return follow_twist(problem.scene, problem.phi_start, problem.phi_stop, options, start=problem.start,
                            observer=observer, **keywords)
    if isinstance(algorithm, PseudoArclength):
        _check_problem(problem, BifurcationProblem, algorithm)
        if isinstance(observer, Observer) or observer is None:
            observer = observed(observer, "pseudo-arclength continuation", ("on_point",)).on_point
        return _arclength_continuation(problem, algorithm, options, observer=observer, **keywords)
    raise TypeError(f"algorithm must be StableOnly() or PseudoArclength(), got {type(algorithm).__name__}")


def _check_problem(problem, kind, algorithm):
    if not isinstance(problem, kind):
        raise TypeError(f"{type(algorithm).__name__} continues a {kind.__name__}, got {type(problem).__name__}")
