"""Natural-parameter continuation of a callable solver (``jaxrod.continuation.natural``): the
sub-steps are equal, at most the step asked for, end exactly at the target, and each solve starts
from the state before it."""
import math

import pytest

from jaxrod.continuation.natural import follow_parameter, substeps


def test_substeps_are_equal_no_longer_than_asked_and_end_at_the_target():
    values = substeps(1.0, 2.3, 0.25)
    assert len(values) == 6 and values[-1] == 2.3
    steps = [b - a for a, b in zip([1.0] + values[:-1], values)]
    assert max(steps) <= 0.25 and max(steps) - min(steps) < 1e-15
    assert substeps(2.0, 1.9, 0.25) == [1.9]  # one step, backwards
    assert substeps(1.0, 1.0, 0.25) == [1.0]
    with pytest.raises(ValueError, match="max_step"):
        substeps(0.0, 1.0, 0.0)


def test_each_solve_starts_from_the_previous_state_and_the_last_is_solve_last():
    # a Newton iteration for x^3 = r, started from the previous root: one step from a close start
    calls = []

    def solve(r, x):
        calls.append(r)
        for _ in range(3):
            x = x - (x ** 3 - r) / (3 * x ** 2)
        return x

    x = follow_parameter(solve, 1.0, 1.0, 8.0, 0.5, solve_last=lambda r, x: ("last", r, solve(r, x)))
    assert x[0] == "last" and x[1] == 8.0 and x[2] == pytest.approx(2.0, rel=1e-12)
    assert len(calls) == 14 and calls[-1] == 8.0 and all(b > a for a, b in zip(calls, calls[1:]))
    assert math.isclose(calls[0], 1.5)
