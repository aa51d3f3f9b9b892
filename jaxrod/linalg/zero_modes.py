"""The symmetry (zero) modes of a rod's Hessian as an orthonormal basis.

A closed or free rod's energy does not change under its 3 translations, 3 rotations and the uniform
shift of its twist angles: the Hessian is singular along them (exactly for translations and the
twist shift, to O(|gradient|) for rotations). Every backend removes them the same way: it works on
their orthogonal complement Z-perp, Z = ``zero_mode_basis(scene, u, phi)``."""
from __future__ import annotations

import jax.numpy as jnp

__all__ = ["orthonormal_columns", "zero_mode_basis", "ZERO_MODE_RTOL"]

# Singular values below this fraction of the largest carry no rank (degenerate generators, e.g.
# rotations about a straight rod's own axis).
ZERO_MODE_RTOL = 1e-10


def orthonormal_columns(z, rtol=ZERO_MODE_RTOL):
    """Orthonormal basis of the column space of z (n, k), as (n, k) with columns that carry no
    rank zeroed out (rank found from the singular values, so it may vary under jit)."""
    if z.shape[1] == 0:
        return z
    u, s, _ = jnp.linalg.svd(z, full_matrices=False)
    keep = s > rtol * jnp.max(s)
    return u * keep[None, :]


def zero_mode_basis(scene, u, phi):
    """(n, z) orthonormal basis of the scene's symmetry generators at the scaled DOFs u (columns
    without rank zeroed); traceable."""
    return orthonormal_columns(scene.scaled_zero_modes(u, phi))
