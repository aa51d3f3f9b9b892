"""Cosserat rods with shear and extension (jaxrod.model.cosserat, jaxrod.studies.shear): a cantilever's
tip deflection against Timoshenko's bending-plus-shear formula, and a pinned column's buckling load,
located by the pseudo-arclength engine as a double branch point, against the formula the model's
shear strain (measured in the material frame) implies: Haringx's, extended to a finite EA, not
Engesser's, which lies 24 % lower at P_E / kGA = 1."""
import math

import pytest

from jaxrod.model.cosserat import cosserat_rod
from jaxrod.studies.shear import (cantilever_tip_deflection, column_buckling_load, engesser_load, euler_load,
                                  haringx_load, timoshenko_deflection)

L, B, C = 1.0, 1.0, 1.0 / 1.5


def test_a_cantilevers_tip_deflection_is_timoshenkos_at_n_200():
    # GA = 3 B / L^2: shear adds a quarter to the bending deflection; the discrete error falls as
    # 0.1 / N^2 (measured: 4e-4, 1e-4, 2.5e-5, 6.25e-6 at N = 25, 50, 100, 200)
    rod = cosserat_rod(N=200, length=L, B=B, C=C, EA=1e4, GA=3.0)
    exact = timoshenko_deflection(1e-3, L, B, 3.0)
    assert cantilever_tip_deflection(rod, 1e-3) == pytest.approx(exact, rel=1e-4)
    assert abs(exact - timoshenko_deflection(1e-3, L, B, math.inf)) > 0.2 * exact  # shear is not negligible here


def test_a_columns_buckling_load_is_haringxs_not_engessers():
    P_E = euler_load(L, B)
    GA, EA = P_E, 1e3 * P_E  # P_E / kGA = 1, where the two formulas differ by 24 %
    loads = []
    for N in (10, 20):
        event = column_buckling_load(cosserat_rod(N=N, length=L, B=B, C=C, EA=EA, GA=GA, support="pinned"))
        assert event.multiplicity == 2  # the two planes of bending
        loads.append(float(event.p))
    richardson = (4.0 * loads[1] - loads[0]) / 3.0  # second order in 1 / N
    haringx = haringx_load(P_E, GA, EA)
    assert richardson == pytest.approx(haringx, rel=1e-3)
    assert abs(loads[1] - haringx) < abs(loads[0] - haringx) / 3.5  # the error falls fourfold
    assert haringx / engesser_load(P_E, GA) == pytest.approx((math.sqrt(5.0) - 1.0), rel=1e-2)  # 1.236 at EA = oo


def test_bad_input_names_the_argument():
    with pytest.raises(ValueError, match="support"):
        cosserat_rod(N=10, length=L, B=B, C=C, EA=1.0, GA=1.0, support="clamped-clamped")
    with pytest.raises(ValueError, match="GA"):
        cosserat_rod(N=10, length=L, B=B, C=C, EA=1.0, GA=0.0)
    with pytest.raises(ValueError, match="N"):
        cosserat_rod(N=1, length=L, B=B, C=C, EA=1.0, GA=1.0)
    with pytest.raises(ValueError, match="cantilever"):
        cantilever_tip_deflection(cosserat_rod(N=4, length=L, B=B, C=C, EA=1.0, GA=1.0, support="pinned"), 1.0)
