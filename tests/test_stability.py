"""Stability analysis: zero modes, negative counts, autodiff sensitivity of a critical twist."""
import math

import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod import Material, clamped_rod, critical_twist, critical_twist_derivative, michell_critical_twist
from jaxrod import ContinuationOptions, EquilibriumOptions, michell_ring, ring, solve_equilibrium, stability

NEWTON = EquilibriumOptions(method="newton")


def test_zero_modes_removed_and_counted():
    scene = ring(N=24, material=Material(1.0, 0.7, 1e3))
    eq = solve_equilibrium(scene, math.pi, options=NEWTON)
    st = eq.stability
    assert st.n_zero_modes == 7 and st.stable and st.n_negative == 0
    # Without removal the raw Hessian has 7 eigenvalues ~0 (3 translations, 3 rotations, twist shift).
    from jaxrod.linalg.stability import scaled_hessian

    raw = np.linalg.eigvalsh(np.asarray(scaled_hessian(scene, scene.to_scaled(jnp.asarray(eq.q)), math.pi)))
    assert np.sum(np.abs(raw) < 1e-9) == 7
    assert st.eigenvalues[0] > 1e-4  # the softest physical mode is well away from zero
    clamped = clamped_rod(N=12, length=1.0, material=Material(1.0, 0.7, 1e3))
    assert stability(clamped, clamped.q_init, 0.0).n_zero_modes == 0


def test_negative_count_beyond_michell():
    scene = michell_ring(N=32)
    below = solve_equilibrium(scene, 5.0 * math.pi, options=NEWTON).stability
    above = solve_equilibrium(scene, 5.6 * math.pi, options=NEWTON).stability
    assert below.n_negative == 0 and above.n_negative == 2


def test_critical_twist_derivative_with_respect_to_material():
    # For the ring, C enters the critical condition only through C * phi (twist moment), so
    # phi* is exactly proportional to 1/C at fixed B, EA: d phi*/dC = -phi*/C. B also sets the
    # extensibility ratio B/(EA R^2) = 6e-6 here, so d phi*/dB = phi*/B up to ~1e-5.
    scene = michell_ring(N=32, nu=0.5)
    an = michell_critical_twist(0.5)
    cp = critical_twist(scene, 0.0, 2 * an, ContinuationOptions(step=an / 8))
    dC = critical_twist_derivative(scene, cp, "C")
    assert dC == pytest.approx(-cp.phi / scene.material.C, rel=1e-7)
    dB = critical_twist_derivative(scene, cp, "B")
    assert dB == pytest.approx(cp.phi / scene.material.B, rel=1e-4)
    # Finite-difference check of dB: re-solve at B(1 +- h).
    h = 1e-3
    phis = []
    for sgn in (-1, 1):
        m = scene.material
        s2 = michell_ring(N=32, nu=0.5)
        s2 = type(s2)(material=Material(B=m.B * (1 + sgn * h), C=m.C, EA=m.EA, D=m.D),
                      rest_lengths=s2.rest_lengths, q_init=s2.q_init, Lk0=s2.Lk0)
        phis.append(critical_twist(s2, 0.0, 2 * an, ContinuationOptions(step=an / 8, tol=1e-10)).phi)
    fd = (phis[1] - phis[0]) / (2 * h * scene.material.B)
    assert dB == pytest.approx(fd, rel=1e-5)
    with pytest.raises(ValueError, match="parameter"):
        critical_twist_derivative(scene, cp, "Q")


def test_the_shape_band_scales_with_N_like_the_shape_modes():
    """A shape mode counts as negative inside the contact band (``shape_modes_in_band``) below
    -scaled_negative_tol: 1e-10 up to N ~ 600, then 0.01 (2 pi / N)^4, as the knot's shape modes
    themselves fall like N^-4 (the trefoil's sit at ~3e-9 at N = 961, where -5e-11 is a real
    crossing that a fixed 1e-10 let pass); slides are never counted, whatever their sign."""
    from types import SimpleNamespace

    import jaxrod as jr
    from jaxrod.linalg.stability import shape_modes_in_band
    from jaxrod.linalg.tolerances import DEFAULT_NEGATIVE_TOL, scaled_negative_tol

    rng = np.random.default_rng(3)
    for N, counted in ((121, False), (961, True)):
        knot = jr.trefoil(D=8.0, L=292.0, N=N)
        expected = DEFAULT_NEGATIVE_TOL if N == 121 else 0.01 * (2 * np.pi / N) ** 4
        assert scaled_negative_tol(knot) == pytest.approx(expected, rel=1e-12)
        shape = rng.normal(size=(knot.n_dof, 1))  # a random field of node motions changes the shape
        e = SimpleNamespace(q=np.asarray(knot.q_init), stability=SimpleNamespace(
            eigenvalues=np.array([-5e-11]), eigenvectors=shape / np.linalg.norm(shape)))
        found = shape_modes_in_band(knot, e, 1e-6)
        assert (len(found) == 1) is counted, (N, found)
        assert shape_modes_in_band(knot, e, 1e-6, strict_tol=DEFAULT_NEGATIVE_TOL) == []  # the fixed band
