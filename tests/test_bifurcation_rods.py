"""jaxrod.continuation.arclength on a rod: Michell's ring (issue 17, acceptance 4; acceptance 9, second part:
the double branch point on a rod).

The ring's trivial branch (the planar circle, twist uniform) is exact for every phi; with the gauge
pinned (``jaxrod.continuation.arclength.rods``) a degenerate pair crosses at phi*, located by Brent on each
eigenvalue and grouped into one double branch point, which must equal ``critical_twist``'s phi* to
1e-9 relative. The buckled solutions form a circle (the buckle slid along the ring); one more pin
(``sliding_slice``) picks one, and the branch switched onto from the branch point goes backwards
(phi < phi*) with Morse index 1: Michell's instability is subcritical.

N = 32 shares critical_twist's compiled code with test_michell.py.
"""
import math

import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod import critical_twist, michell_critical_twist, michell_ring
from jaxrod.continuation import ContinuationOptions
from jaxrod.continuation.arclength import PseudoArclength, Result, continuation, emanating_directions, \
    switch_branches, branch_point_curve
from jaxrod.continuation.arclength.rods import pinned_problem, set_poisson_ratio, sliding_slice

N = 32
ALG = PseudoArclength()
# critical_twist's options (the stable-only engine's ContinuationOptions)
STABLE_ONLY = jr.ContinuationOptions(tol=1e-10 * math.pi, gtol=3e-11)
# the scaled gradient's roundoff floor is ~1e-11 (the stretching stiffness EA l^2/B ~ 1e4 at D/R = 0.01);
# ||J|| ~ 4e4, so eig_rtol = 1e-13 puts the negative band at ~4e-9, far above the eigenvalues' noise (~1e-11)
# and below the buckled branch's negative eigenvalue at the first predicted point
TRIVIAL = ContinuationOptions(ds=2.0, ds_max=8.0, p_max=1.2 * michell_critical_twist(0.5), newton_tol=5e-11,
                              eig_rtol=1e-13)
BUCKLED = ContinuationOptions(ds=1.0, ds_max=1.0, p_min=0.0, p_max=2 * michell_critical_twist(0.5), max_steps=6,
                              newton_tol=5e-11, eig_rtol=1e-13)


@pytest.fixture(scope="module")
def ring():
    scene = michell_ring(N=N, nu=0.5)
    # phi* is known only to ~1e-12 / |dlambda/dphi| in float64 (eigenvalue roundoff, ||J|| ~ 4e4): ~3e-10
    # relative at N = 32 (benchmarks/results/bifurcation_michell.md). At the default gtol (1e-9)
    # critical_twist's crossing eigenvalue is left at ~8e-12, 7.5e-10 relative above the exact-circle
    # root; its equilibria reach ~2e-11, so gtol = 3e-11 takes it to 2.5e-10 of the extended system
    cp = critical_twist(scene, 0.0, 2 * michell_critical_twist(0.5), STABLE_ONLY)
    rod = pinned_problem(scene, np.asarray(scene.q_init), 0.0)
    trivial = continuation(rod.problem, ALG, TRIVIAL)
    return scene, cp, rod, trivial


@pytest.fixture(scope="module")
def buckled(ring):
    _, _, rod, trivial = ring
    rod8, ev8 = sliding_slice(rod, trivial.events[0])
    (direction,) = emanating_directions(rod8.problem, ev8)
    branches = switch_branches(rod8.problem, ev8, ALG, BUCKLED, amplitude=1.0, directions=[direction])
    return rod8, ev8, direction, branches


def test_trivial_branch_is_the_twisted_circle(ring):
    scene, _, rod, trivial = ring
    assert trivial.result is Result.BOUNDARY and trivial.p[-1] > 1.2 * michell_critical_twist(0.5)
    x0 = np.asarray(scene.positions(np.asarray(scene.q_init)))
    for q in trivial.points:
        qq = rod.q(q.u)
        assert np.max(np.abs(np.asarray(scene.positions(qq)) - x0)) <= 1e-11  # the circle, whatever phi
        m = np.asarray(scene.vertex_twists(jnp.asarray(qq), q.p))
        assert np.max(np.abs(m - q.p / N)) <= 1e-12  # twist uniform
        assert rod.full_gradient(q.u, q.p) <= 1e-10  # an equilibrium of the rod, pinned rows included
        assert q.iterations <= 1  # the branch is a straight line in (u, phi): the predictor is exact


