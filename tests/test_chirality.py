"""A shape's distance from its mirror image (``measure.chirality``) and a mode's m-fold pattern
(``measure.profiles.mode_pattern``): analytic curves with known symmetry."""
import math

import numpy as np
import pytest

from jaxrod.measure.chirality import ACHIRAL_TOL, mirror_distance
from jaxrod.measure.profiles import mode_pattern
from jaxrod.model.knots import knot_points


def saddle_ring(n, a=0.4):
    """(cos t, sin t, a cos 2t): a quarter turn about z followed by z -> -z maps it onto itself
    (shifted by n/4 nodes), so it is achiral."""
    t = 2 * math.pi * np.arange(n) / n
    return np.stack([np.cos(t), np.sin(t), a * np.cos(2 * t)], axis=1)


def rotation(axis, angle):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


def test_an_achiral_curve_is_its_own_mirror_image_and_a_trefoil_is_not():
    assert mirror_distance(saddle_ring(40)) < 1e-6  # the symmetry maps nodes onto nodes
    assert mirror_distance(saddle_ring(42)) < 1e-5  # ... between nodes: the spline's error
    n = 42  # nodes placed unevenly along the same curve: the shape, not the nodes, is compared
    t = 2 * math.pi * (np.arange(n) + 0.3 * np.sin(np.arange(n))) / n
    assert mirror_distance(np.stack([np.cos(t), np.sin(t), 0.4 * np.cos(2 * t)], axis=1)) < 1e-3
    trefoil = knot_points("3_1", 101)
    d = mirror_distance(trefoil)
    assert d > 10 * ACHIRAL_TOL
    mirrored = trefoil * np.array([1.0, 1.0, -1.0])
    assert mirror_distance(mirrored) == pytest.approx(d, rel=1e-9)  # the left trefoil: as chiral


def test_the_mirror_distance_ignores_placement_labels_and_size():
    x = knot_points("5_2", 80)
    moved = 3.0 * np.roll(x[::-1], 17, axis=0) @ rotation([1, 2, 3], 0.7).T + np.array([5.0, -1.0, 2.0])
    assert mirror_distance(moved) == pytest.approx(mirror_distance(x), rel=3e-3)  # the spline starts at another node


def test_a_mirror_distance_needs_a_polygon():
    with pytest.raises(ValueError, match="x must be"):
        mirror_distance(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="x must be"):
        mirror_distance(np.full((5, 3), np.nan))


@pytest.mark.parametrize("m", [2, 3, 5])
def test_a_rings_m_lobed_modes_have_pattern_m(m):
    t = 2 * math.pi * np.arange(120) / 120
    ring = np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    out_of_plane = np.stack([0 * t, 0 * t, np.cos(m * t)], axis=1)  # Michell's mode for m = 2
    radial = np.cos(m * t)[:, None] * np.stack([np.cos(t), np.sin(t), 0 * t], axis=1)
    assert mode_pattern(ring, out_of_plane) == m
    assert mode_pattern(ring, radial) == m
    assert mode_pattern(ring, 1e-3 * radial) == m  # the amplitude does not matter


def test_a_trefoils_breathing_mode_keeps_its_three_fold_pattern():
    x = knot_points("3_1", 120)
    assert mode_pattern(x, x - x.mean(axis=0)) == 3
    with pytest.raises(ValueError, match="both be"):
        mode_pattern(x, x[:10])
