"""The loose trefoil's critical twists (benchmarks/results/loose_limit.json at nu = 0.5 and
loose_limit_nu0.3.json, converged in N by the accuracy mode) against the limits derived from the
doubly covered twisted ring (docs/guides/loose-limit.md): the opening side tends to the k = 3 instability 2 pi sqrt(5) (1 + nu), the
tightening side to the k = 4 one, 4 pi sqrt(3) (1 + nu) = 2 x Michell."""
import json
import math
import pathlib

import pytest

import jaxrod as jr

RESULTS = pathlib.Path(__file__).resolve().parent.parent / "benchmarks" / "results"
PI = math.pi


# each result file and the smallest D/L it reaches
RUNS = {"loose_limit.json": 0.002, "loose_limit_nu0.3.json": 0.0035}


@pytest.fixture(scope="module", params=sorted(RUNS))
def loose(request):
    return dict(json.loads((RESULTS / request.param).read_text()), smallest=RUNS[request.param])


def test_the_limits_are_the_doubly_covered_rings_instabilities(loose):
    nu = loose["nu"]
    # Michell's criterion C w R / B = sqrt(m^2 - 1), m = k / 2 waves per turn of a circle traversed
    # twice, whole twist phi = w L = 4 pi R w, B / C = 1 + nu
    for k, key in ((3, "k3"), (4, "k4")):
        phi = 4.0 * PI * (1.0 + nu) * math.sqrt((k / 2.0) ** 2 - 1.0)
        assert loose["limits_over_pi"][key] * PI == pytest.approx(phi, rel=1e-14)
    assert loose["limits_over_pi"]["k4"] * PI == pytest.approx(2.0 * jr.michell_critical_twist(nu), rel=1e-14)


@pytest.mark.parametrize("side", ["plus", "minus"])
def test_each_side_approaches_its_limit_as_the_knot_loosens(loose, side):
    limit = loose["limits_over_pi"]["k3" if side == "plus" else "k4"] * PI
    rows = sorted((r for r in loose["rows"] if r["side"] == side), key=lambda r: -r["D_over_L"])
    assert len(rows) >= 6 and rows[-1]["D_over_L"] <= loose["smallest"] and all(r["error"] <= 0.02 * PI for r in rows)
    gaps = [abs(r["phi_star"]) - limit for r in rows]
    # where the gap stands out of its error bar (and the levels were in their asymptotic range, so
    # that the bar is an error estimate): below the limit on the opening side, above it (in
    # magnitude) on the tightening side
    sign = -1.0 if side == "plus" else 1.0
    significant = [(g, r) for g, r in zip(gaps, rows) if abs(g) >= 2.0 * r["error"] and r["extrapolation"]["asymptotic"]]
    assert len(significant) >= 3 and all(sign * g > 0 for g, _ in significant)
    # the gap falls with D/L: tenfold and more from D/L >= 0.02 to the two thinnest, within 0.02 pi there
    loose_gaps = [abs(g) for g in gaps[-2:]]
    assert loose_gaps and max(loose_gaps) <= 0.02 * PI
    assert all(abs(g) >= 10.0 * max(loose_gaps) for g, r in zip(gaps, rows) if r["D_over_L"] >= 0.02)
    # as (D/L)^2, the fitted exponent within two of its standard errors
    law = loose["approach"][side]
    assert abs(law["exponent"] - 2.0) <= 2.0 * law["exponent_error"] and law["exponent_error"] < 0.5
    # far from Michell's single ring, the paper's estimate for the opening side
    assert abs(abs(rows[-1]["phi_star"]) - jr.michell_critical_twist(loose["nu"])) > 1.0 * PI
