"""Michell's ring at D/R = 0.0025 with no tolerance set by hand: the double branch point is located
and the buckled branch followed to first self-contact.

At this slenderness the stretching stiffness EA l^2/B = 16 (l/D)^2 is ~4e5 in the scaled units at
N = 16, and the residual's roundoff floor (~5e-10) lies far above the fixed tolerances 1e-12
(Newton) and 1e-10 (a located event): the defaults must come from the problem's scale
(``jaxrod.continuation.arclength.scales``). N = 16 is the smallest ring the benchmark's
N-convergence covers (``benchmarks/bifurcation_michell.py``, results in
benchmarks/results/bifurcation_michell.md).
"""
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from jaxrod import michell_ring
from jaxrod.continuation import ContinuationOptions
from jaxrod.continuation.arclength import PseudoArclength, Result, continuation, continuation_until
from jaxrod.continuation.arclength.corrector import correct
from jaxrod.continuation.arclength.rods import pinned_problem, sliding_slice
from jaxrod.continuation.arclength.scales import NEWTON_TOL, scaled_options

N, SLENDERNESS, NU = 16, 0.0025, 0.5
ALG = PseudoArclength()
PHI_MICHELL = 2 * math.sqrt(3) * (1 + NU) * math.pi
# First self-contact at D/R = 0.0025 (benchmarks/results/bifurcation_michell.md): phi/pi = 2.010057 at
# N = 16, falling with N to 2.007366 at N = 64 (differences 1.6e-3, 5.4e-4, 3.7e-4, 1.3e-4 from N = 16
# to 24, 32, 48, 64: second order in 1/N). The range is the N = 16 value +-5e-3, about twice its
# distance to N = 64; it excludes 2 (a rod of zero thickness touches itself there, Wr = 1) and the
# value at D/R = 0.01 (2.029464 at N = 64): phi - 2 pi grows like D. Wr at contact is 0.998 at every N.
PHI_CONTACT_RANGE = (2.005, 2.015)
WRITHE_RANGE = (0.99, 1.0)
START_AMPLITUDE = 0.3


def contact_point(rod8, a, b, D, opts):
    """phi and the state where the closest approach equals D between Points a and b: Brent on the
    hyperplane coordinate s = <z - z_a, t_a>, each evaluation a corrector run."""
    prob = rod8.problem
    sb = float((b.z - a.z) @ a.tangent)

    def point(s):
        c = correct(prob.backend, lambda u, p: prob.linearise(u, p, prob.args), a.z + (s / sb) * (b.z - a.z),
                    a.tangent, opts.newton_tol, opts.newton_max_iter)
        assert c.converged, "the corrector failed while locating the contact"
        return c.z

    z = point(brentq(lambda s: rod8.min_distance(point(s)[:-1]) - D, 0.0, sb, xtol=1e-10 * abs(sb)))
    return float(z[-1]), z[:-1]


@pytest.mark.validation  # the validation tier (-m validation): a buckled branch followed to contact
def test_thin_ring_branch_point_and_contact_without_hand_set_tolerances():
    scene = michell_ring(N=N, nu=NU, slenderness=SLENDERNESS)
    D = float(scene.material.D)
    rod = pinned_problem(scene, np.asarray(scene.q_init), 0.0)
    trivial_options = ContinuationOptions(ds=2.0, ds_max=8.0, p_max=1.2 * PHI_MICHELL)
    resolved = scaled_options(rod.problem, trivial_options, rod.problem.u0, rod.problem.p0)
    assert resolved.newton_tol > 10 * NEWTON_TOL  # the fixed default would lie below the floor here

    trivial = continuation(rod.problem, ALG, trivial_options)
    assert trivial.result is Result.BOUNDARY
    (ev,) = trivial.events
    assert ev.kind == "branch_point" and ev.multiplicity == 2 and ev.converged
    assert (ev.morse_before, ev.morse_after) == (0, 2)
    assert ev.residual <= resolved.event_tol and np.max(np.abs(ev.eigenvalues)) <= resolved.event_tol
    # the discrete ring's threshold lies above Michell's, by ~13% at N = 16 (second order in 1/N)
    assert 1.0 < ev.p / PHI_MICHELL < 1.2

    # the slide pinned, the buckled branch from amplitude r along the kernel: subcritical (phi < phi*)
    # and unstable (Morse index 1) all the way to contact. r = 0.3 edge lengths: the first-order
    # predictor stretches the edges at O(r^2), a residual of ~5e2 that Newton takes 7 iterations to
    # bring to the floor (from r = 1, 5.8e3 and 11 iterations, one more than newton_max_iter)
    rod8, ev8 = sliding_slice(rod, ev)
    v = np.asarray(ev8.v[:, 0])
    start = (np.asarray(ev8.u) + START_AMPLITUDE * v, ev8.p, np.append(v, 0.0))
    buckled = ContinuationOptions(ds=1.0, ds_max=2.0, p_min=0.0, p_max=2 * ev.p, max_steps=10)

    def contact_index(points, _events=()):
        return next((i for i, q in enumerate(points) if rod8.min_distance(q.u) < D), None)

    # checked after each chunk: the last one may go on past the contact, where the rod passes
    # through itself (whatever it reports there does not count)
    branch = continuation_until(rod8.problem, ALG, buckled, lambda p, e: "contact" * (contact_index(p) is not None),
                                start=start)
    i = contact_index(branch.points)
    assert i is not None, f"no contact: {branch.result}, {branch.message}"
    before = branch.points[:i]
    assert all(q.morse_index == 1 for q in before)
    assert not [e for e in branch.events if e.step < i]
    assert all(b.p < a.p for a, b in zip(before, before[1:]))  # phi falls monotonically: no fold

    phi, u = contact_point(rod8, branch.points[i - 1], branch.points[i],
                           D, scaled_options(rod8.problem, buckled, ev8.u, ev8.p))
    assert PHI_CONTACT_RANGE[0] < phi / math.pi < PHI_CONTACT_RANGE[1]
    assert WRITHE_RANGE[0] < rod8.writhe(u) < WRITHE_RANGE[1]
    # nearly the figure-eight elastica, the zero-thickness limit: Tw = phi/2pi - Wr -> 0 in
    # proportion to D/R (2.2 D/R at N = 64), from Tw = phi*/2pi = 2.9 on the circle at its branch point
    assert 0 < phi / (2 * math.pi) - rod8.writhe(u) < 4 * SLENDERNESS
