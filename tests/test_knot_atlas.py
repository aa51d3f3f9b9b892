"""Scenes of the knot atlas (issue 9, part B): the figure-eight 4_1, the cinquefoil 5_1 and the
three-twist knot 5_2 from published parametrisations, beside the trefoil; each refuses a rod
shorter than its ideal ropelength (acceptance 5)."""
import numpy as np
import pytest

import jaxrod as jr
from jaxrod.model.geometry import closest_approach
from jaxrod.model.scenes import IDEAL_ROPELENGTH, knot_points
from jaxrod.model.topology import writhe

# |Lk0| = |round(Wr)| of each parametrisation (4_1 is achiral: its writhe is ~0).
LINKING = {"3_1": 3, "4_1": 0, "5_1": 7, "5_2": 4}


@pytest.mark.parametrize("name", sorted(IDEAL_ROPELENGTH))
def test_each_knot_refuses_a_rod_shorter_than_its_ideal_ropelength(name):
    ideal = IDEAL_ROPELENGTH[name]
    D = 8.0
    with pytest.raises(ValueError, match=f"ropelength {ideal}") as info:
        jr.knot(name, D=D, L=D * (ideal - 0.01), N=61)
    assert "L/D" in str(info.value)
    with pytest.warns(UserWarning, match="nearly tight"):  # just above the ideal: allowed, with a warning
        scene = jr.knot(name, D=D, L=D * (ideal + 0.5), N=61)
    assert scene.n_nodes == 61


@pytest.mark.parametrize("name", sorted(IDEAL_ROPELENGTH))
def test_each_knot_is_a_simple_closed_curve_with_its_linking_number(name):
    points = knot_points(name, 400)
    length = np.sum(np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1))
    assert closest_approach(points) > 1e-4 * length  # never through itself
    scene = jr.knot(name, D=8.0, L=292.0, N=61)
    assert abs(scene.Lk0) == LINKING[name] and scene.Lk0 == round(float(writhe(points)))
    if name == "4_1":
        assert abs(float(writhe(points))) < 0.2  # achiral


def test_unknown_knot_is_refused():
    with pytest.raises(ValueError, match="knot must be one of"):
        jr.knot("6_1", D=8.0, L=292.0, N=61)
