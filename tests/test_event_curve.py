"""event_curve: the first instability of a branch followed in a second parameter, on analytic
systems with known answers (a fold curve p* = mu^2; a first instability that changes kind, from a
branch point to a fold, where the two event curves cross)."""
import csv
import math
import os
from dataclasses import replace

import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod.continuation import ContinuationOptions
from jaxrod.continuation.arclength import BifurcationProblem
from jaxrod.continuation.arclength.event_curve import EventCurveOptions, event_curve


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


OPTS = ContinuationOptions(ds=-0.02, ds_min=1e-8, ds_max=0.05, newton_tol=1e-12, k=2, p_min=-2.0, p_max=3.0)


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


def _steep_energy(u, p, mu):
    # a pitchfork (y) at p = g(mu), g falling by 0.2 within ~0.004 of mu = 0.25 (dp*/dmu = -50 there), and
    # a fold (x) at p = -1 below it; going down in p the first instability is the branch point
    x, y = u[0], u[1]
    g = 0.4 - 0.1 * jnp.tanh((mu - 0.25) / 0.002)
    return x**3 / 3.0 - (p + 1.0) * x + 0.5 * (p - g) * y**2 + 0.25 * y**4


def test_a_slope_that_throws_the_start_off_falls_back_to_the_secant():
    # At mu = 0.25 the implicit function theorem's slope (-50) holds over ~0.002 of mu only: its shift to
    # mu = 0.3 (-2.5) puts the start below the fold at p = -1, and every back-off keeps that shift. The
    # secant of the last two events puts it delta above the event, which is then located as before.
    prob = BifurcationProblem(_steep_energy, jnp.array([1.5, 0.0]), 1.25, jnp.asarray(0.0))
    mus = [0.2, 0.25, 0.3, 0.4]
    said = []
    curve = event_curve(prob, (np.array([1.5, 0.0]), 1.25), _set_mu, 0.1, mus, EventCurveOptions(OPTS, 0.05),
                        progress=said.append)
    assert curve.result.name == "BOUNDARY", curve.message
    mu = curve.mu
    np.testing.assert_allclose(curve.p, 0.4 - 0.1 * np.tanh((mu - 0.25) / 0.002), atol=1e-10)
    assert curve.kind == ["branch_point"] * 5
    assert curve.dp_dmu[2] == pytest.approx(-50.0, rel=1e-8)
    predictors = [q.predictor for q in curve.points]
    assert predictors == ["none", "ift", "ift", "secant", "ift"], predictors
    assert curve.points[3].back_offs == 4 and sum("(ift predictor)" in m for m in said) == 4, said


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


def test_no_instability_at_the_start_ratio_is_one_line_naming_the_flags(tmp_path, capsys):
    # found only after the start's path ran out of span: one line with what to change, exit 1,
    # not a traceback (the figure-eight at N = 121, D/L = 0.026 has no end within 16 pi)
    from jaxrod.cli import main

    args = ["critical-curve", "--quiet", "--N", "40", "--ratios", "0.026", "--sides", "plus", "--span", "0.25pi",
            "--out", str(tmp_path / "c")]
    assert main(args) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--span" in err[0] and "no instability" in err[0], err


def test_ratio_range_parsing():
    from jaxrod.studies.critical_curve import check_ratio_range

    np.testing.assert_allclose(check_ratio_range("0.008:0.010:0.001"), [0.008, 0.009, 0.010])
    np.testing.assert_allclose(check_ratio_range("0.03, 0.01,0.02"), [0.01, 0.02, 0.03])


def test_a_curve_resumed_from_its_last_point_goes_on_as_the_whole_run():
    # Interrupted after mu = 0.2 (on the branch-point part) and resumed from the last point on file:
    # the same events, slopes and predictions as the run that was never interrupted, across the
    # change of kind at mu = 0.25.
    def run(mus, resume=None):
        prob = BifurcationProblem(_crossing_energy, jnp.array([1.0, 0.0]), 1.0, jnp.asarray(0.0))
        start = resume if resume is not None else (np.array([1.0, 0.0]), 1.0)  # resume: the points on file
        return event_curve(prob, start, _set_mu, 0.0, mus, EventCurveOptions(OPTS, 0.05))

    whole = run([0.1, 0.2, 0.3, 0.4])
    first = run([0.1, 0.2])
    rest = run([0.3, 0.4], resume=first.points)
    assert rest.result.name == "BOUNDARY" and [q.mu for q in rest.points] == [0.3, 0.4]
    joined = first.points + rest.points
    for name in ("p", "kind", "dp_dmu", "critical_eigenvalue", "anchor_p"):
        assert [getattr(q, name) for q in joined] == [getattr(q, name) for q in whole.points], name
    np.testing.assert_array_equal([q.predicted for q in joined], [q.predicted for q in whole.points])  # nan first
    with pytest.raises(ValueError, match="anchor"):
        run([0.3], resume=[replace(first.points[-1], anchor_u=None)])


