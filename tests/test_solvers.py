"""Honest convergence: result objects, throw=, Newton vs L-BFGS on rods."""
import math

import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod import LBFGS, ConvergenceError, DampedNewton, Material, Newton, clamped_critical_twist, clamped_rod
from jaxrod import ContinuationOptions, EquilibriumOptions, critical_twist, minimise, solve_equilibrium, closed_curve
from helpers import wobbly_loop


def rosenbrock(y, args):
    a = args
    return jnp.sum(a * (y[1:] - y[:-1] ** 2) ** 2 + (1 - y[:-1]) ** 2)


@pytest.mark.parametrize("solver, start", [(LBFGS(), 0.0), (Newton(), 1.1)])
def test_minimise_converges_and_reports(solver, start):
    sol = minimise(rosenbrock, jnp.full(6, start), 100.0, solver, gtol=1e-10)
    assert sol.converged and sol.reason == "converged"
    assert sol.grad_norm <= 1e-10
    assert sol.iterations > 0
    np.testing.assert_allclose(sol.y, np.ones(6), atol=1e-8)


def double_wells(y, c):
    return jnp.sum(c * (y**2 - 1.0) ** 2)


def test_damped_newton_leaves_a_saddle_with_curvatures_over_six_decades():
    # At y ~ 0 the Hessian is diag(-4 c): negative curvatures from -4e-3 to -4e3, so the shift
    # that makes H + mu I definite must be found by growing attempts, and brought down again
    # as each coordinate reaches its well (quadratic convergence at the end needs mu -> 0).
    c = jnp.asarray(np.logspace(-3, 3, 7))
    y0 = jnp.asarray(np.linspace(-0.02, 0.03, 7))
    sol = minimise(double_wells, y0, c, DampedNewton(), gtol=1e-12)
    assert sol.converged and sol.grad_norm <= 1e-12
    np.testing.assert_allclose(np.abs(sol.y), 1.0, atol=1e-12)
    np.testing.assert_array_equal(np.sign(sol.y), np.sign(np.asarray(y0)))
    assert sol.iterations < 60, sol


def test_unconverged_result_is_never_returned_as_an_answer():
    with pytest.raises(ConvergenceError, match="max_steps"):
        minimise(rosenbrock, jnp.zeros(6), 100.0, LBFGS(), gtol=1e-12, max_steps=3)
    sol = minimise(rosenbrock, jnp.zeros(6), 100.0, LBFGS(), gtol=1e-12, max_steps=3, throw=False)
    assert not sol.converged and sol.reason == "max_steps" and sol.iterations == 3
    assert sol.grad_norm > 1e-12


def test_newton_far_from_a_solution_says_it_stalled():
    # Newton follows |grad f| downhill to the nearest stationary point; from far away on Rosenbrock
    # it stalls, and says so rather than returning the point.
    sol = minimise(rosenbrock, jnp.zeros(6), 100.0, Newton(), gtol=1e-10, throw=False)
    assert not sol.converged and sol.reason in ("stalled", "max_steps")


def test_nonfinite_objective_is_reported():
    f = lambda y, a: jnp.sum(jnp.log(y))  # noqa: E731 - minimising drives y to 0, log to -inf
    sol = minimise(f, jnp.ones(3), None, LBFGS(), max_steps=200, throw=False)
    assert not sol.converged


def test_relaxation_lbfgs_then_newton_gives_the_stable_circle():
    # A wobbly closed loop relaxes to the circle (the regular polygon, whose bending energy is
    # N B (2 tan(pi/N))^2 / (2 l) exactly); L-BFGS gets close, Newton polishes to 1e-9.
    mat = Material.from_engineering(E=1.0, nu=0.5, D=0.05)
    n = 40
    scene = closed_curve(wobbly_loop(n, seed=5, amp=0.07), material=mat, length=2 * math.pi)
    eq = solve_equilibrium(scene, 0.0, options=EquilibriumOptions(method="auto", gtol=1e-9))
    assert eq.solution.converged and eq.solution.grad_norm <= 1e-9
    assert eq.stability.n_zero_modes == 7
    assert eq.stable
    assert eq.Lk == pytest.approx(0.0, abs=1e-8) and abs(eq.Wr) < 1e-8
    l = 2 * math.pi / n
    assert eq.energy_terms["bend"] == pytest.approx(n * mat.B * (2 * math.tan(math.pi / n)) ** 2 / (2 * l), rel=1e-8)


def test_clamped_rod_greenhill_threshold():
    # Straight rod clamped at both ends a fixed distance apart: buckles when M L / B = 8.9868,
    # i.e. phi* = 8.9868 B / C. Second-order convergence in N, from above.
    mat = Material.from_ratio(B=1.0, nu=0.5, D=0.01)
    exact = clamped_critical_twist(mat.B, mat.C)
    err = []
    for N in (24, 48):  # N = 24: the size test_sparse_stability compiles too (one compilation shared)
        cp = critical_twist(clamped_rod(N=N, length=1.0, material=mat), 0.0, 2 * exact, ContinuationOptions(step=exact / 8))
        err.append((cp.phi - exact) / exact)
    assert 0 < err[1] < 5e-3
    assert 3.0 < err[0] / err[1] < 5.0
