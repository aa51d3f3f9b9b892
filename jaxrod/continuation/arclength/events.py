"""Event detection between consecutive points of a branch, handed to the locators.

- fold: the p-component of the tangent changes sign (kinds "soft_fold" and "soft_turn": see
  ``locate.locate_fold``); a fold and a branch point inside one step are reported as the fold;
- branch point: the Morse index changes without a fold (by the multiplicity: the Morse count,
  not the bordered determinant's sign, which symmetric double branch points keep).

A fold in the step before with the Morse index unchanged, then a change without a turn, is that
fold's crossing seen late: the fold is reported again with the new Morse index.
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

