"""Event detection between consecutive points of a branch, handed to the locators.

- fold: the p-component of the tangent changes sign (the path turns back in p); a "soft_fold" if
  the critical mode is soft (``BifurcationProblem.soft_modes``) and the Morse index is unchanged;
  a "soft_turn" if no singular point is found but the path runs along soft directions at both
  ends (over 90% of the tangent) with the Morse index unchanged: a turn to be slid across, like
  a soft fold, with nothing located (residual nan);
- branch point: the Morse index changes without a fold. Its size is the multiplicity (2 for the
  double branch points that symmetry produces, where det of the bordered matrix keeps its sign,
  so the Morse count is the test used; ``Point.bordered_sign`` gives the classic one).
A p-turn whose F_p is orthogonal to the kernel is a branch point (a pitchfork seen from its
non-symmetric branch), and is reported as one (see locate.locate_fold). A fold and a branch point
inside one step are reported as the fold only.

A fold located in the step before, with the Morse index unchanged across it, followed by a change
of the Morse index without a turn, is that fold's crossing seen one step late: the points' Morse
index is counted on the Ritz values left after the soft (sliding) directions are split off their
eigenvectors, and where the fold's mode mixes with a slide that count lags the turn (the trefoil's
tightening side at N = 121: the turn at -11.1843257630 pi with the shape Ritz value still 3e-10,
negative one point later). The fold is reported again with the new Morse index, not a branch point
(whose unfolded system, singular nowhere near, crawled 20-30 Newton iterations to a point 4e-6 pi
away).
"""
from __future__ import annotations

from dataclasses import replace

from ..kinds import EventKind
from .locate import locate_branch_points, locate_fold


def find_events(problem, opts, a, b, step, known=()):
    """Located events (list of Event) between Points a and b = points[step - 1], points[step];
    known: the events located before on this path (a locator landing on one is not taken)."""
    if a.tangent[-1] * b.tangent[-1] < 0:
        # start Newton from the end nearer the fold (smaller |dp/ds|), the other end as a fallback
        starts = (a, b) if abs(a.tangent[-1]) <= abs(b.tangent[-1]) else (b, a)
        return [locate_fold(problem, opts, starts, (a.morse_index, b.morse_index), step)]
    if a.morse_index != b.morse_index:
        fold = next((e for e in known if e.kind == EventKind.FOLD and e.step == step - 1 and e.converged
                     and e.morse_before == e.morse_after == a.morse_index), None)
        if fold is not None and abs(b.morse_index - a.morse_index) == 1:
            return [replace(fold, morse_after=b.morse_index, step=step)]
        return locate_branch_points(problem, opts, a, b, step, known)
    return []

