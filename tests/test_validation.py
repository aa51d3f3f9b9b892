"""Acceptance 6: bad input raises a clear error naming the parameter."""
import math

import numpy as np
import pytest

from jaxrod import Material, clamped_rod, closed_curve, critical_twist, michell_ring, ring, solve_equilibrium


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(E=-1.0, nu=0.5, D=1.0), "E"),
        (dict(E=0.0, nu=0.5, D=1.0), "E"),
        (dict(E=math.inf, nu=0.5, D=1.0), "E"),
        (dict(E=1.0, nu=0.5, D=-2.0), "D"),
        (dict(E=1.0, nu=0.5, D=math.nan), "D"),
        (dict(E=1.0, nu=0.6, D=1.0), "nu"),
        (dict(E=1.0, nu=-1.0, D=1.0), "nu"),
        (dict(E=1.0, nu=math.nan, D=1.0), "nu"),
    ],
)
def test_bad_engineering_material(kwargs, name):
    with pytest.raises(ValueError, match=rf"^{name} "):
        Material.from_engineering(**kwargs)


@pytest.mark.parametrize("field", ["B", "C", "EA"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.nan, math.inf])
def test_bad_stiffness(field, value):
    kw = dict(B=1.0, C=1.0, EA=1.0)
    kw[field] = value
    with pytest.raises(ValueError, match=rf"^{field} "):
        Material(**kw)


def test_bad_geometry_and_resolution():
    mat = Material(1.0, 1.0, 10.0)
    with pytest.raises(ValueError, match="^N "):
        ring(N=3, material=mat)
    with pytest.raises(ValueError, match="^N "):
        michell_ring(N=2)
    with pytest.raises(ValueError, match="^N "):
        clamped_rod(N=4, length=1.0, material=mat)
    with pytest.raises(ValueError, match="^length "):
        clamped_rod(N=10, length=-1.0, material=mat)
    with pytest.raises(ValueError, match="^length "):
        clamped_rod(N=10, length=math.nan, material=mat)
    with pytest.raises(ValueError, match="^radius "):
        ring(N=10, material=mat, radius=0.0)
    with pytest.raises(ValueError, match="^nu "):
        michell_ring(N=16, nu=0.9)
    with pytest.raises(ValueError, match="points"):
        closed_curve(np.full((10, 3), np.nan), material=mat)
    with pytest.raises(ValueError, match="^N "):
        closed_curve(np.random.default_rng(0).normal(size=(3, 3)), material=mat)


def test_non_finite_twist():
    scene = michell_ring(N=8)
    with pytest.raises(ValueError, match="^phi "):
        solve_equilibrium(scene, math.nan)
    with pytest.raises(ValueError, match="^phi "):
        solve_equilibrium(scene, math.inf)
    with pytest.raises(ValueError, match="^phi_stop "):
        critical_twist(scene, 0.0, math.inf)
    with pytest.raises(ValueError, match="^phi_start "):
        critical_twist(scene, math.nan, 1.0)