def _stub_first_instabilities(monkeypatch, calls):
    """critical_twist_curve with each ratio's point study replaced by the analytic crossing system's
    first instability (mu = 10 D/L: a branch point p* = 0.5 - mu, then a fold p* = mu from D/L =
    0.025 on), so that its files and resume are tested in seconds; the point study it calls is tested
    on the knot in test_critical_curve_checks.py. calls: the ratios studied, in order."""
    import jaxrod.studies.critical_curve as cc

    def first_instabilities(knot, n, ratio, options=None, *, progress=None):
        calls.append(float(ratio))
        mu = 10.0 * float(ratio)
        kind, phi, slope = ("branch_point", 0.5 - mu, -10.0) if mu < 0.25 else ("fold", mu, 10.0)
        return {"minus": dict(side="minus", D_over_L=float(ratio), phi_star=phi, phi_star_over_pi=phi / math.pi,
                              kind=kind, located=True, morse_before=0, morse_after=1, critical_eigenvalue=1e-15,
                              residual=1e-14, dphi_dratio=slope, phi_bracketed=phi, phi_located=phi, seconds=0.0)}

    monkeypatch.setattr(cc, "first_instabilities", first_instabilities)


def test_an_interrupted_critical_curve_resumes_to_the_files_of_a_whole_run(tmp_path, monkeypatch):
    import jaxrod.studies.critical_curve as cc

    calls = []
    _stub_first_instabilities(monkeypatch, calls)
    ratios = [0.01, 0.02, 0.03, 0.04]
    opts = cc.CriticalCurveOptions(sides=("minus",), start_ratio=0.02, span=2.0)
    with pytest.warns(UserWarning, match="switches from a branch_point"):
        whole = cc.critical_twist_curve("3_1", 101, ratios, opts, out=str(tmp_path / "whole"))
    assert calls == [0.02, 0.03, 0.04, 0.01]  # from the start ratio up, then down
    assert [r["kind"] for r in whole["rows"]] == ["branch_point"] * 2 + ["fold"] * 2
    np.testing.assert_allclose([r["phi_star"] for r in whole["rows"]], [0.4, 0.3, 0.3, 0.4], atol=1e-10)

    real_save, saved = cc.write_json, []

    def save_then_die(path, obj):
        real_save(path, obj)
        saved.append(path)
        if len(saved) == 3:  # the settings, then 0.02 and 0.03 on file, then killed
            raise KeyboardInterrupt

    monkeypatch.setattr(cc, "write_json", save_then_die)
    cut = str(tmp_path / "cut")
    with pytest.raises(KeyboardInterrupt):
        cc.critical_twist_curve("3_1", 101, ratios, opts, out=cut)
    monkeypatch.setattr(cc, "write_json", real_save)
    said, calls[:] = [], []
    with pytest.warns(UserWarning, match="switches"):
        resumed = cc.critical_twist_curve("3_1", 101, ratios, opts, out=cut, progress=said.append)
    assert resumed["resumed_points"] == 2 and calls == [0.04, 0.01] and "resuming from" in said[0], (said, calls)
    timeless = lambda rows: [{k: v for k, v in r.items() if k != "seconds"} for r in rows]  # noqa: E731
    assert timeless(resumed["rows"]) == timeless(whole["rows"]) and resumed["switches"] == whole["switches"]
    # the CSV as a whole run writes it: the same rows in the same order, digit for digit
    read = lambda folder: timeless(csv.DictReader(open(os.path.join(folder, "critical_curve.csv"))))  # noqa: E731
    assert read(cut) == read(tmp_path / "whole") and len(read(cut)) == 4
    # run again on the finished folder: nothing computed, the same rows
    calls[:] = []
    with pytest.warns(UserWarning, match="switches"):
        again = cc.critical_twist_curve("3_1", 101, ratios, opts, out=cut)
    assert again["resumed_points"] == 4 and not calls and timeless(again["rows"]) == timeless(whole["rows"])
    # another setting on the same folder is refused by name; fresh starts over
    with pytest.raises(ValueError, match="ratios"):
        cc.critical_twist_curve("3_1", 101, ratios[:3], opts, out=cut)
    with pytest.warns(UserWarning, match="switches"):
        fresh = cc.critical_twist_curve("3_1", 101, ratios[:3], opts, out=cut, fresh=True)
    assert fresh["resumed_points"] == 0 and len(fresh["rows"]) == 3
