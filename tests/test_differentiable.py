"""Critical twists as differentiable functions of the scene's parameters (jaxrod.studies.differentiable):
jax.grad, jacfwd, jit and vmap go through phi*(p), whose derivative is the implicit-function
theorem's at the located end. Checked on Michell's ring, where phi* is proportional to 1 / C in the
discrete model as in the continuum (phi* = 2 pi sqrt(3) B / C): d phi*/d nu = phi* / (1 + nu) and
d phi*/d C = -phi* / C exactly, d phi*/d B = phi* / B to the rod's extensibility, and against
central differences of located ends."""
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.studies.differentiable import critical_twist_function, match_critical_twist

PI = math.pi
NU = 0.3
RANGE = (-1.0, 8.0 * PI)  # the phi > 0 side only is searched


@pytest.fixture(scope="module")
def ring():
    return jr.michell_ring(N=24, nu=NU)


@pytest.fixture(scope="module")
def phi_of_nu(ring):
    return critical_twist_function(ring, "plus", "nu", *RANGE)


def test_grad_is_the_exact_sensitivity_and_matches_central_differences(phi_of_nu):
    nu = jnp.array([NU])
    phi = float(phi_of_nu(nu))
    slope = float(jax.grad(phi_of_nu)(nu)[0])
    assert slope == pytest.approx(phi / (1.0 + NU), rel=1e-6)
    h = 1e-4
    central = (float(phi_of_nu(nu + h)) - float(phi_of_nu(nu - h))) / (2 * h)
    assert slope == pytest.approx(central, rel=1e-5)  # the ends are located to ~1e-8 rad: FD noise ~1e-4/11


def test_a_misfit_differentiates_through_it_under_jit_and_vmap(phi_of_nu):
    measured = 4.6 * PI
    misfit = lambda p: (phi_of_nu(p) - measured) ** 2  # noqa: E731
    nu = jnp.array([NU])
    phi, slope = float(phi_of_nu(nu)), float(jax.grad(phi_of_nu)(nu)[0])
    assert float(jax.grad(misfit)(nu)[0]) == pytest.approx(2 * (phi - measured) * slope, rel=1e-12)
    assert float(jax.jit(jax.grad(misfit))(nu)[0]) == pytest.approx(2 * (phi - measured) * slope, rel=1e-12)
    both = jax.vmap(phi_of_nu)(jnp.array([[0.25], [NU]]))
    assert float(both[1]) == phi and float(both[0]) == pytest.approx(phi * 1.25 / (1 + NU), rel=1e-6)


def test_the_jacobian_in_two_parameters_is_b_over_c_scaling(ring):
    f = critical_twist_function(ring, "plus", ("B", "C"), *RANGE)
    b, c = f.base
    phi = float(f(f.base))
    jac = np.asarray(jax.jacfwd(f)(jnp.asarray(f.base)))
    assert jac[1] == pytest.approx(-phi / c, rel=1e-6)  # C enters the twist energy only: exact
    # B also sets the bending-to-stretching ratio B / (EA R^2) = D^2 / (16 R^2) = 6e-6 (D/R = 0.01):
    # the inextensible scaling holds to that order
    assert jac[0] == pytest.approx(phi / b, rel=2e-5) and jac[0] != pytest.approx(phi / b, rel=1e-7)


def test_design_finds_the_poisson_ratio_that_puts_the_end_at_a_target(ring, phi_of_nu):
    target = 5.0 * PI
    result = match_critical_twist(ring, "plus", "nu", target, tol=1e-9, phi_min=RANGE[0], phi_max=RANGE[1])
    assert result.converged and abs(result.residual) <= 1e-9 and 1 <= result.iterations <= 6, result
    phi0 = float(phi_of_nu(jnp.array([NU])))
    assert result.value == pytest.approx((1 + NU) * target / phi0 - 1.0, abs=1e-8)  # phi* is linear in 1 + nu


def test_an_unreachable_target_is_reported_not_converged(ring):
    # nu <= 0.5 bounds phi* at this N below 5.5 pi: Newton runs into the bound and says so
    result = match_critical_twist(ring, "plus", "nu", 6.0 * PI, max_iterations=6, phi_min=RANGE[0], phi_max=RANGE[1])
    assert not result.converged and result.residual < 0 and result.reason


def test_bad_input_names_the_argument(ring, phi_of_nu):
    with pytest.raises(ValueError, match="side"):
        critical_twist_function(ring, "up", "nu")
    with pytest.raises(ValueError, match="parameter"):
        critical_twist_function(ring, "plus", ("nu", "stiffness"))
    with pytest.raises(ValueError, match="values must have shape"):
        phi_of_nu(jnp.array([NU, 0.1]))
    with pytest.raises(ValueError, match="tol"):
        match_critical_twist(ring, "plus", "nu", 5.0 * PI, tol=0.0)