def test_double_branch_point_equals_critical_twist(ring):
    _, cp, rod, trivial = ring
    (e,) = trivial.events
    assert e.kind == "branch_point" and e.converged and e.multiplicity == 2 and cp.multiplicity == 2
    assert abs(e.p - cp.phi) <= 1e-9 * cp.phi
    assert e.critical_eigenvalue <= 1e-10 and e.residual <= 1e-10
    assert (e.morse_before, e.morse_after) == (0, 2)
    assert np.all(trivial.morse_index == np.where(trivial.p < e.p, 0, 2))
    assert rod.full_gradient(e.u, e.p) <= 1e-10


def test_buckled_branch_is_subcritical_and_unstable(ring, buckled):
    _, _, rod, trivial = ring
    rod8, ev8, direction, branches = buckled
    assert abs(ev8.eigenvalues[0]) <= 1e-10 and (ev8.morse_before, ev8.morse_after) == (0, 1)
    # reduced equations: a pitchfork (the cubic vanishes by symmetry) with dp = -kappa r^2, kappa > 0
    assert direction.order == 3 and direction.kappa > 0 and direction.predicted_morse == (1, 1)
    assert len(branches) == 2  # r > 0 and r < 0: the same buckled ring slid by a quarter turn
    for br in branches:
        assert br.result is Result.MAX_STEPS and not br.events
        p = br.p
        assert np.all(p < ev8.p) and np.all(np.diff(p) < 0)  # backwards from phi*: subcritical
        assert np.all(br.morse_index == 1)  # unstable: the one negative mode of a subcritical pitchfork
        r = np.array([(q.u - ev8.u) @ ev8.v[:, 0] for q in br.points])
        slope = (ev8.p - p) / r ** 2
        assert np.all(np.abs(slope / direction.kappa - 1) < 0.15)  # p* - p = kappa r^2 at small r
        wr = [rod8.writhe(q.u) for q in br.points]
        assert 0 < wr[0] and np.all(np.diff(wr) > 0)  # twist goes into writhe, right-handed
        for q in br.points[::3]:
            assert rod8.full_gradient(q.u, q.p) <= 1e-10  # the sliding pin holds no force
    # without the sliding pin the buckled ring has a zero mode (the slide) and one negative mode
    q = branches[0].points[-1]
    u7 = rod.restrict(np.asarray(rod8.embed(jnp.asarray(q.u))))
    _, J, _ = rod.problem.linearise(jnp.asarray(u7), jnp.asarray(q.p), rod.problem.args)
    lam = np.linalg.eigvalsh(np.asarray(J))
    assert abs(lam[1]) <= 1e-9 and lam[0] < -1e-5 and lam[2] > 1e-3


def test_branch_point_curve_in_nu_equals_critical_twist(ring, buckled):
    """Acceptance 6, Michell's phi*(nu): the ring's branch point (made simple by the sliding pin)
    continued in nu over [0, 0.5] (``branch_point_curve``, the unfolded system with nu free, C =
    B/(1 + nu)) equals ``critical_twist`` at nu = 0, 0.25 and 0.5 to 1e-9 relative (measured
    2.5e-10 to 3.7e-10: critical_twist's own float64 floor at N = 32, see the ring fixture). Like
    Michell's 2 pi sqrt(3) (1 + nu), the discrete ring's phi* is proportional to B/C = 1 + nu, so its
    IFT slope is phi*(0.5)/1.5 all along."""
    scene, cp, _, _ = ring
    rod8, ev8, _, _ = buckled
    opts = ContinuationOptions(ds=-0.5, ds_max=2.0, newton_tol=5e-11, p_min=-0.01, p_max=0.51, max_steps=100,
                               report_at=(0.0, 0.25))
    curve = branch_point_curve(rod8.problem, ev8, set_poisson_ratio, 0.5, ALG, opts)
    assert curve.result is Result.BOUNDARY and curve.mu[-1] < 0.0 and np.max(curve.residual) <= 5e-11
    for nu in (0.0, 0.25, 0.5):
        (k,) = np.flatnonzero(curve.mu == nu)
        ref = cp if nu == 0.5 else critical_twist(michell_ring(N=N, nu=nu), 0.0, 2 * michell_critical_twist(nu),
                                                  STABLE_ONLY)
        assert abs(curve.p[k] - ref.phi) <= 1e-9 * ref.phi, (nu, curve.p[k], ref.phi)
    assert np.max(np.abs(curve.dp_dmu - curve.p[0] / 1.5)) <= 1e-8 * curve.p[0]
