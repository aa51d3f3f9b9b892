"""Natural-parameter continuation of any solver: a state carried from one parameter value to
another in equal sub-steps, each solve starting from the state before it.

For studies whose parameter is not the twist of a scene (the end rotation of an end-loaded rod,
``jaxrod.studies.runs.helix``): their solver is a callable, so this layer imports nothing above it.
"""
from __future__ import annotations

import math


def substeps(start, target, max_step):
    """The parameter values from ``start`` (excluded) to ``target`` (included) in equal sub-steps
    of at most ``max_step``: start + (target - start) j / n, j = 1 .. n, the last one exactly target.

    Raises ValueError for a max_step that is not positive and finite."""
    if not (math.isfinite(max_step) and max_step > 0.0):
        raise ValueError(f"max_step must be positive and finite, got {max_step!r}")
    start, target = float(start), float(target)
    n = max(1, math.ceil(abs(target - start) / max_step))
    return [start + (target - start) * j / n for j in range(1, n)] + [target]


def follow_parameter(solve, state, start, target, max_step, *, solve_last=None):
    """The state at ``target``, followed from ``state`` (an equilibrium at ``start``) through
    ``substeps(start, target, max_step)``: ``solve(value, previous_state) -> state`` at each
    intermediate value and ``solve_last`` (default ``solve``) at the target, which may ask for more
    (a stability analysis). A solver's exception (no equilibrium reached) propagates."""
    values = substeps(start, target, max_step)
    for value in values[:-1]:
        state = solve(value, state)
    return (solve_last or solve)(values[-1], state)
