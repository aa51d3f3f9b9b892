"""The continuation algorithms, as objects handed to ``jaxrod.continuation.continuation``.

``StableOnly``: natural continuation in the imposed twist, kept to stable states (a damped-Newton
minimiser as corrector), each branch end located and, on knots, switched past. ``PseudoArclength``:
Keller's pseudo-arclength on F(u, p) = grad_u E = 0, through folds and along unstable branches,
with folds and branch points located on extended systems. Both read one ``ContinuationOptions``.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StableOnly:
    """Natural continuation in phi kept to stable states: each step is predicted along the
    branch's tangent and corrected by minimisation, so the path never leaves the stable branch;
    where it ends (a fold or branch point) the end is located to ``ContinuationOptions.tol`` and,
    with ``switch``, the path goes on from the stable buckled branch.

    It takes no parameters: its settings are the stable-only fields of ``ContinuationOptions``
    (step, tol, negative_tol, jump_tol, switch, ...).
    """


@dataclass(frozen=True)
class PseudoArclength:
    """Keller's pseudo-arclength: tangent predictor, Newton on the bordered (n+1) corrector.

    The step settings (ds, ds_min, ds_max, tolerances, event detection) are the pseudo-arclength
    fields of ``ContinuationOptions``.

    Parameters
    ----------
    min_cos : float, optional
        A step whose tangent turns by more than acos(min_cos) is refused and retried smaller (it
        may have jumped to another branch; default 0.9).
    max_correction : float, optional
        So is a step whose corrector moved the point by more than max_correction * ds from the
        predictor (it may have landed on a nearby branch with a tangent still within min_cos;
        default 0.2).
    grow : float, optional
        The step grows by this factor after a corrector that needed at most ``fast_iterations``
        iterations (default 1.5).
    shrink : float, optional
        The step shrinks by this factor on failure (default 0.5).
    fast_iterations : int, optional
        See ``grow`` (default 3).
    """

    min_cos: float = 0.9
    max_correction: float = 0.2
    grow: float = 1.5
    shrink: float = 0.5
    fast_iterations: int = 3
