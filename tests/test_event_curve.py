"""event_curve: the first instability of a branch followed in a second parameter, on analytic
systems with known answers (a fold curve p* = mu^2; a first instability that changes kind, from a
branch point to a fold, where the two event curves cross)."""
import math

import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod.bifurcation import BifurcationProblem, ContinuationOptions
from jaxrod.bifurcation.event_curve import EventCurveOptions, event_curve


def _set_mu(args, mu):
    return mu


def _fold_energy(u, p, mu):
    # F = u^2 - p + mu^2: the stable branch u = sqrt(p - mu^2) ends at the fold p* = mu^2 going down in p
    return u[0] ** 3 / 3.0 - (p - mu**2) * u[0]


def _crossing_energy(u, p, mu):
    # x: a fold at p = mu; y: a pitchfork (y = 0 always a solution) at p = 0.5 - mu. Going down in p
    # the first instability is the branch point for mu < 0.25 and the fold for mu > 0.25.
    x, y = u[0], u[1]
    return x**3 / 3.0 - (p - mu) * x + 0.5 * (p - 0.5 + mu) * y**2 + 0.25 * y**4


OPTS = ContinuationOptions(ds=-0.02, ds_min=1e-8, ds_max=0.05, newton_tol=1e-12, n_eig=2, p_min=-2.0, p_max=3.0)


def test_fold_curve_of_a_parabola():
    prob = BifurcationProblem(_fold_energy, jnp.array([1.0]), 1.0, jnp.asarray(0.0))
    mus = [0.1, 0.2, 0.3, 0.4]
    curve = event_curve(prob, (np.array([1.0]), 1.0), _set_mu, 0.0, mus, EventCurveOptions(OPTS, 0.05))
    assert curve.result.name == "BOUNDARY", curve.message
    assert curve.kind == ["fold"] * 5
    mu = curve.mu
    np.testing.assert_allclose(mu, [0.0] + mus)
    np.testing.assert_allclose(curve.p, mu**2, atol=1e-10)
    np.testing.assert_allclose(curve.dp_dmu, 2 * mu, atol=1e-8)
    # the predictor is the IFT's first order: its error is the curvature's, (d mu)^2 = 0.01
    pred = curve.column("predicted")[1:]
    np.testing.assert_allclose(pred, mu[1:] ** 2 - 0.01, atol=1e-8)
    assert all(q.morse_before == 0 and q.morse_after == 1 for q in curve.points)


def test_first_instability_changes_kind_where_two_event_curves_cross():
    prob = BifurcationProblem(_crossing_energy, jnp.array([1.0, 0.0]), 1.0, jnp.asarray(0.0))
    mus = [0.1, 0.2, 0.3, 0.4]
    seen = []
    curve = event_curve(prob, (np.array([1.0, 0.0]), 1.0), _set_mu, 0.0, mus, EventCurveOptions(OPTS, 0.05),
                        observer=seen.append)
    assert curve.result.name == "BOUNDARY", curve.message
    assert len(seen) == 5
    mu = curve.mu
    assert curve.kind == ["branch_point"] * 3 + ["fold"] * 2
    np.testing.assert_allclose(curve.p, np.maximum(0.5 - mu, mu), atol=1e-10)
    np.testing.assert_allclose(curve.dp_dmu, np.where(mu < 0.25, -1.0, 1.0), atol=1e-8)
    assert all(q.critical_eigenvalue <= 1e-10 and q.residual <= 1e-10 for q in curve.points)


def test_delta_must_be_positive():
    with pytest.raises(ValueError, match="delta"):
        EventCurveOptions(OPTS, -math.pi)


def test_critical_curve_command_refuses_bad_input_naming_the_flag(tmp_path, capsys):
    # refused before anything is compiled: one line, naming the flag
    from jaxrod.cli import main

    cases = [(["--ratios", "0.03:0.02:0.001"], "--ratios"), (["--ratios", "0.02,abc"], "--ratios"),
             (["--ratios", "0.005,0.02"], "--N"), (["--sides", "up"], "sides"),
             (["--ratios", "0.02,0.03", "--start", "0.04"], "start_ratio"), (["--nu", "0.7"], "nu")]
    for extra, flag in cases:
        assert main(["critical-curve", "--quiet", "--out", str(tmp_path / "c"), *extra]) == 2, extra
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and flag in err[0], (extra, err)


def test_ratio_range_parsing():
    from jaxrod.critical_curve import check_ratio_range

    np.testing.assert_allclose(check_ratio_range("0.008:0.010:0.001"), [0.008, 0.009, 0.010])
    np.testing.assert_allclose(check_ratio_range("0.03, 0.01,0.02"), [0.01, 0.02, 0.03])
