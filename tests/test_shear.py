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


@pytest.mark.validation  # the validation tier (-m validation): a limit over three shear stiffnesses
def test_a_rings_critical_twist_tends_to_the_kirchhoff_one_as_one_over_the_shear_stiffness():
    from jaxrod.model.cosserat import cosserat_ring
    from jaxrod.studies.shear import ring_critical_twist

    # the Cosserat ring's Michell instability (a double branch point, located by the engine) at
    # kGA = 100, 1000 and 10^8 (B = 1, R = 1): the shear lowers phi* by ~13.4 / kGA rad, first order
    # in the compliance, so the differences fall tenfold per decade (measured at N = 16: 9.98)
    phis = []
    for GA in (1e2, 1e3, 1e8):
        event = ring_critical_twist(cosserat_ring(N=16, length=2 * math.pi, B=B, C=C, EA=1e6, GA=GA))
        assert event.multiplicity == 2
        phis.append(float(event.p))
    ratio = (phis[0] - phis[2]) / (phis[1] - phis[2])
    assert 9.5 < ratio < 10.5 and phis[0] < phis[1] < phis[2]
    michell = 2 * math.pi * math.sqrt(3) * B / C  # the Kirchhoff continuum; N = 16 is 0.9 % below it
    assert phis[2] == pytest.approx(michell, rel=1.2e-2)


@pytest.fixture(scope="module")
def trefoil_41():
    import jaxrod as jr

    knot = jr.trefoil(D=8.0, L=292.0, N=41)
    return knot, jr.relax_to_minimum(knot, 0.0)


def test_a_cosserat_knots_gauge_holds_its_seven_symmetries_and_nothing_else(trefoil_41):
    import dataclasses

    import jax
    import jax.numpy as jnp
    import numpy as np

    from jaxrod.model.cosserat import cosserat_knot
    from jaxrod.studies.shear import relax_cosserat

    knot = cosserat_knot(*trefoil_41)
    u = relax_cosserat(knot)
    near = knot.contact_list(u)
    contact = (near.pairs, near.mask)
    autodiff = np.asarray(jax.jit(jax.hessian(knot.energy))(jnp.asarray(u), 0.0, knot.params, contact))
    # the Hessian assembled from its edge, joint and contact-pair blocks is jax.hessian's, here and twisted
    assert np.max(np.abs(np.asarray(jax.jit(knot.hessian)(jnp.asarray(u), 0.0, knot.params, contact)) - autodiff)) \
        <= 1e-12 * np.max(np.abs(autodiff))
    twisted = np.asarray(jax.jit(jax.hessian(knot.energy))(jnp.asarray(u), -3.0, knot.params, contact))
    assert np.max(np.abs(np.asarray(jax.jit(knot.hessian)(jnp.asarray(u), -3.0, knot.params, contact)) - twisted)) \
        <= 1e-12 * np.max(np.abs(twisted))
    pinned = np.linalg.eigvalsh(autodiff)
    free = dataclasses.replace(knot, held=())  # every DOF free, at the same state
    z = jnp.concatenate([a.ravel() for a in knot.full(jnp.asarray(u))])
    full = np.linalg.eigvalsh(np.asarray(jax.jit(jax.hessian(free.energy))(z, 0.0, free.params, contact)))
    by_size = np.sort(np.abs(full))
    # 3 translations, 3 rotations and the frames' common turn about d3: exact zeros at an equilibrium;
    # the eighth is the near-free slide (~1e-4 against a largest of ~1e3), and none is negative
    assert np.all(by_size[:7] < 1e-9 * full[-1]) and by_size[7] > 1e-8 * full[-1] and full[0] > -1e-9 * full[-1]
    # the pinned problem keeps the rest and nothing else: positive definite, its lowest the slide
    assert pinned.size == full.size - 7 and pinned[0] > 1e-8 * pinned[-1]


def test_a_stiff_cosserat_knot_relaxes_to_the_kirchhoff_knot_and_shear_moves_it(trefoil_41):
    import dataclasses

    import jax.numpy as jnp
    import numpy as np

    from jaxrod.model.cosserat import cosserat_knot
    from jaxrod.studies.shear import relax_cosserat

    knot = cosserat_knot(*trefoil_41)
    assert knot.GA == pytest.approx(0.9 * 8.0 * knot.C / 64.0)  # Cowper's k = 0.9 at nu = 0.5; GA = 8 C / D^2
    moves = {}
    for scale in (1.0, 1e4):
        stiff = dataclasses.replace(knot, GA=knot.GA * scale)
        x = np.asarray(stiff.full(jnp.asarray(relax_cosserat(stiff)))[0])
        moves[scale] = float(np.max(np.linalg.norm(x - knot.x_ref, axis=1)))
    # kGA -> oo: the Kirchhoff equilibrium up to the two discretisations' O(h^2) difference (edges
    # of 7.1 mm: 0.014 mm, 0.2 % of D; 0.006 mm at N = 61); shear moves the nodes twice as far
    assert moves[1e4] < 2e-3 * 8.0 and moves[1.0] > 1.5 * moves[1e4]
