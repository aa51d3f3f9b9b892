"""No public function answers None or an empty dict in place of a result: it raises, or returns a
result that carries its reason."""
import math

import numpy as np
import pytest

import jaxrod as jr
from jaxrod.continuation import NoCrossingError
from jaxrod.studies.coarse import CoarseEstimates, CoarseLevelTooSmall, coarse_companion
from jaxrod.studies.diagram import BranchEnd, EndNotFound

PI = math.pi


def test_an_end_that_was_not_met_raises_with_its_reason():
    end = BranchEnd("plus", "symmetric+", None, [], None, "no fold or branch point within 60 points")
    assert not end.located and end.unstable == []
    with pytest.raises(EndNotFound, match="within 60 points") as caught:
        end.kind
    assert caught.value.end is end
    with pytest.raises(EndNotFound, match="within 60 points"):
        end.phi


def test_the_coarse_companion_below_the_resolution_raises(tmp_path):
    ring = jr.michell_ring(N=13)  # the coarse level would have 7 nodes, below the 8 a rod needs
    with pytest.raises(CoarseLevelTooSmall, match="at least 8 nodes"):
        coarse_companion(ring, str(tmp_path), {"instabilities": []})


def test_the_coarse_companion_says_why_a_side_has_no_estimate(tmp_path):
    found = coarse_companion(jr.michell_ring(N=24), str(tmp_path), {"instabilities": [], "tol": 1e-3})
    assert isinstance(found, CoarseEstimates) and not found
    assert set(found.reasons) == {"plus", "minus"} and all(found.reasons.values())


def test_critical_twists_without_an_end_in_range_raises():
    with pytest.raises(NoCrossingError):
        jr.critical_twists(jr.michell_ring(N=24), -0.5 * PI, 0.5 * PI)


def test_the_public_results_are_results():
    ring = jr.michell_ring(N=24)
    eq = jr.equilibrium(ring, 0.5)
    assert eq is not None and eq.stability.minimum and eq.stability.morse_index == 0
    report = jr.stability(ring, eq.q, eq.phi)
    assert report.n_zero_modes > 0 and report.saddle_mode is None and report.saddle_kind is None
    assert np.all(np.asarray(report.eigenvalues) > -report.tol)
