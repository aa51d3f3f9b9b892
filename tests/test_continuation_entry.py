"""The one continuation entry: ``continuation(problem, algorithm, options, observer=)`` runs both
algorithms from one options class and one observer, and refuses what an algorithm would ignore."""
import math

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.continuation import (ContinuationOptions, Observer, PseudoArclength, StableOnly, TwistProblem,
                                 continuation, follow_twist)
from jaxrod.continuation.arclength import BifurcationProblem


def pitchfork_energy(u, p, args):
    """E = x^4/4 - p x^2/2: the branch x = 0 loses stability at p = 0 (a pitchfork)."""
    x = u[0]
    return 0.25 * x ** 4 - 0.5 * p * x ** 2


def test_stable_only_through_the_entry_is_follow_twist():
    ring = jr.michell_ring(N=24)
    options = ContinuationOptions(step=0.5 * math.pi, switch=False)
    seen = []
    path = continuation(TwistProblem(ring, 0.0, 8.0 * math.pi), StableOnly(), options,
                        observer=Observer(on_point=seen.append))
    direct = follow_twist(ring, 0.0, 8.0 * math.pi, options)
    assert path.instabilities and direct.instabilities
    assert path.instabilities[0].phi == direct.instabilities[0].phi  # the same run, to the bit
    assert len(seen) == len(path.points) > 2
    # Michell's threshold 2 pi sqrt(3) (1 + nu) = 16.32 rad, shifted at second order in the edge
    # angle 2 pi / N (5.6 % at N = 24, inside (2 pi / N)^2 = 6.9 %)
    michell = 2 * math.pi * math.sqrt(3) * 1.5
    assert 0 < path.instabilities[0].phi / michell - 1 < (2 * math.pi / 24) ** 2


def test_pseudo_arclength_through_the_entry_calls_the_same_observer():
    problem = BifurcationProblem(pitchfork_energy, jnp.array([0.0]), -0.5, None)
    seen = []
    branch = continuation(problem, PseudoArclength(), ContinuationOptions(ds=0.1, p_max=0.5, k=1),
                          observer=Observer(on_point=seen.append))
    assert len(seen) == len(branch.points) - 1 > 3  # every accepted point after the start
    (event,) = branch.events
    assert event.kind == "branch_point" and abs(event.p) < 1e-10
    assert np.all(np.diff([pt.p for pt in branch.points]) > 0)


def test_the_entry_refuses_mismatches_and_unread_settings():
    ring = jr.michell_ring(N=24)
    problem = BifurcationProblem(pitchfork_energy, jnp.array([0.0]), -0.5, None)
    with pytest.raises(TypeError, match="StableOnly continues a TwistProblem"):
        continuation(problem, StableOnly())
    with pytest.raises(TypeError, match="PseudoArclength continues a BifurcationProblem"):
        continuation(TwistProblem(ring), PseudoArclength())
    with pytest.raises(TypeError, match="algorithm must be"):
        continuation(problem, "arclength")
    with pytest.raises(ValueError, match="tol: not read by pseudo-arclength"):
        continuation(problem, PseudoArclength(), ContinuationOptions(tol=1e-6))
    with pytest.raises(ValueError, match="observer.on_state"):
        continuation(problem, PseudoArclength(), observer=Observer(on_state=print))
    with pytest.raises(ValueError, match="ds_min <= |ds|"):
        ContinuationOptions(ds=0.0)
