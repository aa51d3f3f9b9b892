"""Acceptance 4: Michell's ring. phi* = 2 pi sqrt(3) (1 + nu), approached from above at second order.

The discrete elastic rod's error is a pure discretisation error, ~ c / N^2 with c ~ 31: 3.1% at
N = 32, 0.19% at N = 128. Slenderness D/R = 0.01 keeps extensibility effects ~1e-5 (checked below).
"""
import math

import numpy as np
import pytest

from jaxrod import ContinuationOptions, critical_twist, figure_eight_energy, michell_critical_twist, michell_ring
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


# ---------------------------------------------- first self-contact as D -> 0: the figure-eight elastica

def test_figure_eight_energy_is_the_closed_elastica_built_from_its_curvature():
    from scipy.integrate import cumulative_trapezoid
    from scipy.optimize import brentq
    from scipy.special import ellipe, ellipj, ellipk

    L = 2 * math.pi
    E8 = figure_eight_energy(L)
    # the closed inflectional elastica: sin(theta/2) = k sn(alpha s | m), kappa = 2 k alpha cn(alpha s | m)
    m = brentq(lambda m: 2 * ellipe(m) - ellipk(m), 0.5, 0.99, xtol=1e-15)
    K = float(ellipk(m))
    alpha = 4 * K / L
    s = np.linspace(0, L, 200001)
    sn, cn, _, _ = ellipj(alpha * s, m)
    theta = 2 * np.arcsin(math.sqrt(m) * sn)
    x = np.stack([cumulative_trapezoid(np.cos(theta), s, initial=0), cumulative_trapezoid(np.sin(theta), s, initial=0)])
    assert np.linalg.norm(x[:, -1] - x[:, 0]) < 1e-8 * L  # closed: 2E(m) = K(m)
    kappa = 2 * math.sqrt(m) * alpha * cn
    assert 0.5 * np.trapezoid(kappa ** 2, s) == pytest.approx(E8, rel=1e-9)
    assert E8 == pytest.approx(figure_eight_energy(2 * L) * 2, rel=1e-14)  # 1/L scaling
    # a figure eight: the tangent turns by 0 in all (not 2 pi, the circle's) and the curve crosses itself
    assert abs(theta[-1] - theta[0]) < 1e-9
    assert E8 > math.pi  # above the circle's B pi / R


def test_committed_first_contacts_extrapolate_to_the_figure_eight():
    """benchmarks/results/bifurcation_michell.json: first contact at D/R = 0.01, 0.005, 0.0025 (N = 64)
    and at N = 32, 48, 64 (D/R = 0.0025), extrapolated here on their own and against the benchmark's."""
    import json
    import pathlib

    path = pathlib.Path(__file__).resolve().parent.parent / "benchmarks" / "results" / "bifurcation_michell.json"
    data = json.loads(path.read_text())
    by_d = data["contact_against_D"]
    d = np.array([r["slenderness"] for r in by_d])
    phi = np.array([r["phi_over_pi"] for r in by_d])
    wr = np.array([r["Wr"] for r in by_d])
    for y, limit in ((phi, 2.0), (wr, 1.0), (phi / 2 - wr, 0.0)):  # phi/pi, Wr, Tw: straight lines in D/R
        slope, intercept = np.polyfit(d, y, 1)
        assert abs(intercept - limit) < 1e-6 < 1e-3 < abs(y[-1] - limit)
    by_n = sorted(data["contact_against_N"], key=lambda r: r["N"])[-3:]
    n = np.array([r["N"] for r in by_n], dtype=float)
    e_inf = np.linalg.solve(np.stack([np.ones(3), n ** -2.0, n ** -4.0], axis=1), [r["energy"] for r in by_n])[0]
    thin = np.polyfit(d ** 2, [r["energy"] for r in by_d], 1)[0] * d[-1] ** 2  # E(D) - E(0) at D/R = 0.0025
    assert e_inf - thin == pytest.approx(data["zero_thickness"]["energy"]["value"], rel=1e-12)
    assert e_inf - thin == pytest.approx(figure_eight_energy(), rel=5e-5)
    assert abs(by_n[-1]["energy"] - figure_eight_energy()) > 5e-3  # the extrapolation does the work
