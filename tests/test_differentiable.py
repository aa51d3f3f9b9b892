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
from jaxrod.studies.differentiable import critical_twist_function
from jaxrod.studies.design import match_critical_twist

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


@pytest.fixture(scope="module")
def guide(tmp_path_factory):
    """The namespace of docs/guides/differentiable.md with its python blocks run in order (its knot:
    the trefoil at N = 41 and nu = 0.48, whose phi > 0 end is a simple branch point of the
    symmetric branch, Morse index 0 -> 1, at +6.741 pi; central differences in nu stay below its
    bound 0.5. At nu = 0.45 the first end is a fold at +6.607 pi: its kind changes with nu)."""
    import os
    import pathlib
    import re

    page = pathlib.Path(__file__).resolve().parent.parent / "docs" / "guides/differentiable.md"
    namespace, here = {}, os.getcwd()
    os.chdir(tmp_path_factory.mktemp("guide"))
    try:
        for block in re.findall(r"^```python\n(.*?)^```", page.read_text(), flags=re.S | re.M):
            exec(compile(block, "docs/guides/differentiable.md", "exec"), namespace)
    finally:
        os.chdir(here)
    return namespace


def _central(f, x, i, h, order=2):
    """Central difference of f in x[i], step h: second order, or fourth (Richardson's five points)."""
    e = np.zeros_like(x)
    e[i] = h
    at = lambda s: np.asarray(f(jnp.asarray(x + s * e)))  # noqa: E731
    if order == 2:
        return (at(1) - at(-1)) / (2.0 * h)
    return (8.0 * (at(1) - at(-1)) - (at(2) - at(-2))) / (12.0 * h)


@pytest.mark.validation  # the validation tier (-m validation): second derivatives compile for ~40 s
def test_a_knots_end_has_first_and_second_derivatives_from_its_extended_system(guide):
    f, value_and_grad = guide["f"], guide["value_and_grad"]
    assert f.end.kind == jr.EventKind.BRANCH_POINT and f.end.multiplicity == 1
    x = np.asarray(f.base)
    phi, grad = value_and_grad(jnp.asarray(x))
    assert float(phi) == pytest.approx(f.end.phi, abs=1e-10)  # the base values give the located end back
    # first derivatives against central differences of ends located at p +- h by Newton on the
    # unfolded system (relative steps 1e-5: the ends are found to ~1e-12 rad, the truncation is
    # ~1e-8 relative)
    for i in range(3):
        central = _central(f, x, i, 1e-5 * abs(x[i]))
        assert float(grad[i]) == pytest.approx(float(central), rel=1e-6), (f.parameters[i], grad, central)
    # second derivatives by forward-over-reverse against central differences of the exact gradient
    # (relative steps 5e-5: truncation ~1e-5 relative, measured)
    hessian = np.asarray(guide["second"](jnp.asarray(x)))
    assert np.allclose(hessian, hessian.T, rtol=1e-8, atol=0.0)
    gradient = lambda v: value_and_grad(v)[1]  # noqa: E731
    for i in range(3):
        central = _central(gradient, x, i, 5e-5 * abs(x[i]))
        assert np.allclose(hessian[:, i], central, rtol=1e-4, atol=1e-4 * np.max(np.abs(hessian[:, i]))), (i, hessian,
                                                                                                               central)


@pytest.mark.validation  # the validation tier (-m validation): the guide's knot, relaxed by the fixture above
def test_an_equilibrium_differentiates_in_the_pinned_gauge(guide):
    knot, q, phi = guide["knot"], guide["q"], 2.0 * PI
    x = np.asarray(q.base)
    jac = np.asarray(guide["dq"])
    assert jac.shape == (knot.n_dof, 2) and np.all(np.isfinite(jac))
    # fourth-order differences; relative steps 1e-3 in nu and 1e-4 in D (the contact term makes q
    # vary faster in D), measured: the equilibria's ~1e-13 of roundoff over the step and the
    # truncation are both below 1e-8 relative (second order with steps 1e-5 was 1.5e-6 off in nu)
    for i, step in enumerate((1e-3, 1e-4)):
        central = _central(q, x, i, step * abs(x[i]), order=4)
        assert np.max(np.abs(jac[:, i] - central)) <= 1e-7 * np.max(np.abs(jac[:, i])), i
    # at other values it is an equilibrium of that rod, in every DOF (the pinned ones included)
    thick = knot.with_params(D=float(x[1]) + 0.05)
    moved = np.asarray(q(jnp.asarray(x + np.array([0.0, 0.05]))))
    force = np.asarray(jax.jit(jax.grad(thick.scaled_energy))(jnp.asarray(thick.to_scaled(moved)), phi))
    assert np.max(np.abs(force)) < 1e-8


def test_a_fit_recovers_the_poisson_ratio_and_its_standard_error(ring):
    from jaxrod.studies.design import Measurement, fit_critical_twists

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


def test_the_committed_knot_round_trip_recovers_nu_and_the_contact_stiffness():
    """benchmarks/results/differentiable_trefoil.json: onsets of the trefoil (8, 292) mm at N = 61
    computed with (nu, k) = (0.47, 120), noise 1e-6 pi, fitted back from (0.5, 100) (the run takes
    minutes, so the test reads it): both to 1e-4 relative, within their standard errors."""
    import json
    import pathlib

    path = pathlib.Path(__file__).resolve().parent.parent / "benchmarks" / "results" / "differentiable_trefoil.json"
    trip = json.loads(path.read_text())["round_trip"]
    assert len(trip["ratios"]) == 5 and trip["tightening_ratios"] and trip["converged"]
    assert trip["sigma"] == pytest.approx(1e-6 * math.pi)
    values, truth, se = (np.array(trip[k]) for k in ("values", "truth", "standard_errors"))
    assert np.all(np.abs(values - truth) / truth < 1e-4)
    assert np.all(np.abs(values - truth) < 3 * se)  # covered by the error bars
    assert np.all(se / truth < 1e-4)  # and they are small enough to tell


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


def test_a_rings_second_derivative_is_refused_with_the_reason(phi_of_nu):
    with pytest.raises(NotImplementedError, match="double branch point"):
        jax.hessian(phi_of_nu)(jnp.array([NU]))


def test_the_widest_window_of_michells_ring_is_at_the_largest_poisson_ratio(ring):
    from jaxrod.studies.design import maximise_twist_window

    # the window phi*+ - phi*- = 2 phi* grows as 1 + nu (phi* ~ B / C): widest at the upper bound
    result = maximise_twist_window(ring, ("nu",), [(0.1, 0.45)], phi_min=-8.0 * PI, phi_max=8.0 * PI)
    assert result.converged and result.at_bound[0] and result.values[0] == pytest.approx(0.45, abs=1e-12), result
    assert result.plus == pytest.approx(-result.minus, rel=1e-8) and result.window == result.plus - result.minus
    assert result.gradient[0] == pytest.approx(result.window / 1.45, rel=1e-5)
    with pytest.raises(ValueError, match="bounds"):
        maximise_twist_window(ring, ("nu",), [(0.45, 0.1)])
