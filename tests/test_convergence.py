"""Accuracy asked for, not N (issue 18, item 2): Richardson extrapolation with the order measured,
an error estimate that covers the true error, and the refinement study on Michell's ring, whose
limit is known (2 pi sqrt(3)(1 + nu))."""
import json
import math

import numpy as np
import pytest

import jaxrod as jr
from jaxrod.studies.accuracy import THEORETICAL_ORDER, converged_critical_twists, resolution_levels, richardson

PI = math.pi


def test_richardson_recovers_an_exact_power_law_and_its_order():
    limit, c, p = 1.234, 5.0, 2.0
    N = [20, 40, 80]
    ext = richardson(N, [limit + c / n ** p for n in N])
    assert ext.order_measured and ext.asymptotic
    assert abs(ext.order - p) < 1e-9 and abs(ext.value - limit) < 1e-12


def test_error_estimate_covers_the_true_error_with_a_higher_order_term():
    # v = limit + c h^2 + d h^3: the three-level fit is not exact, the estimate must cover it
    limit = -3.0

    def v(n):
        return limit + 40.0 / n ** 2 - 300.0 / n ** 3

    for N in ([30, 59, 117], [30, 59, 117, 233]):
        ext = richardson(N, [v(n) for n in N])
        assert ext.asymptotic and 1.5 < ext.order < 2.5
        assert abs(ext.value - limit) <= ext.error, (N, ext)
        assert ext.error < abs(v(N[-1]) - limit)  # and the extrapolation beats the finest level
    # two levels: the order assumed, a wider error
    two = richardson([59, 117], [v(59), v(117)])
    assert not two.order_measured and two.order == THEORETICAL_ORDER and abs(two.value - limit) <= two.error


def test_trefoil_levels_of_the_committed_convergence_study():
    # benchmarks/results/trefoil_critical.csv, N = 61, 121, 241 (each bracketed to 5e-4 pi): the
    # issue's "converged values about 6.42 pi / -11.09 pi", now with an order and an error
    plus = richardson([61, 121, 241], [6.60107421875, 6.465332031250001, 6.430175781250002])
    minus = richardson([61, 121, 241], [-11.475097656249996, -11.184082031249996, -11.112229733255427])
    assert abs(plus.order - 2) < 0.1 and abs(minus.order - 2) < 0.1
    assert abs(plus.value - 6.418) < 0.002 and plus.error < 0.01
    assert abs(minus.value + 11.089) < 0.002 and minus.error < 0.01


def test_the_levels_brackets_are_carried_into_the_error():
    # Each level known to +-e (a branch end's bracket): the extrapolation moves by as much as the
    # levels moving within their errors make it (the order re-measured), which the error now
    # includes. Levels of an exact second-order sequence, each pushed by its whole error in every
    # combination of signs (the trefoil's ratio: e ~ 0.4 % of the last difference): the limit lies
    # within the error each time, and without the errors given it does not always.
    N, limit = [61, 121, 241], 6.418
    exact = [limit + 2.0 / n ** 2 for n in N]
    e = 0.004 * (exact[1] - exact[2])
    missed = 0
    for signs in np.ndindex(2, 2, 2):
        values = [v + (1 - 2 * s) * e for v, s in zip(exact, signs)]
        ext = richardson(N, values, [e, e, e])
        assert e < ext.level_error < 10 * e
        assert abs(ext.value - limit) <= ext.error, (signs, ext)
        bare = richardson(N, values)
        missed += abs(bare.value - limit) > bare.error
    assert missed > 0
    two = richardson([121, 241], exact[1:], [e, e])
    c = 1.0 / ((241 / 121) ** 2 - 1.0)
    assert two.level_error == pytest.approx((1 + c) * e + c * e, rel=1e-12)
    with pytest.raises(ValueError, match="errors"):
        richardson(N, exact, [e, e])


def test_non_monotone_levels_are_not_asymptotic():
    ext = richardson([10, 20, 40], [1.0, 1.1, 1.05])
    assert not ext.asymptotic and ext.value == 1.05 and abs(ext.error - 0.05) < 1e-12


@pytest.mark.parametrize("N, values, match", [
    ([10], [1.0], "at least 2 levels"),
    ([20, 10], [1.0, 2.0], "N must increase"),
    ([10, 20], [1.0, float("nan")], "values"),
])
def test_richardson_bad_input_names_the_parameter(N, values, match):
    with pytest.raises(ValueError, match=match):
        richardson(N, values)


