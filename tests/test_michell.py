"""Acceptance 4: Michell's ring. phi* = 2 pi sqrt(3) (1 + nu), approached from above at second order.

The discrete elastic rod's error is a pure discretisation error, ~ c / N^2 with c ~ 31: 3.1% at
N = 32, 0.19% at N = 128. Slenderness D/R = 0.01 keeps extensibility effects ~1e-5 (checked below).
"""
import math

import numpy as np
import pytest

from jaxrod import ContinuationOptions, critical_twist, michell_critical_twist, michell_ring
from jaxrod.solve.solvers import ConvergenceError


def _phi_star(N, nu, slenderness=0.01):
    analytic = michell_critical_twist(nu)
    cp = critical_twist(michell_ring(N=N, nu=nu, slenderness=slenderness), 0.0, 2 * analytic,
                        ContinuationOptions(step=analytic / 8))
    return cp


@pytest.fixture(scope="module")
def series():
    # N = 256 adds ~0.5e-3 of accuracy and a compilation per test run: the benchmark has it.
    return {N: _phi_star(N, 0.5) for N in (32, 64, 128)}


@pytest.mark.parametrize("nu", [0.0, 0.25])
def test_relative_error_below_2e3_at_N128(nu):
    cp = _phi_star(128, nu)
    analytic = michell_critical_twist(nu)
    rel = (cp.phi - analytic) / analytic
    assert 0.0 < rel < 2e-3
    assert cp.multiplicity == 2  # the ring's modes come in degenerate pairs (rotation symmetry)
    assert cp.phi_error < 1e-6 * math.pi


def test_convergence_order_and_richardson(series):
    analytic = michell_critical_twist(0.5)
    Ns = sorted(series)
    err = np.array([(series[N].phi - analytic) / analytic for N in Ns])
    assert np.all(err > 0)  # from above
    assert err[Ns.index(128)] < 2e-3
    orders = np.log2(err[:-1] / err[1:])
    assert np.all((orders > 1.8) & (orders < 2.2)), orders
    # Richardson with the observed second order: (4 phi(2N) - phi(N)) / 3
    rich = (4 * series[128].phi - series[64].phi) / 3
    assert abs(rich - analytic) / analytic < 1e-4
    for N in Ns:
        assert series[N].phi_error < 1e-6 * math.pi
        assert series[N].hessian_evaluations <= 8  # Newton on the eigenvalue, not bisection


def test_crossing_eigenvalue_and_its_derivative(series):
    cp = series[64]
    assert abs(cp.eigenvalue) < 1e-9
    assert cp.dlambda_dphi < 0
    # Finite-difference check of the autodiff derivative along the branch.
    from jaxrod import EquilibriumOptions, eigenvalue_phi_derivative, solve_equilibrium

    scene = michell_ring(N=64, nu=0.5)
    # h = 1e-2: eigenvalues ~5e-7 apart, round-off (~1e-13) and truncation (~h^2 lambda''' ~ 1e-12)
    # both below 1e-6 of the derivative.
    h = 1e-2
    lam = []
    for phi in (cp.phi - h, cp.phi + h):
        eq = solve_equilibrium(scene, phi, cp.equilibrium.q, EquilibriumOptions(method="newton"))
        lam.append(eigenvalue_phi_derivative(scene, eq.q, phi, 0)[0])
    fd = (lam[1] - lam[0]) / (2 * h)
    assert cp.dlambda_dphi == pytest.approx(fd, rel=1e-5)


def test_threshold_insensitive_to_extensibility():
    a = _phi_star(32, 0.5, slenderness=0.01).phi
    b = _phi_star(32, 0.5, slenderness=0.002).phi
    assert abs(a - b) / b < 2e-5


def test_refinement_refuses_a_bracket_without_sign_change(series):
    # Issue 16, defect 3 (in this file to reuse the N = 32 compilation of ``series``).
    # A negative_tol that is large against the eigenvalues (as 1e-10 was for N = 2000): the
    # count changes steps after the crossing; the old refinement then converged on a bracket end
    # and reported it as phi* (N = 2000: 6.27 pi for 5.20 pi, error "1.6e-6").
    ring = michell_ring(N=32)
    analytic = michell_critical_twist(0.5)
    with pytest.raises(ConvergenceError, match="same sign"):
        critical_twist(ring, 0.0, 2.0 * analytic, ContinuationOptions(step=analytic / 10.0, negative_tol=5e-3))
