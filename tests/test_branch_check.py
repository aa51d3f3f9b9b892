"""The stable-only continuation stays on its branch: a zero of a shape mode's eigenvalue between two
stable states is located, and a step that lands on a state beside the branch is refused.

The reference for each located end is independent of the study's steps: the branch is followed
from a state well before the end by Newton's method in steps of 0.001 pi, its lowest shape
eigenvalue tracked by eigenvector overlap, and its zero then refined by regula falsi.
"""
import json
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from jaxrod.continuation.branch_check import predicted_crossing
from jaxrod.solve.equilibrium import EquilibriumOptions, solve_equilibrium
from jaxrod.model.scenes import trefoil

# The validation tier (-m validation): the tightening side followed at a fine step.
pytestmark = pytest.mark.validation

EXE = [shutil.which("jaxrod") or os.path.join(os.path.dirname(sys.executable), "jaxrod")]
NEWTON = EquilibriumOptions(method="newton", gtol=1e-11, near_null_tol=1e-6)
D, L, N = 7.008, 292.0, 61  # D/L = 0.024


@pytest.fixture(scope="module")
def tightening(tmp_path_factory):
    """Command 1's pipeline (study, then each end located on the extended system) on the
    tightening side at D/L = 0.024, N = 61, with a short opening side."""
    out = tmp_path_factory.mktemp("t024")
    run = subprocess.run([*EXE, "trefoil", "--D", str(D), "--L", str(L), "--N", str(N), "--phi-min=-11.5pi",
                          "--phi-max", "0.5pi", "--out", str(out), "--json", "--no-figures", "--quiet"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    return out, json.loads(run.stdout)


def _step_file(out, phi_after):
    """(q, phi) of the study's last saved state on its first tightening branch with phi > phi_after."""
    best = None
    for f in sorted((out / "steps").glob("minus_*.npz")):
        d = np.load(f)
        if str(d["branch"]) == "symmetric-" and float(d["phi"]) > phi_after:
            if best is None or float(d["phi"]) < best[1]:
                best = (np.asarray(d["q"]), float(d["phi"]))
    return best


def _fine_step_zero(scene, q, phi, h, limit):
    """Newton continuation from (q, phi) in steps h (< 0 here) until the lowest eigenvalue of the
    mode tracked by overlap changes sign; its zero by linear interpolation, in units of pi."""
    e = solve_equilibrium(scene, phi, q, NEWTON)
    lam, v = float(e.stability.eigenvalues[0]), np.asarray(e.stability.eigenvectors[:, 0])
    assert lam > 0.0
    while abs(e.phi) < abs(limit):
        nxt = solve_equilibrium(scene, e.phi + h, e.q, NEWTON, nbr=e.neighbourhood)
        overlap = np.abs(np.asarray(nxt.stability.eigenvectors).T @ v)
        j = int(np.argmax(overlap))
        lam_next = float(nxt.stability.eigenvalues[j])
        if lam_next < 0.0:
            return _secant_zero(scene, e, lam, v, nxt.phi, lam_next) / math.pi
        e, lam, v = nxt, lam_next, np.asarray(nxt.stability.eigenvectors[:, j])
    raise AssertionError("no zero within the limit")


def _secant_zero(scene, e, lam, v, phi_b, lam_b, iterations=4):
    """The zero of the tracked eigenvalue bracketed by (e.phi, lam > 0) and (phi_b, lam_b < 0):
    regula falsi, each trial solved by Newton from the stable end e."""
    phi_a, lam_a = e.phi, lam
    for _ in range(iterations):
        phi = phi_a + (phi_b - phi_a) * lam_a / (lam_a - lam_b)
        t = solve_equilibrium(scene, phi, e.q, NEWTON, nbr=e.neighbourhood)
        j = int(np.argmax(np.abs(np.asarray(t.stability.eigenvectors).T @ v)))
        lam_t = float(t.stability.eigenvalues[j])
        if lam_t > 0.0:
            phi_a, lam_a = phi, lam_t
        else:
            phi_b, lam_b = phi, lam_t
    return phi_a + (phi_b - phi_a) * lam_a / (lam_a - lam_b)


def test_tightening_onset_is_the_fine_step_zero_not_a_late_jump(tightening):
    out, summary = tightening
    located = summary["phi_minus_over_pi"]
    scene = trefoil(D=D, L=L, N=N)
    q, phi = _step_file(out, -11.25 * math.pi)  # on the branch, 0.02 pi before its end
    reference = _fine_step_zero(scene, q, phi, -0.001 * math.pi, -11.3 * math.pi)
    # the reference is the zero of the tracked eigenvalue to ~1e-9 pi (regula falsi inside a bracket of
    # 0.001 pi); the old path, which jumped beside the branch, ended 0.015 pi later
    assert abs(located - reference) < 1e-6, (located, reference)
    assert abs(located - (-11.2675)) < 1e-4


def test_every_end_in_the_outputs_agrees(tightening):
    out, summary = tightening
    critical = json.loads((out / "critical.json").read_text())
    diagram = json.loads((out / "diagram.json").read_text())
    minus = [e for e in critical["events"] if e["direction"] == "minus" and e.get("located")]
    assert minus and minus[0]["phi_over_pi"] == summary["phi_minus_over_pi"]
    text = json.dumps(diagram)
    assert repr(summary["phi_minus_over_pi"])[:12] in text


def test_a_zero_between_two_stable_states_is_predicted():
    """The crossing is predicted from the last state alone: its lowest shape mode's eigenvalue and
    derivative along the branch (here a ring twisted just below Michell's threshold, whose
    buckling pair goes soft linearly in phi)."""
    from dataclasses import replace

    from jaxrod import michell_critical_twist, michell_ring
    from jaxrod.linalg.stability import branch_analysis

    scene = michell_ring(N=32)
    phi_star = michell_critical_twist(0.5)
    phi = 0.9 * phi_star
    e = solve_equilibrium(scene, phi, scene.q_init, EquilibriumOptions(method="newton"))
    stab, _, _, _, dq = branch_analysis(scene, e.q, e.phi, 0)
    e = replace(e, stability=stab)
    # the discrete ring's threshold lies a few percent above the continuum value
    assert predicted_crossing(scene, e, dq, 0.95 * phi_star, 1e-10) is None
    found = predicted_crossing(scene, e, dq, 1.3 * phi_star, 1e-10)
    assert found is not None and phi < found.phi < 1.3 * phi_star


@pytest.mark.parametrize("sparse", [False, True])
def test_the_model_block_is_the_hessian_derivative_along_the_branch(sparse):
    """BranchModel.block (a central difference of the exact Hessian along the branch: the dense
    one, or the sparse one of the O(N) path) against the exact third-derivative contractions
    v_i^T (dH along (du, 1)) v_j by autodiff, on a trefoil with its contact pairs and its slopes
    near zero."""
    from dataclasses import replace

    from jaxrod import relax_to_minimum
    from jaxrod.continuation.branch_check import branch_model
    from jaxrod.linalg.stability import branch_analysis, scene_bilinear_gradient

    scene = trefoil(D=8.0, L=292.0, N=41)
    e = relax_to_minimum(scene, 5.0 * math.pi)
    stab, _, _, _, dq = branch_analysis(scene, e.q, e.phi, 0, tol=1e-6, pinv_tol=1e-6, nbr=e.neighbourhood)
    model = branch_model(scene, replace(e, stability=stab), dq, 1e-6, sparse=sparse)
    u, m = scene.to_scaled(e.q), model.vectors.shape[1]
    exact = np.empty((m, m))
    for i in range(m):
        for j in range(m):
            gu, gp = scene_bilinear_gradient(scene, u, e.phi, e.neighbourhood, model.vectors[:, i],
                                             model.vectors[:, j], 0.0)
            exact[i, j] = float(np.asarray(gu) @ model.du + float(gp))
    assert m == 4 and np.abs(exact).max() > 1e-4
    assert np.abs(model.block - exact).max() <= 1e-6 * np.abs(exact).max()  # measured 1e-8: the difference's roundoff
    assert np.array_equal(model.slopes, np.diag(model.block))


def test_the_located_onset_is_verified_in_every_output(tightening):
    out, summary = tightening
    diagram = json.loads((out / "diagram.json").read_text())
    onset = diagram["onsets"]["minus"]
    assert onset["located"] and onset["phi_over_pi"] == summary["phi_minus_over_pi"]
    end = diagram["ends"][0]
    assert end["confirmed"] and end["verified"]["vanishes"] and end["verified"]["first"]
    assert end["verified"]["overlap"] > 0.9  # the study's critical mode


def test_two_events_in_one_bracket_are_both_reported_in_order(tmp_path):
    """D/L = 0.0202, N = 61, opening side: the lowest eigenvalue crosses zero at 6.74440 pi (a mode
    that mixes with the material's slide), and 1.7e-4 pi later the branch folds. Depending on the
    last bits of the arithmetic, the path on the extended system (pinned gauge) locates the crossing
    (verified: the study's mode, eigenvalue ~1e-15) or meets the fold first and cannot locate it as
    the study's mode; then the study's bracketed crossing is the onset and the fold is listed
    after it. Either way the summary, critical.json and diagram.json give the same onset, before the
    fold."""
    run = subprocess.run([*EXE, "trefoil", "--D", "5.8984", "--L", "292", "--N", "61", "--phi-min=-0.5pi",
                          "--phi-max", "7pi", "--out", str(tmp_path), "--json", "--no-figures", "--quiet"],
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    summary = json.loads(run.stdout)
    critical = json.loads((tmp_path / "critical.json").read_text())
    diagram = json.loads((tmp_path / "diagram.json").read_text())
    events = critical["phi_plus_events"]
    assert [e["phi"] for e in events] == sorted(e["phi"] for e in events)
    onset = events[0]
    assert summary["phi_plus"] == critical["phi_plus"] == onset["phi"] == diagram["onsets"]["plus"]["phi"]
    assert summary["phi_plus_kind"] == onset["kind"]
    assert onset["phi_over_pi"] < 6.7445  # the fold, at 6.74458 pi, is not the onset
    end, event = diagram["ends"][0], critical["events"][0]
    assert end["confirmed"] == event["confirmed"] == (onset["source"] == "extended system")
    if end["confirmed"]:
        assert event["verified"]["vanishes"] and event["verified"]["first"] and len(events) == 1
    else:
        assert [e["source"] for e in events] == ["study", "extended system"]