def test_levels_keep_every_node():
    assert resolution_levels(61, 481) == [61, 121, 241, 481]
    with pytest.raises(ValueError, match="N_max"):
        converged_critical_twists(jr.michell_ring(N=16), 0.01 * PI, N_max=40)
    with pytest.raises(ValueError, match="accuracy"):
        converged_critical_twists(jr.michell_ring(N=16), -1.0)
    with pytest.raises(ValueError, match="closed rods"):
        converged_critical_twists(jr.clamped_rod(N=11, length=1.0, material=jr.Material.from_ratio(B=1.0, nu=0.5, D=0.01)), 0.01 * PI)


@pytest.mark.validation  # the validation tier (-m validation): a ring converged in N by the accuracy mode
def test_michell_ring_converged_to_the_accuracy_asked_for():
    # The ring at N = 16, 32, 64 (each level started from the previous one resampled): the
    # extrapolated phi* is within its own error estimate of Michell's value, and that estimate
    # is below the accuracy asked for.
    analytic = jr.michell_critical_twist(0.5)
    said = []
    (side,) = converged_critical_twists(jr.michell_ring(N=16, nu=0.5), 0.02 * PI, sides=("plus",),
                                        levels=(16, 32, 64), progress=said.append).values()
    assert side.reached, side.reason
    assert [lv.N for lv in side.levels] == [16, 32, 64]
    assert side.levels[1].phi_start > 0.0  # started near the previous end, not from 0
    assert abs(side.phi_star - analytic) <= side.error <= 0.02 * PI
    assert abs(side.extrapolation.order - 2.0) < 0.2
    # the finest level alone is further off than the extrapolation
    assert abs(side.levels[-1].phi_star - analytic) > 3 * abs(side.phi_star - analytic)
    assert any("extrapolated" in line for line in said)