def test_a_knots_branch_point_has_its_derivative_from_the_unfolded_system():
    # the trefoil's phi > 0 end at N = 41 is a simple branch point (Morse index 0 -> 1): its
    # derivative in D by the implicit function theorem on the unfolded branch-point system, against
    # central differences of the located ends (h = 1e-4 mm: measured, h = 1e-3 is off by 4.5e-5 by
    # truncation and 1e-4 by 4.5e-7; the ends are located to ~1e-10 rad)
    knot = jr.trefoil(D=8.0, L=292.0, N=41)
    f = critical_twist_function(knot, "plus", "D", -0.5 * PI, 8.0 * PI)
    slope = float(jax.grad(f)(jnp.array([8.0]))[0])
    h = 1e-4
    central = (float(f(jnp.array([8.0 + h]))) - float(f(jnp.array([8.0 - h])))) / (2 * h)
    assert slope == pytest.approx(central, rel=1e-5) and abs(slope) > 0.01


def test_a_fit_recovers_the_poisson_ratio_and_its_standard_error(ring):
    from jaxrod.studies.differentiable import Measurement, fit_critical_twists

    rods = (ring, jr.michell_ring(N=32, nu=NU))
    nu_true, sigma = 0.35, 0.01
    truth = [float(critical_twist_function(r, "plus", "nu", *RANGE)(jnp.array([nu_true]))) for r in rods]
    fit = fit_critical_twists([Measurement(r, "plus", t, sigma) for r, t in zip(rods, truth)], ("nu",),
                              phi_min=RANGE[0], phi_max=RANGE[1])
    assert fit.converged and fit.values[0] == pytest.approx(nu_true, abs=1e-8), fit
    assert np.max(np.abs(fit.residuals)) < 1e-7 and fit.chi2 < 1e-9
    # one parameter: sigma_nu = 1 / sqrt(sum_i (dphi_i/dnu / sigma)^2), dphi/dnu = phi / (1 + nu)
    expected = 1.0 / math.sqrt(sum((t / (1 + nu_true) / sigma) ** 2 for t in truth))
    assert fit.standard_errors[0] == pytest.approx(expected, rel=1e-5)
    with pytest.raises(ValueError, match="sigma"):
        fit_critical_twists([Measurement(ring, "plus", truth[0], 0.0)], ("nu",))


def test_the_fit_command_reads_a_csv_and_writes_the_estimates(tmp_path, capsys):
    import json

    from jaxrod.cli import main

    length = 2 * PI  # Michell's ring of radius 1: D = 0.01 R
    truth = [float(critical_twist_function(jr.michell_ring(N=n, nu=NU), "plus", "nu", *RANGE)(jnp.array([0.35])))
             for n in (24, 32)]
    table = tmp_path / "onsets.csv"
    table.write_text("knot,N,D,L,side,phi,sigma\n" + "".join(
        f"ring,{n},{0.01 * length / (2 * PI)!r},{length!r},plus,{t!r},0.03\n" for n, t in zip((24, 32), truth)))
    out = tmp_path / "fit"
    assert main(["fit", str(table), "--nu", str(NU), "--phi-min", "-1", "--phi-max", "8pi", "--out", str(out),
                 "--quiet"]) == 0
    saved = json.loads((out / "fit.json").read_text())
    assert saved["converged"] and saved["parameters"]["nu"]["value"] == pytest.approx(0.35, abs=1e-8)
    assert saved["parameters"]["nu"]["standard_error"] > 0 and len(saved["measurements"]) == 2
    assert "nu = 0.35" in capsys.readouterr().out
    bad = tmp_path / "bad.csv"
    bad.write_text("knot,N,D,L,side,phi\nring,24,0.01,6.28,plus,4.8pi\n")
    assert main(["fit", str(bad)]) == 2
    assert "no column sigma" in capsys.readouterr().err


def test_a_knots_double_branch_point_is_refused_not_differentiated():
    knot = jr.trefoil(D=8.0, L=292.0, N=41)
    double = jr.CriticalEnd(side="plus", phi=6.8 * PI, kind=jr.EventKind.BRANCH_POINT, bracket=(6.7 * PI, 6.9 * PI),
                            phi_error=1e-10, q=np.zeros(knot.n_dof), mode=np.zeros(knot.n_dof), multiplicity=2)
    with pytest.raises(ValueError, match="multiplicity 2"):
        jr.critical_twist_sensitivity(knot, double, "D")
