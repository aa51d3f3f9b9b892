"""jaxrod critical-curve: each row is the first instability of the branch from phi = 0 at its ratio,
as the point study finds it; where the kind of that event changes along a side, the row is marked
and a warning names it, and the slope check never compares across it.

The point studies here are the library's own calls (``twist_study``, then ``unstable_branches``),
not the curve's, so that a change of the point study shows in both."""
import math
import warnings

import numpy as np
import pytest

import jaxrod.studies.critical_curve as cc

# The validation tier (-m validation): a critical curve of point studies.
pytestmark = pytest.mark.validation

N = 61
# 0.0187: the symmetric state at phi = 0 is a saddle of a shape mode (lowest eigenvalue -6.6e-5), so
# the branch starts at the minimum off the symmetry; 0.0237, a thicker rod, for comparison
RATIOS = (0.0187, 0.0237)


def _point_study(ratio):
    """The opening (phi > 0) side's first instability at one D/L, as ``jaxrod trefoil`` reports it
    (phi_plus: the located end, or the study's bracket where the two disagree). No branch
    switching and a short phi < 0 side: neither changes the first end on the phi > 0 side."""
    from jaxrod.continuation import ContinuationOptions
    from jaxrod.studies.diagram import unstable_branches
    from jaxrod.model.scenes import knot
    from jaxrod.studies.twist import twist_study

    scene = knot("3_1", D=ratio * cc.LENGTH, L=cc.LENGTH, N=N)  # as jaxrod trefoil --D ratio*292 --L 292 builds it
    study = twist_study(scene, -0.5 * math.pi, 16.0 * math.pi, ContinuationOptions(max_switches=0))
    return unstable_branches(scene, study).study.critical


@pytest.fixture(scope="module")
def curve():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        # without the slopes (their programs cost ~7 s to compile here; the slope check is tested on
        # analytic rows below) and without files (tested in test_event_curve.py)
        result = cc.critical_twist_curve("3_1", N, RATIOS, cc.CriticalCurveOptions(sides=("plus",), slopes=False))
        return result, {r: _point_study(r) for r in RATIOS}


def test_the_curve_starts_where_the_symmetric_state_at_phi_0_is_unstable(curve):
    # the point study relaxes to the minimum off the symmetry and goes on; the curve starts as it does
    result, _ = curve
    assert not result["failures"]
    assert [q["D_over_L"] for q in result["rows"]] == list(RATIOS)


def test_every_row_is_the_point_studys_first_instability(curve):
    result, studies = curve
    for q in result["rows"]:
        critical = studies[q["D_over_L"]]
        assert abs(q["phi_star"] - critical["phi_plus"]) <= 1e-8 * math.pi, (q, critical["phi_plus"] / math.pi)
        located = critical.get("phi_plus_located")
        assert q["located"] == (located is not None)
        if located is not None:
            assert q["kind"] == located["kind"]


def _stub(table):
    """first_instabilities from a table {ratio: (kind, phi*, slope) or None}: one side, 'minus'."""
    def first_instabilities(knot, n, ratio, options=None, *, progress=None):
        entry = table[round(float(ratio), 10)]
        if entry is None:
            return {"minus": "no instability within -2 pi (stub)"}
        kind, phi, slope = entry
        return {"minus": dict(side="minus", D_over_L=float(ratio), phi_star=phi, phi_star_over_pi=phi / math.pi,
                              kind=kind, located=True, morse_before=0, morse_after=1, critical_eigenvalue=0.0,
                              residual=0.0, dphi_dratio=slope, phi_bracketed=phi, phi_located=phi, seconds=0.0)}
    return first_instabilities


def test_a_change_of_kind_is_marked_warned_and_never_in_a_secant(monkeypatch):
    # A branch point p* = 0.5 - 10 r up to r = 0.02, then a fold p* = 10 r (two event curves crossing at
    # r = 0.025): the secants on each piece equal the slopes exactly; one across the switch (0.3 - 0.3)
    # would give 0 and a disagreement of 1 at both rows next to it.
    table = {0.01: ("branch_point", 0.4, -10.0), 0.02: ("branch_point", 0.3, -10.0), 0.03: ("fold", 0.3, 10.0),
             0.04: ("fold", 0.4, 10.0)}
    monkeypatch.setattr(cc, "first_instabilities", _stub(table))
    opts = cc.CriticalCurveOptions(sides=("minus",), start_ratio=0.02)
    with pytest.warns(UserWarning, match="switches from a branch_point at D/L = 0.02000 to a fold at 0.03000"):
        result = cc.critical_twist_curve("3_1", 101, sorted(table), opts)
    rows = result["rows"]
    assert [q["switched"] for q in rows] == [False, False, True, False]
    assert rows[2]["previous_kind"] == "branch_point" and rows[2]["previous_ratio"] == 0.02
    assert result["switches"] == [dict(side="minus", D_over_L=0.03, kind="fold", previous_kind="branch_point")]
    np.testing.assert_allclose([q["secant_slope"] for q in rows], [-10.0, -10.0, 10.0, 10.0], rtol=1e-9)
    np.testing.assert_allclose([q["slope_disagreement"] for q in rows], 0.0, atol=1e-9)


def test_a_jump_within_one_kind_is_flagged_by_the_slope_check(monkeypatch):
    # A fold whose p* jumps by 0.1 between 0.02 and 0.03 with the slope 1 throughout: the same kind, so
    # no switch, but the secants (~10) disagree with the slope by more than SLOPE_DOUBT
    table = {0.01: ("fold", 0.40, 1.0), 0.02: ("fold", 0.41, 1.0), 0.03: ("fold", 0.52, 1.0), 0.04: ("fold", 0.53, 1.0)}
    monkeypatch.setattr(cc, "first_instabilities", _stub(table))
    with pytest.warns(UserWarning, match="minus D/L = 0.02000, minus D/L = 0.03000"):
        result = cc.critical_twist_curve("3_1", 101, sorted(table), cc.CriticalCurveOptions(sides=("minus",)))
    assert not any(q["switched"] for q in result["rows"])
    assert [q["slope_disagreement"] > cc.SLOPE_DOUBT for q in result["rows"]] == [False, True, True, False]