def test_cli_accuracy_writes_its_files_and_resumes_from_the_finished_levels(tmp_path, monkeypatch, capsys):
    # The CLI layer of --accuracy (flags, files, printing, exit code, resume): the levels' physics
    # replaced by a known convergence phi*(N) = phi_inf + c / N^2 + d / N^3 (the continuation itself
    # is tested above on Michell's ring and in test_trefoil_twist.py).
    import numpy as np

    import jaxrod.studies.accuracy as conv
    import jaxrod.solve.equilibrium as equilibrium
    from jaxrod.cli import main

    limits = {"plus": 6.42 * PI, "minus": -11.09 * PI}
    calls = []

    def fake_level(scene, side, phi_start, start, span, step, tol, say, cancel):
        N = int(scene.n_nodes)
        calls.append((side, N))
        phi = limits[side] + math.copysign(1.0, limits[side]) * (4e3 / N ** 2 - 2e4 / N ** 3)
        q = np.asarray(scene.q_init)
        states = ((phi_start, q), (0.5 * (phi_start + phi), q))
        return conv.Level(N, phi, tol, "jump", phi_start, 0.01, states), "", states

    monkeypatch.setattr(conv, "level_of_side", fake_level)
    monkeypatch.setattr(equilibrium, "relax_to_minimum", lambda scene, phi, q0=None: None)
    out = tmp_path / "acc"
    args = ["trefoil", "--accuracy", "0.01pi", "--N-max", "481", "--out", str(out), "--quiet"]
    assert main(args + ["--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    for side in ("plus", "minus"):
        s = summary[side]
        assert s["reached"] and s["error"] <= 0.01 * PI and abs(s["phi_star"] - limits[side]) <= s["error"]
        assert [lv["N"] for lv in s["levels"]] == [61, 121, 241]
    assert sorted(calls) == sorted((s, n) for s in ("plus", "minus") for n in (61, 121, 241))
    for name in ("convergence.json", "convergence.csv", "convergence.png", "levels/run.json",
                 "levels/plus_N00241.npz"):
        assert (out / name).stat().st_size > 0, name
    # again: every level is on file, none is computed again; the same numbers, printed as text
    calls.clear()
    assert main(args) == 0
    text = capsys.readouterr().out
    assert calls == [] and f"{summary['plus']['phi_star'] / PI:+.5f} pi" in text and "NOT CONVERGED" not in text
    # another study's folder is refused, naming what differs
    assert main(["trefoil", "--accuracy", "0.02pi", "--N-max", "481", "--out", str(out), "--quiet"]) == 2
    assert "accuracy" in capsys.readouterr().err


def test_coarse_companion_of_a_study_brackets_the_converged_value(tmp_path):
    # What the CLI prints after a study: each end found again at (N + 1) / 2 from the study's own
    # state, and a rough extrapolation (order assumed, factor 3) that covers the converged value.
    from jaxrod.studies.coarse import coarse_companion
    from jaxrod.studies.twist import twist_study

    from jaxrod.continuation import Observer

    ring = jr.michell_ring(N=32, nu=0.5)
    handed = []  # the CLI starts each end's work here, while the study goes on
    study = twist_study(ring, -0.5 * PI, 6.0 * PI, jr.ContinuationOptions(step=0.5 * PI, tol=1e-3 * PI, max_switches=0),
                        out=str(tmp_path / "ring"), observer=Observer(on_instability=lambda *a: handed.append(a)))
    (direction, index, entry, state), = handed  # each end once it is on file, with its last stable state
    assert (direction, index) == ("plus", 0) and entry == study.critical["instabilities"][0]
    assert np.array_equal(state[0], study.end_states[0][0]) and state[1] == study.end_states[0][1]
    found = coarse_companion(ring, str(tmp_path / "ring"), study.critical, step=0.5 * PI, tol=1e-3 * PI)
    assert list(found) == ["plus"]  # nothing ends on the minus side within -0.5 pi
    # one side from its own entry (as the CLI runs it, once that end is found): the same estimate
    alone = coarse_companion(ring, str(tmp_path / "ring"), {"instabilities": [entry]}, step=0.5 * PI, tol=1e-3 * PI,
                             sides=("plus",))
    assert alone["plus"][1] == found["plus"][1]
    with pytest.raises(ValueError, match="sides"):
        coarse_companion(ring, str(tmp_path / "ring"), study.critical, sides=("up",))
    level, ext = found["plus"]
    analytic = jr.michell_critical_twist(0.5)
    assert level.N == 16 and level.phi_star > study.critical["phi_plus"] > analytic  # from above, as Michell's
    assert ext.N == (16, 32) and not ext.order_measured
    assert abs(ext.value - analytic) <= ext.error < abs(level.phi_star - analytic)


def test_a_level_sequence_out_of_its_asymptotic_range_is_not_called_converged_nor_given_an_error():
    # The trefoil (8, 292), tightening side, as measured (benchmarks/accuracy_trefoil.py): a fold at
    # N = 61, 121, then a shape-mode pair crossing zero at 241, 481. The last change is tiny (5.6e-4 pi)
    # but the measured order (7.4) says the levels are not one asymptotic sequence; the message said
    # "error estimate 5.6e-04 pi > 1.0e-02 pi" before.
    from jaxrod.studies.accuracy import Level, unconverged_reason

    pis = (-11.475440, -11.184210, -11.093990, -11.093434)
    kinds = ("jump", "jump", "unstable", "unstable")
    levels = [Level(n, v * math.pi, 1e-4, k, 0.0, 1.0) for n, v, k in zip((61, 121, 241, 481), pis, kinds)]
    ext = richardson([lv.N for lv in levels], [lv.phi_star for lv in levels])
    assert not ext.asymptotic and ext.order > 4
    why = unconverged_reason(481, ext, 0.01 * math.pi, levels)
    assert "not in their asymptotic range" in why and "not an error estimate" in why
    assert "changed kind" in why and "241: unstable" in why and ">" not in why


def test_the_summary_extrapolates_from_the_located_end_not_the_bracket():
    # command 1's summary: where the end at N was located on its extended system, the two-level
    # Richardson uses that value (error 0), not the study's wider bracket
    from jaxrod.studies.accuracy import Level, richardson
    from jaxrod.studies.runs.trefoil import extrapolated_fields

    coarse = Level(N=61, phi_star=20.7369, phi_error=2e-4, kind="jump", phi_start=18.0, seconds=1.0)
    bracketed = richardson([61, 121], [20.7369, 20.3209], [2e-4, 0.03])
    located = {"phi_plus": 20.3100, "phi_plus_located": {"kind": "fold"}}
    fields = extrapolated_fields({"plus": (coarse, bracketed)}, located, 121)["phi_plus_extrapolated"]
    again = richardson([61, 121], [20.7369, 20.3100], [2e-4, 0.0])
    assert fields["values"] == [20.7369, 20.3100] and fields["value"] == again.value and fields["error"] == again.error
    assert fields["value"] != bracketed.value
    # no located end: the study's own extrapolation, unchanged
    kept = extrapolated_fields({"plus": (coarse, bracketed)}, {"phi_plus": 20.3209}, 121)["phi_plus_extrapolated"]
    assert kept["value"] == bracketed.value and kept["values"] == [20.7369, 20.3209]
