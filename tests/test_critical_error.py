"""``critical_twists(..., discretisation_error=True)`` fills each end's discretisation error from a
coarser level, or says why it cannot: never None when asked."""
import math

import pytest

import jaxrod as jr
from jaxrod.studies.coarse import CoarseLevelTooSmall

PI = math.pi
FAST = jr.ContinuationOptions(step=0.5 * PI)  # the crossing is still located to tol: only the scan is coarser


@pytest.mark.validation  # the validation tier (-m validation): a ring converged in N
def test_the_discretisation_error_of_michells_ring_bounds_its_true_error():
    N, nu = 24, 0.5
    ends = jr.critical_twists(jr.michell_ring(N=N, nu=nu), -7 * PI, 7 * PI, FAST, discretisation_error=True)
    # the ring is symmetric in phi: the coarse level's plus end serves both sides
    coarse = jr.critical_twist(jr.michell_ring(N=(N + 1) // 2, nu=nu), 0.0, 7 * PI, FAST).phi
    analytic = jr.michell_critical_twist(nu)  # the slenderness shifts it by ~1e-5 relative: far below the errors
    for end in ends:
        error = end.discretisation_error
        assert math.isfinite(error) and error > 0.0
        true_error = abs(abs(end.phi) - analytic)
        # the estimate bounds the true error, without being wildly pessimistic
        assert true_error <= error <= 5.0 * true_error, (end.side, error / PI, true_error / PI)
        # two levels, the order 2 assumed and Roache's factor 3: about the distance to the coarse level
        assert error <= 1.5 * abs(abs(end.phi) - coarse)


def test_without_the_switch_there_is_no_estimate():
    ends = jr.critical_twists(jr.michell_ring(N=16), -7 * PI, 7 * PI, FAST)
    assert ends.plus.discretisation_error is None and ends.minus.discretisation_error is None


def test_a_coarse_level_below_the_knots_resolution_is_refused_before_any_work():
    knot = jr.trefoil(N=61, D=8.0, L=292.0)  # N_c = 31 < L/D = 36.5: edges longer than the diameter
    with pytest.raises(CoarseLevelTooSmall, match="at least 37 nodes") as caught:
        jr.critical_twists(knot, discretisation_error=True)
    assert isinstance(caught.value, ValueError) and "73" in str(caught.value)


def test_an_open_rod_is_refused_with_its_reason():
    rod = jr.clamped_rod(N=11, length=1.0, material=jr.Material.from_ratio(B=1.0, nu=0.5, D=0.01))
    with pytest.raises(ValueError, match="closed rods"):
        jr.critical_twists(rod, discretisation_error=True)
    with pytest.raises(TypeError, match="True or False"):
        jr.critical_twists(rod, discretisation_error="yes")


def test_a_coarse_level_without_an_end_in_range_says_so():
    # N = 16 buckles at 5.87 pi; its coarse level N = 8 not below 7 pi
    with pytest.raises(RuntimeError, match=r"plus: no discretisation error estimate.*N = 8"):
        jr.critical_twists(jr.michell_ring(N=16), -7 * PI, 7 * PI, FAST, discretisation_error=True)
