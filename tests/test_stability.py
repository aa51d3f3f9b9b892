"""Stability analysis: zero modes, negative counts, autodiff sensitivity of a critical twist."""
import math

import jax.numpy as jnp
import numpy as np
import pytest

from jaxrod import Material, clamped_rod, critical_twist, critical_twist_derivative, michell_critical_twist
from jaxrod import ContinuationOptions, michell_ring, ring, solve_equilibrium, stability


def test_zero_modes_removed_and_counted():
    scene = ring(24, Material(1.0, 0.7, 1e3))
    eq = solve_equilibrium(scene, math.pi, method="newton")
    st = eq.stability
    assert st.n_zero_modes == 7 and st.stable and st.n_negative == 0
    # Without removal the raw Hessian has 7 eigenvalues ~0 (3 translations, 3 rotations, twist shift).
    from jaxrod.stability import scaled_hessian

    raw = np.linalg.eigvalsh(np.asarray(scaled_hessian(scene, scene.to_scaled(jnp.asarray(eq.q)), math.pi)))
    assert np.sum(np.abs(raw) < 1e-9) == 7
    assert st.eigenvalues[0] > 1e-4  # the softest physical mode is well away from zero
    clamped = clamped_rod(12, 1.0, Material(1.0, 0.7, 1e3))
    assert stability(clamped, clamped.q_init, 0.0).n_zero_modes == 0


def test_negative_count_beyond_michell():
    scene = michell_ring(32)
    below = solve_equilibrium(scene, 5.0 * math.pi, method="newton").stability
    above = solve_equilibrium(scene, 5.6 * math.pi, method="newton").stability
    assert below.n_negative == 0 and above.n_negative == 2


def test_critical_twist_derivative_with_respect_to_material():
    # For the ring, C enters the critical condition only through C * phi (twist moment), so
    # phi* is exactly proportional to 1/C at fixed B, EA: d phi*/dC = -phi*/C. B also sets the
    # extensibility ratio B/(EA R^2) = 6e-6 here, so d phi*/dB = phi*/B up to ~1e-5.
    scene = michell_ring(32, nu=0.5)
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
        s2 = michell_ring(32, nu=0.5)
        s2 = type(s2)(material=Material(B=m.B * (1 + sgn * h), C=m.C, EA=m.EA, D=m.D),
                      rest_lengths=s2.rest_lengths, q_init=s2.q_init, Lk0=s2.Lk0)
        phis.append(critical_twist(s2, 0.0, 2 * an, ContinuationOptions(step=an / 8, tol=1e-10)).phi)
    fd = (phis[1] - phis[0]) / (2 * h * scene.material.B)
    assert dB == pytest.approx(fd, rel=1e-5)
    with pytest.raises(ValueError, match="parameter"):
        critical_twist_derivative(scene, cp, "Q")
